"""PV and Slack: ANDES' static generators in the time domain, for a generator the case gives no
dynamic model: components without states whose current holds the load flow's set points.

States  none
Inputs  u = (Vs [pu], theta_vs [rad]: the bus voltage, network frame; P0, Q0 [pu, system base]: the
        power injected at the load flow (generator convention), V0 [pu], theta0 [rad]: the bus
        voltage there; set points the start takes from the load flow, held after)
Outputs y = (I_re, I_im [pu, system base]: the current injected into the bus, network frame; P, Q
        [pu, system base]: the power injected into the bus, generator convention)

ANDES keeps a static generator's own equations in its time-domain simulation where no machine or
converter names it (`gen`): a PV bus holds its active power at p0 and its voltage magnitude at v0
with whatever reactive power that takes (its reactive limits are off there: ANDES' pv2pq = 0), the
slack holds its voltage magnitude v0 and angle a0 (an infinite bus). Both are algebraic: exact
constraints of the network. Here they are bus devices like any other, as stiff sources:

    PV:     P = P0,   Q = Q0 + Kv (V0 - Vs)          I = (P - j Q) e^{j theta} / Vs
    Slack:  I = I0 + (V0 e^{j theta0} - Vs e^{j theta}) / (j xs),   I0 = conj((P0 + j Q0) / (V0 e^{j theta0}))

Kv [pu reactive power per pu voltage, system base] and xs [pu, system base] set how stiff: the
voltage held moves by dQ / Kv (PV) and xs |dI| (slack) from ANDES' exact constraint, 1e-5 pu per pu
of reactive power or current at the defaults (1e5, 1e-5: the stiffness of ANDES' EI_33 sources,
GENCLS with xd1 = 1e-5, which both of opfmu's solvers take). At the load flow both inject exactly
P0 + j Q0. The slack's current is affine in the bus voltage (its Norton form), the PV's is not.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import BusPort, Ports
from .common import finite_inputs
from .zip import current

STIFFNESS = (1.0, 1e8)  # pu: the range of Kv (and of 1 / xs)


@dataclass(frozen=True)
class PVParams(Parameters):
    """Kv [pu reactive power per pu voltage, system base]: how stiffly the PV holds its voltage."""

    Kv: float = 1e5

    def check(self) -> None:
        low, high = STIFFNESS
        self.require("Kv", low <= self.Kv <= high, f"lie in [{low:g}, {high:g}] pu")


@dataclass(frozen=True)
class SlackParams(Parameters):
    """xs [pu, system base]: the reactance behind which the slack holds its voltage."""

    xs: float = 1e-5

    def check(self) -> None:
        low, high = STIFFNESS
        self.require("xs", 1 / high <= self.xs <= 1 / low, f"lie in [{1 / high:g}, {1 / low:g}] pu")


def _no_state(x, u, p, m):
    """(): a static generator has no state."""
    return ()


def pv_outputs(x, u, p: PVParams, m):
    """(I_re, I_im, P, Q) [pu, system base, injected] for u = (Vs, theta_vs, P0, Q0, V0, theta0)."""
    Vs, theta, P0, Q0, V0, _ = u
    Q = Q0 + p.Kv * (V0 - Vs)
    return (*current(Vs, theta, P0, Q, m), P0, Q)


def slack_outputs(x, u, p: SlackParams, m):
    """(I_re, I_im, P, Q) [pu, system base, injected] for u = (Vs, theta_vs, P0, Q0, V0, theta0)."""
    Vs, theta, P0, Q0, V0, theta0 = u
    c0, s0, c, s = m.cos(theta0), m.sin(theta0), m.cos(theta), m.sin(theta)
    I0_re, I0_im = current(V0, theta0, P0, Q0, m)
    dV_re, dV_im = V0 * c0 - Vs * c, V0 * s0 - Vs * s
    I_re, I_im = I0_re + dV_im / p.xs, I0_im - dV_re / p.xs
    V_re, V_im = Vs * c, Vs * s
    return I_re, I_im, V_re * I_re + V_im * I_im, V_im * I_re - V_re * I_im


def _equilibrium(name: str):
    def equilibrium(u, p) -> np.ndarray:
        """The (empty) state at rest at finite inputs."""
        finite_inputs(u, name)
        return np.zeros(0)
    return equilibrium


def _start(given, p) -> tuple:
    """(no state, no solved input): P0, Q0, V0, theta0 are the load-flow point's (Component.start
    takes them from `given`); ValueError where the bus voltage given is not V0 at theta0."""
    if not (abs(float(given["Vs"]) - float(given["V0"])) <= 1e-12 * abs(float(given["V0"]))
            and abs(float(given["theta_vs"]) - float(given["theta0"])) <= 1e-12 * max(1.0, abs(float(given["theta0"])))):
        raise ValueError(f"static generator: started at {given['Vs']!r} pu, {given['theta_vs']!r} rad, not at its "
                         f"load flow's {given['V0']!r} pu, {given['theta0']!r} rad")
    return np.zeros(0), {}


_INPUTS = (Quantity("Vs", "pu", "bus voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
           Quantity("theta_vs", "rad", "bus voltage angle", start=0.0, operating_range=(-0.5, 0.5)),
           Quantity("P0", "pu", "active power injected at the load flow (system base; set point)", start=0.5,
                    operating_range=(0.0, 1.0)),
           Quantity("Q0", "pu", "reactive power injected at the load flow (system base; set point)", start=0.1,
                    operating_range=(-0.5, 0.5)),
           Quantity("V0", "pu", "bus voltage magnitude held (the load flow's; set point)", start=1.0,
                    operating_range=(0.9, 1.1), minimum=0.01),
           Quantity("theta0", "rad", "bus voltage angle at the load flow (set point)", start=0.0,
                    operating_range=(-0.5, 0.5)))
_OUTPUTS = (Quantity("I_re", "pu", "current injected into the bus, real part (network frame, system base)"),
            Quantity("I_im", "pu", "current injected into the bus, imaginary part (network frame, system base)"),
            Quantity("P", "pu", "active power injected into the bus (system base)"),
            Quantity("Q", "pu", "reactive power injected into the bus (system base)"))
_PORTS = Ports(bus=BusPort(voltage=("Vs", "theta_vs"), current=("I_re", "I_im")))

PV = Component(
    name="pv",
    description="static PV generator (ANDES' PV in the time domain: P and |V| held), on a bus",
    states=(), inputs=_INPUTS, outputs=_OUTPUTS, params_type=PVParams, derivatives=_no_state,
    output_equations=pv_outputs, equilibrium=_equilibrium("PV"), state_scales=(), ports=_PORTS,
    initialisation=Initialisation((), _start),
)

SLACK = Component(
    name="slack",
    description="slack generator (ANDES' Slack in the time domain: |V| and angle held, an infinite bus), on a bus",
    states=(), inputs=_INPUTS, outputs=_OUTPUTS, params_type=SlackParams, derivatives=_no_state,
    output_equations=slack_outputs, equilibrium=_equilibrium("Slack"), state_scales=(), ports=_PORTS,
    affine_current=True, initialisation=Initialisation((), _start),
)
