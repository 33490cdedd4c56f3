"""ZIP: the polynomial (constant impedance, current and power) load of ANDES, on a bus: a component
without states, its current a function of its bus voltage and of the load-flow point it draws from.

States  none
Inputs  u = (Vs [pu], theta_vs [rad]: the bus voltage, network frame; P0, Q0 [pu, system base]: the
        power it injects at the load flow (generator convention: negative, drawn), V0 [pu]: the bus
        voltage there; P0, Q0, V0 are set points the start takes from the load flow, held after)
Outputs y = (I_re, I_im [pu, system base]: the current injected into the bus, network frame; P, Q
        [pu, system base]: the power injected into the bus, generator convention)

    drawn:  Pd(V) = pp0 + pi0 V + pz0 V^2,   Qd(V) = qp0 + qi0 V + qz0 V^2        [pu, system base]
    pp0 = Pl kpp / ksp,  pi0 = Pl kpi / (ksp V0),  pz0 = Pl kpz / (ksp V0^2),  Pl = -P0,  ksp = kpp + kpi + kpz
    (likewise qp0, qi0, qz0 from Ql = -Q0, kqp, kqi, kqz)
    injected:  P + j Q = -(Pd + j Qd) = V e^{j theta} conj(I),  so I = (P - j Q) e^{j theta} / V

(ANDES 2.0 model reference, DynLoad: ZIP.) Its share of the load: ANDES switches the PQ load a ZIP
replaces off (u = 0) and the ZIP draws its percentages of the PQ's load-flow power, Ppf (kpp + kpi +
kpz) / 100 and Qpf (kqp + kqi + kqz) / 100, the rest dropped (where a sum is not 100 ANDES' TDS
initialisation reports the mismatch at the bus and runs on: ieee14_zip.json's 50 + 40 + 0). P0 + j Q0 is
that share, injected; then pp0 = Ppf kpp / 100 ... as ANDES computes them. Ppf, Qpf are the PQ's
power at its load flow, after its conversion to an impedance outside [vmin, vmax] there; neither the
ZIP nor the PQ converts anything during the time-domain simulation in ANDES 2.0.0.

The load-flow point is no parameter of the component (ANDES' p0, q0, v0 are services it takes from
the load flow, not data): its start (Component.start with the load-flow point in `given`) takes P0,
Q0, V0 as the inputs of those names and refuses a point its percentages cannot draw (P0 != 0 with
kpp = kpi = kpz = 0). ZIPParams, the percentages with a load-flow point, serves the functions below.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..component import Component, Initialisation, ParameterError, Parameters, Quantity
from ..ports import BusPort, Ports
from .common import finite_inputs

PERCENT = (0.0, 100.0)
POWER_LIMIT = 1e4  # pu: the largest |P0|, |Q0| taken
ACTIVE, REACTIVE = ("kpp", "kpi", "kpz"), ("kqp", "kqi", "kqz")


@dataclass(frozen=True)
class ZIPPercentages(Parameters):
    """ANDES' ZIP percentages of active power (kpp: constant power, kpi: current, kpz: impedance)
    and of reactive power (kqp, kqi, kqz) [%]: the component's parameters."""

    kpp: float = 0.0
    kpi: float = 0.0
    kpz: float = 100.0
    kqp: float = 0.0
    kqi: float = 0.0
    kqz: float = 100.0

    def check(self) -> None:
        low, high = PERCENT
        for name in ACTIVE + REACTIVE:
            self.require(name, low <= getattr(self, name) <= high, f"lie in [{low:g}, {high:g}] %")


@dataclass(frozen=True)
class ZIPParams(ZIPPercentages):
    """The percentages with the load-flow point the ZIP draws from: P0 + j Q0 [pu, system base] its
    share injected (negative: drawn) at the bus voltage V0 [pu]."""

    P0: float = 0.0
    Q0: float = 0.0
    V0: float = 1.0

    def check(self) -> None:
        super().check()
        self.require("V0", 0.01 <= self.V0 <= 3.0, "lie in [0.01, 3] pu")
        for name, parts in (("P0", ACTIVE), ("Q0", REACTIVE)):
            self.require(name, abs(getattr(self, name)) <= POWER_LIMIT,
                         f"lie in [-{POWER_LIMIT:g}, {POWER_LIMIT:g}] pu")
            self.require(name, getattr(self, name) == 0 or sum(getattr(self, k) for k in parts) > 0,
                         f"be 0 where {' + '.join(parts)} = 0 (nothing of the load is drawn)")


def split(p: ZIPPercentages, P0, Q0, V0) -> tuple:
    """(pp0, pi0, pz0, qp0, qi0, qz0) [pu, system base] of percentages p drawing -(P0 + j Q0) at V0
    (numbers, arrays or the C tracers): the power drawn at V is pp0 + pi0 V + pz0 V^2 (likewise Q)."""
    out = []
    for drawn, parts in ((-P0, (p.kpp, p.kpi, p.kpz)), (-Q0, (p.kqp, p.kqi, p.kqz))):
        total = sum(parts)
        scale = drawn / total if total > 0 else 0.0
        out += [scale * parts[0], scale * parts[1] / V0, scale * parts[2] / (V0 * V0)]
    return tuple(out)


