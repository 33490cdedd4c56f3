"""The reachable-state envelope a co-simulation operator must cover, measured rather than guessed.

The envelope holds the component's state at rest on a grid over its inputs' level ranges (SM4:
Vs in [0.7, 1.2] pu, theta_vs in [-0.5, 0.5] rad, Pm and Efd in the preset's levels; below the
lowest voltage with an equilibrium, the one there), and every probe state. A probe is one reference window started at rest under the
signal's first input value, under a signal of one family: the states a machine at rest reaches within one window when the bus voltage
moves the way that family moves it. The envelope is the bounding box of every probe state; the
probe states themselves are the pool that reachable initial conditions are drawn from.
"""
from __future__ import annotations

import numpy as np
from scipy.stats import qmc

from reference_models.component import Component
from reference_models.families import default_levels, family


def probe_plan(families, per_family: int, horizon: float, rng: np.random.Generator, model: Component, params,
               levels: dict | None = None):
    """Initial states x0 [n, n_x], signals [n] and family names [n] of the probe windows of the
    component `model` with parameters `params`: x0 is the state at rest under the signal's u(0)
    (Component.rest_state), or the state a recorded signal comes with (Signal.x0)."""
    x0s, signals, names = [], [], []
    for name, _ in families:
        fam = family(name)
        for signal in fam.sample(qmc.LatinHypercube(d=fam.dim, rng=rng).random(per_family), horizon, levels, params):
            x0s.append(np.asarray(signal.x0) if signal.x0 is not None else model.rest_state(signal.at(0.0), params))
            signals.append(signal)
            names.append(name)
    return np.array(x0s), signals, names


def equilibria(model: Component, params, levels: dict | None = None, points: int = 625) -> np.ndarray:
    """States at rest [n^n_u, n_x] on a grid over each input's level range (`levels`, default the
    operating ranges), n points per input (n^n_u about `points`, at least 3)."""
    levels = {**default_levels(model), **(levels or {})}
    n = max(3, int(round(points ** (1.0 / model.n_inputs))))
    axes = [np.linspace(*levels[q.name], n) for q in model.inputs]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, model.n_inputs)
    return np.array([model.rest_state(u, params) for u in grid])


def reachable_summary(x: np.ndarray, names, model: Component, params, levels: dict | None = None) -> dict:
    """Ranges [state -> (min, max)] of the states at rest and the probe trajectories x [n, S, n_x],
    overall and per family."""

    def ranges(block):
        flat = block.reshape(-1, model.n_states)
        return {s: [float(flat[:, i].min()), float(flat[:, i].max())] for i, s in enumerate(model.state_names)}

    names = np.asarray(names)
    rest = equilibria(model, params, levels)
    return {
        "all": ranges(np.concatenate([rest, x.reshape(-1, model.n_states)])),
        "equilibria": ranges(rest),
        "per_family": {f: ranges(x[names == f]) for f in dict.fromkeys(names.tolist())},
        "probes": int(len(x)),
    }


def reachable_box(summary: dict) -> dict:
    """The initial-condition box [state -> (low, high)] spanned by the probes."""
    return {s: tuple(r) for s, r in summary["all"].items()}
