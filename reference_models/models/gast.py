"""GAST: the gas turbine-governor (PSS/E GAST, ANDES), as ANDES 2.0.0 computes it.

States  x = (LAG_y [pu] fuel valve held within [VMIN, VMAX], LG2_y [pu] turbine lag,
        LG3_y [pu] exhaust temperature measurement lag)
Inputs  u = (omega [pu] rotor speed, Pref [pu] reference: ANDES' pref, in the units of R times
        power (at rest at omega = wref0: Pref = R Pm), as TGOV1's)
Outputs y = (Pm [pu] mechanical power)

Equations (ANDES 2.0 model reference, TurbineGov: GAST):

    wd = omega - wref0
    pd = (Pref - wd) / R                                  (valve demand)
    v9 = AT + KT (AT - LG3_y)                             (temperature limit)
    low-value gate: LVG = min(pd, v9)
    non-windup lag 1 / (1 + s T1):  T1 dLAG_y/dt = LVG - LAG_y,  VMIN <= LAG_y <= VMAX
        (reset: LAG_y at or beyond a limit while LVG - LAG_y pushes outward is placed on it)
    lags 1 / (1 + s T2) of LAG_y -> LG2_y, 1 / (1 + s T3) of LG2_y -> LG3_y (T = 0: the lag
        passes its input, its state held)
    Pm = LG2_y - Dt wd

At rest the valve is min(pd, AT): the temperature loop holds it at AT when the demand exceeds it.

Bases: R, VMAX, VMIN, AT, Dt and Pm on the turbine's base, which the integration takes as the
machine's base Sn (ANDES' default when Tn is not given); ANDES converts them to the system base,
where its equations are the same (KT is a ratio).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blocks import lag, lag_non_windup, lag_non_windup_reset, low_value_gate
from ..component import Parameters, Quantity
from .common import check_limits, check_ranges, finite_inputs
from .tgov1 import turbine_governor

PARAMETER_RANGES = {"R": (0.001, 10.0, "pu"), "KT": (0.0, 1000.0, "pu"), "AT": (0.0, 100.0, "pu"),
                    "T1": (0.0, 100.0, "s"), "T2": (0.0, 100.0, "s"), "T3": (0.0, 100.0, "s"),
                    "Dt": (0.0, 100.0, "pu"), "wref0": (0.5, 1.5, "pu")}


@dataclass(frozen=True)
class GASTParams(Parameters):
    """ANDES/PSS/E GAST data: droop R [pu], valve limits VMAX, VMIN [pu], temperature limiter gain
    KT [pu] and ambient temperature load limit AT [pu], time constants T1 (valve), T2 (turbine),
    T3 (temperature measurement) [s], turbine damping Dt [pu], speed reference wref0 [pu]."""

    R: float = 0.05
    VMAX: float = 1.2
    VMIN: float = 0.0
    KT: float = 5.0
    AT: float = 1.0
    T1: float = 0.1
    T2: float = 0.2
    T3: float = 10.0
    Dt: float = 0.0
    wref0: float = 1.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "VMIN", "VMAX")


def _gate(x, u, p: GASTParams, m):
    """(LVG, LG2_y, LG3_y, rates of LG2, LG3): the gated valve demand and the turbine lags."""
    omega, Pref = u
    d_LG2, LG2_y = lag(m, x[0], x[1], 1.0, p.T2)
    d_LG3, LG3_y = lag(m, LG2_y, x[2], 1.0, p.T3)
    pd = (Pref - (omega - p.wref0)) / p.R
    return low_value_gate(m, pd, p.AT + p.KT * (p.AT - LG3_y)), LG2_y, d_LG2, d_LG3


def derivatives(x, u, p: GASTParams, m):
    """(dLAG_y, dLG2_y, dLG3_y)/dt for x = (LAG_y, LG2_y, LG3_y), u = (omega, Pref)."""
    LVG, _, d_LG2, d_LG3 = _gate(x, u, p, m)
    return lag_non_windup(m, LVG, x[0], 1.0, p.T1, p.VMIN, p.VMAX)[0], d_LG2, d_LG3


def reset(x, u, p: GASTParams, m):
    """x after the reset of the valve's non-windup limit (blocks.lag_non_windup_reset)."""
    LVG = _gate(x, u, p, m)[0]
    return lag_non_windup_reset(m, LVG, x[0], 1.0, p.T1, p.VMIN, p.VMAX), x[1], x[2]


def outputs(x, u, p: GASTParams, m):
    """(Pm,) = LG2_y - Dt (omega - wref0)."""
    return (_gate(x, u, p, m)[1] - p.Dt * (u[0] - p.wref0),)


def _rest(valve: float, p: GASTParams) -> np.ndarray:
    if not p.VMIN <= valve <= p.VMAX:
        raise ValueError(f"GAST: the valve position {valve:.6g} pu at rest lies outside [VMIN, VMAX]")
    return np.array([valve, valve, valve])


def equilibrium(u, p: GASTParams) -> np.ndarray:
    """The steady state [3] at constant (omega, Pref): the valve at min(pd, AT); ValueError
    outside [VMIN, VMAX]."""
    omega, Pref = finite_inputs(u, "GAST")
    return _rest(min((Pref - (omega - p.wref0)) / p.R, p.AT), p)


def start(given, p: GASTParams) -> tuple:
    """(x0 [3], {"Pref": ...}): at rest at speed given["omega"] giving Pm = given["Pm"] (ANDES:
    pref = R tm0 at omega = wref0); ValueError where the valve would rest above the temperature
    limit AT or outside [VMIN, VMAX]."""
    wd = float(given["omega"]) - p.wref0
    valve = float(given["Pm"]) + p.Dt * wd
    if valve > p.AT:
        raise ValueError(f"GAST: the valve position {valve:.6g} pu at rest exceeds the temperature limit AT")
    return _rest(valve, p), {"Pref": p.R * valve + wd}


GAST = turbine_governor(
    "gast", "GAST gas turbine-governor (PSS/E, ANDES 2.0.0)",
    states=(Quantity("LAG_y", "pu", "fuel valve position (non-windup limited)"),
            Quantity("LG2_y", "pu", "turbine lag"),
            Quantity("LG3_y", "pu", "exhaust temperature measurement lag")),
    reference=Quantity("Pref", "pu", "reference (R times power at rest)", start=0.035, operating_range=(0.0, 0.05)),
    params_type=GASTParams, state_scales=(0.2, 0.2, 0.2),
    derivatives=derivatives, outputs=outputs, equilibrium=equilibrium, reset=reset, start=start)
