"""ESST4B: the IEEE ST4B static exciter with potential and current source (PSS/E ESST4B, ANDES).

States  x = (LG_y [pu] sensed voltage, PI1_xi [pu] voltage regulator's integrator, LA_y [pu]
        regulator delay output, PI2_xi [pu] inner loop's integrator)
Inputs  u = (Vt [pu], theta_vs [rad]: the terminal voltage phasor; I_re, I_im [pu, system base]:
        the machine's current into the bus; Vref [pu] set point; XadIfd [pu] the machine's field
        current)
Outputs y = (Efd [pu] field voltage)

Equations (ANDES 2.0.0, andes/models/exciter/esst4b.py, as it computes them):

    sensing lag 1 / (1 + s TR) of Vt (TR = 0: LG_y held, Vt used)
    vi = Vref - LG_y
    PI regulator with tracking anti-windup (ANDES' PITrackAW, tracking gain ks = 2, ANDES'
        config ksr):  ys1 = KPR vi + PI1_xi,  PI1_y = ys1 clipped to [VRMIN, VRMAX],
        dPI1_xi/dt = KIR (vi - ks (ys1 - PI1_y))
    lag 1 / (1 + s TA) of PI1_y:  TA dLA_y/dt = PI1_y - LA_y  (TA = 0: LA_y held, PI1_y used)
    VB = min(VE FEX(KC XadIfd / VE), VBMAX),  VE = |KPC V + j (KI + KPC XL) I|  (esst3a.bridge_voltage)
    inner PI, tracking gain ks = 2 (ANDES' ksm):  ys2 = KPM (LA_y - VG) + PI2_xi,
        PI2_y = ys2 clipped to [VMMIN, VMMAX],  dPI2_xi/dt = KIM (LA_y - VG - ks (ys2 - PI2_y))
    Efd = VB PI2_y,  VG = min(KG Efd, VGMAX)

VG closes an algebraic loop through PI2_y (ANDES solves it with its network); here in closed
form: PI2_y is y* = (KPM LA_y + PI2_xi) / (1 + KPM KG VB), or y* = KPM (LA_y - VGMAX) + PI2_xi
where KG VB y* reaches VGMAX, clipped to [VMMIN, VMMAX] (the loop's gain KPM KG VB >= 0 makes
the solution unique). The tracking anti-windup holds no state at a limit: no reset. ANDES' ESST4B
has no stabiliser input (and no low value gate): there is no Vss.

Bases: I is on the system base and KI, XL multiply it unconverted, as ANDES 2.0 does (ESST3A's
choice, esst3a.py).

Start (ANDES' initialisation): LG_y = Vt, Vref = Vt (vi = 0), PI2_xi = Efd / VB, VG = min(KG Efd,
VGMAX), PI1_xi = LA_y = VG.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import clip, lag
from ..component import Component, Initialisation, Parameters, Quantity
from ..piecewise import where
from ..ports import Link, Ports
from .common import check_limits, check_ranges, finite_inputs
from .esst3a import TERMINAL_INPUTS, TERMINAL_LINKS, bridge_voltage
from .exac1 import XADIFD

TRACKING_GAIN = 2.0  # ANDES' ESST4B config ksr = ksm: the PI controllers' tracking anti-windup gain
PARAMETER_RANGES = {"TR": (0.0, 10.0, "s"), "KPR": (0.0, 1000.0, "pu"), "KIR": (0.0, 1000.0, "pu/s"),
                    "TA": (0.0, 10.0, "s"), "KPM": (0.0, 1000.0, "pu"), "KIM": (0.0, 1000.0, "pu/s"),
                    "KG": (0.0, 10.0, "pu"), "KP": (0.0, 100.0, "pu"), "KI": (0.0, 100.0, "pu"),
                    "VBMAX": (0.01, 1000.0, "pu"), "KC": (0.0, 10.0, "pu"), "XL": (0.0, 10.0, "pu"),
                    "THETAP": (-180.0, 180.0, "deg"), "VGMAX": (0.0, 1000.0, "pu")}


@dataclass(frozen=True)
class ESST4BParams(Parameters):
    """ANDES/PSS/E ESST4B data (ANDES' defaults): time constants [s], gains [pu], PI integral
    gains KIR, KIM [pu/s], limits [pu], THETAP [deg]."""

    TR: float = 0.01
    KPR: float = 1.0
    KIR: float = 0.0
    VRMAX: float = 8.0
    VRMIN: float = 0.0
    TA: float = 0.1
    KPM: float = 1.0
    KIM: float = 0.0
    VMMAX: float = 8.0
    VMMIN: float = 0.0
    KG: float = 1.0
    KP: float = 4.0
    KI: float = 0.1
    VBMAX: float = 18.0
    KC: float = 0.1
    XL: float = 0.01
    THETAP: float = 0.0
    VGMAX: float = 20.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "VRMIN", "VRMAX")
        check_limits(self, "VMMIN", "VMMAX")


def inner_loop(LA_y, PI2_xi, VB, p: ESST4BParams, m) -> tuple:
    """(ys2, PI2_y, VG): the inner PI's sum and output and the field voltage feedback, solved
    together (the loop PI2_y -> Efd = VB PI2_y -> VG -> ys2; module docstring)."""
    gain = p.KG * VB  # VG = min(gain PI2_y, VGMAX)
    free = (p.KPM * LA_y + PI2_xi) / (1.0 + p.KPM * gain)
    PI2_y = clip(m, where(m, gain * free >= p.VGMAX, p.KPM * (LA_y - p.VGMAX) + PI2_xi, free), p.VMMIN, p.VMMAX)
    VG = clip(m, gain * PI2_y, -math.inf, p.VGMAX)
    return p.KPM * (LA_y - VG) + PI2_xi, PI2_y, VG


def _loops(x, u, p: ESST4BParams, m) -> tuple:
    """(dLG_y, dPI1_xi, dLA_y, dPI2_xi, Efd)."""
    LG_y, PI1_xi, LA_y, PI2_xi = x
    Vt, theta_vs, I_re, I_im, Vref, XadIfd = u
    d_LG, sensed = lag(m, Vt, LG_y, 1.0, p.TR)
    vi = Vref - sensed
    ys1 = p.KPR * vi + PI1_xi
    PI1_y = clip(m, ys1, p.VRMIN, p.VRMAX)
    d_LA, LA_out = lag(m, PI1_y, LA_y, 1.0, p.TA)
    VB = bridge_voltage(Vt, theta_vs, I_re, I_im, XadIfd, p, m)
    ys2, PI2_y, VG = inner_loop(LA_out, PI2_xi, VB, p, m)
    return (d_LG, p.KIR * (vi - TRACKING_GAIN * (ys1 - PI1_y)), d_LA,
            p.KIM * (LA_out - VG - TRACKING_GAIN * (ys2 - PI2_y)), VB * PI2_y)


def derivatives(x, u, p: ESST4BParams, m):
    """(dLG_y, dPI1_xi, dLA_y, dPI2_xi)/dt for x = (LG_y, PI1_xi, LA_y, PI2_xi),
    u = (Vt, theta_vs, I_re, I_im, Vref, XadIfd)."""
    return _loops(x, u, p, m)[:4]


def outputs(x, u, p: ESST4BParams, m):
    """(Efd,) = VB PI2_y."""
    return (_loops(x, u, p, m)[4],)


def start(given, p: ESST4BParams) -> tuple:
    """Initialisation.start (ANDES' initialisation): (x0, {"Vref": Vt}) giving the demanded Efd at
    the given Vt, theta_vs, I_re, I_im, XadIfd; ValueError where a limit would hold it."""
    Vt, Efd = float(given["Vt"]), float(given["Efd"])
    VB = bridge_voltage(Vt, float(given["theta_vs"]), float(given["I_re"]), float(given["I_im"]),
                        float(given["XadIfd"]), p, math)
    PI2_y = Efd / VB
    VG = min(p.KG * Efd, p.VGMAX)
    if not (p.VMMIN <= PI2_y <= p.VMMAX and p.VRMIN <= VG <= p.VRMAX):
        raise ValueError(f"ESST4B: a regulator at rest with field voltage {Efd:.6g} pu lies outside its limits")
    return np.array([Vt, VG, VG, PI2_y]), {"Vref": Vt}


def equilibrium(u, p: ESST4BParams) -> np.ndarray:
    """A steady state [4] at constant inputs: a PI integrator rests wherever its error is nil, so the
    rest at given inputs is not unique (ANDES' initialisation picks it from the field voltage the
    machine needs: `start`); this one has both integrator states at 0 (a regulator that has
    integrated nothing) and LA_y at the outer PI's output. ValueError where that is no rest (an
    integral gain with an error left). At the start inputs (Vref = Vt) it is the rest at Efd = 0
    for any gains whose limits span 0."""
    values = finite_inputs(u, "ESST4B")
    Vt, Vref = values[0], values[4]
    x = np.array([Vt, 0.0, float(clip(math, p.KPR * (Vref - Vt), p.VRMIN, p.VRMAX)), 0.0])
    rates = np.array(derivatives(list(x), values, p, math))
    if np.abs(rates).max() > 1e-12 * (1.0 + np.abs(x).max()):
        raise ValueError("ESST4B: no rest with its PI integrators at 0 at these inputs")
    return x


ESST4B = Component(
    name="esst4b",
    description="ESST4B IEEE ST4B static exciter (PSS/E, ANDES)",
    states=(Quantity("LG_y", "pu", "sensed terminal voltage"),
            Quantity("PI1_xi", "pu", "voltage regulator integrator state"),
            Quantity("LA_y", "pu", "regulator delay output"),
            Quantity("PI2_xi", "pu", "inner loop integrator state")),
    inputs=TERMINAL_INPUTS + (Quantity("Vref", "pu", "voltage set point", start=1.0, operating_range=(0.9, 1.2)),
                              XADIFD),
    outputs=(Quantity("Efd", "pu", "field voltage"),),
    params_type=ESST4BParams,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.5, 0.5, 0.1),
    ports=Ports(inputs=TERMINAL_LINKS + (Link("voltage_reference", "Vref"), Link("field_current", "XadIfd")),
                outputs=(Link("field_voltage", "Efd"),)),
    initialisation=Initialisation(("Vref",), start),
)
