"""ESST3A: the IEEE ST3A static exciter with potential and current source (PSS/E ESST3A, ANDES).

States  x = (LG_y [pu] sensed voltage, LL_x [pu] lead-lag state, VR [pu] regulator output held
        within [VRMIN, VRMAX], VM [pu] inner-loop output held within [VMMIN, VMMAX])
Inputs  u = (Vt [pu], theta_vs [rad]: the terminal voltage phasor; I_re, I_im [pu, system base]:
        the machine's current into the bus; Vref [pu] set point; Vss [pu] stabiliser signal;
        XadIfd [pu] the machine's field current)
Outputs y = (Efd [pu] field voltage)

Equations (ANDES 2.0 model reference, Exciter: ESST3A):

    sensing lag 1 / (1 + s TR) of Vt (TR = 0: LG_y held, Vt used)
    vi = Vref - LG_y + Vss,  vil = vi clipped to [VIMIN, VIMAX] (windup limiter; the
        under-excitation gate max(UEL, vil) passes vil, UEL = -9999 as ANDES)
    lead-lag (1 + s TC) / (1 + s TB) of vil (TB = 0: a gain of 1) -> LL_y
    non-windup lag KA / (1 + s TA):  TA dVR/dt = KA LL_y - VR,  VRMIN <= VR <= VRMAX
        (TA = 0: VR held, KA LL_y clipped to the limits used)
    VE = |KPC V + j (KI + KPC XL) I|,  KPC = KP exp(j THETAP [deg]), V = Vt exp(j theta_vs),
        I = I_re + j I_im (both rotate with the rotor frame alike, so VE equals ANDES' dq form)
    IN = KC XadIfd / VE,  FEX = FEX(IN) (reference_models.blocks.rectifier_loading)
    VB = min(VE FEX, VBMAX),  Efd = VB VM,  VG = min(KG Efd, VGMAX)
    non-windup lag KM / (1 + s TM):  TM dVM/dt = KM (VR - VG) - VM,  VMMIN <= VM <= VMMAX
    reset (both non-windup lags, at the same state): VR or VM at or beyond a limit while its
        unlimited rate pushes outward is placed on it

Bases: I is on the system base and KI, XL multiply it unconverted, as ANDES 2.0 does (its Id, Iq
are on the system base); for a machine whose Sn differs from Sb this is ANDES' choice, kept.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import clip, lag, lag_non_windup, lag_non_windup_reset, lead_lag, rectifier_loading
from ..component import Component, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_limits, check_ranges, controller_initialisation, finite_inputs, set_point

PARAMETER_RANGES = {"TR": (0.0, 10.0, "s"), "KM": (0.01, 5000.0, "pu"), "TC": (0.0, 100.0, "s"),
                    "TB": (0.0, 100.0, "s"), "KA": (0.01, 5000.0, "pu"), "TA": (0.0, 10.0, "s"),
                    "KG": (0.0, 10.0, "pu"), "KP": (0.0, 100.0, "pu"), "KI": (0.0, 100.0, "pu"),
                    "VBMAX": (0.01, 1000.0, "pu"), "KC": (0.0, 10.0, "pu"), "XL": (0.0, 10.0, "pu"),
                    "VGMAX": (0.0, 1000.0, "pu"), "THETAP": (-180.0, 180.0, "deg"), "TM": (0.001, 10.0, "s")}


@dataclass(frozen=True)
class ESST3AParams(Parameters):
    """ANDES/PSS/E ESST3A data: time constants [s], gains [pu], limits [pu], THETAP [deg]."""

    TR: float = 0.01
    VIMAX: float = 0.8
    VIMIN: float = -0.1
    KM: float = 500.0
    TC: float = 3.0
    TB: float = 15.0
    KA: float = 50.0
    TA: float = 0.1
    VRMAX: float = 8.0
    VRMIN: float = 0.0
    KG: float = 1.0
    KP: float = 4.0
    KI: float = 0.1
    VBMAX: float = 18.0
    KC: float = 0.1
    XL: float = 0.01
    VGMAX: float = 4.0
    THETAP: float = 0.0
    TM: float = 0.1
    VMMAX: float = 1.0
    VMMIN: float = 0.1

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        for low, high in (("VIMIN", "VIMAX"), ("VRMIN", "VRMAX"), ("VMMIN", "VMMAX")):
            check_limits(self, low, high)


def bridge_voltage(Vt, theta_vs, I_re, I_im, XadIfd, p: ESST3AParams, m):
    """VB = min(VE FEX(KC XadIfd / VE), VBMAX) [pu], the rectifier's available voltage."""
    c, s = math.cos(math.radians(p.THETAP)), math.sin(math.radians(p.THETAP))
    V_re, V_im = Vt * m.cos(theta_vs), Vt * m.sin(theta_vs)
    a, b = p.KI + p.KP * p.XL * c, p.KP * p.XL * s  # KI + KPC XL = a + j b
    real = p.KP * (c * V_re - s * V_im) - b * I_re - a * I_im
    imag = p.KP * (s * V_re + c * V_im) + a * I_re - b * I_im
    VE = m.sqrt(real * real + imag * imag)
    return clip(m, VE * rectifier_loading(m, p.KC * XadIfd / VE), -math.inf, p.VBMAX)


