"""WTDS: the single-mass drive train of a wind turbine (ANDES' WTDS: one swing equation for the turbine
and generator masses together; Chow and Sanchez-Gasca, Power System Modeling, Computation, and
Control, 2020, p. 518), in place of the two-mass WTDTA1 of a type-3 wind turbine.

States  x = (s1_y [pu] the speed of the combined mass, the turbine's and the generator's)
Inputs  u = (Pm [pu] mechanical power from the aerodynamics; Pe [pu] the converter's active power;
        wr0 [pu] the speed reference: its torque controller's power-speed characteristic fPe)
Outputs y = (wt, wg [pu]: the turbine and generator speeds, both s1_y; wref [pu]: the speed set
        point w0, the pitch controller's speed reference)

Equations (ANDES 2.0 model reference, RenGovernor: WTDS), on the system base:

    wge = 1 + s1_y - wr0
    2 H ds1_y/dt = (Pm - Pe) / wge - D (s1_y - wr0)

wge is the generator speed ANDES' electrical controller holds (REECA1's wg): ANDES sums into it the
drive train's s1_y - 1 and its torque controller's 1 - fPe, and sets wr0 = fPe (the torque
controller replaces the drive train's w0 by its characteristic); the swing equation divides the
power by that speed, 1 at the start. Without a torque controller ANDES' wge is s1_y and wr0 = w0:
the same equation where w0 = 1 (ANDES' default), the speed reference then held at its start value.

Bases: the powers Pm, Pe on the system base Sb, as ANDES computes them. The parameters are as the
case data give them, on the converter's base Sn (ANDES takes its REGCA1's Sn); H and D are converted
by Sn / Sb as ANDES converts them. ANDES' unused state s3_y (no equation; its torque controller
writes Pe / wg into it at the start) is left out.

Start: the speed is what its torque controller demands (WTTQA1: the speed of its power-speed
characteristic at the converter's power), w0 without one; s1_y = wr0 = that speed (ANDES: s1_y
starts at wr0) and the mechanical power Pm = Pe the aerodynamics have to give (ANDES: Pm = Pe0).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_ranges, finite_inputs

PARAMETER_RANGES = {
    "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA"), "H": (1e-3, 100.0, "s"), "D": (0.0, 1e3, "pu"),
    "w0": (0.1, 2.0, "pu"),
}


@dataclass(frozen=True)
class WTDSParams(Parameters):
    """ANDES' WTDS data: the converter's base Sn [MVA] and the system base Sb [MVA]; the total inertia
    H [s] and the damping D [pu, base Sn]; the speed set point w0 [pu]."""

    Sn: float = 100.0
    Sb: float = 100.0
    H: float = 3.0
    D: float = 1.0
    w0: float = 1.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)

    @property
    def mass(self) -> tuple:
        """(2 H, D) on the system base."""
        k = self.Sn / self.Sb
        return 2.0 * self.H * k, self.D * k


def derivatives(x, u, p: WTDSParams, m):
    """(ds1_y/dt,) for x = (s1_y,), u = (Pm, Pe, wr0)."""
    (w,) = x
    Pm, Pe, wr0 = u
    H2, D = p.mass
    return ((Pm - Pe) / (1.0 + w - wr0) - D * (w - wr0)) / H2,


def outputs(x, u, p: WTDSParams, m):
    """(wt, wg, wref) [pu]."""
    return x[0], x[0], p.w0 + 0.0 * x[0]


def _start(given, p: WTDSParams) -> tuple:
    w = float(given.get("wg", p.w0))
    if not w > 0:
        raise ValueError(f"WTDS: no start at the generator speed {w:.6g} pu")
    return np.array([w]), {"Pm": float(given["Pe"]), "wr0": w}


def equilibrium(u, p: WTDSParams) -> np.ndarray:
    """The steady state [1] at constant (Pm, Pe, wr0): the speed s1_y = wr0 + d where the damping takes
    the power difference, D d (1 + d) = Pm - Pe (the root with 1 + d > 0); without damping (D = 0)
    the speed rests at wr0 where Pm = Pe and runs away otherwise (ValueError)."""
    Pm, Pe, wr0 = finite_inputs(u, "WTDS")
    D = p.mass[1]
    if D == 0:
        if abs(Pm - Pe) > 1e-12 * max(1.0, abs(Pe)):
            raise ValueError(f"WTDS: no steady state without damping where Pm = {Pm:.6g} differs from Pe = {Pe:.6g}")
        return np.array([wr0])
    discriminant = 1.0 + 4.0 * (Pm - Pe) / D
    if discriminant < 0:
        raise ValueError(f"WTDS: no steady state where Pe exceeds Pm by {Pe - Pm:.6g} pu (the damping cannot "
                         "take it at any speed)")
    return np.array([wr0 + 0.5 * (math.sqrt(discriminant) - 1.0)])


WTDS = Component(
    name="wtds",
    description="WTDS single-mass drive train of a wind turbine (ANDES)",
    states=(Quantity("s1_y", "pu", "speed of the turbine and generator mass"),),
    inputs=(Quantity("Pm", "pu", "mechanical power (system base)", start=0.5, operating_range=(0.0, 1.0)),
            Quantity("Pe", "pu", "the converter's active power (system base)", start=0.5,
                     operating_range=(0.0, 1.0)),
            Quantity("wr0", "pu", "speed reference (the torque controller's power-speed characteristic)", start=1.0,
                     operating_range=(0.6, 1.2))),
    outputs=(Quantity("wt", "pu", "turbine speed"),
             Quantity("wg", "pu", "generator speed"),
             Quantity("wref", "pu", "speed set point w0 (the pitch controller's reference)")),
    params_type=WTDSParams,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.05,),
    ports=Ports(inputs=(Link("mechanical_power", "Pm"), Link("active_power", "Pe"),
                        Link("generator_speed_reference", "wr0")),
                outputs=(Link("turbine_speed", "wt"), Link("generator_speed", "wg"),
                         Link("turbine_speed_reference", "wref"))),
    initialisation=Initialisation(("Pm", "wr0"), _start),
)
