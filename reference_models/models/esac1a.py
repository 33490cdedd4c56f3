"""ESAC1A: the IEEE AC1A exciter (PSS/E ESAC1A, ANDES), with the AC exciter of EXAC1 (exac1.py).

States  x = (LG_y [pu] sensed voltage, LL_x [pu] lead-lag state, LA_y [pu] regulator output VA
        held within [VAMIN, VAMAX], INT_y [pu] exciter voltage VE)
Inputs  u = (Vt [pu] terminal voltage, Vref [pu] set point, Vss [pu] stabiliser signal,
        XadIfd [pu] the machine's field current)
Outputs y = (Efd [pu] field voltage)

Equations (ANDES 2.0.0, andes/models/exciter/esac1a.py, as it computes them):

    sensing lag 1 / (1 + s TR):  TR dLG_y/dt = Vt - LG_y  (TR = 0: LG_y held, Vt used)
    vi = Vref - LG_y + Vss  (ANDES adds its constant limiter signals UEL = -999 and OEL = 999, which
        cancel)
    lead-lag (1 + s TC) / (1 + s TB) of vi (TB = 0: a gain of 1) -> LL_y
    non-windup lag KA / (1 + s TA):  TA dLA_y/dt = KA LL_y - LA_y,  VAMIN <= LA_y <= VAMAX
        (TA = 0: LA_y held, KA LL_y clipped to the limits used as VA)
        reset: LA_y at or beyond a limit while KA LL_y - LA_y pushes outward is placed on it
    VR = min(max(UEL, VA), OEL)  (ANDES' high and low value gates)
    VFE = KE VE + Se VE + KD XadIfd  (exac1.ac_feedback),  TE dVE/dt = VR - VFE
    Efd = VE FEX(KC XadIfd / VE)  (exac1.ac_field_voltage)

As ANDES 2.0.0 computes it, unlike PSS/E: the rate feedback (KF, TF) is built but not fed back
into vi, and VR is not limited to [VRMIN, VRMAX]; those data are therefore no parameters here.

Start (ANDES' initialisation): VE from Efd as EXAC1's (exac1.ac_rest), VA = VFE,
LL_x = VFE / KA, LG_y = Vt, Vref = Vt + VFE / KA - Vss. Machine base, as the case data give them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blocks import clip, lag, lag_non_windup, lag_non_windup_reset, lead_lag
from ..component import Component, Initialisation, Quantity
from ..ports import Link, Ports
from .common import check_limits, check_ranges, finite_inputs
from .exac1 import (AC_STATES, VT, XADIFD, ACExciterParams, ac_derivative, ac_equilibrium, ac_field_voltage, ac_rest,
                    regulator_within)

UEL, OEL = -999.0, 999.0  # pu: ANDES' constant under- and over-excitation limiter signals
PARAMETER_RANGES = {"TR": (0.0, 10.0, "s")}


@dataclass(frozen=True)
class ESAC1AParams(ACExciterParams):
    """ANDES/PSS/E ESAC1A data (ANDES' defaults): the AC exciter's (exac1.ACExciterParams), the
    sensing lag TR [s] and the regulator limits VAMIN, VAMAX [pu]."""

    TR: float = 0.01
    VAMAX: float = 999.0
    VAMIN: float = -999.0

    def check(self) -> None:
        super().check()
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "VAMIN", "VAMAX")


def _regulator_input(x, u, p: ESAC1AParams, m):
    """(dLG_y, dLL_x, LL_y): the sensing lag's and lead-lag's derivatives and the regulator's input."""
    LG_y, LL_x, _, _ = x
    Vt, Vref, Vss, _ = u
    d_LG, sensed = lag(m, Vt, LG_y, 1.0, p.TR)
    d_LL, LL_y = lead_lag(m, Vref - sensed + Vss, LL_x, 1.0, p.TC, p.TB)
    return d_LG, d_LL, LL_y


def derivatives(x, u, p: ESAC1AParams, m):
    """(dLG_y, dLL_x, dLA_y, dINT_y)/dt for x = (LG_y, LL_x, LA_y, INT_y), u = (Vt, Vref, Vss, XadIfd)."""
    d_LG, d_LL, LL_y = _regulator_input(x, u, p, m)
    d_LA, VA = lag_non_windup(m, LL_y, x[2], p.KA, p.TA, p.VAMIN, p.VAMAX)
    d_VE, _ = ac_derivative(clip(m, VA, UEL, OEL), x[3], u[3], p, m)
    return d_LG, d_LL, d_LA, d_VE


def reset(x, u, p: ESAC1AParams, m):
    """x after the reset of the regulator's non-windup limit (blocks.lag_non_windup_reset)."""
    LL_y = _regulator_input(x, u, p, m)[2]
    return x[0], x[1], lag_non_windup_reset(m, LL_y, x[2], p.KA, p.TA, p.VAMIN, p.VAMAX), x[3]


def outputs(x, u, p: ESAC1AParams, m):
    """(Efd,) = VE FEX(KC XadIfd / VE)."""
    return (ac_field_voltage(x[3], u[3], p, m),)


def rest(Efd: float, Vt: float, Vss: float, XadIfd: float, p: ESAC1AParams) -> tuple:
    """(x [4], Vref [pu]): the state at rest giving field voltage Efd [pu] and the set point that
    holds it (ANDES' initialisation; ValueError where VA would lie outside [VAMIN, VAMAX] or the
    gates [UEL, OEL])."""
    VE, VFE = ac_rest(Efd, XadIfd, p)
    regulator_within(VFE, max(p.VAMIN, UEL), min(p.VAMAX, OEL), "ESAC1A")
    return np.array([Vt, VFE / p.KA, VFE, VE]), Vt + VFE / p.KA - Vss


def start(given, p: ESAC1AParams) -> tuple:
    """Initialisation.start: (x0, {"Vref": ...}) from given Vt, Vss, XadIfd and the demanded Efd."""
    x0, Vref = rest(float(given["Efd"]), float(given["Vt"]), float(given["Vss"]), float(given["XadIfd"]), p)
    return x0, {"Vref": Vref}


def equilibrium(u, p: ESAC1AParams) -> np.ndarray:
    """The steady state [4] at constant (Vt, Vref, Vss, XadIfd); ValueError where there is none
    within the regulator limits."""
    Vt, Vref, Vss, XadIfd = finite_inputs(u, "ESAC1A")
    return ac_equilibrium(lambda Efd: rest(Efd, Vt, Vss, XadIfd, p), Vref, "ESAC1A")


ESAC1A = Component(
    name="esac1a",
    description="ESAC1A IEEE AC1A exciter (PSS/E, ANDES)",
    states=(Quantity("LG_y", "pu", "sensed terminal voltage"),) + AC_STATES,
    inputs=(VT, Quantity("Vref", "pu", "voltage set point", start=1.03, operating_range=(0.9, 1.2)),
            Quantity("Vss", "pu", "stabiliser signal", start=0.0, operating_range=(-0.1, 0.1)), XADIFD),
    outputs=(Quantity("Efd", "pu", "field voltage"),),
    params_type=ESAC1AParams,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.01, 2.0, 0.5),
    reset=reset,
    ports=Ports(inputs=(Link("terminal_voltage", "Vt"), Link("voltage_reference", "Vref"),
                        Link("stabiliser_signal", "Vss"), Link("field_current", "XadIfd")),
                outputs=(Link("field_voltage", "Efd"),)),
    initialisation=Initialisation(("Vref",), start),
)
