"""The IEEE Type I exciter (Sauer-Pai, without regulator limits): `IEEE1`.

States  x = (Efd [pu] field voltage, RF [pu] rate-feedback state, VR [pu] regulator output)
Inputs  u = (Vt [pu] terminal voltage magnitude, Vref [pu] voltage set point)
Outputs y = (SE [pu] the saturation function SE(Efd) = Ax exp(Bx Efd))

    TE dEfd/dt = -(KE + SE(Efd)) Efd + VR
    TF dRF/dt  = -RF + (KF / TF) Efd
    TA dVR/dt  = -VR + KA RF - (KA KF / TF) Efd + KA (Vref - Vt)

Defaults: the WSCC 9-bus exciters (KA 20, TA 0.2, KE 1, TE 0.314, KF 0.063, TF 0.35,
SE = 0.0039 exp(1.555 Efd)). The regulator limits VRmin, VRmax are not modelled yet: the traced
equations are smooth.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .component import Component, Parameters, Quantity


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

    def check(self) -> None:
        for name in ("KA", "TA", "TE", "TF"):
            self.require(name, getattr(self, name) > 0, "be > 0")
        for name in ("KF", "Ax", "Bx"):
            self.require(name, getattr(self, name) >= 0, "be >= 0")
        self.require("KE", self.KE > 0, "be > 0 (a separately excited exciter; self-excited ones are not modelled)")


def derivatives(x, u, p: IEEE1Params, m):
    """(d Efd, d RF, d VR)/dt for x = (Efd, RF, VR), u = (Vt, Vref)."""
    Efd, RF, VR = x
    Vt, Vref = u
    SE = p.Ax * m.exp(p.Bx * Efd)
    d_Efd = (-(p.KE + SE) * Efd + VR) / p.TE
    d_RF = (-RF + p.KF / p.TF * Efd) / p.TF
    d_VR = (-VR + p.KA * RF - p.KA * p.KF / p.TF * Efd + p.KA * (Vref - Vt)) / p.TA
    return d_Efd, d_RF, d_VR


def derived(x, u, p: IEEE1Params, m):
    """(SE,): the saturation function at the current field voltage."""
    return (p.Ax * m.exp(p.Bx * x[0]),)


def equilibrium(u, p: IEEE1Params) -> np.ndarray:
    """The steady state [3] at constant (Vt, Vref): (KE + SE(Efd)) Efd = KA (Vref - Vt), which is
    increasing in Efd for KE > 0 and Efd >= -1 / Bx; ValueError outside that branch."""
    from scipy.optimize import brentq

    Vt, Vref = (float(v) for v in u)
    drive = p.KA * (Vref - Vt)

    def balance(Efd):
        return (p.KE + p.Ax * np.exp(p.Bx * Efd)) * Efd - drive

    low = -1.0 / p.Bx if p.Bx > 0 else -1e3
    high = 1.0
    while balance(high) < 0 and high < 1e3:
        high *= 2.0
    if not (np.isfinite(drive) and balance(low) <= 0 <= balance(high)):
        raise ValueError(f"no steady state of IEEE1 at Vt={Vt} pu, Vref={Vref} pu")
    Efd = brentq(balance, low, high, xtol=1e-15, rtol=1e-15)
    return np.array([Efd, p.KF / p.TF * Efd, (p.KE + p.Ax * np.exp(p.Bx * Efd)) * Efd])


IEEE1 = Component(
    name="ieee1",
    description="IEEE Type I exciter (Sauer-Pai, no regulator limits)",
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
    # dRF/dt = (KF/TF Efd - RF)/TF and dVR/dt = (... - VR)/TA: each affine in itself
    affine_states=(1, 2),
)
