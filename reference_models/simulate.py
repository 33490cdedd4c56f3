"""RK45 reference simulation of a component under a time-varying input signal (scipy `solve_ivp`)."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.integrate import solve_ivp

from .signals import Signal
from .component import Component
from .sm4 import SM4


@dataclass(frozen=True)
class SolverConfig:
    """scipy solve_ivp settings; the defaults keep the reference well below any surrogate's error."""

    method: str = "RK45"
    rtol: float = 1e-8
    atol: float = 1e-10

    def __post_init__(self):
        if self.method not in ("RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA"):
            raise ValueError(f"unknown solve_ivp method {str(self.method)[:40]!r}")
        if not all(isinstance(v, (int, float)) and 0 < v < 1 for v in (self.rtol, self.atol)):
            raise ValueError(f"rtol and atol must be numbers in (0, 1), got {self.rtol!r}, {self.atol!r}")

    def to_dict(self) -> dict:
        return asdict(self)


def _scalar_rhs(u_of_t, component: Component, p):
    derivatives = component.derivatives

    def f(t, x):
        return derivatives(x, u_of_t(t), p, math)

    return f


def simulate(
    x0,
    signal: Signal,
    t_eval,
    p=None,
    solver: SolverConfig = SolverConfig(),
    component: Component = SM4,
) -> np.ndarray:
    """States x [S, n_x] at times t_eval [S] (ascending, from 0) for initial state x0 [n_x], with
    parameters p of `component` (default: its defaults).

    The solve restarts at every breakpoint of the signal, so jumps and kinks are never stepped over;
    a state at a jump time is the (continuous) state there.
    """
    t_eval = np.asarray(t_eval, dtype=float)
    horizon = float(t_eval[-1])
    edges = np.concatenate([[0.0], signal.breakpoints(horizon), [horizon]])
    p = component.params_type() if p is None else p
    x = np.empty((t_eval.size, component.n_states))
    state = np.asarray(x0, dtype=float)
    for start, stop in zip(edges[:-1], edges[1:]):
        inside = (t_eval >= start) & (t_eval <= stop)
        # the signal on [start, stop): evaluated just inside the segment so a jump at `stop` is not seen
        f = _scalar_rhs(_segment_input(signal, start, math.nextafter(stop, start)), component, p)
        # `stop` is always evaluated too: it is the next segment's initial state
        times = np.union1d(t_eval[inside], [stop])
        sol = solve_ivp(f, (start, stop), state, method=solver.method, t_eval=times,
                        rtol=solver.rtol, atol=solver.atol)
        if sol.status != 0 or not np.all(np.isfinite(sol.y)):
            raise RuntimeError(f"reference solve failed on [{start:.6g}, {stop:.6g}] s: {sol.message}")
        x[inside] = sol.y[:, np.searchsorted(times, t_eval[inside])].T
        state = sol.y[:, -1]
    return x


def _segment_input(signal: Signal, start: float, last: float):
    """u(t) for a solve on [start, stop]: the signal clamped to [start, last] so the value on the
    segment's right end is its left limit there."""

    if signal.hold > 0:  # held input: one value over the whole segment
        value = signal.at(start)
        return lambda t: value

    def u_of_t(t):
        return signal.at(min(max(t, start), last))

    return u_of_t


def simulate_many(x0s, signals, t_eval, p=None, solver: SolverConfig = SolverConfig(), component: Component = SM4):
    """States [N, S, n_x] for initial states x0s [N, n_x] and N signals (serial; see surrogate.data for dask)."""
    return np.stack([simulate(x0, s, t_eval, p, solver, component) for x0, s in zip(x0s, signals)])
