"""WTTQA1: the torque controller of a type-3 wind turbine (PSS/E WTTQA1, WECC WTGTRQ_A, ANDES), which
drives its electrical controller's active power reference.

States  x = (s1_y [pu] filtered active power; s2_y [pu] speed reference (filtered power-speed
        characteristic); PI_xi [pu] the torque PI's integrator (non-windup); Pref0 [pu] the active
        power reference at the start, held)
Inputs  u = (Pe [pu] the converter's active power; wg [pu] the generator speed (its drive train's);
        Pext [pu] the plant controller's active power reference, where there is one (else held))
Outputs y = (Pref [pu]: the electrical controller's active power reference)

Equations (ANDES 2.0 model reference, RenTorque: WTTQA1), on the system base:

    Tp ds1_y/dt = Pe - s1_y  (Tp = 0: s1_y held, Pe used)
    fPe = the power-speed characteristic at s1_y: piecewise linear through (p1, sp1) .. (p4, sp4),
        sp1 below p1 and sp4 above p4
    Twref ds2_y/dt = fPe - s2_y
    Tsel = (Pe - Pref0) / wg (Tflag = 1: power error) or s2_y - wg (Tflag = 0: speed error)
    dPI_xi/dt = Kip Tsel, non-windup within [Temin, Temax];  PI_y = Kpp Tsel + PI_xi clipped to [Temin, Temax]
    Pref = PI_y wg + (Pext - Pref0),  dPref0/dt = 0

The plant controller's command adds to the torque controller's (ANDES: both add their terms to
REECA1's Pref equation, the plant's Pext as its change from the start): the torque controller
sits in series on `active_power_reference` (case.unit_wiring), taking REPCA1's Pext and giving
the sum; without a plant controller Pext is held at its start value, and adds nothing.

Bases: the powers and torques on the system base Sb, as ANDES computes them. The parameters are as
the case data give them: p1..p4, Temax, Temin on the turbine's base Sn (ANDES: Tn, or its
converter's Sn where Tn is not given), converted by Sn / Sb as ANDES converts them; the speeds
sp1..sp4 in pu.

In ANDES the torque controller also adds 1 - fPe to its electrical controller's generator speed
(which its drive train makes wg there: 1 + wg - fPe, 1 at the start), a speed that REECA1 uses only
with PFLAG = 1 (Psel = wg Pfilt); with PFLAG = 0, as ANDES intends with a torque controller, it
changes nothing. The PI is not frozen during a voltage dip (ANDES notes that freeze as not implemented).

Start (ANDES' initialisation): given its power Pe and the reference Pref its electrical controller
demands (else Pe): s1_y = Pe, the generator speed wg = s2_y = fPe, which its drive train then has
to give, Pref0 = Pref, PI_xi = Pref / wg (ANDES' Pref0 / fPe), Pext = Pref (what a plant
controller then has to give).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import clip, integrator_non_windup, integrator_non_windup_reset, lag, piecewise_linear
from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_limits, check_ranges, finite_inputs

PARAMETER_RANGES = {
    "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA"), "Kip": (0.0, 1e4, "1/s"), "Kpp": (0.0, 1e4, ""),
    "Tp": (0.0, 100.0, "s"), "Twref": (1e-3, 1e3, "s"), "Temax": (-10.0, 10.0, "pu"), "Temin": (-10.0, 10.0, "pu"),
    "p1": (0.0, 10.0, "pu"), "p2": (0.0, 10.0, "pu"), "p3": (0.0, 10.0, "pu"), "p4": (0.0, 10.0, "pu"),
    "sp1": (0.1, 3.0, "pu"), "sp2": (0.1, 3.0, "pu"), "sp3": (0.1, 3.0, "pu"), "sp4": (0.1, 3.0, "pu"),
}


@dataclass(frozen=True)
class WTTQA1Params(Parameters):
    """ANDES/PSS/E WTTQA1 data: the turbine's base Sn [MVA] (ANDES' Tn, or its converter's Sn) and
    the system base Sb [MVA]; the PI gains Kpp, Kip and its torque limits Temin, Temax [pu, base Sn];
    the power filter Tp [s] and the speed reference filter Twref [s]; Tflag (1: power error, 0: speed
    error); the power-speed characteristic p1..p4 [pu, base Sn], sp1..sp4 [pu]."""

    Sn: float = 100.0
    Sb: float = 100.0
    Kip: float = 0.1
    Kpp: float = 0.0
    Tp: float = 0.05
    Twref: float = 30.0
    Temax: float = 1.2
    Temin: float = 0.0
    Tflag: float = 0.0
    p1: float = 0.2
    sp1: float = 0.58
    p2: float = 0.4
    sp2: float = 0.72
    p3: float = 0.6
    sp3: float = 0.86
    p4: float = 0.8
    sp4: float = 1.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        self.require("Tflag", self.Tflag in (0.0, 1.0), "be 0 or 1")
        check_limits(self, "Temin", "Temax")
        for low, high in (("p1", "p2"), ("p2", "p3"), ("p3", "p4")):
            check_limits(self, low, high)

    @property
    def base_ratio(self) -> float:
        """Sn / Sb: a power or torque on the turbine's base times this is on the system base."""
        return self.Sn / self.Sb

    @property
    def torque_limits(self) -> tuple:
        """(Temin, Temax) on the system base."""
        return self.Temin * self.base_ratio, self.Temax * self.base_ratio

    def speed_of_power(self, m, power):
        """fPe: the speed reference [pu] at a power [pu, system base]."""
        points = tuple(getattr(self, f"p{i}") * self.base_ratio for i in range(1, 5))
        return piecewise_linear(m, power, points, tuple(getattr(self, f"sp{i}") for i in range(1, 5)))