def coefficients(p: ZIPParams) -> tuple:
    """(pp0, pi0, pz0, qp0, qi0, qz0) [pu, system base] of p's percentages and load-flow point (`split`)."""
    return split(p, p.P0, p.Q0, p.V0)


def injected(V, c: tuple) -> tuple:
    """(P, Q) [pu, system base]: the power injected into the bus at voltage magnitude V [pu] by the
    coefficients c = (pp0, pi0, pz0, qp0, qi0, qz0)."""
    pp0, pi0, pz0, qp0, qi0, qz0 = c
    return -(pp0 + (pi0 + pz0 * V) * V), -(qp0 + (qi0 + qz0 * V) * V)


def current(V, theta, P, Q, m=math) -> tuple:
    """(I_re, I_im) [pu]: the current (network frame) carrying P + j Q into a bus at V [pu], theta [rad]."""
    c, s = m.cos(theta), m.sin(theta)
    return (P * c + Q * s) / V, (P * s - Q * c) / V


def zip_power(V, p: ZIPParams) -> tuple:
    """(P, Q) [pu, system base]: the power injected into the bus at voltage magnitude V [pu]."""
    return injected(V, coefficients(p))


def zip_current(V, theta, p: ZIPParams, m=math) -> tuple:
    """(I_re, I_im) [pu, system base]: the current injected into the bus (network frame) at the bus
    voltage V [pu] at angle theta [rad], written against the math namespace m (math, numpy, torch,
    the C tracers) so its derivatives come from the same expression."""
    return current(V, theta, *zip_power(V, p), m)


def derivatives(x, u, p: ZIPPercentages, m):
    """(): the ZIP has no state."""
    return ()


def outputs(x, u, p: ZIPPercentages, m):
    """(I_re, I_im, P, Q) [pu, system base, injected into the bus] for u = (Vs, theta_vs, P0, Q0, V0)."""
    Vs, theta, P0, Q0, V0 = u
    P, Q = injected(Vs, split(p, P0, Q0, V0))
    return (*current(Vs, theta, P, Q, m), P, Q)


def equilibrium(u, p: ZIPPercentages) -> np.ndarray:
    """The (empty) state at rest at finite inputs."""
    finite_inputs(u, "ZIP")
    return np.zeros(0)


def _start(given, p: ZIPPercentages) -> tuple:
    """(no state, no solved input): its inputs P0, Q0, V0 are the load-flow point's (Component.start
    takes them from `given`); ValueError where the ZIP does not inject P0 + j Q0 at its bus voltage
    there (percentages that draw nothing of a nonzero P0 or Q0, a point out of range, a bus voltage
    given other than V0)."""
    try:
        point = ZIPParams(**p.to_dict(), **{k: float(given[k]) for k in ("P0", "Q0", "V0")})
    except ParameterError as exc:
        raise ValueError(f"ZIP: {exc}") from None
    P, Q = zip_power(float(given["Vs"]), point)
    if not all(abs(got - want) <= 1e-12 * max(1.0, abs(want)) for got, want in ((P, point.P0), (Q, point.Q0))):
        raise ValueError(f"ZIP: at the bus voltage Vs = {given['Vs']!r} pu it injects P + jQ = {P:.10g} + j{Q:.10g} "
                         f"pu, not the load flow's {point.P0:.10g} + j{point.Q0:.10g} pu at V0 = {point.V0!r} pu")
    return np.zeros(0), {}


ZIP = Component(
    name="zip",
    description="ZIP polynomial (constant impedance, current and power) load (ANDES), on a bus",
    states=(),
    inputs=(Quantity("Vs", "pu", "bus voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
            Quantity("theta_vs", "rad", "bus voltage angle", start=0.0, operating_range=(-0.5, 0.5)),
            Quantity("P0", "pu", "active power injected at the load flow (system base, negative: drawn; set point)",
                     start=-0.5, operating_range=(-1.0, 0.0)),
            Quantity("Q0", "pu", "reactive power injected at the load flow (system base; set point)", start=-0.2,
                     operating_range=(-0.5, 0.5)),
            Quantity("V0", "pu", "bus voltage magnitude at the load flow (set point)", start=1.0,
                     operating_range=(0.9, 1.1), minimum=0.01)),
    outputs=(Quantity("I_re", "pu", "current injected into the bus, real part (network frame, system base)"),
             Quantity("I_im", "pu", "current injected into the bus, imaginary part (network frame, system base)"),
             Quantity("P", "pu", "active power injected into the bus (system base; negative: drawn)"),
             Quantity("Q", "pu", "reactive power injected into the bus (system base)")),
    params_type=ZIPPercentages,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(),
    ports=Ports(bus=BusPort(voltage=("Vs", "theta_vs"), current=("I_re", "I_im"))),
    initialisation=Initialisation((), _start),
)
