"""EXAC1: the IEEE AC1 exciter (PSS/E EXAC1, ANDES); its AC exciter (the `ac_*` functions and
ACExciterParams) also serves ESAC1A (esac1a.py).

States  x = (LL_x [pu] lead-lag state, LA_y [pu] regulator output VR held within [VRMIN, VRMAX],
        INT_y [pu] exciter voltage VE, WF_x [pu] feedback washout state)
Inputs  u = (Vt [pu] terminal voltage, Vref [pu] set point, XadIfd [pu] the machine's field
        current)
Outputs y = (Efd [pu] field voltage)

Equations (ANDES 2.0.0, andes/models/exciter/exac1.py, as it computes them):

    VFE = KE VE + Se VE + KD XadIfd,  Se VE = B (VE - A)^2 where VE >= A, else 0
        (quadratic saturation through (E1, SE1), (E2, SE2), ANDES' ExcQuadSat)
    washout s KF / (1 + s TF) of VFE:  TF dWF_x/dt = VFE - WF_x,  WF_y = KF (VFE - WF_x) / TF
    vi = Vref - Vt - WF_y
    lead-lag (1 + s TC) / (1 + s TB) of vi (TB = 0: a gain of 1) -> LL_y
    non-windup lag KA / (1 + s TA):  TA dLA_y/dt = KA LL_y - LA_y,  VRMIN <= LA_y <= VRMAX
        (TA = 0: LA_y held, KA LL_y clipped to the limits used as VR)
        reset: LA_y at or beyond a limit while KA LL_y - LA_y pushes outward is placed on it
    integrator:  TE dVE/dt = VR - VFE
    IN = KC XadIfd / VE,  Efd = VE FEX(IN)  (reference_models.blocks.rectifier_loading)

As ANDES 2.0.0 computes it, unlike PSS/E: vi takes the terminal voltage Vt itself (ANDES builds a
sensing lag of time constant TR but leaves its output unused, so TR is no parameter here), and
there is no stabiliser input (ANDES' EXAC1 has none).

Start (ANDES' initialisation): VE solves VE FEX(KC XadIfd / VE) = Efd (unique for Efd > 0: the
product rises with VE; `ac_exciter_voltage`), VR = VFE, LL_x = VFE / KA, WF_x = VFE,
Vref = Vt + VFE / KA. All quantities on the machine base, as the case data give them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import (lag_non_windup, lag_non_windup_reset, lead_lag, quadratic_saturation_coefficients,
                      quadratic_saturation_product, rectifier_loading, washout)
from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_limits, check_ranges, finite_inputs, set_point

AC_PARAMETER_RANGES = {"TE": (0.001, 10.0, "s"), "KE": (-1.0, 10.0, "pu"), "KD": (0.0, 10.0, "pu"),
                       "KC": (0.0, 10.0, "pu"), "E1": (0.0, 20.0, "pu"), "SE1": (0.0, 10.0, "pu"),
                       "E2": (0.0, 20.0, "pu"), "SE2": (0.0, 10.0, "pu"), "TC": (0.0, 100.0, "s"),
                       "TB": (0.0, 100.0, "s"), "KA": (0.01, 5000.0, "pu"), "TA": (0.0, 10.0, "s")}


@dataclass(frozen=True)
class ACExciterParams(Parameters):
    """The data an AC exciter (EXAC1, ESAC1A) shares, ANDES' defaults: the regulator's lead-lag
    TC, TB [s] and gain KA [pu] with lag TA [s]; the exciter's TE [s], KE [pu] and field-current
    feedback KD [pu], the rectifier's KC [pu], saturation points E1, E2 [pu] with SE1, SE2 [pu]."""

    TB: float = 1.0
    TC: float = 1.0
    KA: float = 80.0
    TA: float = 0.04
    TE: float = 0.8
    KC: float = 0.1
    KD: float = 0.0
    KE: float = 1.0
    E1: float = 0.0
    SE1: float = 0.0
    E2: float = 1.0
    SE2: float = 1.0

    def check(self) -> None:
        check_ranges(self, AC_PARAMETER_RANGES)
        self.require("E2", self.E2 != self.E1 or self.SE1 == 0, f"differ from E1 = {self.E1!r}")

    @property
    def saturation(self) -> tuple:
        """(A, B) of Se VE = B (VE - A)^2 (ANDES: ExcQuadSat(E1, SE1, E2, SE2))."""
        return quadratic_saturation_coefficients(self.E1, self.SE1, self.E2, self.SE2)


