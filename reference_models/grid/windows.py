"""The windows a machine FMU of a grid co-simulation would start, read off a monolithic run.

A surrogate FMU starts a window every time it rolls over and on both sides of every event. Taking
those windows from a monolithic simulation (monolithic.simulate with `event_rows`) gives, per
machine, what its operator is asked in the grid: the start state, the inputs at the operator's
sensor times, and the monolithic states over the window, which an operator evaluated open loop
under those inputs should reproduce. Angles in rad, speeds in rad/s, the rest in pu; times in s.
"""
from __future__ import annotations

import numpy as np

from .result import GridResult


def window_starts(result: GridResult, horizon: float, every: float, events=()) -> list:
    """Row indices of `result` where a window of `horizon` s starts: every `every` s and at each of
    the times `events` [s], always the later row of two at one time (the state after an event), and
    only where the whole window lies within the run. Needs rows every `every` s or finer."""
    t = result.time
    stop = float(t[-1])
    after = np.r_[np.diff(t) > 0, True]
    on_grid = np.abs(t / every - np.round(t / every)) < 1e-6
    at_event = np.zeros(t.shape, bool)
    for e in events:
        at_event |= np.abs(t - e) < 1e-9
    return [int(i) for i in np.nonzero((on_grid | at_event) & after & (t + horizon <= stop + 1e-9))[0]]


def machine_windows(result: GridResult, k: int, starts: list, sensor_times: np.ndarray, times: np.ndarray,
                    state_names, input_names):
    """(x0 [n, X], u [n, S, C], x [n, M, X]) of unit column k (generator order) for the windows
    starting at rows `starts`: the machine's states `state_names` (X) there, its inputs
    `input_names` (C, from result.machine_inputs) at the window times sensor_times [S] and its
    states at the window times `times` [M], interpolated linearly between rows (after any event at
    the start time)."""
    states = np.stack([result.states[n][:, k] for n in state_names], axis=1)
    inputs = np.stack([result.machine_inputs[n][:, k] for n in input_names], axis=1)
    x0 = states[starts]
    u = np.empty((len(starts), len(sensor_times), inputs.shape[1]))
    x = np.empty((len(starts), len(times), states.shape[1]))
    for j, i in enumerate(starts):
        rel = result.time[i:] - result.time[i]
        keep = np.r_[np.diff(rel) > 0, True]  # the row after each event (the row order puts it last)
        for c in range(inputs.shape[1]):
            u[j, :, c] = np.interp(sensor_times, rel[keep], inputs[i:, c][keep])
        for c in range(states.shape[1]):
            x[j, :, c] = np.interp(times, rel[keep], states[i:, c][keep])
    return x0, u, x
