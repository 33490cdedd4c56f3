"""EXAC4: the IEEE AC4 exciter (PSS/E EXAC4, ANDES).

States  x = (LG_y [pu] sensed voltage, LL_x [pu] lead-lag state, LR_y [pu] regulator output)
Inputs  u = (Vt [pu] terminal voltage, Vref [pu] set point, XadIfd [pu] the machine's field
        current)
Outputs y = (Efd [pu] field voltage)

Equations (ANDES 2.0.0, andes/models/exciter/exac4.py, as it computes them):

    sensing lag 1 / (1 + s TR):  TR dLG_y/dt = Vt - LG_y  (TR = 0: LG_y held, Vt used)
    vi = Vref - LG_y,  vil = vi clipped to [VIMIN, VIMAX]  (windup limiter)
    lead-lag (1 + s TC) / (1 + s TB) of vil (TB = 0: a gain of 1) -> LL_y
    regulator lag KA / (1 + s TA):  TA dLR_y/dt = KA LL_y - LR_y  (no limit on the state;
        TA = 0: LR_y held, KA LL_y used)
    vfmax = VRMAX - KC XadIfd,  vfmin = VRMIN - KC XadIfd
    Efd = the regulator output clipped to [vfmin, vfmax]  (windup limiter)

ANDES 2.0.0 holds its reference at the initial value vref0 and has no stabiliser input: Vref here
is that constant (an input, at rest Vref = Vt + Efd / KA, ANDES' vref0), and there is no Vss. No
non-windup limit: no reset.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blocks import clip, clip_between, lag, lead_lag
from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_limits, check_ranges, finite_inputs
from .exac1 import VT, XADIFD

PARAMETER_RANGES = {"TR": (0.0, 10.0, "s"), "TC": (0.0, 100.0, "s"), "TB": (0.0, 100.0, "s"),
                    "KA": (0.01, 5000.0, "pu"), "TA": (0.0, 10.0, "s"), "KC": (0.0, 10.0, "pu")}


@dataclass(frozen=True)
class EXAC4Params(Parameters):
    """ANDES/PSS/E EXAC4 data (ANDES' defaults): time constants [s], gain KA [pu], input limits
    VIMIN, VIMAX [pu], regulator limits VRMIN, VRMAX [pu], field-current compensation KC [pu]."""

    TR: float = 0.01
    VIMAX: float = 5.0
    VIMIN: float = -0.1
    TC: float = 1.0
    TB: float = 1.0
    KA: float = 80.0
    TA: float = 0.04
    VRMAX: float = 8.0
    VRMIN: float = 0.0
    KC: float = 0.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "VIMIN", "VIMAX")
        check_limits(self, "VRMIN", "VRMAX")


def _regulator(x, u, p: EXAC4Params, m):
    """(dLG_y, dLL_x, dLR_y, VR): the derivatives and the regulator's output (LR_y; with TA = 0 the
    gain KA times the lead-lag's output)."""
    LG_y, LL_x, LR_y = x
    Vt, Vref, _ = u
    d_LG, sensed = lag(m, Vt, LG_y, 1.0, p.TR)
    d_LL, LL_y = lead_lag(m, clip(m, Vref - sensed, p.VIMIN, p.VIMAX), LL_x, 1.0, p.TC, p.TB)
    d_LR, VR = lag(m, LL_y, LR_y, p.KA, p.TA)
    return d_LG, d_LL, d_LR, VR


def derivatives(x, u, p: EXAC4Params, m):
    """(dLG_y, dLL_x, dLR_y)/dt for x = (LG_y, LL_x, LR_y), u = (Vt, Vref, XadIfd)."""
    return _regulator(x, u, p, m)[:3]


def outputs(x, u, p: EXAC4Params, m):
    """(Efd,): the regulator output within [VRMIN - KC XadIfd, VRMAX - KC XadIfd]."""
    XadIfd = u[2]
    return (clip_between(m, _regulator(x, u, p, m)[3], p.VRMIN - p.KC * XadIfd, p.VRMAX - p.KC * XadIfd),)


def rest(Efd: float, Vt: float, XadIfd: float, p: EXAC4Params) -> tuple:
    """(x [3], Vref [pu]): the state at rest giving field voltage Efd [pu] and the set point that
    holds it (ANDES' initialisation: vi = Efd / KA, LR_y = Efd); ValueError where vi lies outside
    [VIMIN, VIMAX] or Efd outside the output limits."""
    vi = Efd / p.KA
    if not p.VIMIN <= vi <= p.VIMAX:
        raise ValueError(f"EXAC4: the input {vi:.6g} pu at rest lies outside [VIMIN, VIMAX]")
    if not p.VRMIN - p.KC * XadIfd <= Efd <= p.VRMAX - p.KC * XadIfd:
        raise ValueError(f"EXAC4: the field voltage {Efd:.6g} pu lies outside the output limits")
    return np.array([Vt, vi, Efd]), Vt + vi


def start(given, p: EXAC4Params) -> tuple:
    """Initialisation.start: (x0, {"Vref": ...}) from given Vt, XadIfd and the demanded Efd."""
    x0, Vref = rest(float(given["Efd"]), float(given["Vt"]), float(given["XadIfd"]), p)
    return x0, {"Vref": Vref}


def equilibrium(u, p: EXAC4Params) -> np.ndarray:
    """The steady state [3] at constant (Vt, Vref, XadIfd): Efd = KA (Vref - Vt); ValueError where
    a limiter would hold it."""
    Vt, Vref, XadIfd = finite_inputs(u, "EXAC4")
    return rest(p.KA * (Vref - Vt), Vt, XadIfd, p)[0]


EXAC4 = Component(
    name="exac4",
    description="EXAC4 IEEE AC4 exciter (PSS/E, ANDES)",
    states=(Quantity("LG_y", "pu", "sensed terminal voltage"),
            Quantity("LL_x", "pu", "lead-lag state"),
            Quantity("LR_y", "pu", "regulator output")),
    inputs=(VT, Quantity("Vref", "pu", "voltage set point", start=1.02, operating_range=(0.9, 1.2)), XADIFD),
    outputs=(Quantity("Efd", "pu", "field voltage"),),
    params_type=EXAC4Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.01, 0.5),
    ports=Ports(inputs=(Link("terminal_voltage", "Vt"), Link("voltage_reference", "Vref"),
                        Link("field_current", "XadIfd")),
                outputs=(Link("field_voltage", "Efd"),)),
    initialisation=Initialisation(("Vref",), start),
)
