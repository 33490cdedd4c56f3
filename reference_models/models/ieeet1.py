"""IEEET1: the IEEE Type 1 exciter (PSS/E IEEET1) as ANDES 2.0.0 computes it.

States  x = (LG_y [pu] sensed voltage, LA_y [pu] regulator output held within [VRMIN, VRMAXc],
        INT_y [pu] exciter output, WF_x [pu] feedback washout state)
Inputs  u = (Vt [pu] input voltage (terminal, or compensated by IEEEVC), Vref [pu] set point,
        Vss [pu] stabiliser signal)
Outputs y = (Efd [pu] field voltage = INT_y)

Equations (ANDES 2.0.0, andes/models/exciter/ieeet1.py):

    sensing lag 1 / (1 + s TR):  TR dLG_y/dt = Vt - LG_y  (TR = 0: LG_y held, Vt used)
    washout s KF / (1 + s TF) of INT_y:  TF dWF_x/dt = INT_y - WF_x,  WF_y = KF (INT_y - WF_x) / TF
    vi = Vref - LG_y + Vss
    non-windup lag KA / (1 + s TA) of vi - WF_y:  TA dLA_y/dt = KA (vi - WF_y) - LA_y,
        VRMIN <= LA_y <= VRMAXc, VRMAXc = VRMAX, or 999 where VRMAX = 0
        (reset: LA_y at or beyond a limit while its unlimited rate pushes outward is placed on it);
        its output VR = LA_y; TA = 0 (ei/EI_33): LA_y held, VR = KA (vi - WF_y) clipped to
        [VRMIN, VRMAXc] (ANDES: the lag's equation algebraic, pegged by its limiter)
    TE dINT_y/dt = VR - KE INT_y - Se,  Se = B (INT_y - A)^2 where INT_y >= A, else 0
        (quadratic saturation, ANDES' ExcQuadSat; esdc2a.exciter_rate)
    Efd = INT_y

At rest (ANDES' initialisation, exdc2.dc_initialise without its lead-lag state): LG_y = Vt,
LA_y = KE Efd + Se(Efd), INT_y = WF_x = Efd, Vref = Vt + LA_y / KA - Vss.

How ANDES 2.0.0's IEEET1 differs from its EXDC2 (exdc2.py): no lead-lag (four states, not five);
the washout's input is INT_y = Efd, subtracted after the summing point with the sensed voltage,
as EXDC2's; no speed multiplication (Efd = INT_y; EXDC2: omega vp) and the saturation's switch
compares INT_y itself with A; the same quadratic saturation (not the exponential one); the same
constant limits (ceiling 999 where VRMAX = 0); names KF, TF (EXDC2: KF1, TF1). ANDES' parameter
Switch (unused) is not a parameter here.

Bases: pu of the exciter's base (the machine's field voltage); no powers.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blocks import lag, lag_non_windup, lag_non_windup_reset, washout
from ..component import Component, Parameters, Quantity
from .common import controller_initialisation, finite_inputs
from .esdc2a import ESDC_PORTS, ceiling, check_dc_exciter, exciter_rate, saturation_of
from .exdc2 import DC_INPUTS, dc_equilibrium, dc_initialise

PARAMETER_RANGES = {"TR": (0.0, 10.0, "s"), "KA": (0.01, 5000.0, "pu"), "TA": (0.0, 10.0, "s"),
                    "KE": (-1.0, 10.0, "pu"), "TE": (0.001, 10.0, "s"), "KF": (0.0, 10.0, "pu"),
                    "TF": (0.001, 100.0, "s"), "E1": (0.0, 20.0, "pu"), "SE1": (0.0, 10.0, "pu"),
                    "E2": (0.0, 20.0, "pu"), "SE2": (0.0, 10.0, "pu")}


@dataclass(frozen=True)
class IEEET1Params(Parameters):
    """ANDES/PSS/E IEEET1 data: time constants [s], gains [pu], regulator limits VRMAX (0: 999),
    VRMIN [pu], saturation points E1, E2 [pu] with SE1, SE2 [pu]."""

    TR: float = 0.02
    KA: float = 5.0
    TA: float = 0.04
    VRMAX: float = 7.3
    VRMIN: float = -7.3
    KE: float = 1.0
    TE: float = 0.8
    KF: float = 0.1
    TF: float = 1.0
    E1: float = 0.0
    SE1: float = 0.0
    E2: float = 1.0
    SE2: float = 1.0

    def check(self) -> None:
        check_dc_exciter(self, PARAMETER_RANGES)

    @property
    def saturation(self) -> tuple:
        return saturation_of(self)


def _regulator(x, u, p: IEEET1Params, m):
    """(dLG_y/dt, dWF_x/dt, the regulator's input vi - WF_y)."""
    LG_y, LA_y, INT_y, WF_x = x
    Vt, Vref, Vss = u
    d_LG, sensed = lag(m, Vt, LG_y, 1.0, p.TR)
    d_WF, WF_y = washout(m, INT_y, WF_x, p.KF, p.TF)
    return d_LG, d_WF, Vref - sensed + Vss - WF_y


def derivatives(x, u, p: IEEET1Params, m):
    """(dLG_y, dLA_y, dINT_y, dWF_x)/dt for x = (LG_y, LA_y, INT_y, WF_x), u = (Vt, Vref, Vss)."""
    d_LG, d_WF, error = _regulator(x, u, p, m)
    d_LA, VR = lag_non_windup(m, error, x[1], p.KA, p.TA, p.VRMIN, ceiling(p.VRMAX))
    return d_LG, d_LA, exciter_rate(m, VR, x[2], p), d_WF


def reset(x, u, p: IEEET1Params, m):
    """x after the reset of the regulator's limits VRMIN, VRMAXc (blocks.lag_non_windup_reset)."""
    LA_y = lag_non_windup_reset(m, _regulator(x, u, p, m)[2], x[1], p.KA, p.TA, p.VRMIN, ceiling(p.VRMAX))
    return x[0], LA_y, x[2], x[3]


def outputs(x, u, p: IEEET1Params, m):
    """(Efd,) = INT_y."""
    return (x[2],)


def _dc_start(Efd: float, u, p: IEEET1Params) -> tuple:
    """(x [5] of the DC exciter with a lead-lag, Vref): exdc2.dc_initialise at u = (Vt, Vref, Vss)."""
    Vt, _, Vss = (float(v) for v in u)
    return dc_initialise(Efd, Vt, Vss, 1.0, p)


def initialise(Efd: float, u, p: IEEET1Params) -> tuple:
    """(x [4], Vref [pu]): the state at rest giving field voltage Efd [pu] at inputs u (its Vref
    ignored) and the set point that holds it (ANDES' initialisation)."""
    x, Vref = _dc_start(Efd, u, p)
    return np.delete(x, 1), Vref


def equilibrium(u, p: IEEET1Params) -> np.ndarray:
    """The steady state [4] at constant (Vt, Vref, Vss); ValueError where there is none within the
    regulator limits."""
    _, Vref, _ = finite_inputs(u, "IEEET1")
    x = dc_equilibrium(lambda e: _dc_start(e, u, p), Vref, (p.VRMIN, ceiling(p.VRMAX)), "IEEET1")
    return np.delete(x, 1)


IEEET1 = Component(
    name="ieeet1",
    description="IEEET1 IEEE Type 1 exciter (PSS/E, ANDES 2.0.0)",
    states=(Quantity("LG_y", "pu", "sensed voltage"),
            Quantity("LA_y", "pu", "regulator output (non-windup limited)"),
            Quantity("INT_y", "pu", "exciter output (field voltage)"),
            Quantity("WF_x", "pu", "feedback washout state")),
    inputs=DC_INPUTS,
    outputs=(Quantity("Efd", "pu", "field voltage"),),
    params_type=IEEET1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 1.0, 0.5, 0.5),
    reset=reset,
    ports=ESDC_PORTS,
    initialisation=controller_initialisation(DC_INPUTS, "Efd", "Vref", initialise),
)
