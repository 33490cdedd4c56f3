"""IEEET3: the IEEE Type 3 exciter (PSS/E IEEET3, potential and current source) as ANDES 2.0.0
computes it.

States  x = (LG_y [pu] sensed voltage, LA3_y [pu] regulator output VR held within
        [VRMIN, VRMAXc], LA1_y [pu] exciter output, WF_x [pu] feedback washout state)
Inputs  u = (Vt [pu], theta_vs [rad]: the terminal voltage phasor; I_re, I_im [pu, system base]:
        the machine's current into the bus; Vref [pu] set point; Vss [pu] stabiliser signal;
        XadIfd [pu] the machine's field current)
Outputs y = (Efd [pu] field voltage = LA1_y)

Equations (ANDES 2.0.0, andes/models/exciter/ieeet3.py):

    sensing lag 1 / (1 + s TR):  TR dLG_y/dt = Vt - LG_y  (TR = 0: LG_y held, Vt used)
    washout s KF / (1 + s TF) of LA1_y:  TF dWF_x/dt = LA1_y - WF_x,  WF_y = KF (LA1_y - WF_x) / TF
    vi = Vref - LG_y + Vss  (ANDES' UEL = OEL = 0)
    non-windup lag KA / (1 + s TA) of vi - WF_y:  TA dLA3_y/dt = KA (vi - WF_y) - LA3_y,
        VRMIN <= LA3_y <= VRMAXc, VRMAXc = VRMAX, or 999 where VRMAX = 0
        (reset: LA3_y at or beyond a limit while its unlimited rate pushes outward is placed on it);
        its output VR = LA3_y; TA = 0: LA3_y held, VR = KA (vi - WF_y) clipped to [VRMIN, VRMAXc]
        (ANDES: the lag's equation algebraic, pegged by its limiter)
    VE = |KP V + j KI I|,  V = Vt exp(j theta_vs), I = I_re + j I_im (ANDES' dq form
        |KP (vd + j vq) + j KI (Id + j Iq)|: both phasors rotate alike, so the magnitude is the same)
    SQE = VE^2 - (0.78 XadIfd)^2
    VB = VR + sqrt(SQE) where SQE > 0, else VR
    lag 1 / (KE + s TE) of VB clipped to [0, VBMAX] (windup limiter):
        TE dLA1_y/dt = min(max(VB, 0), VBMAX) - KE LA1_y
    Efd = LA1_y

At rest (ANDES' initialisation): LG_y = Vt, LA1_y = WF_x = Efd, LA3_y = KE Efd - sqrt(SQE),
Vref = Vt + LA3_y / KA - Vss (ANDES takes sqrt(SQE) of the starting point and has no rest where
SQE < 0; here that part is 0 there, as in the equations).

Bases: I is on the system base and KI multiplies it unconverted, as ANDES 2.0 does (its machine
currents Id, Iq are on the system base), like ESST3A (esst3a.py). VE uses Vt, the same input as the
sensing lag: with a voltage compensator (IEEEVC) giving the unit's terminal_voltage, ANDES' VE
still takes the machine's own vd, vq, this model the compensated magnitude.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import clip, lag, lag_non_windup, lag_non_windup_reset, sqrt_positive_part, washout
from ..component import Component, Parameters, Quantity
from ..piecewise import where
from .common import check_ranges, controller_initialisation, finite_inputs
from .esdc2a import ceiling
from .esst3a import ESST3A, INPUTS

PARAMETER_RANGES = {"TR": (0.0, 10.0, "s"), "KA": (0.01, 5000.0, "pu"), "TA": (0.0, 10.0, "s"),
                    "VBMAX": (0.01, 1000.0, "pu"), "KE": (-1.0, 10.0, "pu"), "TE": (0.001, 10.0, "s"),
                    "KF": (0.0, 10.0, "pu"), "TF": (0.001, 100.0, "s"), "KP": (0.0, 100.0, "pu"),
                    "KI": (0.0, 100.0, "pu")}


@dataclass(frozen=True)
class IEEET3Params(Parameters):
    """ANDES/PSS/E IEEET3 data: time constants [s], gains [pu], regulator limits VRMAX (0: 999),
    VRMIN [pu], VBMAX [pu], potential and current source gains KP, KI [pu]."""

    TR: float = 0.02
    KA: float = 5.0
    TA: float = 0.04
    VRMAX: float = 7.3
    VRMIN: float = -7.3
    VBMAX: float = 18.0
    KE: float = 1.0
    TE: float = 1.0
    KF: float = 0.1
    TF: float = 1.0
    KP: float = 4.0
    KI: float = 0.1

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        self.require("VRMIN", self.VRMIN < ceiling(self.VRMAX),
                     f"lie below the ceiling {ceiling(self.VRMAX)!r} (VRMAX, or 999 for VRMAX = 0)")


def source_voltage_squared(Vt, theta_vs, I_re, I_im, XadIfd, p: IEEET3Params, m):
    """SQE = |KP V + j KI I|^2 - (0.78 XadIfd)^2 [pu^2]."""
    real = p.KP * Vt * m.cos(theta_vs) - p.KI * I_im
    imag = p.KP * Vt * m.sin(theta_vs) + p.KI * I_re
    return real * real + imag * imag - (0.78 * XadIfd) * (0.78 * XadIfd)


def _signals(x, u, p: IEEET3Params, m):
    """(dLG_y/dt, dLA3_y/dt, dWF_x/dt, the regulator's input vi - WF_y, the exciter lag's input VB
    clipped)."""
    LG_y, LA3_y, LA1_y, WF_x = x
    Vt, theta_vs, I_re, I_im, Vref, Vss, XadIfd = u
    d_LG, sensed = lag(m, Vt, LG_y, 1.0, p.TR)
    d_WF, WF_y = washout(m, LA1_y, WF_x, p.KF, p.TF)
    SQE = source_voltage_squared(Vt, theta_vs, I_re, I_im, XadIfd, p, m)
    root = sqrt_positive_part(m, SQE)  # finite past SQE = 0 with the branch below locked (blocks.py)
    error = Vref - sensed + Vss - WF_y
    d_LA3, VR = lag_non_windup(m, error, LA3_y, p.KA, p.TA, p.VRMIN, ceiling(p.VRMAX))
    VB = VR + where(m, SQE > 0.0, root, 0.0 * SQE)
    return d_LG, d_LA3, d_WF, error, clip(m, VB, 0.0, p.VBMAX)


def derivatives(x, u, p: IEEET3Params, m):
    """(dLG_y, dLA3_y, dLA1_y, dWF_x)/dt for x = (LG_y, LA3_y, LA1_y, WF_x),
    u = (Vt, theta_vs, I_re, I_im, Vref, Vss, XadIfd)."""
    d_LG, d_LA3, d_WF, _, VB = _signals(x, u, p, m)
    return d_LG, d_LA3, (VB - p.KE * x[2]) / p.TE, d_WF


def reset(x, u, p: IEEET3Params, m):
    """x after the reset of LA3_y's limits VRMIN, VRMAXc (blocks.lag_non_windup_reset)."""
    LA3_y = lag_non_windup_reset(m, _signals(x, u, p, m)[3], x[1], p.KA, p.TA, p.VRMIN, ceiling(p.VRMAX))
    return x[0], LA3_y, x[2], x[3]


