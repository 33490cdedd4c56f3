"""ShuntSw: ANDES' switched shunt, on a bus: capacitor or reactor steps switched in and out when the
bus voltage leaves a band, one step at a time, no sooner than a delay after the last switching.

States  x = (sel [-]: the number of steps in, a whole number; tau [s]: the time since the last
        switching, or since the start)
Inputs  u = (Vs [pu], theta_vs [rad]: the bus voltage, network frame)
Outputs y = (I_re, I_im [pu, system base]: the current injected into the bus, network frame; P, Q
        [pu, system base]: the power injected into the bus, generator convention)

    G + j B = G_sel + j B_sel   (the admittance with `sel` steps in: the tables G0..G8, B0..B8)
    I = -(G + j B) Vs e^{j theta},   P = -G Vs^2,   Q = B Vs^2
    dsel/dt = 0,   dtau/dt = 1 while tau < dt (then 0: ready)
    switching (the reset, where integrators restart: each communication step of an FMU, each step
    of the monolithic DAE whose end it moves):
        tau >= dt and Vs < vref - dv and sel < n:  sel + 1, tau = 0
        tau >= dt and Vs > vref + dv and sel > 0:  sel - 1, tau = 0

(ANDES 2.0 model reference, StaticShunt: ShuntSw, its ShuntAdjust and SwBlock.) ANDES' blocks
(`bs`, `gs`: a step's susceptance and conductance per block, `ns`: the steps of each block) expand
into the cumulative tables B_k, G_k = b, g with the first k steps in, k = 0 .. n (n = the sum of
`ns`, at most MAX_STEPS here), on the system base as ANDES converts them; the conversion reads them
from ANDES' SwBlock. ANDES switches the steps in its power flow too (without delay); the time
domain starts with the steps of its load flow (`sel` found from the load flow's reactive power)
and its timer at 0 (ANDES' t_last = 0 at TDS initialisation: a first switching from t = dt on).
ANDES checks at every step of its own; here the switching happens at the first restart after the
conditions hold (within a communication step).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..component import Component, Initialisation, Parameters, Quantity
from ..piecewise import where
from ..ports import BusPort, Ports
from .common import finite_inputs

MAX_STEPS = 8  # steps a ShuntSw may have here (ANDES: any; the stock cases have 5)
READY_MARGIN = 1e-9  # relative: a timer this close to its delay has run it out (its stop is located to rounding)


@dataclass(frozen=True)
class ShuntSwParams(Parameters):
    """Cumulative tables B0..B8, G0..G8 [pu, system base] (the admittance with k steps in), n the
    number of steps, the voltage band vref +- dv [pu] and the delay dt [s] between switchings."""

    B0: float = 0.0
    B1: float = 0.0
    B2: float = 0.0
    B3: float = 0.0
    B4: float = 0.0
    B5: float = 0.0
    B6: float = 0.0
    B7: float = 0.0
    B8: float = 0.0
    G0: float = 0.0
    G1: float = 0.0
    G2: float = 0.0
    G3: float = 0.0
    G4: float = 0.0
    G5: float = 0.0
    G6: float = 0.0
    G7: float = 0.0
    G8: float = 0.0
    n: float = 0.0
    vref: float = 1.0
    dv: float = 0.05
    dt: float = 30.0

    def check(self) -> None:
        self.require("n", self.n == int(self.n) and 0 <= self.n <= MAX_STEPS, f"be a whole number in [0, {MAX_STEPS}]")
        self.require("vref", 0.5 <= self.vref <= 1.5, "lie in [0.5, 1.5] pu")
        self.require("dv", 0.0 < self.dv <= 0.5, "lie in (0, 0.5] pu")
        self.require("dt", 0.0 <= self.dt <= 3600.0, "lie in [0, 3600] s")
        for k in range(MAX_STEPS + 1):
            for name in (f"B{k}", f"G{k}"):
                self.require(name, abs(getattr(self, name)) <= 1e3, "lie in [-1000, 1000] pu")

    def table(self, kind: str) -> tuple:
        """(B0, .., Bn) or (G0, .., Gn) [pu]."""
        return tuple(getattr(self, f"{kind}{k}") for k in range(int(self.n) + 1))


def admittance(m, sel, p: ShuntSwParams) -> tuple:
    """(G, B) [pu] with `sel` steps in (a whole number in [0, n])."""
    G, B = p.G0 + 0.0 * sel, p.B0 + 0.0 * sel
    for k in range(1, int(p.n) + 1):
        G = where(m, sel >= k - 0.5, p.table("G")[k] + 0.0 * sel, G)
        B = where(m, sel >= k - 0.5, p.table("B")[k] + 0.0 * sel, B)
    return G, B


def derivatives(x, u, p: ShuntSwParams, m):
    """(dsel/dt, dtau/dt) = (0, 1 until tau reaches dt, then 0: ready to switch)."""
    return 0.0 * x[0], where(m, x[1] < p.dt, 1.0 + 0.0 * x[1], 0.0 * x[1])


def reset(x, u, p: ShuntSwParams, m):
    """(sel, tau) after a switching: a step in below the band, out above it, once tau >= dt."""
    sel, tau = x
    Vs = u[0]
    ready = tau >= p.dt - READY_MARGIN * max(1.0, p.dt)  # the timer stops at dt, as located: to its rounding
    step_in = where(m, Vs < p.vref - p.dv, where(m, sel < p.n - 0.5, 1.0 + 0.0 * sel, 0.0 * sel), 0.0 * sel)
    step_out = where(m, Vs > p.vref + p.dv, where(m, sel > 0.5, -1.0 + 0.0 * sel, 0.0 * sel), 0.0 * sel)
    change = where(m, ready, step_in + step_out, 0.0 * sel)
    switched = where(m, change * change > 0.5, 1.0 + 0.0 * sel, 0.0 * sel)
    return sel + change, tau * (1.0 - switched)


def outputs(x, u, p: ShuntSwParams, m):
    """(I_re, I_im, P, Q) [pu, system base, injected into the bus]."""
    Vs, theta = u
    G, B = admittance(m, x[0], p)
    V_re, V_im = Vs * m.cos(theta), Vs * m.sin(theta)
    return -(G * V_re - B * V_im), -(G * V_im + B * V_re), -G * Vs * Vs, B * Vs * Vs


def equilibrium(u, p: ShuntSwParams) -> np.ndarray:
    """All steps out, the timer run out (ready); a case's start takes `sel` from its load flow and
    the timer at 0 (_start)."""
    finite_inputs(u, "ShuntSw")
    return np.array([0.0, p.dt])


def _start(given, p: ShuntSwParams) -> tuple:
    """(sel, 0): the steps in whose admittance draws the load flow's P0 + j Q0 at V0; ValueError
    where none does."""
    V0 = float(given["V0"])
    G, B = -float(given["P0"]) / V0 ** 2, float(given["Q0"]) / V0 ** 2
    for k, (g, b) in enumerate(zip(p.table("G"), p.table("B"))):
        if abs(g - G) <= 1e-9 * max(1.0, abs(G)) and abs(b - B) <= 1e-9 * max(1.0, abs(B)):
            return np.array([float(k), 0.0]), {}
    raise ValueError(f"ShuntSw: no number of steps gives G + jB = {G:.6g} + j{B:.6g} pu at the load flow "
                     f"(B: {', '.join(f'{b:g}' for b in p.table('B'))})")


SHUNTSW = Component(
    name="shuntsw",
    description="ShuntSw switched shunt (ANDES): steps switched by the bus voltage after a delay, on a bus",
    states=(Quantity("sel", "-", "steps switched in (a whole number)"),
            Quantity("tau", "s", "time since the last switching")),
    inputs=(Quantity("Vs", "pu", "bus voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
            Quantity("theta_vs", "rad", "bus voltage angle", start=0.0, operating_range=(-0.5, 0.5))),
    outputs=(Quantity("I_re", "pu", "current injected into the bus, real part (network frame, system base)"),
             Quantity("I_im", "pu", "current injected into the bus, imaginary part (network frame, system base)"),
             Quantity("P", "pu", "active power injected into the bus (system base)"),
             Quantity("Q", "pu", "reactive power injected into the bus (system base)")),
    params_type=ShuntSwParams,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(1.0, 1.0),
    reset=reset,
    ports=Ports(bus=BusPort(voltage=("Vs", "theta_vs"), current=("I_re", "I_im"))),
    affine_current=True,
    initialisation=Initialisation((), _start),
)
