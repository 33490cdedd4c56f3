"""The 4th-order synchronous machine (Sauer-Pai two-axis model) on a bus of varying voltage: `SM4`.

States  x = (delta [rad], omega [rad/s, deviation from synchronous], Ed_p [pu], Eq_p [pu])
Inputs  u = (Vs [pu], theta_vs [rad], Pm [pu] mechanical power, Efd [pu] field voltage)
Outputs y = (Id, Iq, I_re, I_im, P, Q, rotor_speed) [pu]: stator currents, bus current in the
        network frame, power into the bus, and the rotor speed in pu of synchronous speed,
        1 + omega / Wb (1 at rest): what a standard machine's omega is (GENROU, GENCLS), and what
        the `rotor_speed` port link gives a governor or stabiliser.
Arrays carry the state or input on their last axis: x [..., 4], u [..., 4].

The equations see delta and theta_vs only through delta - theta_vs, and omega only through
d delta/dt = omega and the damping torque D omega: `SM4.drift` declares this symmetry
(reference_models/drift.py), which the operators use to follow a machine whose angle and speed
drift with its network.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .component import Component, Initialisation, Parameters, Quantity
from .drift import Drift
from .ports import BusPort, Link, Ports


# The physical range of each parameter (low, high, unit): a machine outside it is a typing error or
# one no integrator follows in a co-simulation's time (H = 1e-9 s with Table I's D makes the speed's
# damping rate Wb D / (2 H) 3e11 1/s). Wide enough for machine data on a system base (H of a large
# area's equivalent machine up to hundreds of seconds) and for 16.7-400 Hz networks (Wb). D [pu
# torque per rad/s] is bounded with H and Wb too: that damping rate (63 1/s for Table I's machine)
# at most MAX_DAMPING_RATE. At the corners of these ranges the fastest mode is about 1e5 1/s.
PARAMETER_RANGES = {
    "H": (0.1, 1000.0, "s"), "D": (0.0, 100.0, "pu"),
    "Td0_p": (0.01, 100.0, "s"), "Tq0_p": (0.01, 100.0, "s"),
    "Xd": (0.01, 10.0, "pu"), "Xd_p": (0.01, 10.0, "pu"), "Xq": (0.01, 10.0, "pu"), "Xq_p": (0.01, 10.0, "pu"),
    "Rs": (0.0, 1.0, "pu"), "Re": (0.0, 1.0, "pu"), "Xep": (0.0, 10.0, "pu"),
    "Wb": (50.0, 3000.0, "rad/s"),
}
MAX_DAMPING_RATE = 1e4  # 1/s


@dataclass(frozen=True)
class SM4Params(Parameters):
    """Machine and network parameters (paper Table I); reactances in pu on the machine base, times
    in s, Wb in rad/s. The operating point (Pm, Efd) is an input, not a parameter."""

    D: float = 2.0
    H: float = 5.06
    Rs: float = 0.0
    Td0_p: float = 4.75
    Tq0_p: float = 1.6
    Xd: float = 1.25
    Xd_p: float = 0.232
    Xq: float = 1.22
    Xq_p: float = 0.715
    Xep: float = 0.1
    Re: float = 0.0
    Wb: float = 314.159

    def check(self) -> None:
        for name in ("H", "Td0_p", "Tq0_p", "Xd", "Xd_p", "Xq", "Xq_p", "Wb"):
            self.require(name, getattr(self, name) > 0, "be > 0")
        for name in ("D", "Rs", "Re", "Xep"):
            self.require(name, getattr(self, name) >= 0, "be >= 0")
        for name, (low, high, unit) in PARAMETER_RANGES.items():
            self.require(name, low <= getattr(self, name) <= high, f"lie in [{low:g}, {high:g}] {unit}")
        rate = self.Wb * self.D / (2.0 * self.H)
        self.require("D", rate <= MAX_DAMPING_RATE, f"keep the speed's damping rate Wb D / (2 H) = {rate:.3g} 1/s "
                                                   f"at most {MAX_DAMPING_RATE:g} 1/s")
        self.require("Xd_p", self.Xd_p <= self.Xd, f"not exceed Xd = {self.Xd!r}")
        self.require("Xq_p", self.Xq_p <= self.Xq, f"not exceed Xq = {self.Xq!r}")


def stator_currents(delta, Ed_p, Eq_p, Vs, theta_vs, p: SM4Params, m):
    """Id, Iq [pu] from the algebraic stator-network equations, solved in closed form (2x2)."""
    ra = p.Rs + p.Re
    xq = p.Xq_p + p.Xep
    xd = p.Xd_p + p.Xep
    a = Ed_p - Vs * m.sin(delta - theta_vs)
    b = Eq_p - Vs * m.cos(delta - theta_vs)
    det = ra * ra + xq * xd
    Id = (ra * a + xq * b) / det
    Iq = (ra * b - xd * a) / det
    return Id, Iq


def electrical_power(Ed_p, Eq_p, Id, Iq, p: SM4Params):
    """Air-gap power Pe [pu]."""
    return Ed_p * Id + Eq_p * Iq + (p.Xq_p - p.Xd_p) * Id * Iq


def derivatives(x, u, p: SM4Params, m):
    """(d delta, d omega, d Ed_p, d Eq_p)/dt for x = (delta, omega, Ed_p, Eq_p), u = (Vs, theta_vs, Pm, Efd)."""
    delta, omega, Ed_p, Eq_p = x
    Vs, theta_vs, Pm, Efd = u
    Id, Iq = stator_currents(delta, Ed_p, Eq_p, Vs, theta_vs, p, m)
    Pe = electrical_power(Ed_p, Eq_p, Id, Iq, p)
    d_delta = omega
    d_omega = p.Wb / (2.0 * p.H) * (Pm - Pe - p.D * omega)
    d_Ed_p = (-Ed_p + (p.Xq - p.Xq_p) * Iq) / p.Tq0_p
    d_Eq_p = (-Eq_p - (p.Xd - p.Xd_p) * Id + Efd) / p.Td0_p
    return d_delta, d_omega, d_Ed_p, d_Eq_p


def derived(x, u, p: SM4Params, m):
    """(Id, Iq, I_re, I_im, P, Q, rotor_speed) in pu.

    Bus current in the network frame: I = (Id + j Iq) exp(j (delta - pi/2));
    power into the bus: P + jQ = Vs exp(j theta_vs) conj(I);
    rotor speed in pu of synchronous speed: 1 + omega / Wb (omega [rad/s] the deviation, Wb [rad/s]
    the synchronous speed 2 pi fn).
    """
    delta, omega, Ed_p, Eq_p = x
    Vs, theta_vs = u[0], u[1]
    Id, Iq = stator_currents(delta, Ed_p, Eq_p, Vs, theta_vs, p, m)
    # exp(j(delta - pi/2)) = sin(delta) - j cos(delta)
    I_re = Id * m.sin(delta) + Iq * m.cos(delta)
    I_im = Iq * m.sin(delta) - Id * m.cos(delta)
    V_re, V_im = Vs * m.cos(theta_vs), Vs * m.sin(theta_vs)
    P = V_re * I_re + V_im * I_im
    Q = V_im * I_re - V_re * I_im
    return Id, Iq, I_re, I_im, P, Q, 1.0 + omega / p.Wb


def _steady_fluxes(angle, Vs, Efd, p: SM4Params):
    """Ed_p, Eq_p [pu] (arrays shaped like angle) with d Ed_p/dt = d Eq_p/dt = 0 at rotor angle
    delta - theta_vs = angle [rad], bus voltage Vs and field voltage Efd [pu] (numpy)."""
    ra, xq, xd = p.Rs + p.Re, p.Xq_p + p.Xep, p.Xd_p + p.Xep
    det = ra * ra + xq * xd
    kq, kd = (p.Xq - p.Xq_p) / det, (p.Xd - p.Xd_p) / det
    # Ed = kq (ra b - xd a), Eq = Efd - kd (ra a + xq b), a = Ed - Vs sin, b = Eq - Vs cos: linear in (Ed, Eq)
    s, c = Vs * np.sin(angle), Vs * np.cos(angle)
    inverse = np.linalg.inv(np.array([[1 + kq * xd, -kq * ra], [kd * ra, 1 + kd * xq]]))
    r0, r1 = kq * (xd * s - ra * c), Efd + kd * (ra * s + xq * c)
    return inverse[0, 0] * r0 + inverse[0, 1] * r1, inverse[1, 0] * r0 + inverse[1, 1] * r1


def _steady_power(angle, Vs, Efd, p: SM4Params):
    """Pe [pu] at the steady fluxes of rotor angle `angle` (arrays shaped like angle)."""
    Ed_p, Eq_p = _steady_fluxes(angle, Vs, Efd, p)
    Id, Iq = stator_currents(angle, Ed_p, Eq_p, Vs, 0.0, p, np)
    return electrical_power(Ed_p, Eq_p, Id, Iq, p)


_ANGLES = np.linspace(-math.pi / 2, math.pi, 301)  # rad: where the stable branch is looked for


def equilibrium(u, p: SM4Params) -> np.ndarray:
    """The stable equilibrium x* [4] for constant inputs u = (Vs, theta_vs, Pm, Efd): omega = 0,
    Pe = Pm on the rising side of the steady-state power-angle curve.

    Raises ValueError when the machine cannot transfer Pm at this voltage and field (no equilibrium).
    """
    from scipy.optimize import brentq

    Vs, theta_vs, Pm, Efd = (float(v) for v in u)
    if not all(math.isfinite(v) for v in (Vs, theta_vs, Pm, Efd)) or Vs <= 0:
        raise ValueError(f"no stable equilibrium of SM4 at Vs={Vs} pu, theta_vs={theta_vs} rad, Pm={Pm} pu, Efd={Efd} pu")
    values = _steady_power(_ANGLES, Vs, Efd, p) - Pm
    rising = np.nonzero((values[:-1] < 0) & (values[1:] >= 0))[0]
    if rising.size == 0:
        raise ValueError(f"no stable equilibrium of SM4 at Vs={Vs} pu, theta_vs={theta_vs} rad, Pm={Pm} pu, Efd={Efd} pu")
    i = rising[0]
    angle = brentq(lambda a: float(_steady_power(a, Vs, Efd, p)) - Pm, _ANGLES[i], _ANGLES[i + 1],
                   xtol=1e-15, rtol=1e-15)
    Ed_p, Eq_p = _steady_fluxes(angle, Vs, Efd, p)
    return np.array([theta_vs + angle, 0.0, float(Ed_p), float(Eq_p)])


def has_equilibrium(Vs: float, Pm: float, Efd: float, p: SM4Params) -> bool:
    """Whether SM4 has a stable equilibrium at bus voltage Vs, mechanical power Pm, field Efd [pu]."""
    values = _steady_power(_ANGLES, Vs, Efd, p) - Pm
    return bool(np.any((values[:-1] < 0) & (values[1:] >= 0)))


def rest(u, p: SM4Params) -> np.ndarray:
    """The equilibrium [4] at u = (Vs, theta_vs, Pm, Efd), Vs raised to the lowest voltage that has one."""
    Vs, theta_vs, Pm, Efd = (float(v) for v in u)
    return equilibrium((max(Vs, min_voltage_with_equilibrium(p, Pm, Efd)), theta_vs, Pm, Efd), p)


def _start(given, p: SM4Params) -> tuple:
    """(x0, {Pm, Efd}): SM4 at rest at the load-flow point (initialisation.machine_start)."""
    from .initialisation import machine_start

    s = machine_start(given["V0"], given["theta0"], given["P0"], given["Q0"], p)
    return s.x0, {"Pm": s.Pm, "Efd": s.Efd}


SM4 = Component(
    name="sm4",
    description="SM4 synchronous machine: Sauer-Pai two-axis model on a bus of varying voltage",
    states=(Quantity("delta", "rad", "rotor angle"),
            Quantity("omega", "rad/s", "rotor speed deviation"),
            Quantity("Ed_p", "pu", "d-axis transient voltage"),
            Quantity("Eq_p", "pu", "q-axis transient voltage")),
    inputs=(Quantity("Vs", "pu", "bus voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
            Quantity("theta_vs", "rad", "bus voltage angle", start=0.0, operating_range=(-0.5, 0.5)),
            Quantity("Pm", "pu", "mechanical power", start=0.7048, operating_range=(0.3, 1.0)),
            Quantity("Efd", "pu", "field voltage", start=1.08, operating_range=(0.8, 2.5))),
    outputs=(Quantity("Id", "pu", "d-axis stator current"),
             Quantity("Iq", "pu", "q-axis stator current"),
             Quantity("I_re", "pu", "bus current, real part (network frame)"),
             Quantity("I_im", "pu", "bus current, imaginary part (network frame)"),
             Quantity("P", "pu", "active power into the bus"),
             Quantity("Q", "pu", "reactive power into the bus"),
             Quantity("rotor_speed", "pu", "rotor speed in pu of synchronous speed, 1 + omega / Wb (1 at rest)")),
    params_type=SM4Params,
    derivatives=derivatives,
    output_equations=derived,
    equilibrium=equilibrium,
    state_scales=(0.5, 0.25, 0.1, 0.1),
    # d omega/dt = Wb/(2H) (Pm - Pe(delta, Ed_p, Eq_p, u)) - Wb D/(2H) omega
    affine_states=(1,),
    rest=rest,
    # delta and theta_vs enter as delta - theta_vs; omega as d delta/dt and the damping torque D omega
    drift=Drift(angle_states=(0,), angle_inputs=(1,), speed_state=1, torque_inputs=((2, "D"),), speed_step=2.0),
    ports=Ports(bus=BusPort(voltage=("Vs", "theta_vs"), current=("I_re", "I_im")),
                inputs=(Link("mechanical_power", "Pm"), Link("field_voltage", "Efd")),
                outputs=(Link("rotor_angle", "delta"), Link("speed", "omega"), Link("rotor_speed", "rotor_speed"),
                         Link("electrical_power", "P"))),
    initialisation=Initialisation(("Pm", "Efd"), lambda given, p: _start(given, p)),
    affine_current=True,
)

STATE_NAMES = SM4.state_names
STATE_UNITS = tuple(q.unit for q in SM4.states)
INPUT_NAMES = SM4.input_names
INPUT_UNITS = tuple(q.unit for q in SM4.inputs)
OUTPUT_NAMES = SM4.output_names
DEFAULT_PARAMS = SM4Params()


def rhs(x, u, p: SM4Params = DEFAULT_PARAMS):
    """dx/dt [..., 4] for states x [..., 4] and inputs u [..., 4] (numpy or torch, broadcast)."""
    return SM4.rhs(x, u, p)


def outputs(x, u, p: SM4Params = DEFAULT_PARAMS):
    """Derived outputs (Id, Iq, I_re, I_im, P, Q, rotor_speed) [..., 7] in pu for x [..., 4], u [..., 4]."""
    return SM4.output_values(x, u, p)


def steady_state(Vs: float = 1.0, theta_vs: float = 0.0, p: SM4Params = DEFAULT_PARAMS,
                 Pm: float = SM4.inputs[2].start, Efd: float = SM4.inputs[3].start) -> np.ndarray:
    """The stable equilibrium x* [4] at constant (Vs, theta_vs, Pm, Efd); ValueError where there is none."""
    return SM4.steady_state((Vs, theta_vs, Pm, Efd), p)


@lru_cache(maxsize=4096)
def min_voltage_with_equilibrium(p: SM4Params = DEFAULT_PARAMS, Pm: float = SM4.inputs[2].start,
                                 Efd: float = SM4.inputs[3].start, tol: float = 1e-9) -> float:
    """The lowest bus voltage Vs [pu] at which an equilibrium exists at mechanical power Pm and field
    voltage Efd [pu] (bisection).

    With Pm and Efd held there is none below it: the machine cannot deliver Pm there and, held long
    enough (Td0_p), loses synchronism. Cached per machine and operating point (all frozen).
    """
    low, high = 1e-3, 10.0
    if not has_equilibrium(high, Pm, Efd, p):
        return high
    while high - low > tol:
        mid = 0.5 * (low + high)
        if has_equilibrium(mid, Pm, Efd, p):
            high = mid
        else:
            low = mid
    return high