def _signals(x, u, p: WTTQA1Params, m) -> tuple:
    """(ds1_y/dt, ds2_y/dt, Tsel, PI_y) at x, u."""
    s1, s2_y, PI_xi, Pref0 = x
    Pe, wg = u[0], u[1]
    d_s1, s1_y = lag(m, Pe, s1, 1.0, p.Tp)
    d_s2, _ = lag(m, p.speed_of_power(m, s1_y), s2_y, 1.0, p.Twref)
    Tsel = (Pe - Pref0) / wg if p.Tflag else s2_y - wg
    low, high = p.torque_limits
    return d_s1, d_s2, Tsel, clip(m, p.Kpp * Tsel + PI_xi, low, high)


def derivatives(x, u, p: WTTQA1Params, m):
    """(ds1_y, ds2_y, dPI_xi, dPref0)/dt for x = (s1_y, s2_y, PI_xi, Pref0), u = (Pe, wg, Pext)."""
    d_s1, d_s2, Tsel, _ = _signals(x, u, p, m)
    low, high = p.torque_limits
    return d_s1, d_s2, integrator_non_windup(m, Tsel, x[2], p.Kip, 1.0, low, high)[0], 0.0 * x[3]


def reset(x, u, p: WTTQA1Params, m):
    """x after the reset of PI_xi's non-windup limits [Temin, Temax] (blocks.non_windup_reset)."""
    Tsel = _signals(x, u, p, m)[2]
    low, high = p.torque_limits
    return x[0], x[1], integrator_non_windup_reset(m, Tsel, x[2], p.Kip, 1.0, low, high), x[3]


def outputs(x, u, p: WTTQA1Params, m):
    """(Pref,) [pu, system base]: PI_y wg plus the plant controller's change Pext - Pref0."""
    return (_signals(x, u, p, m)[3] * u[1] + u[2] - x[3],)


def _start(given, p: WTTQA1Params) -> tuple:
    Pe = float(given["Pe"])
    Pref = float(given.get("Pref", Pe))
    wg = p.speed_of_power(math, Pe)
    low, high = p.torque_limits
    if not low <= Pref / wg <= high:
        raise ValueError(f"WTTQA1: the torque {Pref / wg:.6g} pu of its power reference at the speed {wg:.6g} pu "
                         f"lies outside [Temin, Temax]")
    return np.array([Pe, wg, Pref / wg, Pref]), {"wg": wg, "Pext": Pref}


def equilibrium(u, p: WTTQA1Params) -> np.ndarray:
    """The steady state [4] at constant (Pe, wg, Pext): the filters at their inputs, Pref0 = Pe, the PI's
    integrator on the limit its input drives it to where that input is not 0, else at the torque
    Pe / wg (its reference the power delivered) within the limits."""
    Pe, wg, _ = finite_inputs(u, "WTTQA1")
    if not wg > 0:
        raise ValueError(f"WTTQA1: no steady state at the generator speed {wg:.6g} pu")
    x = np.array([Pe, p.speed_of_power(math, Pe), 0.0, Pe])
    rate = p.Kip * _signals(x, (Pe, wg), p, math)[2]
    low, high = p.torque_limits
    x[2] = high if rate > 0 else low if rate < 0 else min(max(Pe / wg, low), high)
    return x


WTTQA1 = Component(
    name="wttqa1",
    description="WTTQA1 torque controller of a type-3 wind turbine (PSS/E, WECC WTGTRQ_A, ANDES)",
    states=(Quantity("s1_y", "pu", "filtered active power (system base)"),
            Quantity("s2_y", "pu", "speed reference (filtered power-speed characteristic)"),
            Quantity("PI_xi", "pu", "torque PI integrator (non-windup, system base)"),
            Quantity("Pref0", "pu", "active power reference at the start (held, system base)")),
    inputs=(Quantity("Pe", "pu", "the converter's active power (system base)", start=0.5, operating_range=(0.0, 1.0)),
            Quantity("wg", "pu", "generator speed", start=0.79, operating_range=(0.6, 1.2), minimum=0.0),
            Quantity("Pext", "pu", "the plant controller's active power reference (system base)", start=0.5,
                     operating_range=(0.0, 1.0))),
    outputs=(Quantity("Pref", "pu", "active power reference of the electrical controller (system base)"),),
    params_type=WTTQA1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.05, 0.1, 0.1),
    reset=reset,
    ports=Ports(inputs=(Link("active_power", "Pe"), Link("generator_speed", "wg"),
                        Link("active_power_reference", "Pext")),
                outputs=(Link("active_power_reference", "Pref"),)),
    initialisation=Initialisation(("wg", "Pext"), _start),
)
