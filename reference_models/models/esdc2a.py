"""ESDC2A: the IEEE 421.5 DC2A exciter as ANDES 2.0.0 computes it (PSS/E ESDC2A); its equations,
with constant regulator limits, also serve ESDC1A (esdc1a.py: esdc_exciter makes both components),
and its exciter and saturation IEEET1 (ieeet1.py).

States  x = (LG_y [pu] sensing lag output (computed, not used: below), LL_x [pu] lead-lag state,
        LA_y [pu] regulator output VR, held within [VRMIN Vt, VRMAXc Vt], INT_y [pu] exciter output,
        WF_x [pu] feedback washout state)
Inputs  u = (Vt [pu] the exciter's input voltage: the terminal voltage, or the compensated voltage
        where a compensator (IEEEVC) gives the unit's terminal_voltage; Vref [pu] set point;
        Vss [pu] stabiliser signal)
Outputs y = (Efd [pu] field voltage = INT_y)

Equations (ANDES 2.0.0, andes/models/exciter/esdc2a.py):

    sensing lag 1 / (1 + s TR):  TR dLG_y/dt = Vt - LG_y  (TR = 0: LG_y held)
    washout s KF / (1 + s TF1) of INT_y:  TF1 dWF_x/dt = INT_y - WF_x,  WF_y = KF (INT_y - WF_x) / TF1
    vi = Vref - Vt - WF_y + Vss
    lead-lag (1 + s TC) / (1 + s TB) of vi -> LL_y  (TB = 0: a gain of 1)
    non-windup lag KA / (1 + s TA):  TA dLA_y/dt = KA LL_y - LA_y,  VRMIN Vt <= LA_y <= VRMAXc Vt,
        VRMAXc = VRMAX, or 999 where VRMAX = 0 (ANDES: "0 - unlimited")
        (reset: LA_y at or beyond a limit while KA LL_y - LA_y pushes outward is placed on it);
        its output VR = LA_y; TA = 0: LA_y held, VR = KA LL_y clipped to the limits (ANDES: the
        lag's equation algebraic, 0 = KA LL_y - LA_y, pegged by its limiter)
    TE dINT_y/dt = VR - KE INT_y - Se,  Se = B (INT_y - A)^2 where INT_y >= A, else 0
        (quadratic saturation through (E1, SE1), (E2, SE2): ANDES' ExcQuadSat; the defaults
        E2 = SE2 = 0 give B = 0, no saturation)
    Efd = INT_y
    (ANDES declares the under-excitation gate max(UEL, LL_y) but skips it: UEL = 0 is unused)

At rest (ANDES' initialisation, exdc2.dc_initialise): INT_y = WF_x = Efd, LA_y = KE Efd + Se(Efd),
LL_x = LA_y / KA, LG_y = Vt, Vref = Vt + LA_y / KA - Vss.

How ANDES 2.0.0's ESDC2A differs from its EXDC2 (exdc2.py), whose start and equilibrium it shares
(dc_initialise, dc_equilibrium; its derivatives cannot be shared, for the first three points):
- vi takes the input voltage Vt itself, not the sensing lag's output: ANDES' vi equation reads its
  `v`; its lag LG is a state that follows Vt and that nothing reads. Kept as a state (ANDES' state
  vector, its rate (Vt - LG_y) / TR), unused.
- the regulator's limits move with the input voltage: VRMIN Vt, VRMAXc Vt (ANDES' VarServices VRU,
  VRL, evaluated at every step; EXDC2: constant VRMIN, VRMAX); ESDC1A's are constant.
- no speed multiplication: Efd = INT_y (EXDC2: omega vp), and the saturation's switch compares
  INT_y itself with A (EXDC2: omega vp).
- the saturation is the same quadratic one, Se = B (INT_y - A)^2 (ANDES' ExcQuadSat; PSS/E's
  exponential form is not what ANDES computes for any of ESDC1A, ESDC2A, IEEET1, EXDC2).
- the feedback gain is KF (EXDC2: KF1), and VRMAX = 0 means a ceiling of 999 pu.
ANDES' parameter Switch (unused by ANDES and PSS/E) is not a parameter here.

Bases: every quantity in pu of the exciter's own base (the machine's field voltage); no powers.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blocks import (lag, lag_non_windup_between, lag_non_windup_reset, lead_lag, quadratic_saturation_coefficients,
                      quadratic_saturation_product, washout)
from ..component import Component, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_ranges, controller_initialisation, finite_inputs
from .exdc2 import DC_INPUTS, dc_equilibrium, dc_initialise

UNLIMITED_CEILING = 999.0  # pu: the regulator ceiling where the data give VRMAX = 0 (ANDES' VRMAXc)

PARAMETER_RANGES = {"TR": (0.0, 10.0, "s"), "KA": (0.01, 5000.0, "pu"), "TA": (0.0, 10.0, "s"),
                    "TB": (0.0, 100.0, "s"), "TC": (0.0, 100.0, "s"), "KE": (-1.0, 10.0, "pu"),
                    "TE": (0.001, 10.0, "s"), "KF": (0.0, 10.0, "pu"), "TF1": (0.001, 100.0, "s"),
                    "E1": (0.0, 20.0, "pu"), "SE1": (0.0, 10.0, "pu"), "E2": (0.0, 20.0, "pu"),
                    "SE2": (0.0, 10.0, "pu")}


def ceiling(VRMAX: float) -> float:
    """The regulator's upper limit [pu]: VRMAX, or 999 where VRMAX = 0 (ANDES' VRMAXc of ESDC1A,
    ESDC2A, IEEET1, IEEET3), in ANDES' floating-point arithmetic: it evaluates VRMAX - 999 z + 999
    (z = 1 where VRMAX is not 0; sympy's form of VRMAX + 999 (1 - z)), so VRMAX = 7.3 gives
    7.2999999999999545, and a regulator ANDES holds at its ceiling is at this one."""
    z = 1.0 if VRMAX != 0 else 0.0
    return VRMAX - UNLIMITED_CEILING * z + UNLIMITED_CEILING


def check_dc_exciter(params, ranges: dict) -> None:
    """The checks of a DC exciter's data (ESDC1A, ESDC2A, IEEET1): ranges, VRMIN below the ceiling,
    two distinct saturation points where SE1 is given."""
    check_ranges(params, ranges)
    params.require("VRMIN", params.VRMIN < ceiling(params.VRMAX),
                   f"lie below the ceiling {ceiling(params.VRMAX)!r} (VRMAX, or 999 for VRMAX = 0)")
    params.require("E2", params.E2 != params.E1 or params.SE1 == 0, f"differ from E1 = {params.E1!r}")


def saturation_of(params) -> tuple:
    """(A, B) of Se = B (INT_y - A)^2 (ANDES: ExcQuadSat(E1, SE1, E2, SE2))."""
    return quadratic_saturation_coefficients(params.E1, params.SE1, params.E2, params.SE2)


@dataclass(frozen=True)
class ESDC2AParams(Parameters):
    """ANDES/PSS/E ESDC2A (and ESDC1A) data: time constants [s], gains [pu], regulator limits
    VRMAX (0: 999), VRMIN [pu] (times Vt for ESDC2A), saturation points E1, E2 [pu] with SE1, SE2 [pu]."""

    TR: float = 0.01
    KA: float = 80.0
    TA: float = 0.04
    TB: float = 1.0
    TC: float = 1.0
    VRMAX: float = 7.3
    VRMIN: float = -7.3
    KE: float = 1.0
    TE: float = 0.8
    KF: float = 0.1
    TF1: float = 1.0
    E1: float = 0.0
    SE1: float = 0.0
    E2: float = 0.0
    SE2: float = 0.0

    def check(self) -> None:
        check_dc_exciter(self, PARAMETER_RANGES)

    @property
    def saturation(self) -> tuple:
        return saturation_of(self)


def exciter_rate(m, VR, INT_y, p):
    """dINT_y/dt of the DC exciter: TE dINT_y/dt = VR - KE INT_y - B (INT_y - A)^2 [INT_y >= A]
    (ESDC1A, ESDC2A, IEEET1), VR the regulator's output."""
    A, B = p.saturation
    return (VR - p.KE * INT_y - quadratic_saturation_product(m, INT_y, A, B)) / p.TE


def _limits(Vt, p: ESDC2AParams, proportional: bool) -> tuple:
    """(low, high) of the regulator: VRMIN Vt, VRMAXc Vt (proportional, ESDC2A) or VRMIN, VRMAXc."""
    if proportional:
        return p.VRMIN * Vt, ceiling(p.VRMAX) * Vt
    return p.VRMIN, ceiling(p.VRMAX)


def _regulator(x, u, p: ESDC2AParams, m):
    """(dLG_y/dt, dLL_x/dt, dWF_x/dt, the regulator lag's input LL_y)."""
    LG_y, LL_x, LA_y, INT_y, WF_x = x
    Vt, Vref, Vss = u
    d_LG, _ = lag(m, Vt, LG_y, 1.0, p.TR)  # ANDES' sensing lag: a state nothing reads
    d_WF, WF_y = washout(m, INT_y, WF_x, p.KF, p.TF1)
    d_LL, LL_y = lead_lag(m, Vref - Vt - WF_y + Vss, LL_x, 1.0, p.TC, p.TB)
    return d_LG, d_LL, d_WF, LL_y


def _esdc_derivatives(x, u, p: ESDC2AParams, m, proportional: bool):
    """(dLG_y, dLL_x, dLA_y, dINT_y, dWF_x)/dt for x = (LG_y, LL_x, LA_y, INT_y, WF_x),
    u = (Vt, Vref, Vss); the regulator's limits proportional to Vt (ESDC2A) or constant (ESDC1A)."""
    d_LG, d_LL, d_WF, LL_y = _regulator(x, u, p, m)
    low, high = _limits(u[0], p, proportional)
    d_LA, VR = lag_non_windup_between(m, LL_y, x[2], p.KA, p.TA, low, high)
    return d_LG, d_LL, d_LA, exciter_rate(m, VR, x[3], p), d_WF


def _esdc_reset(x, u, p: ESDC2AParams, m, proportional: bool):
    """x after the reset of the regulator's non-windup limit (blocks.lag_non_windup_reset)."""
    low, high = _limits(u[0], p, proportional)
    LA_y = lag_non_windup_reset(m, _regulator(x, u, p, m)[3], x[2], p.KA, p.TA, low, high)
    return x[0], x[1], LA_y, x[3], x[4]


def esdc_initialise(Efd: float, u, p: ESDC2AParams) -> tuple:
    """(x [5], Vref [pu]): the state at rest giving field voltage Efd [pu] at inputs u = (Vt, Vref,
    Vss) (its Vref ignored) and the set point that holds it (ANDES' initialisation)."""
    Vt, _, Vss = (float(v) for v in u)
    return dc_initialise(Efd, Vt, Vss, 1.0, p)


def _esdc_equilibrium(u, p: ESDC2AParams, proportional: bool, name: str) -> np.ndarray:
    """The steady state [5] at constant (Vt, Vref, Vss); ValueError where there is none within the
    regulator limits."""
    Vt, Vref, _ = finite_inputs(u, name)
    return dc_equilibrium(lambda e: esdc_initialise(e, u, p), Vref, _limits(Vt, p, proportional), name)


ESDC_STATES = (Quantity("LG_y", "pu", "sensing lag output (ANDES computes it and does not use it)"),
               Quantity("LL_x", "pu", "lead-lag state"),
               Quantity("LA_y", "pu", "regulator output (non-windup limited)"),
               Quantity("INT_y", "pu", "exciter output (field voltage)"),
               Quantity("WF_x", "pu", "feedback washout state"))
ESDC_PORTS = Ports(inputs=(Link("terminal_voltage", "Vt"), Link("voltage_reference", "Vref"),
                           Link("stabiliser_signal", "Vss")),
                   outputs=(Link("field_voltage", "Efd"),))


def esdc_exciter(name: str, description: str, proportional: bool) -> Component:
    """The Component of ESDC2A (proportional: the regulator's limits VRMIN Vt, VRMAXc Vt) or ESDC1A
    (constant limits VRMIN, VRMAXc): states x = (LG_y, LL_x, LA_y, INT_y, WF_x), inputs
    u = (Vt, Vref, Vss), output Efd = INT_y, data ESDC2AParams."""
    label = name.upper()

    def derivatives(x, u, p: ESDC2AParams, m):
        """(dLG_y, dLL_x, dLA_y, dINT_y, dWF_x)/dt."""
        return _esdc_derivatives(x, u, p, m, proportional)

    def reset(x, u, p: ESDC2AParams, m):
        """x after the reset of the regulator's limits."""
        return _esdc_reset(x, u, p, m, proportional)

    def outputs(x, u, p: ESDC2AParams, m):
        """(Efd,) = INT_y."""
        return (x[3],)

    def equilibrium(u, p: ESDC2AParams) -> np.ndarray:
        """The steady state [5] at constant (Vt, Vref, Vss)."""
        return _esdc_equilibrium(u, p, proportional, label)

    return Component(
        name=name,
        description=description,
        states=ESDC_STATES,
        inputs=DC_INPUTS,
        outputs=(Quantity("Efd", "pu", "field voltage"),),
        params_type=ESDC2AParams,
        derivatives=derivatives,
        output_equations=outputs,
        equilibrium=equilibrium,
        state_scales=(0.1, 0.05, 1.0, 0.5, 0.5),
        reset=reset,
        ports=ESDC_PORTS,
        initialisation=controller_initialisation(DC_INPUTS, "Efd", "Vref", esdc_initialise),
    )


ESDC2A = esdc_exciter("esdc2a", "ESDC2A IEEE DC2A exciter (PSS/E, ANDES 2.0.0)", True)