def _signals(x, u, p: ESST3AParams, m):
    """(dLG_y/dt, dLL_x/dt, LL_y, VG): the sensing lag's and lead-lag's derivatives, the
    regulator's input and the field voltage feedback."""
    LG_y, LL_x, VR, VM = x
    Vt, theta_vs, I_re, I_im, Vref, Vss, XadIfd = u
    d_LG, sensed = lag(m, Vt, LG_y, 1.0, p.TR)
    vil = clip(m, Vref - sensed + Vss, p.VIMIN, p.VIMAX)
    d_LL, LL_y = lead_lag(m, vil, LL_x, 1.0, p.TC, p.TB)
    Efd = bridge_voltage(Vt, theta_vs, I_re, I_im, XadIfd, p, m) * VM
    return d_LG, d_LL, LL_y, clip(m, p.KG * Efd, -math.inf, p.VGMAX)


def derivatives(x, u, p: ESST3AParams, m):
    """(dLG_y, dLL_x, dVR, dVM)/dt for x = (LG_y, LL_x, VR, VM),
    u = (Vt, theta_vs, I_re, I_im, Vref, Vss, XadIfd)."""
    d_LG, d_LL, LL_y, VG = _signals(x, u, p, m)
    d_VR, VR = lag_non_windup(m, LL_y, x[2], p.KA, p.TA, p.VRMIN, p.VRMAX)
    d_VM, _ = lag_non_windup(m, VR - VG, x[3], p.KM, p.TM, p.VMMIN, p.VMMAX)
    return d_LG, d_LL, d_VR, d_VM


def reset(x, u, p: ESST3AParams, m):
    """x after the resets of VR's and VM's non-windup limits, both at x (blocks.lag_non_windup_reset);
    TA = 0: VR held, VM's input KA LL_y clipped as in the derivatives."""
    _, _, LL_y, VG = _signals(x, u, p, m)
    VR = lag_non_windup(m, LL_y, x[2], p.KA, p.TA, p.VRMIN, p.VRMAX)[1]
    return (x[0], x[1], lag_non_windup_reset(m, LL_y, x[2], p.KA, p.TA, p.VRMIN, p.VRMAX),
            lag_non_windup_reset(m, VR - VG, x[3], p.KM, p.TM, p.VMMIN, p.VMMAX))


def outputs(x, u, p: ESST3AParams, m):
    """(Efd,) = VB VM."""
    Vt, theta_vs, I_re, I_im, _, _, XadIfd = u
    return (bridge_voltage(Vt, theta_vs, I_re, I_im, XadIfd, p, m) * x[3],)


def initialise(Efd: float, u, p: ESST3AParams) -> tuple:
    """(x [4], Vref [pu]): the state at rest giving field voltage Efd [pu] at inputs u (its Vref
    ignored) and the set point that holds it (ANDES' initialisation)."""
    Vt, theta_vs, I_re, I_im, _, Vss, XadIfd = (float(v) for v in u)
    VM = Efd / bridge_voltage(Vt, theta_vs, I_re, I_im, XadIfd, p, math)
    VR = VM / p.KM + min(p.KG * Efd, p.VGMAX)
    vil = VR / p.KA
    return np.array([Vt, vil, VR, VM]), vil + Vt - Vss


def equilibrium(u, p: ESST3AParams) -> np.ndarray:
    """The steady state [4] at constant inputs; ValueError where there is none within the limits."""
    finite_inputs(u, "ESST3A")
    Efd = set_point(lambda e: initialise(e, u, p)[1], float(u[4]), 1.0, "ESST3A")
    x = initialise(Efd, u, p)[0]
    if not (p.VRMIN <= x[2] <= p.VRMAX and p.VMMIN <= x[3] <= p.VMMAX and p.VIMIN <= x[1] <= p.VIMAX):
        raise ValueError("ESST3A: the steady state at these inputs lies outside the limits")
    return x


# the terminal voltage phasor and the machine's current that bridge_voltage takes (ESST3A, ESST4B)
TERMINAL_INPUTS = (
    Quantity("Vt", "pu", "terminal voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
    Quantity("theta_vs", "rad", "terminal voltage angle", start=0.0, operating_range=(-0.5, 0.5)),
    Quantity("I_re", "pu", "machine current into the bus, real part (system base)", start=1.0,
             operating_range=(0.0, 5.0)),
    Quantity("I_im", "pu", "machine current into the bus, imaginary part (system base)", start=-0.2,
             operating_range=(-2.0, 2.0)))
TERMINAL_LINKS = (Link("terminal_voltage", "Vt"), Link("terminal_voltage_angle", "theta_vs"),
                  Link("terminal_current_real", "I_re"), Link("terminal_current_imaginary", "I_im"))

INPUTS = TERMINAL_INPUTS + (Quantity("Vref", "pu", "voltage set point", start=1.03, operating_range=(0.9, 1.2)),
                            Quantity("Vss", "pu", "stabiliser signal", start=0.0, operating_range=(-0.1, 0.1)),
                            Quantity("XadIfd", "pu", "machine field current", start=1.5, operating_range=(0.5, 3.0)))

ESST3A = Component(
    name="esst3a",
    description="ESST3A IEEE ST3A static exciter (PSS/E, ANDES)",
    states=(Quantity("LG_y", "pu", "sensed terminal voltage"),
            Quantity("LL_x", "pu", "lead-lag state"),
            Quantity("VR", "pu", "regulator output (non-windup limited)"),
            Quantity("VM", "pu", "inner loop output (non-windup limited)")),
    inputs=INPUTS,
    outputs=(Quantity("Efd", "pu", "field voltage"),),
    params_type=ESST3AParams,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.01, 0.5, 0.1),
    reset=reset,
    ports=Ports(inputs=TERMINAL_LINKS + (Link("voltage_reference", "Vref"), Link("stabiliser_signal", "Vss"),
                                         Link("field_current", "XadIfd")),
                outputs=(Link("field_voltage", "Efd"),)),
    initialisation=controller_initialisation(INPUTS, "Efd", "Vref", initialise),
)
