"""Transient-stability measures of grid runs: the first-swing peak and the critical clearing time
(CCT) by bisection, for any runner (the co-simulation master with any FMU kinds, or the monolithic
reference).

A run is stable when no rotor-angle difference between two machines exceeds pi rad before the
run's stop time (docs/grid.md, "The coupling", Stability). The CCT of a fault and its clearing
action is the longest fault duration after which the run is stable: bisection between a stable and an unstable clearing time
to `resolution` (1 ms by default), the bracket found by doubling the fault duration from 50 ms.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from reference_models.grid.contingency import Contingency

FIRST_SWING_S = 1.0  # s after the clearing: the window of the first swing


def first_swing_peak(result, clear_s: float | None) -> float:
    """The largest |delta_i - delta_1| [rad] over the other machines within FIRST_SWING_S of the
    clearing (of the whole run without one)."""
    t = result.time
    end = (clear_s if clear_s is not None else 0.0) + FIRST_SWING_S
    rows = t <= end + 1e-12
    peaks = [np.max(np.abs(result.angle_difference(b)[rows])) for b in result.gen_buses[1:]]
    return float(max(peaks))


@dataclass(frozen=True)
class CCTResult:
    """cct_s [s, absolute clearing time]: the latest clearing found stable (None: even the earliest
    tried, fault_start + resolution, is unstable); bounded: False when every clearing time up to
    `max_duration` after the fault start was stable (cct_s is then that bound); runs: every
    (clearing time, stable) tried, in order."""

    cct_s: float | None
    unstable_s: float | None
    resolution_s: float
    bounded: bool
    runs: tuple = field(default_factory=tuple)

    def to_dict(self) -> dict:
        return {"cct_s": self.cct_s, "first_unstable_s": self.unstable_s, "resolution_s": self.resolution_s,
                "bounded": self.bounded, "runs": [{"clear_s": c, "stable": s} for c, s in self.runs]}


def critical_clearing_time(stable, contingency: Contingency, resolution: float = 1e-3,
                           max_duration: float = 1.0, first_duration: float = 0.05) -> CCTResult:
    """The CCT of `contingency` (its clearing time is what varies) with `stable(contingency) ->
    bool` deciding each run."""
    if contingency.fault_bus is None:
        raise ValueError("a critical clearing time needs a fault")
    if not (0 < resolution <= 0.1 and math.isfinite(resolution)):
        raise ValueError(f"the resolution must be a time in (0, 0.1] s, got {resolution!r}")
    start = contingency.fault_start
    runs = []

    def trial(duration: float) -> bool:
        clear = round(start + duration, 9)
        verdict = bool(stable(contingency.with_clearing(clear)))
        runs.append((clear, verdict))
        return verdict

    lo, hi = 0.0, None  # fault durations: lo stable (0: no fault at all), hi unstable
    d = min(first_duration, max_duration)
    while True:
        if trial(d):
            lo = d
            if d >= max_duration:
                return CCTResult(start + max_duration, None, resolution, False, tuple(runs))
            d = min(2.0 * d, max_duration)
        else:
            hi = d
            break
    slack = 1e-9 * resolution  # so rounding never repeats a trial
    while hi - lo > resolution + slack:
        mid = 0.5 * (lo + hi)
        if hi - lo < 2.0 * resolution:  # the last split lands one resolution above lo
            mid = lo + resolution
        if trial(mid):
            lo = mid
        else:
            hi = mid
    if lo == 0.0:  # unstable down to the resolution: check the shortest fault
        if trial(resolution):
            lo = resolution
        else:
            return CCTResult(None, start + resolution, resolution, True, tuple(runs))
    return CCTResult(round(start + lo, 9), round(start + hi, 9), resolution, True, tuple(runs))
