"""ESST1A: the IEEE ST1A static exciter (PSS/E ESST1A, ANDES).

States  x = (LG_y [pu] sensed voltage, LL_x, LL1_x [pu] lead-lag states, LA_y [pu] regulator
        output VA held within [VAMIN, VAMAX], WF_x [pu] feedback washout state)
Inputs  u = (Vt [pu] terminal voltage, Vref [pu] set point, Vss [pu] stabiliser signal,
        XadIfd [pu] the machine's field current)
Outputs y = (Efd [pu] field voltage)

Equations (ANDES 2.0.0, andes/models/exciter/esst1a.py, as it computes them), with ANDES'
constant limiter signals UEL = -999, OEL = 999 and its floor LLIM = -9999 of an unused gate:

    sensing lag 1 / (1 + s TR):  TR dLG_y/dt = Vt - LG_y  (TR = 0: LG_y held, Vt used)
    vi = Vref - LG_y - WF_y + Vss (+ UEL where UELc = 1)
    vil = vi clipped to [VIMIN, VIMAX],  HVG1 = max(UEL where UELc = 2 else LLIM, vil)
    lead-lags (1 + s TC) / (1 + s TB), (1 + s TC1) / (1 + s TB1) (TB, TB1 = 0: gains of 1) -> LL1_y
    non-windup lag KA / (1 + s TA):  TA dLA_y/dt = KA LL1_y - LA_y,  VAMIN <= LA_y <= VAMAX,
        VA = LA_y (TA > 0: with TA = 0 the feedback through WF_y would be an algebraic loop)
        reset: LA_y at or beyond a limit while KA LL1_y - LA_y pushes outward is placed on it
    ILR loop: LR_y = max(KLR (XadIfd - ILR), 0),  vas = VA - LR_y
    LVG_y = min(max(UEL where UELc = 3 else LLIM, vas), OEL)
    washout s KF / (1 + s TF) of LVG_y:  TF dWF_x/dt = LVG_y - WF_x,  WF_y = KF (LVG_y - WF_x) / TF
    Efd = LVG_y clipped to [Vt VRMIN, Vt VRMAX - KC XadIfd]  (windup limiter; ANDES' |vd + j vq| is
        the terminal voltage Vt)

With UELc = 1 (ANDES' default and its cases' data) the constant UEL = -999 enters vi, so the set
point that holds a rest is about 1000 pu: Vref = Vt + (Efd + LR_y) / KA + 999 - Vss, ANDES' vref.
ANDES' stabiliser alternatives (VOSc) act on a signal SG that is 0: no parameter here.

Start (ANDES' initialisation): VA = Efd + LR_y, LL_x = LL1_x = VA / KA, WF_x = Efd, LG_y = Vt.
Machine base, as the case data give them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import clip, clip_between, lag, lag_non_windup, lag_non_windup_reset, lead_lag, washout
from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_limits, check_ranges, finite_inputs
from .exac1 import VT, XADIFD, regulator_within

UEL, OEL, LLIM = -999.0, 999.0, -9999.0  # pu: ANDES' constant limiter signals and an unused gate's input
PARAMETER_RANGES = {"TR": (0.0, 10.0, "s"), "TB": (0.0, 100.0, "s"), "TC": (0.0, 100.0, "s"),
                    "TB1": (0.0, 100.0, "s"), "TC1": (0.0, 100.0, "s"), "KA": (0.01, 5000.0, "pu"),
                    "TA": (0.001, 10.0, "s"), "ILR": (0.0, 100.0, "pu"), "KLR": (0.0, 100.0, "pu"),
                    "KF": (0.0, 10.0, "pu"), "TF": (0.001, 100.0, "s"), "KC": (0.0, 10.0, "pu")}


@dataclass(frozen=True)
class ESST1AParams(Parameters):
    """ANDES/PSS/E ESST1A data (ANDES' defaults): time constants [s], gains [pu], limits [pu], the
    field current limit ILR [pu] with its gain KLR [pu], and UELc, where ANDES' UEL signal enters
    (0: nowhere, 1: the summing point, 2: after the input limiter, 3: after the regulator)."""

    TR: float = 0.01
    VIMAX: float = 0.8
    VIMIN: float = -0.1
    TB: float = 1.0
    TC: float = 1.0
    TB1: float = 1.0
    TC1: float = 1.0
    VAMAX: float = 999.0
    VAMIN: float = -999.0
    KA: float = 80.0
    TA: float = 0.04
    ILR: float = 1.0
    KLR: float = 1.0
    VRMAX: float = 7.3
    VRMIN: float = -7.3
    KF: float = 0.1
    TF: float = 1.0
    KC: float = 0.1
    UELc: float = 1.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        for low, high in (("VIMIN", "VIMAX"), ("VAMIN", "VAMAX"), ("VRMIN", "VRMAX")):
            check_limits(self, low, high)
        self.require("UELc", self.UELc in (0.0, 1.0, 2.0, 3.0), "be 0, 1, 2 or 3")

    def uel(self, code: float) -> float:
        """The gate input where UEL enters at `code`: UEL there, LLIM elsewhere (ANDES' UEL2, UEL3)."""
        return UEL if self.UELc == code else LLIM

    @property
    def summed_uel(self) -> float:
        """What UEL adds to vi: UEL where UELc = 1, else 0 [pu]."""
        return UEL if self.UELc == 1.0 else 0.0


def _current_limit(XadIfd, p: ESST1AParams, m):
    """LR_y = max(KLR (XadIfd - ILR), 0) [pu]: the field current limiter's signal."""
    return clip(m, p.KLR * (XadIfd - p.ILR), 0.0, math.inf)


def _signals(x, u, p: ESST1AParams, m):
    """(dLG_y, dLL_x, dLL1_x, dWF_x, LL1_y, LVG_y): the sensing lag's, lead-lags' and washout's
    derivatives, the regulator's input and the gated regulator output."""
    LG_y, LL_x, LL1_x, LA_y, WF_x = x
    Vt, Vref, Vss, XadIfd = u
    d_LG, sensed = lag(m, Vt, LG_y, 1.0, p.TR)
    LVG_y = clip(m, LA_y - _current_limit(XadIfd, p, m), p.uel(3.0), OEL)
    d_WF, WF_y = washout(m, LVG_y, WF_x, p.KF, p.TF)
    vi = Vref - sensed - WF_y + Vss + p.summed_uel
    HVG1 = clip(m, clip(m, vi, p.VIMIN, p.VIMAX), p.uel(2.0), math.inf)
    d_LL, LL_y = lead_lag(m, HVG1, LL_x, 1.0, p.TC, p.TB)
    d_LL1, LL1_y = lead_lag(m, LL_y, LL1_x, 1.0, p.TC1, p.TB1)
    return d_LG, d_LL, d_LL1, d_WF, LL1_y, LVG_y


def derivatives(x, u, p: ESST1AParams, m):
    """(dLG_y, dLL_x, dLL1_x, dLA_y, dWF_x)/dt for x = (LG_y, LL_x, LL1_x, LA_y, WF_x),
    u = (Vt, Vref, Vss, XadIfd)."""
    d_LG, d_LL, d_LL1, d_WF, LL1_y, _ = _signals(x, u, p, m)
    d_LA, _ = lag_non_windup(m, LL1_y, x[3], p.KA, p.TA, p.VAMIN, p.VAMAX)
    return d_LG, d_LL, d_LL1, d_LA, d_WF


def reset(x, u, p: ESST1AParams, m):
    """x after the reset of the regulator's non-windup limit (blocks.lag_non_windup_reset)."""
    LL1_y = _signals(x, u, p, m)[4]
    return x[0], x[1], x[2], lag_non_windup_reset(m, LL1_y, x[3], p.KA, p.TA, p.VAMIN, p.VAMAX), x[4]


def outputs(x, u, p: ESST1AParams, m):
    """(Efd,): LVG_y within [Vt VRMIN, Vt VRMAX - KC XadIfd]."""
    Vt, XadIfd = u[0], u[3]
    return (clip_between(m, _signals(x, u, p, m)[5], Vt * p.VRMIN, Vt * p.VRMAX - p.KC * XadIfd),)


def rest(Efd: float, Vt: float, Vss: float, XadIfd: float, p: ESST1AParams) -> tuple:
    """(x [5], Vref [pu]): the state at rest giving field voltage Efd [pu] and the set point that
    holds it (ANDES' initialisation); ValueError where a limit would hold it (vi outside
    [VIMIN, VIMAX], VA outside [VAMIN, VAMAX], Efd outside the gates or the output limits)."""
    VA = Efd + _current_limit(XadIfd, p, math)
    vi = VA / p.KA
    if not p.VIMIN <= vi <= p.VIMAX:
        raise ValueError(f"ESST1A: the input {vi:.6g} pu at rest lies outside [VIMIN, VIMAX]")
    regulator_within(VA, p.VAMIN, p.VAMAX, "ESST1A")
    if not max(p.uel(3.0), Vt * p.VRMIN) <= Efd <= min(OEL, Vt * p.VRMAX - p.KC * XadIfd):
        raise ValueError(f"ESST1A: the field voltage {Efd:.6g} pu lies outside the output limits")
    Vref = Vt + vi - Vss - p.summed_uel
    return np.array([Vt, vi, vi, VA, Efd]), Vref


def start(given, p: ESST1AParams) -> tuple:
    """Initialisation.start: (x0, {"Vref": ...}) from given Vt, Vss, XadIfd and the demanded Efd."""
    x0, Vref = rest(float(given["Efd"]), float(given["Vt"]), float(given["Vss"]), float(given["XadIfd"]), p)
    return x0, {"Vref": Vref}


def equilibrium(u, p: ESST1AParams) -> np.ndarray:
    """The steady state [5] at constant (Vt, Vref, Vss, XadIfd): VA = KA vi at rest; ValueError
    where a limit would hold it."""
    Vt, Vref, Vss, XadIfd = finite_inputs(u, "ESST1A")
    vi = Vref - Vt + Vss + p.summed_uel
    return rest(p.KA * vi - _current_limit(XadIfd, p, math), Vt, Vss, XadIfd, p)[0]


#: the set point at rest at the start inputs (1 pu, 1.5 pu field current, Efd 1.5 pu) with ANDES'
#: UELc = 1: about 1000 pu (module docstring)
VREF_START = 1.0 + (1.5 + 0.5) / 80.0 - UEL

ESST1A = Component(
    name="esst1a",
    description="ESST1A IEEE ST1A static exciter (PSS/E, ANDES)",
    states=(Quantity("LG_y", "pu", "sensed terminal voltage"),
            Quantity("LL_x", "pu", "first lead-lag state"),
            Quantity("LL1_x", "pu", "second lead-lag state"),
            Quantity("LA_y", "pu", "regulator output VA (non-windup limited)"),
            Quantity("WF_x", "pu", "feedback washout state")),
    inputs=(VT, Quantity("Vref", "pu", "voltage set point (about 1000 pu with UELc = 1, as ANDES)", start=VREF_START,
                         operating_range=(VREF_START - 0.1, VREF_START + 0.15)),
            Quantity("Vss", "pu", "stabiliser signal", start=0.0, operating_range=(-0.1, 0.1)), XADIFD),
    outputs=(Quantity("Efd", "pu", "field voltage"),),
    params_type=ESST1AParams,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.01, 0.01, 2.0, 0.5),
    reset=reset,
    ports=Ports(inputs=(Link("terminal_voltage", "Vt"), Link("voltage_reference", "Vref"),
                        Link("stabiliser_signal", "Vss"), Link("field_current", "XadIfd")),
                outputs=(Link("field_voltage", "Efd"),)),
    initialisation=Initialisation(("Vref",), start),
)
