"""REGF1: the grid-forming inverter with droop control (ANDES 2.0 REGF1, after EPRI's proposal of
generic grid-forming positive-sequence models), on a bus; and what REGF2 (virtual synchronous
machine) and REGF3 (dispatchable virtual oscillator) share with it: the power measurements and
limits, the outer voltage and inner current PI loops, the voltage source behind its filter impedance.

States  x = (Psen_y, Qsen_y [pu]: the measured power; Psig_y, Qsig_y [pu]: the limited power signals;
        PIplim_xi, PIqlim_xi [pu]: the integrators of the power-limit PI controllers; delta [rad]: the
        virtual rotor angle, network frame; the primary control's states (REGF1: none); PIvd_xi,
        PIvq_xi [pu]: the outer voltage PIs' integrators; PIId_xi, PIIq_xi [pu]: the inner current
        PIs' integrators; udLag_y, uqLag_y [pu]: the converter's internal voltage, frame at delta)
Inputs  u = (Vs [pu], theta_vs [rad]: the bus voltage; vref [pu]: the voltage set point; Paux,
        Qaux [pu]: auxiliary power inputs, 0 in ANDES)
Outputs y = (I_re, I_im [pu]: the current into the bus, network frame; P, Q [pu]: the power into the
        bus (ANDES' Pe, Qe); Id, Iq [pu]: the current in the frame at delta; vd, vq [pu]: the bus
        voltage in that frame; dw [rad/s]: the virtual rotor's speed deviation; vdref [pu]: the
        voltage reference after the primary control, ANDES' vref2)

Equations (ANDES 2.0 model reference, RenGen: REGF1), on the system base:

    vd = Vs cos(delta - theta_vs),  vq = -Vs sin(delta - theta_vs)
    ud = vd + rf Id - xf Iq,  uq = vq + rf Iq + xf Id  (solved for Id, Iq: the internal voltage
        udLag_y + j uqLag_y behind rf + j xf)
    P = vd Id + vq Iq,  Q = vq Id - vd Iq,  I = (Id + j Iq) exp(j delta)
    Tr dPsen_y/dt = P - Psen_y,  Tr dQsen_y/dt = Q - Qsen_y  (Tr = 0: Psen = P, Qsen = Q)
    Tpm dPsig_y/dt = Psen + Paux - Psig_y, non-windup within [Pmin, Pmax]; Qsig_y likewise within
        [Qmin, Qmax] (Tpm = 0: the clipped input)
    ep = Psig - Psen,  PIplim_y = KPplim ep + PIplim_xi,  dPIplim_xi/dt = KIplim ep  (q: KPqlim, KIqlim)
    primary control (REGF1, droop): dw = w0 wdrp (PIplim_y - Psen) clipped to [dwmin, dwmax],
        vref2 = (PIqlim_y - Qsen) Qdrp + vref;  w0 = 2 pi fn
    ddelta/dt = dw
    Idref = KPv (vref2 - vd) + PIvd_xi,  dPIvd_xi/dt = KIv (vref2 - vd)
    Iqref = KPv (-vq) + PIvq_xi,  dPIvq_xi/dt = KIv (-vq)
    PIId_y = KPi (Idref - Id) + PIId_xi,  dPIId_xi/dt = KIi (Idref - Id)  (PIIq likewise with Iq)
    Te dudLag_y/dt = udref - udLag_y = PIId_y,  Te duqLag_y/dt = PIIq_y
        (ANDES' udref = PIId_y + vd + rf Id - xf Iq, which is PIId_y + udLag_y exactly)

The power's level has no reference: at rest PIplim_xi = Psen (dw = 0), any power; a grid frequency
off nominal moves it along the droop. ANDES' Pref, Qref only start the states.

Bases: ANDES converts rf, xf (its `z` parameters, without a Vn: Sb / Sn) and Pmax, Pmin, Qmax, Qmin
(`power`: Sn / Sb) to the system base; the gains, droops, fn, dwmax, dwmin are used as given. The
parameters here are as the case data give them (Sn base), converted the same way. ANDES' Vdip,
Tfrz, PQFLAG (in its data, in none of its 2.0.0 equations) and gammap, gammaq (the share of the
static generator, which the load-flow point P0, Q0 already is) are not parameters.

Start (ANDES' initialisation): from the load-flow point V0, theta0, P0, Q0: delta = theta0 (vd = V0,
vq = 0), Id0 = P0 / V0, Iq0 = -Q0 / V0, Psen = Psig = PIplim_xi = P0, Qsen = Qsig = PIqlim_xi = Q0,
PIvd_xi = Id0, PIvq_xi = Iq0, PIId_xi = PIIq_xi = 0, udLag_y = V0 + rf Id0 - xf Iq0,
uqLag_y = rf Iq0 + xf Id0; set points vref = V0, Paux = Qaux = 0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import clip, lag, lag_non_windup, lag_non_windup_reset
from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import BusPort, Link, Ports
from .common import check_limits, check_ranges, finite_inputs

PARAMETER_RANGES = {
    "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA"), "fn": (1.0, 1000.0, "Hz"), "rf": (0.0, 10.0, "pu"),
    "xf": (0.0, 10.0, "pu"), "dwmax": (-1e4, 1e4, "rad/s"), "dwmin": (-1e4, 1e4, "rad/s"), "wdrp": (0.0, 10.0, "pu"),
    "Qdrp": (0.0, 1.0, "pu"), "Tr": (0.0, 100.0, "s"), "Te": (1e-5, 100.0, "s"), "KPi": (0.0, 1e4, "pu"),
    "KIi": (0.0, 1e4, "pu/s"), "KPv": (0.0, 1e4, "pu"), "KIv": (0.0, 1e4, "pu/s"), "Pmax": (0.0, 1e4, "pu"),
    "Pmin": (-1e4, 1e4, "pu"), "KPplim": (0.0, 1e4, "pu"), "KIplim": (0.0, 1e4, "pu/s"), "Qmax": (0.0, 1e4, "pu"),
    "Qmin": (-1e4, 1e4, "pu"), "KPqlim": (0.0, 1e4, "pu"), "KIqlim": (0.0, 1e4, "pu/s"), "Tpm": (0.0, 100.0, "s"),
}


@dataclass(frozen=True)
class REGF1Params(Parameters):
    """ANDES REGF1 data: the inverter's base Sn [MVA] and the system base Sb [MVA]; the filter
    resistance rf and reactance xf [pu, base Sn]; rated frequency fn [Hz]; the limits dwmax, dwmin
    [rad/s] of the virtual speed deviation; the frequency and voltage droops wdrp, Qdrp; the
    measurement and output time constants Tr, Te [s]; the current (KPi, KIi) and voltage (KPv, KIv)
    PI gains; the power limits Pmax, Pmin, Qmax, Qmin [pu, base Sn] with their PI gains (KPplim,
    KIplim, KPqlim, KIqlim); the power signal delay Tpm [s]."""

    Sn: float = 100.0
    Sb: float = 100.0
    fn: float = 60.0
    rf: float = 0.0
    xf: float = 0.2
    dwmax: float = 75.0
    dwmin: float = -75.0
    wdrp: float = 0.033
    Qdrp: float = 0.045
    Tr: float = 0.005
    Te: float = 0.005
    KPi: float = 0.5
    KIi: float = 20.0
    KPv: float = 3.0
    KIv: float = 10.0
    Pmax: float = 1.0
    Pmin: float = -1.0
    KPplim: float = 5.0
    KIplim: float = 30.0
    Qmax: float = 1.0
    Qmin: float = -1.0
    KPqlim: float = 0.1
    KIqlim: float = 1.5
    Tpm: float = 0.025

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        self.require("xf", self.rf > 0 or self.xf > 0, "be > 0 where rf = 0 (the filter impedance)")
        for low, high in (("dwmin", "dwmax"), ("Pmin", "Pmax"), ("Qmin", "Qmax")):
            check_limits(self, low, high)

    @property
    def w0(self) -> float:
        """The rated angular frequency 2 pi fn [rad/s]."""
        return 2.0 * math.pi * self.fn

    @property
    def impedance(self) -> tuple:
        """(rf, xf) on the system base (ANDES' `z` conversion: times Sb / Sn)."""
        k = self.Sb / self.Sn
        return self.rf * k, self.xf * k

    @property
    def power_limits(self) -> tuple:
        """(Pmin, Pmax, Qmin, Qmax) on the system base (times Sn / Sb)."""
        k = self.Sn / self.Sb
        return self.Pmin * k, self.Pmax * k, self.Qmin * k, self.Qmax * k


N_POWER = 7  # the states before the primary control's: the power loops' six and delta
N_CURRENT = 6  # the states after it: the voltage and current PIs' four, the internal voltage's two


def terminal(delta, ud, uq, Vs, theta_vs, p: REGF1Params, m) -> tuple:
    """(vd, vq, Id, Iq, P, Q) [pu, system base]: the bus voltage in the frame at delta and the current
    the internal voltage ud + j uq drives through rf + j xf into it, with its power."""
    rf, xf = p.impedance
    vd, vq = Vs * m.cos(delta - theta_vs), -Vs * m.sin(delta - theta_vs)
    a, b = ud - vd, uq - vq
    det = rf * rf + xf * xf
    Id, Iq = (rf * a + xf * b) / det, (rf * b - xf * a) / det
    return vd, vq, Id, Iq, vd * Id + vq * Iq, vq * Id - vd * Iq


def _power_loops(x, P, Q, Paux, Qaux, p: REGF1Params, m) -> tuple:
    """(rates of the six power-loop states, (Psen, Qsen, PIplim_y, PIqlim_y))."""
    Pmin, Pmax, Qmin, Qmax = p.power_limits
    d_Psen, Psen = lag(m, P, x[0], 1.0, p.Tr)
    d_Qsen, Qsen = lag(m, Q, x[1], 1.0, p.Tr)
    d_Psig, Psig = lag_non_windup(m, Psen + Paux, x[2], 1.0, p.Tpm, Pmin, Pmax)
    d_Qsig, Qsig = lag_non_windup(m, Qsen + Qaux, x[3], 1.0, p.Tpm, Qmin, Qmax)
    ep, eq = Psig - Psen, Qsig - Qsen
    rates = (d_Psen, d_Qsen, d_Psig, d_Qsig, p.KIplim * ep, p.KIqlim * eq)
    return rates, (Psen, Qsen, p.KPplim * ep + x[4], p.KPqlim * eq + x[5])


def equations(x, u, p, m, primary, n_primary: int) -> tuple:
    """(dx/dt, outputs) of a grid-forming inverter whose primary control `primary(x_primary, powers,
    u, p, m) -> (its states' rates, dw, vref2)` has n_primary states after delta; powers =
    (Psen, Qsen, PIplim_y, PIqlim_y)."""
    Vs, theta_vs, _, Paux, Qaux = u
    delta, x_primary = x[N_POWER - 1], x[N_POWER:N_POWER + n_primary]
    xvd, xvq, xId, xIq, ud, uq = x[N_POWER + n_primary:]
    vd, vq, Id, Iq, P, Q = terminal(delta, ud, uq, Vs, theta_vs, p, m)
    power_rates, powers = _power_loops(x, P, Q, Paux, Qaux, p, m)
    primary_rates, dw, vref2 = primary(x_primary, powers, u, p, m)
    ev, eq = vref2 - vd, -vq
    ed, eq_current = p.KPv * ev + xvd - Id, p.KPv * eq + xvq - Iq
    current_rates = (p.KIv * ev, p.KIv * eq, p.KIi * ed, p.KIi * eq_current,
                     (p.KPi * ed + xId) / p.Te, (p.KPi * eq_current + xIq) / p.Te)
    c, s = m.cos(delta), m.sin(delta)
    out = (Id * c - Iq * s, Id * s + Iq * c, P, Q, Id, Iq, vd, vq, dw, vref2)
    return (*power_rates, dw, *primary_rates, *current_rates), out


def droop(x_primary, powers, u, p: REGF1Params, m) -> tuple:
    """REGF1's primary control (no states): ((), dw [rad/s], vref2 [pu])."""
    Psen, Qsen, PIplim_y, PIqlim_y = powers
    dw = clip(m, p.w0 * p.wdrp * (PIplim_y - Psen), p.dwmin, p.dwmax)
    return (), dw, (PIqlim_y - Qsen) * p.Qdrp + u[2]


def reset(x, u, p: REGF1Params, m) -> tuple:
    """x after the resets of Psig_y's and Qsig_y's non-windup limits (blocks.lag_non_windup_reset)."""
    Pmin, Pmax, Qmin, Qmax = p.power_limits
    Psen, Qsen = x[0], x[1]
    if p.Tr == 0:  # no measurement lag: the measured power is the power itself
        Psen, Qsen = terminal(x[N_POWER - 1], x[-2], x[-1], u[0], u[1], p, m)[4:]
    Psig = lag_non_windup_reset(m, Psen + u[3], x[2], 1.0, p.Tpm, Pmin, Pmax)
    Qsig = lag_non_windup_reset(m, Qsen + u[4], x[3], 1.0, p.Tpm, Qmin, Qmax)
    return (x[0], x[1], Psig, Qsig, *x[4:])


def operating_point(V0: float, theta0: float, P0: float, Q0: float, p: REGF1Params, name: str = "REGF1") -> tuple:
    """(power-loop states and delta [7], current-loop states [6]) at rest delivering P0 + jQ0 [pu,
    system base] at the bus voltage V0 at theta0 (ANDES' initialisation); ValueError where a power
    limit forbids it."""
    Pmin, Pmax, Qmin, Qmax = p.power_limits
    if V0 <= 0:
        raise ValueError(f"{name}: no start at bus voltage {V0:.6g} pu")
    if not (Pmin <= P0 <= Pmax and Qmin <= Q0 <= Qmax):
        raise ValueError(f"{name}: the load-flow power {P0:.6g} + j{Q0:.6g} pu lies beyond its limits "
                         f"[{Pmin:.6g}, {Pmax:.6g}], [{Qmin:.6g}, {Qmax:.6g}] pu (system base)")
    rf, xf = p.impedance
    Id0, Iq0 = P0 / V0, -Q0 / V0
    return (np.array([P0, Q0, P0, Q0, P0, Q0, theta0]),
            np.array([Id0, Iq0, 0.0, 0.0, V0 + rf * Id0 - xf * Iq0, rf * Iq0 + xf * Id0]))


def start(given, p, primary_start, name: str) -> tuple:
    """(x0, set points) of a grid-forming inverter whose primary control's states at rest are
    primary_start(V0, theta0, p) (ANDES' initialisation, module docstring)."""
    V0, theta0 = float(given["V0"]), float(given["theta0"])
    power, current = operating_point(V0, theta0, float(given["P0"]), float(given["Q0"]), p, name)
    x0 = np.concatenate([power, primary_start(V0, theta0, p), current])
    return x0, {"vref": V0, "Paux": 0.0, "Qaux": 0.0}


def rest(u, p, primary_start, name: str) -> np.ndarray:
    """The equilibrium of a grid-forming inverter at constant inputs: it holds its bus voltage at
    vref, so a fixed bus voltage Vs other than vref (or an auxiliary power, which its limit PIs
    integrate) leaves it no rest; at Vs = vref any power is at rest: the one chosen delivers none."""
    Vs, theta_vs, vref, Paux, Qaux = finite_inputs(u, name)
    if abs(Vs - vref) > 1e-12 * max(1.0, abs(vref)) or Paux != 0 or Qaux != 0:
        raise ValueError(f"{name}: no steady state at a bus voltage {Vs:.6g} pu held off its set point vref = "
                         f"{vref:.6g} pu or at an auxiliary power ({Paux:.6g}, {Qaux:.6g}) pu")
    return start({"V0": Vs, "theta0": theta_vs, "P0": 0.0, "Q0": 0.0}, p, primary_start, name)[0]


STATES = (Quantity("Psen_y", "pu", "measured active power"), Quantity("Qsen_y", "pu", "measured reactive power"),
          Quantity("Psig_y", "pu", "active power signal (non-windup limited to [Pmin, Pmax])"),
          Quantity("Qsig_y", "pu", "reactive power signal (non-windup limited to [Qmin, Qmax])"),
          Quantity("PIplim_xi", "pu", "active power limit PI integrator"),
          Quantity("PIqlim_xi", "pu", "reactive power limit PI integrator"),
          Quantity("delta", "rad", "virtual rotor angle (network frame)"))
CURRENT_STATES = (Quantity("PIvd_xi", "pu", "d-axis voltage PI integrator (d-axis current reference)"),
                  Quantity("PIvq_xi", "pu", "q-axis voltage PI integrator (q-axis current reference)"),
                  Quantity("PIId_xi", "pu", "d-axis current PI integrator"),
                  Quantity("PIIq_xi", "pu", "q-axis current PI integrator"),
                  Quantity("udLag_y", "pu", "d-axis internal voltage"),
                  Quantity("uqLag_y", "pu", "q-axis internal voltage"))
SCALES, CURRENT_SCALES = (0.2, 0.2, 0.2, 0.2, 0.2, 0.2, 0.1), (0.2, 0.2, 0.05, 0.05, 0.1, 0.1)
INPUTS = (Quantity("Vs", "pu", "bus voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
          Quantity("theta_vs", "rad", "bus voltage angle", start=0.0, operating_range=(-0.5, 0.5)),
          Quantity("vref", "pu", "voltage set point", start=1.0, operating_range=(0.9, 1.1)),
          Quantity("Paux", "pu", "auxiliary active power input (system base)", start=0.0, operating_range=(-0.3, 0.3)),
          Quantity("Qaux", "pu", "auxiliary reactive power input (system base)", start=0.0,
                   operating_range=(-0.3, 0.3)))
OUTPUTS = (Quantity("I_re", "pu", "bus current, real part (network frame, system base)"),
           Quantity("I_im", "pu", "bus current, imaginary part (network frame, system base)"),
           Quantity("P", "pu", "active power into the bus (system base)"),
           Quantity("Q", "pu", "reactive power into the bus (system base)"),
           Quantity("Id", "pu", "d-axis current (frame at delta)"), Quantity("Iq", "pu", "q-axis current (frame at delta)"),
           Quantity("vd", "pu", "d-axis bus voltage (frame at delta)"),
           Quantity("vq", "pu", "q-axis bus voltage (frame at delta)"),
           Quantity("dw", "rad/s", "virtual rotor speed deviation"),
           Quantity("vdref", "pu", "d-axis voltage reference after the primary control (vref2)"))
PORTS = Ports(bus=BusPort(voltage=("Vs", "theta_vs"), current=("I_re", "I_im")),
              outputs=(Link("active_power", "P"), Link("reactive_power", "Q")))


def grid_forming(name: str, description: str, params_type: type, functions: tuple, primary_states: tuple,
                 primary_scales: tuple) -> Component:
    """A grid-forming inverter component: REGF1's states with the primary control's after delta;
    functions = (derivatives, outputs, equilibrium, start) of its module."""
    derivatives, outputs, equilibrium, start_fn = functions
    return Component(
        name=name, description=description,
        states=STATES + primary_states + CURRENT_STATES,
        inputs=INPUTS, outputs=OUTPUTS, params_type=params_type,
        derivatives=derivatives, output_equations=outputs, equilibrium=equilibrium,
        state_scales=SCALES + primary_scales + CURRENT_SCALES,
        reset=reset, ports=PORTS, affine_current=True,
        initialisation=Initialisation(("vref", "Paux", "Qaux"), start_fn),
    )


def derivatives(x, u, p: REGF1Params, m):
    """dx/dt [13] of REGF1 for u = (Vs, theta_vs, vref, Paux, Qaux)."""
    return equations(x, u, p, m, droop, 0)[0]


def outputs(x, u, p: REGF1Params, m):
    """(I_re, I_im, P, Q, Id, Iq, vd, vq, dw, vdref)."""
    return equations(x, u, p, m, droop, 0)[1]


def _no_primary_states(V0: float, theta0: float, p) -> np.ndarray:
    return np.zeros(0)


def _start(given, p: REGF1Params) -> tuple:
    return start(given, p, _no_primary_states, "REGF1")


def equilibrium(u, p: REGF1Params) -> np.ndarray:
    """The steady state [13] at constant inputs (`rest`)."""
    return rest(u, p, _no_primary_states, "REGF1")


REGF1 = grid_forming("regf1", "REGF1 grid-forming inverter with droop control (ANDES) on a bus", REGF1Params,
                     (derivatives, outputs, equilibrium, _start), (), ())
