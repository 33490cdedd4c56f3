"""The reachable-state envelope of SM4 a co-simulation operator must cover, measured rather than guessed.

The envelope holds every equilibrium for Vs in [lowest voltage with one, 1.2] pu and theta_vs in
[-0.5, 0.5] rad (below that lowest voltage there is none), and every probe state. A probe is one
reference window started at the equilibrium of the signal's first input value, under a
signal of one family: the states a machine at rest reaches within one window when the bus voltage
moves the way that family moves it. The envelope is the bounding box of every probe state; the
probe states themselves are the pool that reachable initial conditions are drawn from.
"""
from __future__ import annotations

import numpy as np
from scipy.stats import qmc

from reference_models.families import THETA_RANGE, VS_RANGE, family
from reference_models.scenarios import rest_state
from reference_models.sm4 import DEFAULT_PARAMS, STATE_NAMES, SM4Params, min_voltage_with_equilibrium, steady_state


def probe_plan(families, per_family: int, horizon: float, rng: np.random.Generator,
               params: SM4Params = DEFAULT_PARAMS):
    """Initial states x0 [n, 4], signals [n] and family names [n] of the probe windows of machine params.

    x0 is the equilibrium at the signal's u(0); where Vs(0) is below the lowest voltage with an
    equilibrium, the equilibrium at that lowest voltage (the closest state at rest).
    """
    x0s, signals, names = [], [], []
    for name, _ in families:
        fam = family(name)
        for signal in fam.sample(qmc.LatinHypercube(d=fam.dim, rng=rng).random(per_family), horizon):
            x0s.append(rest_state(*signal.at(0.0), params))
            signals.append(signal)
            names.append(name)
    return np.array(x0s), signals, names


def equilibria(n: int = 11, params: SM4Params = DEFAULT_PARAMS) -> np.ndarray:
    """Equilibrium states [n*n, 4] of machine params on a grid of Vs in [lowest with one, 1.2] pu x
    theta_vs in [-0.5, 0.5] rad."""
    grid = [(v, th) for v in np.linspace(min_voltage_with_equilibrium(params), max(VS_RANGE[1],
                                         min_voltage_with_equilibrium(params)), n)
            for th in np.linspace(*THETA_RANGE, n)]
    return np.array([steady_state(v, th, params) for v, th in grid])


def reachable_summary(x: np.ndarray, names, params: SM4Params = DEFAULT_PARAMS) -> dict:
    """Ranges [state -> (min, max)] of machine params' equilibria and the probe trajectories
    x [n, S, 4], overall and per family."""

    def ranges(block):
        flat = block.reshape(-1, 4)
        return {s: [float(flat[:, i].min()), float(flat[:, i].max())] for i, s in enumerate(STATE_NAMES)}

    names = np.asarray(names)
    rest = equilibria(params=params)
    return {
        "all": ranges(np.concatenate([rest, x.reshape(-1, 4)])),
        "equilibria": ranges(rest),
        "per_family": {f: ranges(x[names == f]) for f in dict.fromkeys(names.tolist())},
        "probes": int(len(x)),
        "min_voltage_with_equilibrium_pu": min_voltage_with_equilibrium(params),
    }


def reachable_box(summary: dict) -> dict:
    """The initial-condition box [state -> (low, high)] spanned by the probes."""
    return {s: tuple(r) for s, r in summary["all"].items()}
