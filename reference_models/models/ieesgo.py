"""IEESGO: the IEEE standard steam turbine-governor (PSS/E IEESGO, ANDES), as ANDES 2.0.0 computes it.

States  x = (F1_y [pu] controller lag, F2_x [pu] lead-lag state, F3_y, F4_y, F5_y [pu] steam
        inlet, reheater and crossover lags)
Inputs  u = (omega [pu] rotor speed, Pref [pu] power reference: ANDES' pref0, the mechanical
        power at rest at omega = wref0)
Outputs y = (Pm [pu] mechanical power)

Equations (ANDES 2.0 model reference, TurbineGov: IEESGO), with c = Sn / Sb:

    wd = omega - wref0
    lag K1 / (1 + s T1) of wd -> F1 (T1 = 0: F1 = K1 wd, the state held)
    lead-lag (1 + s T2) / (1 + s T3) of F1 -> F2 (T3 = 0: F2 = F1, the state held)
    HL = Pref - F2 / c, clipped to [PMIN, PMAX] (windup limiter)
    lags 1 / (1 + s T4) of HL -> F3,  K2 / (1 + s T5) of F3 -> F4,  K3 / (1 + s T6) of F4 -> F5
        (a T of 0: the lag is its gain, the state held)
    Pm = (1 - K2) F3 + (1 - K3) F4 + F5                  (= HL at rest)

Bases: PMAX, PMIN, Pref and Pm on the turbine's base, which the integration takes as the
machine's base Sn (ANDES' default when Tn is not given). ANDES converts them to the system base Sb
but not K1 (1 / pu regulation, which PSS/E reads on the turbine base), so its speed signal F2 is
taken as a power on the system base: on the turbine base it enters as F2 / c (parameters Sn, Sb
[MVA]; Sn = Sb: PSS/E's equations).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blocks import clip, lag, lead_lag
from ..component import Parameters, Quantity
from .common import check_limits, check_ranges, finite_inputs
from .tgov1 import turbine_governor

PARAMETER_RANGES = {**{f"T{i}": (0.0, 100.0, "s") for i in range(1, 7)},
                    "K1": (0.0, 1000.0, "pu"), "K2": (0.0, 10.0, "pu"), "K3": (-10.0, 10.0, "pu"),
                    "wref0": (0.5, 1.5, "pu"), "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA")}


@dataclass(frozen=True)
class IEESGOParams(Parameters):
    """ANDES/PSS/E IEESGO data: time constants T1 (controller lag), T2 (lead), T3 (governor lag),
    T4 (steam inlet), T5 (reheater), T6 (crossover) [s], regulation gain K1 [1/pu], fractions K2,
    K3, power limits PMAX, PMIN [pu], speed reference wref0 [pu], the turbine's base Sn and the
    system base Sb [MVA] (ANDES' bases, above)."""

    T1: float = 0.02
    T2: float = 1.0
    T3: float = 1.0
    T4: float = 0.5
    T5: float = 10.0
    T6: float = 0.5
    K1: float = 0.02
    K2: float = 1.0
    K3: float = 1.0
    PMAX: float = 5.0
    PMIN: float = 0.0
    wref0: float = 1.0
    Sn: float = 100.0
    Sb: float = 100.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "PMIN", "PMAX")


def _chain(x, u, p: IEESGOParams, m):
    """(derivatives [5], (F3, F4, F5) outputs)."""
    F1_y, F2_x, F3_y, F4_y, F5_y = x
    omega, Pref = u
    d_F1, F1 = lag(m, omega - p.wref0, F1_y, p.K1, p.T1)
    d_F2, F2 = lead_lag(m, F1, F2_x, 1.0, p.T2, p.T3)
    d_F3, F3 = lag(m, clip(m, Pref - F2 * (p.Sb / p.Sn), p.PMIN, p.PMAX), F3_y, 1.0, p.T4)
    d_F4, F4 = lag(m, F3, F4_y, p.K2, p.T5)
    d_F5, F5 = lag(m, F4, F5_y, p.K3, p.T6)
    return (d_F1, d_F2, d_F3, d_F4, d_F5), (F3, F4, F5)


def derivatives(x, u, p: IEESGOParams, m):
    """(dF1_y, dF2_x, dF3_y, dF4_y, dF5_y)/dt for x as the states, u = (omega, Pref)."""
    return _chain(x, u, p, m)[0]


def outputs(x, u, p: IEESGOParams, m):
    """(Pm,) = (1 - K2) F3 + (1 - K3) F4 + F5."""
    F3, F4, F5 = _chain(x, u, p, m)[1]
    return ((1.0 - p.K2) * F3 + (1.0 - p.K3) * F4 + F5,)


def _rest(wd: float, HL: float, p: IEESGOParams) -> np.ndarray:
    return np.array([p.K1 * wd, p.K1 * wd, HL, p.K2 * HL, p.K3 * p.K2 * HL])


def equilibrium(u, p: IEESGOParams) -> np.ndarray:
    """The steady state [5] at constant (omega, Pref): every block at its input."""
    omega, Pref = finite_inputs(u, "IEESGO")
    wd = omega - p.wref0
    return _rest(wd, min(max(Pref - p.K1 * wd * p.Sb / p.Sn, p.PMIN), p.PMAX), p)


def start(given, p: IEESGOParams) -> tuple:
    """(x0 [5], {"Pref": ...}): at rest at speed given["omega"] giving Pm = given["Pm"] (ANDES:
    pref0 = tm0 at omega = wref0); ValueError outside [PMIN, PMAX]."""
    wd, Pm = float(given["omega"]) - p.wref0, float(given["Pm"])
    if not p.PMIN <= Pm <= p.PMAX:
        raise ValueError(f"IEESGO: the mechanical power {Pm:.6g} pu lies outside [PMIN, PMAX]")
    return _rest(wd, Pm, p), {"Pref": Pm + p.K1 * wd * p.Sb / p.Sn}


IEESGO = turbine_governor(
    "ieesgo", "IEESGO IEEE standard steam turbine-governor (PSS/E, ANDES 2.0.0)",
    states=(Quantity("F1_y", "pu", "controller lag"), Quantity("F2_x", "pu", "lead-lag state"),
            Quantity("F3_y", "pu", "steam inlet lag"), Quantity("F4_y", "pu", "reheater lag"),
            Quantity("F5_y", "pu", "crossover lag")),
    reference=Quantity("Pref", "pu", "power reference (mechanical power at rest at wref0)", start=0.7,
                       operating_range=(0.0, 1.2)),
    params_type=IEESGOParams, state_scales=(0.01, 0.01, 0.2, 0.2, 0.2),
    derivatives=derivatives, outputs=outputs, equilibrium=equilibrium, start=start)
