"""ZIP: the polynomial (constant impedance, current and power) load of ANDES, as a function of its
bus voltage for the network solve: it has no state, so it is no Component (one needs a state).

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
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..component import Parameters

PERCENT = (0.0, 100.0)
POWER_LIMIT = 1e4  # pu: the largest |P0|, |Q0| taken


@dataclass(frozen=True)
class ZIPParams(Parameters):
    """ANDES' ZIP percentages of active power (kpp: constant power, kpi: current, kpz: impedance)
    and of reactive power (kqp, kqi, kqz) [%], with the load-flow point it draws from: P0 + j Q0 [pu,
    system base] its share injected (negative: drawn) at the bus voltage V0 [pu]."""

    kpp: float = 0.0
    kpi: float = 0.0
    kpz: float = 100.0
    kqp: float = 0.0
    kqi: float = 0.0
    kqz: float = 100.0
    P0: float = 0.0
    Q0: float = 0.0
    V0: float = 1.0

    def check(self) -> None:
        low, high = PERCENT
        for name in ("kpp", "kpi", "kpz", "kqp", "kqi", "kqz"):
            self.require(name, low <= getattr(self, name) <= high, f"lie in [{low:g}, {high:g}] %")
        self.require("V0", 0.01 <= self.V0 <= 3.0, "lie in [0.01, 3] pu")
        for name, parts in (("P0", ("kpp", "kpi", "kpz")), ("Q0", ("kqp", "kqi", "kqz"))):
            self.require(name, abs(getattr(self, name)) <= POWER_LIMIT,
                         f"lie in [-{POWER_LIMIT:g}, {POWER_LIMIT:g}] pu")
            self.require(name, getattr(self, name) == 0 or sum(getattr(self, k) for k in parts) > 0,
                         f"be 0 where {' + '.join(parts)} = 0 (nothing of the load is drawn)")


def coefficients(p: ZIPParams) -> tuple:
    """(pp0, pi0, pz0, qp0, qi0, qz0) [pu, system base]: the power drawn at V is pp0 + pi0 V + pz0 V^2
    (and likewise Q), -(P0 + j Q0) at V0."""
    out = []
    for drawn, parts in ((-p.P0, (p.kpp, p.kpi, p.kpz)), (-p.Q0, (p.kqp, p.kqi, p.kqz))):
        total = sum(parts)
        scale = drawn / total if total > 0 else 0.0
        out += [scale * parts[0], scale * parts[1] / p.V0, scale * parts[2] / p.V0 ** 2]
    return tuple(out)


def zip_power(V, p: ZIPParams) -> tuple:
    """(P, Q) [pu, system base]: the power injected into the bus at voltage magnitude V [pu]."""
    pp0, pi0, pz0, qp0, qi0, qz0 = coefficients(p)
    return -(pp0 + (pi0 + pz0 * V) * V), -(qp0 + (qi0 + qz0 * V) * V)


def zip_current(V, theta, p: ZIPParams, m=math) -> tuple:
    """(I_re, I_im) [pu, system base]: the current injected into the bus (network frame) at the bus
    voltage V [pu] at angle theta [rad], written against the math namespace m (math, numpy, torch,
    the C tracers) so its derivatives come from the same expression."""
    P, Q = zip_power(V, p)
    c, s = m.cos(theta), m.sin(theta)
    return (P * c + Q * s) / V, (P * s - Q * c) / V
