"""Transient-stability measures of grid runs: the verdict of a run, the first-swing peak and the
critical clearing time (CCT) by bisection, for any runner (the co-simulation master with any FMU
kinds, the monolithic reference, ANDES' own simulation: cosim.runners).

A run is stable when no rotor-angle difference between two machines in service exceeds pi rad before
the run's stop time (docs/grid.md, "The coupling", Stability): the spread max(delta) - min(delta)
over the units whose bus device gives a rotor angle [rad] (GridResult.angles: the `rotor_angle`
signal of its ports, whatever its model; an inverter or a load gives none and is not judged), the
units a topology trips (`Topology.tripped`) left out from their trip on. A case without two machines
is judged stable. It is ANDES' own criterion (TDS `ddelta_limit` = 180 deg over every
synchronous generator). The CCT of a fault and its clearing action is the longest fault duration
after which the run is stable: bisection between a stable and an unstable clearing time to
`resolution` (1 ms by default), the bracket found by doubling the fault duration from 50 ms.

A first-swing loss shows within a second of the clearing; a slow inter-area mode (Kundur's two areas
swing at about 0.6 Hz) can lose synchronism on its second swing, 2-3 s after the clearing:
`default_stop` gives a run SECOND_SWING_S after the fault start.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from reference_models.grid.contingency import Contingency

FIRST_SWING_S = 1.0  # s after the clearing: the window of the first swing
SECOND_SWING_S = 4.0  # s after the fault start a stability run lasts (default_stop)


def default_stop(contingency: Contingency) -> float:
    """The stop time [s] of a stability run of `contingency`: its fault start (without a fault, its
    trip) plus SECOND_SWING_S, so that a loss on the second swing of an inter-area mode is seen."""
    start = contingency.fault_start if contingency.fault_bus is not None else (contingency.clear_s or 0.0)
    return round(start + SECOND_SWING_S, 9)


def in_service(result, contingency: Contingency, stop: float) -> np.ndarray:
    """[n, units] bool: whether each unit is in service at each row of `result` (False from the start
    of a topology that trips it, `contingency.topologies(stop)`)."""
    t = np.asarray(result.time, dtype=float)
    mask = np.ones((len(t), len(result.gen_buses)), dtype=bool)
    for tp in contingency.topologies(stop):
        if tp.tripped:
            rows = t >= tp.start - 1e-12
            mask[np.ix_(rows, list(tp.tripped))] = False
    return mask


def angle_spread(result, contingency: Contingency, stop: float) -> np.ndarray:
    """[n] rad: max - min of the rotor angles of the units in service at each row (0 with fewer than two)."""
    delta = np.asarray(result.angles, dtype=float)
    mask = in_service(result, contingency, stop) & np.isfinite(delta)
    high = np.where(mask, delta, -np.inf).max(axis=1)
    low = np.where(mask, delta, np.inf).min(axis=1)
    return np.where(mask.sum(axis=1) >= 2, high - low, 0.0)


def loss_of_synchronism(result, contingency: Contingency, stop: float) -> float | None:
    """The time [s] the spread of the rotor angles in service first exceeds pi (linear between the two
    rows around it), None if it never does."""
    spread = angle_spread(result, contingency, stop)
    beyond = np.flatnonzero(spread > math.pi)
    if not len(beyond):
        return None
    i = int(beyond[0])
    t = np.asarray(result.time, dtype=float)
    if i == 0 or spread[i] <= spread[i - 1]:
        return float(t[i])
    return float(t[i - 1] + (t[i] - t[i - 1]) * (math.pi - spread[i - 1]) / (spread[i] - spread[i - 1]))


def run_verdict(runner, contingency: Contingency, stop: float):
    """(stable, loss time [s] or None, GridResult) of one run of `contingency` to `stop` by `runner`
    (cosim.runners), ended early at a loss of synchronism. The verdict is this module's (units in
    service only): where the runner stopped at a spread that a tripped unit made, the run is made
    again to `stop` without the early end."""
    result, _ = runner.run(contingency, stop, stop_at_loss=True)
    lost = loss_of_synchronism(result, contingency, stop)
    if lost is None and result.time[-1] < stop - 1e-9 and result.loss_of_synchronism_s is not None:
        result, _ = runner.run(contingency, stop, stop_at_loss=False)
        lost = loss_of_synchronism(result, contingency, stop)
    return lost is None, lost, result


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
                           max_duration: float = 1.0, first_duration: float = 0.05,
                           guess: float | None = None) -> CCTResult:
    """The CCT of `contingency` (its clearing time is what varies) with `stable(contingency) ->
    bool` deciding each run (e.g. `runner_stable(runner, stop)`). With `guess` [s, absolute clearing
    time: another run kind's CCT], the bracket is sought from there on the grid of fault durations
    that are multiples of `resolution`, in steps of 4 resolutions that double until a stable and an
    unstable duration are found, and bisected on that grid: a few runs where the guess is close."""
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

    if guess is not None:
        return _from_guess(trial, start, guess, resolution, max_duration, runs)
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


def _from_guess(trial, start: float, guess: float, resolution: float, max_duration: float, runs: list) -> CCTResult:
    """critical_clearing_time from a guessed CCT, in whole resolutions of fault duration (0: no fault,
    stable; top: max_duration)."""
    top = max(1, int(math.floor(max_duration / resolution + 1e-9)))
    k = min(max(1, int(round((guess - start) / resolution))), top)
    lo, hi, width = None, None, 4
    if trial(k * resolution):
        lo = k
        while hi is None:
            if lo >= top:
                return CCTResult(round(start + top * resolution, 9), None, resolution, False, tuple(runs))
            k = min(lo + width, top)
            if trial(k * resolution):
                lo = k
            else:
                hi = k
            width *= 2
    else:
        hi = k
        while lo is None:
            k = max(hi - width, 0)
            if k == 0 or trial(k * resolution):
                lo = k
            else:
                hi = k
            width *= 2
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if trial(mid * resolution):
            lo = mid
        else:
            hi = mid
    if lo == 0:
        return CCTResult(None, round(start + resolution, 9), resolution, True, tuple(runs))
    return CCTResult(round(start + lo * resolution, 9), round(start + hi * resolution, 9), resolution, True,
                     tuple(runs))


def runner_stable(runner, stop: float | None = None):
    """`stable(contingency) -> bool` for critical_clearing_time: run_verdict of `runner` to `stop`
    [s] (None: default_stop of each contingency)."""
    def stable(contingency: Contingency) -> bool:
        end = stop if stop is not None else default_stop(contingency)
        return run_verdict(runner, contingency, end)[0]

    return stable