def ac_feedback(VE, XadIfd, p: ACExciterParams, m):
    """VFE = KE VE + Se VE + KD XadIfd [pu]: the exciter's voltage feedback (saturation included)."""
    A, B = p.saturation
    return p.KE * VE + quadratic_saturation_product(m, VE, A, B) + p.KD * XadIfd


def ac_field_voltage(VE, XadIfd, p: ACExciterParams, m):
    """Efd = VE FEX(KC XadIfd / VE) [pu]: the exciter voltage through the loaded rectifier."""
    return VE * rectifier_loading(m, p.KC * XadIfd / VE)


def ac_exciter_voltage(Efd: float, XadIfd: float, KC: float) -> float:
    """VE [pu] with VE FEX(KC XadIfd / VE) = Efd, on the piece of FEX where IN = KC XadIfd / VE falls
    (closed form on each piece); ValueError where there is none (Efd <= 0 with IN > 0, or Efd in
    the gaps FEX leaves at its breakpoints)."""
    I = KC * XadIfd
    if I <= 0.0:
        return Efd
    if Efd > 0.0:  # a loaded rectifier gives VE FEX > 0 but at IN >= 1 (0, whatever VE)
        pieces = ((Efd + 0.577 * I, 0.0, 0.433),  # Efd = VE - 0.577 I
                  (math.sqrt((Efd * Efd + I * I) / 0.75), 0.433, 0.75),  # Efd^2 = 0.75 VE^2 - I^2
                  (I + Efd / 1.732, 0.75, 1.0))  # Efd = 1.732 (VE - I)
        for VE, low, high in pieces:
            if low < I / VE <= high:
                return VE
    raise ValueError(f"no exciter voltage gives the field voltage {Efd:.6g} pu at a rectifier load "
                     f"KC XadIfd = {I:.6g} pu")


def ac_derivative(VR, VE, XadIfd, p: ACExciterParams, m):
    """(dVE/dt, VFE): the exciter's integrator TE dVE/dt = VR - VFE and its feedback."""
    VFE = ac_feedback(VE, XadIfd, p, m)
    return (VR - VFE) / p.TE, VFE


def ac_rest(Efd: float, XadIfd: float, p: ACExciterParams) -> tuple:
    """(VE, VFE) [pu] of the AC exciter at rest giving field voltage Efd: the regulator output VR
    then equals VFE."""
    VE = ac_exciter_voltage(Efd, XadIfd, p.KC)
    return VE, ac_feedback(VE, XadIfd, p, math)


def ac_equilibrium(rest, Vref: float, name: str) -> np.ndarray:
    """The state at rest at set point Vref, rest(Efd) -> (x, Vref) giving the state at rest with field
    voltage Efd or raising ValueError where there is none: the field voltage nearest 1 pu whose set
    point is Vref (common.set_point); ValueError naming the model where there is none."""

    def set_point_at(Efd):
        try:
            return rest(Efd)[1]
        except ValueError:
            return math.nan

    return rest(set_point(set_point_at, Vref, 1.0, name))[0]


def regulator_within(VR: float, low: float, high: float, name: str) -> None:
    """ValueError naming the model unless the regulator output at rest VR lies within [low, high]."""
    if not low <= VR <= high:
        raise ValueError(f"{name}: the regulator output {VR:.6g} pu at rest lies outside [{low:g}, {high:g}]")


PARAMETER_RANGES = {"TF": (0.001, 100.0, "s"), "KF": (0.0, 10.0, "pu")}


@dataclass(frozen=True)
class EXAC1Params(ACExciterParams):
    """ANDES/PSS/E EXAC1 data (ANDES' defaults): the AC exciter's (ACExciterParams), the regulator
    limits VRMIN, VRMAX [pu] and the rate feedback KF [pu], TF [s]."""

    VRMAX: float = 8.0
    VRMIN: float = 0.0
    KF: float = 0.1
    TF: float = 1.0

    def check(self) -> None:
        super().check()
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "VRMIN", "VRMAX")