def outputs(x, u, p: IEEET3Params, m):
    """(Efd,) = LA1_y."""
    return (x[2],)


def initialise(Efd: float, u, p: IEEET3Params) -> tuple:
    """(x [4], Vref [pu]): the state at rest giving field voltage Efd [pu] at inputs u (its Vref
    ignored) and the set point that holds it (ANDES' initialisation)."""
    Vt, theta_vs, I_re, I_im, _, Vss, XadIfd = (float(v) for v in u)
    SQE = source_voltage_squared(Vt, theta_vs, I_re, I_im, XadIfd, p, math)
    VR = p.KE * Efd - (math.sqrt(SQE) if SQE > 0 else 0.0)
    return np.array([Vt, VR, Efd, Efd]), Vt + VR / p.KA - Vss


def equilibrium(u, p: IEEET3Params) -> np.ndarray:
    """The steady state [4] at constant inputs: VR = KA (Vref - Vt + Vss), Efd = VB / KE; ValueError
    where VR or VB would rest beyond its limits (or KE = 0 with VB not 0)."""
    Vt, theta_vs, I_re, I_im, Vref, Vss, XadIfd = finite_inputs(u, "IEEET3")
    VR = p.KA * (Vref - Vt + Vss)
    SQE = source_voltage_squared(Vt, theta_vs, I_re, I_im, XadIfd, p, math)
    VB = VR + (math.sqrt(SQE) if SQE > 0 else 0.0)
    if not (p.VRMIN <= VR <= ceiling(p.VRMAX) and 0.0 <= VB <= p.VBMAX and p.KE != 0):
        raise ValueError(f"IEEET3: no steady state within the limits at these inputs (VR {VR:.6g}, VB {VB:.6g} pu)")
    Efd = VB / p.KE
    return np.array([Vt, VR, Efd, Efd])


IEEET3 = Component(
    name="ieeet3",
    description="IEEET3 IEEE Type 3 exciter (PSS/E, ANDES 2.0.0)",
    states=(Quantity("LG_y", "pu", "sensed voltage"),
            Quantity("LA3_y", "pu", "regulator output VR (non-windup limited)"),
            Quantity("LA1_y", "pu", "exciter output (field voltage)"),
            Quantity("WF_x", "pu", "feedback washout state")),
    inputs=INPUTS,
    outputs=(Quantity("Efd", "pu", "field voltage"),),
    params_type=IEEET3Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.5, 0.5, 0.5),
    reset=reset,
    ports=ESST3A.ports,
    initialisation=controller_initialisation(INPUTS, "Efd", "Vref", initialise),
)
