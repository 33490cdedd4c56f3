"""HYGOV: the hydro turbine-governor (PSS/E HYGOV, ANDES), as ANDES 2.0.0 computes it; HYGOVDB
(hygovdb.py) is the same with a dead band on the speed deviation.

States  x = (LG_y [pu] filtered speed error, gtpos [pu] gate position of the governor's integral
        part, held within [GMIN, GMAX] at rates within the gate velocity limits, LAG_y [pu] gate
        opening (servo), q_y [pu] turbine flow)
Inputs  u = (omega [pu] rotor speed, Pref [pu] reference: ANDES' pref, in the units of R times gate
        opening (at rest at omega = wref0: Pref = R (Pm / At + qNL)))
Outputs y = (Pm [pu] mechanical power)

Equations (ANDES 2.0 model reference, TurbineGov: HYGOV), with c = Sn / Sb:

    wd = omega - wref0;  sig = wd (HYGOVDB: its dead band of wd)
    dg = gtpos + LG_y / r                                (desired gate)
    lag 1 / (1 + s Tf):  Tf dLG_y/dt = Pref - sig - R dg - LG_y
    dgtpos/dt = LG_y / c clipped to [-VELM - LG_y / r, VELM - LG_y / r] (rate limit), with a
        non-windup limit GMIN <= gtpos <= GMAX (ANDES' AntiWindupRate; reset: gtpos at or beyond
        a limit while its rate-limited derivative pushes outward is placed on it)
    lag 1 / (1 + s Tg) of dg -> LAG_y (g; Tg = 0: g = dg, the state held)
    h = q_y^2 / g^2;   dq_y/dt = (1 - h) / (c Tw)
    Pm = At h (q_y - qNL) - c Dt wd g

ANDES' HYGOV differs from PSS/E's in two ways that are kept: it ignores the input lead-lag, and
its governor integrates with gain 1 where PSS/E's (1 + s Tr) / (r Tr s) has 1 / (r Tr): the two
agree only for r Tr = 1 (ANDES' data r = Tr = 1), and Tr, which ANDES reads but does not use, is
not a parameter here.

Bases: R, r, GMAX, GMIN, VELM, Dt, qNL, Pm on the turbine's base, which the integration takes as
the machine's base Sn (ANDES' default when Tn is not given). ANDES converts them to the system
base Sb, where its equations mix bases: the gate integrates the base-free LG_y, the flow the
base-free 1 - h, and its damping Dt wd g multiplies two powers; on the turbine base that is the
factor c = Sn / Sb above (parameters Sn, Sb [MVA]; Sn = Sb: PSS/E's equations).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blocks import lag, rate_limited_non_windup, rate_limited_non_windup_reset
from ..component import Component, Parameters, Quantity
from .common import check_limits, check_ranges, finite_inputs
from .tgov1 import turbine_governor

PARAMETER_RANGES = {"R": (0.001, 10.0, "pu"), "r": (0.001, 100.0, "pu"), "VELM": (0.0, 100.0, "pu/s"),
                    "Tf": (0.001, 100.0, "s"), "Tg": (0.0, 100.0, "s"), "Dt": (0.0, 100.0, "pu"),
                    "qNL": (0.0, 10.0, "pu"), "Tw": (0.001, 100.0, "s"), "At": (0.001, 100.0, "pu"),
                    "wref0": (0.5, 1.5, "pu"), "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA")}


@dataclass(frozen=True)
class HYGOVParams(Parameters):
    """ANDES/PSS/E HYGOV data: permanent droop R and temporary droop r [pu], gate limits GMAX, GMIN
    [pu] and velocity limit VELM [pu/s], time constants Tf (filter), Tg (servo), Tw (water inertia)
    [s], turbine damping Dt [pu], no-load flow qNL [pu], turbine gain At, speed reference wref0
    [pu], the turbine's base Sn and the system base Sb [MVA] (ANDES' bases, above)."""

    R: float = 0.05
    r: float = 1.0
    GMAX: float = 1.0
    GMIN: float = 0.0
    VELM: float = 0.3
    Tf: float = 0.05
    Tg: float = 0.05
    Dt: float = 0.0
    qNL: float = 0.1
    Tw: float = 1.0
    At: float = 1.0
    wref0: float = 1.0
    Sn: float = 100.0
    Sb: float = 100.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "GMIN", "GMAX")


def hydro_governor(name: str, description: str, params_type: type, speed_signal) -> Component:
    """The HYGOV equations as a Component, with `speed_signal(wd, p, m)` the signal the governor
    takes of the speed deviation wd = omega - wref0 (HYGOV: wd itself)."""
    label = name.upper()

    def _chain(x, u, p, m):
        """(dLG_y, (gate rate before its limits, rate limits), dLAG_y, g, h, dq_y, wd)."""
        LG_y, gtpos, LAG_y, q_y = x
        omega, Pref = u
        c = p.Sn / p.Sb
        wd = omega - p.wref0
        dg = gtpos + LG_y / p.r
        d_LG, _ = lag(m, Pref - speed_signal(wd, p, m) - p.R * dg, LG_y, 1.0, p.Tf)
        d_LAG, g = lag(m, dg, LAG_y, 1.0, p.Tg)
        h = q_y * q_y / (g * g)
        gate = (LG_y / c, -p.VELM - LG_y / p.r, p.VELM - LG_y / p.r)
        return d_LG, gate, d_LAG, g, h, (1.0 - h) / (c * p.Tw), wd

    def derivatives(x, u, p, m):
        """(dLG_y, dgtpos, dLAG_y, dq_y)/dt for x = (LG_y, gtpos, LAG_y, q_y), u = (omega, Pref)."""
        d_LG, (rate, low, high), d_LAG, _, _, d_q, _ = _chain(x, u, p, m)
        return d_LG, rate_limited_non_windup(m, rate, x[1], low, high, p.GMIN, p.GMAX), d_LAG, d_q

    def reset(x, u, p, m):
        """x after the reset of the gate position's non-windup limit (at its rate-limited derivative)."""
        rate, low, high = _chain(x, u, p, m)[1]
        return x[0], rate_limited_non_windup_reset(m, rate, x[1], low, high, p.GMIN, p.GMAX), x[2], x[3]

    def outputs(x, u, p, m):
        """(Pm,) = At h (q_y - qNL) - c Dt wd g."""
        _, _, _, g, h, _, wd = _chain(x, u, p, m)
        return (p.At * h * (x[3] - p.qNL) - p.Sn / p.Sb * p.Dt * wd * g,)

    def _rest(gate: float, p) -> np.ndarray:
        if not (p.GMIN <= gate <= p.GMAX and gate > 0):
            raise ValueError(f"{label}: the gate position {gate:.6g} pu at rest lies outside [GMIN, GMAX] "
                             "or is not positive")
        return np.array([0.0, gate, gate, gate])

    def equilibrium(u, p) -> np.ndarray:
        """The steady state [4] at constant (omega, Pref): gate and flow at (Pref - sig) / R, the
        filter at 0; ValueError outside [GMIN, GMAX]."""
        omega, Pref = finite_inputs(u, label)
        return _rest((Pref - float(speed_signal(omega - p.wref0, p, np))) / p.R, p)

    def start(given, p) -> tuple:
        """(x0 [4], {"Pref": ...}): at rest at speed given["omega"] giving Pm = given["Pm"] (ANDES:
        gate and flow at q0 = tm0 / At + qNL, pref = R q0 at omega = wref0)."""
        wd = float(given["omega"]) - p.wref0
        slope = p.At - p.Sn / p.Sb * p.Dt * wd
        if slope <= 0:
            raise ValueError(f"{label}: no gate position at rest gives the power at this speed")
        x0 = _rest((float(given["Pm"]) + p.At * p.qNL) / slope, p)
        return x0, {"Pref": float(speed_signal(wd, p, np)) + p.R * x0[1]}

    return turbine_governor(
        name, description,
        states=(Quantity("LG_y", "pu", "filtered speed error"),
                Quantity("gtpos", "pu", "gate position, integral part (rate and non-windup limited)"),
                Quantity("LAG_y", "pu", "gate opening"),
                Quantity("q_y", "pu", "turbine flow")),
        reference=Quantity("Pref", "pu", "reference (R times gate opening at rest)", start=0.04,
                           operating_range=(0.0, 0.05)),
        params_type=params_type, state_scales=(0.01, 0.2, 0.2, 0.2),
        derivatives=derivatives, outputs=outputs, equilibrium=equilibrium, reset=reset, start=start)


HYGOV = hydro_governor("hygov", "HYGOV hydro turbine-governor (PSS/E, ANDES 2.0.0)", HYGOVParams,
                       lambda wd, p, m: wd)