def _regulator(x, u, p: EXAC1Params, m):
    """(dLL_x, dWF_x, LL_y, VFE): the lead-lag's and washout's derivatives, the regulator's input
    and the exciter's feedback."""
    LL_x, LA_y, INT_y, WF_x = x
    Vt, Vref, XadIfd = u
    VFE = ac_feedback(INT_y, XadIfd, p, m)
    d_WF, WF_y = washout(m, VFE, WF_x, p.KF, p.TF)
    d_LL, LL_y = lead_lag(m, Vref - Vt - WF_y, LL_x, 1.0, p.TC, p.TB)
    return d_LL, d_WF, LL_y, VFE


def derivatives(x, u, p: EXAC1Params, m):
    """(dLL_x, dLA_y, dINT_y, dWF_x)/dt for x = (LL_x, LA_y, INT_y, WF_x), u = (Vt, Vref, XadIfd)."""
    d_LL, d_WF, LL_y, VFE = _regulator(x, u, p, m)
    d_LA, VR = lag_non_windup(m, LL_y, x[1], p.KA, p.TA, p.VRMIN, p.VRMAX)
    return d_LL, d_LA, (VR - VFE) / p.TE, d_WF


def reset(x, u, p: EXAC1Params, m):
    """x after the reset of the regulator's non-windup limit (blocks.lag_non_windup_reset)."""
    LL_y = _regulator(x, u, p, m)[2]
    return x[0], lag_non_windup_reset(m, LL_y, x[1], p.KA, p.TA, p.VRMIN, p.VRMAX), x[2], x[3]


def outputs(x, u, p: EXAC1Params, m):
    """(Efd,) = VE FEX(KC XadIfd / VE)."""
    return (ac_field_voltage(x[2], u[2], p, m),)


def rest(Efd: float, Vt: float, XadIfd: float, p: EXAC1Params) -> tuple:
    """(x [4], Vref [pu]): the state at rest giving field voltage Efd [pu] and the set point that
    holds it (ANDES' initialisation; ValueError where VR would lie outside [VRMIN, VRMAX])."""
    VE, VFE = ac_rest(Efd, XadIfd, p)
    regulator_within(VFE, p.VRMIN, p.VRMAX, "EXAC1")
    return np.array([VFE / p.KA, VFE, VE, VFE]), Vt + VFE / p.KA


def start(given, p: EXAC1Params) -> tuple:
    """Initialisation.start: (x0, {"Vref": ...}) from given Vt, XadIfd and the demanded Efd."""
    x0, Vref = rest(float(given["Efd"]), float(given["Vt"]), float(given["XadIfd"]), p)
    return x0, {"Vref": Vref}


def equilibrium(u, p: EXAC1Params) -> np.ndarray:
    """The steady state [4] at constant (Vt, Vref, XadIfd); ValueError where there is none within
    the regulator limits."""
    Vt, Vref, XadIfd = finite_inputs(u, "EXAC1")
    return ac_equilibrium(lambda Efd: rest(Efd, Vt, XadIfd, p), Vref, "EXAC1")


AC_STATES = (Quantity("LL_x", "pu", "lead-lag state"),
             Quantity("LA_y", "pu", "regulator output VR (non-windup limited)"),
             Quantity("INT_y", "pu", "exciter voltage VE"))
VT = Quantity("Vt", "pu", "terminal voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0)
XADIFD = Quantity("XadIfd", "pu", "machine field current", start=1.5, operating_range=(0.5, 3.0))

EXAC1 = Component(
    name="exac1",
    description="EXAC1 IEEE AC1 exciter (PSS/E, ANDES)",
    states=AC_STATES + (Quantity("WF_x", "pu", "feedback washout state"),),
    inputs=(VT, Quantity("Vref", "pu", "voltage set point", start=1.03, operating_range=(0.9, 1.2)), XADIFD),
    outputs=(Quantity("Efd", "pu", "field voltage"),),
    params_type=EXAC1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.01, 0.5, 0.5, 0.5),
    reset=reset,
    ports=Ports(inputs=(Link("terminal_voltage", "Vt"), Link("voltage_reference", "Vref"),
                        Link("field_current", "XadIfd")),
                outputs=(Link("field_voltage", "Efd"),)),
    initialisation=Initialisation(("Vref",), start),
)
