"""EXST1: the IEEE ST1 static exciter (PSS/E EXST1, ANDES).

States  x = (LG_y [pu] sensed voltage, LL_x [pu] lead-lag state, LR_y [pu] regulator output,
        WF_x [pu] feedback washout state)
Inputs  u = (Vt [pu] terminal voltage, Vref [pu] set point, Vss [pu] stabiliser signal,
        XadIfd [pu] the machine's field current)
Outputs y = (Efd [pu] field voltage)

Equations (ANDES 2.0 model reference, Exciter: EXST1):

    sensing lag 1 / (1 + s TR):  TR dLG_y/dt = Vt - LG_y  (TR = 0: LG_y held, Vt used)
    washout s KF / (1 + s TF) of LR_y:  TF dWF_x/dt = LR_y - WF_x,  WF_y = KF (LR_y - WF_x) / TF
    vi = Vref - LG_y - WF_y + Vss,  vl = vi clipped to [VIMIN, VIMAX]  (windup limiter)
    lead-lag (1 + s TC) / (1 + s TB) of vl: TB dLL_x/dt = vl - LL_x  (TB = 0: a gain of 1)
    regulator lag KA / (1 + s TA):  TA dLR_y/dt = KA LL_y - LR_y  (no limit on the state)
    vfmax = VRMAX - KC XadIfd,  vfmin = VRMIN - KC XadIfd
    Efd = vfmax where WF_y >= vfmax, vfmin where WF_y <= vfmin, else LR_y

The output limiter compares the washout output WF_y (not LR_y) with its bounds, as ANDES 2.0
writes it; at rest WF_y = 0, so Efd = LR_y there whenever vfmin < 0 < vfmax.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blocks import clip, lag, lead_lag, washout
from ..component import Component, Parameters, Quantity
from ..piecewise import where
from ..ports import Link, Ports
from .common import check_limits, check_ranges, controller_initialisation, finite_inputs

PARAMETER_RANGES = {"TR": (0.0, 10.0, "s"), "TC": (0.0, 100.0, "s"), "TB": (0.0, 100.0, "s"),
                    "KA": (0.01, 5000.0, "pu"), "TA": (0.001, 10.0, "s"), "KC": (0.0, 10.0, "pu"),
                    "KF": (0.0, 10.0, "pu"), "TF": (0.001, 100.0, "s")}


@dataclass(frozen=True)
class EXST1Params(Parameters):
    """ANDES/PSS/E EXST1 data: time constants [s], gains [pu], limits [pu]."""

    TR: float = 0.01
    VIMAX: float = 0.2
    VIMIN: float = 0.0
    TC: float = 1.0
    TB: float = 1.0
    KA: float = 80.0
    TA: float = 0.05
    VRMAX: float = 8.0
    VRMIN: float = -3.0
    KC: float = 0.2
    KF: float = 0.1
    TF: float = 1.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "VIMIN", "VIMAX")
        check_limits(self, "VRMIN", "VRMAX")


def derivatives(x, u, p: EXST1Params, m):
    """(dLG_y, dLL_x, dLR_y, dWF_x)/dt for x = (LG_y, LL_x, LR_y, WF_x), u = (Vt, Vref, Vss, XadIfd)."""
    LG_y, LL_x, LR_y, WF_x = x
    Vt, Vref, Vss, _ = u
    d_LG, sensed = lag(m, Vt, LG_y, 1.0, p.TR)
    d_WF, WF_y = washout(m, LR_y, WF_x, p.KF, p.TF)
    vl = clip(m, Vref - sensed - WF_y + Vss, p.VIMIN, p.VIMAX)
    d_LL, LL_y = lead_lag(m, vl, LL_x, 1.0, p.TC, p.TB)
    d_LR, _ = lag(m, LL_y, LR_y, p.KA, p.TA)
    return d_LG, d_LL, d_LR, d_WF


def outputs(x, u, p: EXST1Params, m):
    """(Efd,): LR_y within the output limits (the limiter compares WF_y with them, as ANDES)."""
    LR_y, WF_x = x[2], x[3]
    XadIfd = u[3]
    _, WF_y = washout(m, LR_y, WF_x, p.KF, p.TF)
    vfmax, vfmin = p.VRMAX - p.KC * XadIfd, p.VRMIN - p.KC * XadIfd
    return (where(m, WF_y >= vfmax, vfmax, where(m, WF_y <= vfmin, vfmin, LR_y)),)


def initialise(Efd: float, u, p: EXST1Params) -> tuple:
    """(x [4], Vref [pu]): the state at rest giving field voltage Efd [pu] at inputs u (its Vref
    ignored) and the set point that holds it (ANDES' initialisation; vi = Efd / KA within
    [VIMIN, VIMAX])."""
    Vt, _, Vss, _ = (float(v) for v in u)
    vi = Efd / p.KA
    return np.array([Vt, vi, Efd, Efd]), Vt + vi - Vss


def equilibrium(u, p: EXST1Params) -> np.ndarray:
    """The steady state [4] at constant (Vt, Vref, Vss, XadIfd); ValueError where the input
    limiter would hold it (vi outside [VIMIN, VIMAX] at rest)."""
    Vt, Vref, Vss, _ = finite_inputs(u, "EXST1")
    vi = Vref - Vt + Vss
    if not p.VIMIN <= vi <= p.VIMAX:
        raise ValueError(f"EXST1: the input {vi:.6g} pu at rest lies outside [VIMIN, VIMAX]")
    return initialise(p.KA * vi, u, p)[0]


INPUTS = (Quantity("Vt", "pu", "terminal voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
          Quantity("Vref", "pu", "voltage set point", start=1.02, operating_range=(0.9, 1.2)),
          Quantity("Vss", "pu", "stabiliser signal", start=0.0, operating_range=(-0.1, 0.1)),
          Quantity("XadIfd", "pu", "machine field current", start=1.5, operating_range=(0.5, 3.0)))

EXST1 = Component(
    name="exst1",
    description="EXST1 IEEE ST1 static exciter (PSS/E, ANDES)",
    states=(Quantity("LG_y", "pu", "sensed terminal voltage"),
            Quantity("LL_x", "pu", "lead-lag state"),
            Quantity("LR_y", "pu", "regulator output"),
            Quantity("WF_x", "pu", "feedback washout state")),
    inputs=INPUTS,
    outputs=(Quantity("Efd", "pu", "field voltage"),),
    params_type=EXST1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.01, 0.5, 0.5),
    ports=Ports(inputs=(Link("terminal_voltage", "Vt"), Link("voltage_reference", "Vref"),
                        Link("stabiliser_signal", "Vss"), Link("field_current", "XadIfd")),
                outputs=(Link("field_voltage", "Efd"),)),
    initialisation=controller_initialisation(INPUTS, "Efd", "Vref", initialise),
)
