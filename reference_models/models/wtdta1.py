"""WTDTA1: the two-mass drive train of a type-3 wind turbine (PSS/E WTDTA1, WECC WTGT_A, ANDES).

States  x = (s1_y [pu] turbine speed wt; s2_y [pu] generator speed wg; s3_y [pu] shaft torque)
Inputs  u = (Pm [pu] mechanical power from the aerodynamics; Pe [pu] the converter's active power)
Outputs y = (wt, wg [pu]: the turbine and generator speeds; wref [pu]: the speed set point w0, the
        pitch controller's speed reference)

Equations (ANDES 2.0 model reference, RenGovernor: WTDTA1), on the system base:

    Ht2 = 2 Htfrac H,  Hg2 = 2 (1 - Htfrac) H,  Kshaft = Ht2 Hg2 Freq1^2 / (2 H)
    pd = Dshaft (s1_y - s2_y)
    Ht2 ds1_y/dt = Pm / s1_y - s3_y - pd
    Hg2 ds2_y/dt = -Pe / s2_y + s3_y - DAMP (s2_y - w0) + pd
    ds3_y/dt = Kshaft (s1_y - s2_y)

Freq1 is in pu of the nominal frequency (ANDES: (2 pi Freq1)^2 in pu is Freq1^2).

Bases: the powers Pm, Pe and the torque s3_y are on the system base Sb, as ANDES computes them. The
parameters are as the case data give them, on the converter's base Sn (the drive train's rating:
ANDES takes its REGCA1's Sn); H, DAMP and Dshaft are converted by Sn / Sb as ANDES converts them.
Htfrac = 0 or 1 (a single mass, where ANDES makes a speed algebraic) is not modelled.

Its electrical controller: ANDES' REECA1 takes the generator speed from the drive train (its wg,
used for PFLAG = 1) and with it the power reference p0 / wg, unless a torque controller (WTTQA1)
drives that reference; here the electrical controller's reference is its torque controller's
output (models/wttqa1.py), so a drive train without a WTTQA1 behaves as ANDES' only at the start.

Start: its generator speed wg0 is what its torque controller demands (WTTQA1: the speed of its
power-speed characteristic at the converter's power), w0 without one; wt = wg = wg0,
s3_y = Pe / wg0 + DAMP (wg0 - w0) and the mechanical power Pm = wg0 s3_y the aerodynamics have to
give (ANDES' initialisation: s3_y = Pe0 / wg0, Pm = Pe0, the same for DAMP = 0 or wg0 = w0; otherwise
ANDES' start is not at rest, its generator accelerating at -DAMP (wg0 - w0) / Hg2).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_ranges, finite_inputs

PARAMETER_RANGES = {
    "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA"), "H": (1e-3, 100.0, "s"), "DAMP": (0.0, 1e3, "pu"),
    "Htfrac": (0.0, 1.0, ""), "Freq1": (1e-3, 100.0, "pu"), "Dshaft": (0.0, 1e3, "pu"), "w0": (0.1, 2.0, "pu"),
}


@dataclass(frozen=True)
class WTDTA1Params(Parameters):
    """ANDES/PSS/E WTDTA1 data: the converter's base Sn [MVA] and the system base Sb [MVA]; the total
    inertia H [s] and its turbine fraction Htfrac; the generator's damping DAMP and the shaft's
    Dshaft [pu, base Sn]; the first torsional frequency Freq1 [pu]; the speed set point w0 [pu]."""

    Sn: float = 100.0
    Sb: float = 100.0
    H: float = 3.0
    DAMP: float = 0.0
    Htfrac: float = 0.5
    Freq1: float = 1.0
    Dshaft: float = 1.0
    w0: float = 1.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        self.require("Htfrac", 0.0 < self.Htfrac < 1.0, "lie strictly between 0 and 1 (a single mass is not modelled)")

    @property
    def base_ratio(self) -> float:
        """Sn / Sb: an inertia, a damping or a power on the converter's base times this is on the
        system base."""
        return self.Sn / self.Sb

    @property
    def masses(self) -> tuple:
        """(Ht2, Hg2, Kshaft, DAMP, Dshaft) on the system base."""
        k = self.base_ratio
        H = self.H * k
        Ht2, Hg2 = 2.0 * self.Htfrac * H, 2.0 * H * (1.0 - self.Htfrac)
        return Ht2, Hg2, Ht2 * Hg2 * 0.5 * self.Freq1 * self.Freq1 / H, self.DAMP * k, self.Dshaft * k


def derivatives(x, u, p: WTDTA1Params, m):
    """(ds1_y, ds2_y, ds3_y)/dt for x = (s1_y, s2_y, s3_y), u = (Pm, Pe)."""
    wt, wg, s3_y = x
    Pm, Pe = u
    Ht2, Hg2, Kshaft, DAMP, Dshaft = p.masses
    pd = Dshaft * (wt - wg)
    return ((Pm / wt - s3_y - pd) / Ht2, (-Pe / wg + s3_y - DAMP * (wg - p.w0) + pd) / Hg2, Kshaft * (wt - wg))


def outputs(x, u, p: WTDTA1Params, m):
    """(wt, wg, wref) [pu]."""
    return x[0], x[1], p.w0 + 0.0 * x[0]


def _rest(w: float, Pe: float, p: WTDTA1Params) -> tuple:
    """(x [3], Pm): the drive train at rest at speed w delivering Pe [pu, system base]."""
    DAMP = p.masses[3]
    s3_y = Pe / w + DAMP * (w - p.w0)
    return np.array([w, w, s3_y]), w * s3_y


def _start(given, p: WTDTA1Params) -> tuple:
    wg = float(given.get("wg", p.w0))
    if not wg > 0:
        raise ValueError(f"WTDTA1: no start at the generator speed {wg:.6g} pu")
    x0, Pm = _rest(wg, float(given["Pe"]), p)
    return x0, {"Pm": Pm}


def equilibrium(u, p: WTDTA1Params) -> np.ndarray:
    """The steady state [3] at constant (Pm, Pe): both masses at the speed w where the generator's
    damping takes the power difference, DAMP w (w - w0) = Pm - Pe; without damping (DAMP = 0) the
    speed rests at w0 where Pm = Pe and runs away otherwise (ValueError)."""
    Pm, Pe = finite_inputs(u, "WTDTA1")
    DAMP = p.masses[3]
    if DAMP == 0:
        if abs(Pm - Pe) > 1e-12 * max(1.0, abs(Pe)):
            raise ValueError(f"WTDTA1: no steady state without damping where Pm = {Pm:.6g} differs from Pe = {Pe:.6g}")
        return _rest(p.w0, Pe, p)[0]
    discriminant = p.w0 * p.w0 + 4.0 * (Pm - Pe) / DAMP
    if discriminant < 0:
        raise ValueError(f"WTDTA1: no steady state where Pe exceeds Pm by {Pe - Pm:.6g} pu (the damping cannot "
                         "take it at any speed)")
    return _rest(0.5 * (p.w0 + math.sqrt(discriminant)), Pe, p)[0]


WTDTA1 = Component(
    name="wtdta1",
    description="WTDTA1 two-mass drive train of a type-3 wind turbine (PSS/E, WECC WTGT_A, ANDES)",
    states=(Quantity("s1_y", "pu", "turbine speed wt"),
            Quantity("s2_y", "pu", "generator speed wg"),
            Quantity("s3_y", "pu", "shaft torque (system base)")),
    inputs=(Quantity("Pm", "pu", "mechanical power (system base)", start=0.5, operating_range=(0.0, 1.0)),
            Quantity("Pe", "pu", "the converter's active power (system base)", start=0.5,
                     operating_range=(0.0, 1.0))),
    outputs=(Quantity("wt", "pu", "turbine speed"),
             Quantity("wg", "pu", "generator speed"),
             Quantity("wref", "pu", "speed set point w0 (the pitch controller's reference)")),
    params_type=WTDTA1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.05, 0.05, 0.1),
    ports=Ports(inputs=(Link("mechanical_power", "Pm"), Link("active_power", "Pe")),
                outputs=(Link("turbine_speed", "wt"), Link("generator_speed", "wg"),
                         Link("turbine_speed_reference", "wref"))),
    initialisation=Initialisation(("Pm",), _start),
)
