"""TG2: the turbine-governor of Milano's book (ANDES TG2), as ANDES 2.0.0 computes it.

States  x = (ll_x [pu] lead-lag state)
Inputs  u = (omega [pu] rotor speed, Pref [pu] power reference: ANDES' pref0, the mechanical
        power at rest at omega = wref0)
Outputs y = (Pm [pu] mechanical power)

Equations (ANDES 2.0 model reference, TurbineGov: TG2):

    w_d = wref0 - omega                                  (positive for under-speed)
    w_dm = w_d where w_d > dbu or w_d < dbl, else 0       (deadband = 1: a dead band that steps)
    w_dm = 0                                             (deadband = 0, ANDES' default)
    lead-lag (1 + s T1) / (1 + s T2) of w_dm / R (T2 = 0: a gain of 1) -> ll_y
    Pm = Pref + ll_y, clipped to [pmin, pmax] (hardlimit = 1, windup limiter; 0: not clipped)

ANDES' configuration of the model enters as two parameters with its defaults: `deadband` (0) and
`hardlimit` (1). With the dead band disabled, as in ANDES' default configuration, ANDES' dead band
flags stay at "inside the band" and its TG2 takes no speed signal at all: its output is Pref, held
(ANDES' pjm5bus case runs so). ANDES' return flags of the dead band never leave 0 in 2.0.0, so its
outputs dbl, dbu on return are absent, and its neutral value dbc is not used (not a parameter here).

Bases: R, pmax, pmin, Pref and Pm on the turbine's base, which the integration takes as the
machine's base Sn (ANDES' default when Tn is not given); ANDES converts them to the system base,
where its equations are the same.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blocks import clip, lead_lag, step_dead_band
from ..component import Parameters, Quantity
from .common import check_limits, check_ranges, finite_inputs
from .tgov1 import turbine_governor

PARAMETER_RANGES = {"R": (0.001, 10.0, "pu"), "dbl": (-1.0, 0.0, "pu"), "dbu": (0.0, 1.0, "pu"),
                    "T1": (0.0, 100.0, "s"), "T2": (0.0, 100.0, "s"), "wref0": (0.5, 1.5, "pu")}


@dataclass(frozen=True)
class TG2Params(Parameters):
    """ANDES TG2 data: droop R [pu], output limits pmax, pmin [pu], dead band dbl, dbu [pu speed],
    lead-lag time constants T1, T2 [s], speed reference wref0 [pu]; ANDES' configuration: deadband
    (1 enables the dead band, 0 as ANDES' default: no speed signal), hardlimit (1 clips the output,
    ANDES' default)."""

    R: float = 0.05
    pmax: float = 999.0
    pmin: float = 0.0
    dbl: float = -0.0001
    dbu: float = 0.0001
    T1: float = 0.2
    T2: float = 10.0
    wref0: float = 1.0
    deadband: float = 0.0
    hardlimit: float = 1.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "pmin", "pmax")
        self.require("deadband", self.deadband in (0.0, 1.0), "be 0 (no speed signal, ANDES' default) or 1")
        self.require("hardlimit", self.hardlimit in (0.0, 1.0), "be 0 or 1 (output clipped, ANDES' default)")


def _speed_signal(omega, p: TG2Params, m):
    """w_dm / R: the speed deviation after the dead band, over the droop [pu power]."""
    if p.deadband == 0.0:
        return 0.0 * omega
    return step_dead_band(m, p.wref0 - omega, p.dbl, p.dbu) / p.R


def _limited(m, power, p: TG2Params):
    return clip(m, power, p.pmin, p.pmax) if p.hardlimit == 1.0 else power


def derivatives(x, u, p: TG2Params, m):
    """(dll_x/dt,) for x = (ll_x,), u = (omega, Pref)."""
    return (lead_lag(m, _speed_signal(u[0], p, m), x[0], 1.0, p.T1, p.T2)[0],)


def outputs(x, u, p: TG2Params, m):
    """(Pm,) = Pref + ll_y, limited."""
    omega, Pref = u
    _, ll_y = lead_lag(m, _speed_signal(omega, p, m), x[0], 1.0, p.T1, p.T2)
    return (_limited(m, Pref + ll_y, p),)


def equilibrium(u, p: TG2Params) -> np.ndarray:
    """The steady state [1] at constant (omega, Pref): the lead-lag at its input."""
    omega, _ = finite_inputs(u, "TG2")
    return np.array([_speed_signal(omega, p, np)])


def start(given, p: TG2Params) -> tuple:
    """(x0 [1], {"Pref": ...}): at rest at speed given["omega"] giving Pm = given["Pm"] (ANDES:
    pref0 = tm0 at omega = wref0); ValueError outside [pmin, pmax]."""
    omega, Pm = float(given["omega"]), float(given["Pm"])
    if p.hardlimit == 1.0 and not p.pmin <= Pm <= p.pmax:
        raise ValueError(f"TG2: the mechanical power {Pm:.6g} pu lies outside [pmin, pmax]")
    ll = float(_speed_signal(omega, p, np))
    return np.array([ll]), {"Pref": Pm - ll}


TG2 = turbine_governor(
    "tg2", "TG2 turbine-governor (Milano; ANDES 2.0.0)",
    states=(Quantity("ll_x", "pu", "lead-lag state"),),
    reference=Quantity("Pref", "pu", "power reference (mechanical power at rest at wref0)", start=0.7,
                       operating_range=(0.0, 1.2)),
    params_type=TG2Params, state_scales=(0.2,),
    derivatives=derivatives, outputs=outputs, equilibrium=equilibrium, start=start)
