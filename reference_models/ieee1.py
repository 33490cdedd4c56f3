"""The IEEE Type I exciter (Sauer-Pai, optional non-windup regulator limits): `IEEE1`.

States  x = (Efd [pu] field voltage, RF [pu] rate-feedback state, VR [pu] regulator output)
Inputs  u = (Vt [pu] terminal voltage magnitude, Vref [pu] voltage set point)
Outputs y = (SE [pu] the saturation function SE(Efd) = Ax exp(Bx Efd))

    TE dEfd/dt = -(KE + SE(Efd)) Efd + VR
    TF dRF/dt  = -RF + (KF / TF) Efd
    TA dVR/dt  = -VR + KA RF - (KA KF / TF) Efd + KA (Vref - Vt) =: f,   VRmin <= VR <= VRmax

The regulator limit is Sauer-Pai's non-windup limit: VR stops at a limit while the regulator
pushes beyond it (dVR/dt = 0 where VR >= VRmax and f > 0, or VR <= VRmin and f < 0) and leaves
it as soon as f turns back. A limit at or beyond NO_LIMIT (1e6 pu) in magnitude is none: the
defaults VRmin = -1e6, VRmax = 1e6 leave VR unlimited and the traced equations smooth (no
conditional is generated for an absent limit).

Defaults: the WSCC 9-bus exciters (KA 20, TA 0.2, KE 1, TE 0.314, KF 0.063, TF 0.35,
SE = 0.0039 exp(1.555 Efd)), without limits.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .component import Component, Initialisation, Parameters, Quantity
from .piecewise import where
from .ports import Link, Ports

NO_LIMIT = 1e6  # pu: a regulator limit this large (or larger) in magnitude is no limit


# The physical range of each gain and time constant (low, high, unit): outside it an exciter is a
# typing error or has a mode no integrator follows in a co-simulation's time (within these ranges
# the fastest is below 5e4 1/s). The regulator limits are any numbers (beyond NO_LIMIT: none).
PARAMETER_RANGES = {
    "KA": (0.0, 1000.0, "pu"), "TA": (0.005, 10.0, "s"), "KE": (0.0, 10.0, "pu"), "TE": (0.01, 10.0, "s"),
    "KF": (0.0, 1.0, "pu"), "TF": (0.01, 100.0, "s"), "Ax": (0.0, 1.0, "pu"), "Bx": (0.0, 5.0, "1/pu"),
}


@dataclass(frozen=True)
class IEEE1Params(Parameters):
    """Gains (pu/pu), time constants [s] and the saturation coefficients Ax [pu], Bx [1/pu]."""

    KA: float = 20.0
    TA: float = 0.2
    KE: float = 1.0
    TE: float = 0.314
    KF: float = 0.063
    TF: float = 0.35
    Ax: float = 0.0039
    Bx: float = 1.555
    VRmin: float = -NO_LIMIT
    VRmax: float = NO_LIMIT

    def check(self) -> None:
        for name in ("KA", "TA", "TE", "TF"):
            self.require(name, getattr(self, name) > 0, "be > 0")
        for name in ("KF", "Ax", "Bx"):
            self.require(name, getattr(self, name) >= 0, "be >= 0")
        self.require("KE", self.KE > 0, "be > 0 (a separately excited exciter; self-excited ones are not modelled)")
        for name, (low, high, unit) in PARAMETER_RANGES.items():
            self.require(name, low <= getattr(self, name) <= high, f"lie in [{low:g}, {high:g}] {unit}")
        self.require("VRmax", self.VRmax > self.VRmin, f"exceed VRmin = {self.VRmin!r}")


def regulator_limits(p: IEEE1Params) -> tuple:
    """(low, high) [pu] of the regulator output VR: -inf, inf for an absent limit (|limit| >= NO_LIMIT)."""
    return (p.VRmin if p.VRmin > -NO_LIMIT else -math.inf, p.VRmax if p.VRmax < NO_LIMIT else math.inf)


def non_windup(rate, VR, p: IEEE1Params, m):
    """dVR/dt under the non-windup limit: `rate` (the unlimited one), held at 0 while VR is at a
    limit and the rate pushes it beyond."""
    low, high = regulator_limits(p)
    if high < math.inf:
        rate = where(m, VR >= high, where(m, rate > 0.0, 0.0, rate), rate)
    if low > -math.inf:
        rate = where(m, VR <= low, where(m, rate < 0.0, 0.0, rate), rate)
    return rate


def derivatives(x, u, p: IEEE1Params, m):
    """(d Efd, d RF, d VR)/dt for x = (Efd, RF, VR), u = (Vt, Vref)."""
    Efd, RF, VR = x
    Vt, Vref = u
    SE = p.Ax * m.exp(p.Bx * Efd)
    d_Efd = (-(p.KE + SE) * Efd + VR) / p.TE
    d_RF = (-RF + p.KF / p.TF * Efd) / p.TF
    d_VR = non_windup((-VR + p.KA * RF - p.KA * p.KF / p.TF * Efd + p.KA * (Vref - Vt)) / p.TA, VR, p, m)
    return d_Efd, d_RF, d_VR


def derived(x, u, p: IEEE1Params, m):
    """(SE,): the saturation function at the current field voltage."""
    return (p.Ax * m.exp(p.Bx * x[0]),)


def equilibrium(u, p: IEEE1Params) -> np.ndarray:
    """The steady state [3] at constant (Vt, Vref): (KE + SE(Efd)) Efd = VR, VR = KA (Vref - Vt)
    within the regulator limits (else the limit it rests at), which is increasing in Efd for KE > 0
    and Efd >= -1 / Bx; ValueError outside that branch."""
    from scipy.optimize import brentq

    Vt, Vref = (float(v) for v in u)
    if not (np.isfinite(Vt) and np.isfinite(Vref)):
        raise ValueError(f"no steady state of IEEE1 at Vt={Vt} pu, Vref={Vref} pu")
    vr_low, vr_high = regulator_limits(p)
    drive = min(max(p.KA * (Vref - Vt), vr_low), vr_high)

    def balance(Efd):
        return (p.KE + p.Ax * np.exp(p.Bx * Efd)) * Efd - drive

    low = -1.0 / p.Bx if p.Bx > 0 else -1e3
    high = 1.0
    while balance(high) < 0 and high < 1e3:
        high *= 2.0
    if not (np.isfinite(drive) and balance(low) <= 0 <= balance(high)):
        raise ValueError(f"no steady state of IEEE1 at Vt={Vt} pu, Vref={Vref} pu")
    Efd = brentq(balance, low, high, xtol=1e-15, rtol=1e-15)
    at_limit = drive in (vr_low, vr_high)  # VR rests exactly at the limit, held there
    VR = drive if at_limit else (p.KE + p.Ax * np.exp(p.Bx * Efd)) * Efd
    return np.array([Efd, p.KF / p.TF * Efd, VR])



def _start(given, p: IEEE1Params) -> tuple:
    """(x0, {Vref}): IEEE1 at rest holding the field voltage given["Efd"] at the terminal voltage
    given["Vt"] (initialisation.exciter_start)."""
    from .initialisation import exciter_start

    s = exciter_start(given["Efd"], given["Vt"], p)
    return s.x0, {"Vref": s.Vref}

IEEE1 = Component(
    name="ieee1",
    description="IEEE Type I exciter (Sauer-Pai, optional non-windup regulator limits)",
    states=(Quantity("Efd", "pu", "field voltage"),
            Quantity("RF", "pu", "rate-feedback state"),
            Quantity("VR", "pu", "regulator output")),
    inputs=(Quantity("Vt", "pu", "terminal voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
            Quantity("Vref", "pu", "voltage set point", start=1.05, operating_range=(0.9, 1.2))),
    outputs=(Quantity("SE", "pu", "saturation function SE(Efd)"),),
    params_type=IEEE1Params,
    derivatives=derivatives,
    output_equations=derived,
    equilibrium=equilibrium,
    state_scales=(0.5, 0.1, 0.5),
    # dRF/dt = (KF/TF Efd - RF)/TF: affine in RF. dVR/dt = (... - VR)/TA is affine in VR only
    # without regulator limits (the limit holds VR), so VR is not declared affine
    affine_states=(1,),
    ports=Ports(inputs=(Link("terminal_voltage", "Vt"), Link("voltage_reference", "Vref")),
                outputs=(Link("field_voltage", "Efd"),)),
    initialisation=Initialisation(("Vref",), lambda given, p: _start(given, p)),
)
