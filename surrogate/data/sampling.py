"""Latin hypercube sampling of initial states and input signals for one dataset split."""
from __future__ import annotations

import numpy as np
from scipy.stats import qmc

from reference_models.families import family
from reference_models.progress import progress_bar

SAMPLE_CHUNK = 50  # windows built between two progress updates (a `case-` window may run a grid)


def split_counts(n: int, weights) -> list[int]:
    """n split by weights, largest remainder first, so the counts add up to n exactly."""
    w = np.asarray(weights, dtype=float)
    raw = n * w / w.sum()
    counts = np.floor(raw).astype(int)
    for i in np.argsort(-(raw - counts), kind="stable")[: n - counts.sum()]:
        counts[i] += 1
    return counts.tolist()


def sample_split(n: int, families, ic_box: dict, horizon: float, rng: np.random.Generator,
                 pool: np.ndarray | None = None, pool_fraction: float = 0.0, levels: dict | None = None,
                 machine=None, progress: bool = False, desc: str = "sampling"):
    """Initial states x0 [n, n_x], signals [n] and family names [n] for one split; ic_box maps every
    state name, in the component's order, to its (low, high).

    Per family, one scrambled Latin hypercube spans the varying initial-state dimensions of ic_box
    and the family's parameters. With a pool of reachable states [P, n_x], a `pool_fraction` of the
    initial states is drawn from it instead. `levels` [input -> (low, high)]: the input level ranges
    (default: the component's operating ranges); `machine`: the component's parameters (the families
    that record a closed loop need them). A signal that brings its own initial state (Signal.x0)
    keeps it. Rows are shuffled so families interleave. With `progress`, a bar (or a line every few
    seconds) named `desc` counts the windows built: a family that records its windows from grid runs
    takes minutes.
    """
    lows, highs = np.array(list(ic_box.values()), dtype=float).T
    varying = np.nonzero(highs > lows)[0]
    x0_parts, signals, names = [], [], []
    bar = progress_bar(total=n, desc=desc, unit="window", enabled=progress)
    for (name, _), count in zip(families, split_counts(n, [w for _, w in families])):
        if count == 0:
            continue
        fam = family(name)
        unit = qmc.LatinHypercube(d=varying.size + fam.dim, rng=rng).random(count)
        x0 = np.tile(lows, (count, 1))
        x0[:, varying] = lows[varying] + unit[:, : varying.size] * (highs - lows)[varying]
        x0_parts.append(x0)
        for start in range(0, count, SAMPLE_CHUNK):
            chunk = unit[start:start + SAMPLE_CHUNK, varying.size:]
            signals += fam.sample(chunk, horizon, levels, machine)
            bar.update(len(chunk))
        names += [name] * count
    bar.close()
    x0 = np.concatenate(x0_parts)
    if pool is not None and pool_fraction > 0:
        chosen = rng.random(n) < pool_fraction
        x0[chosen] = pool[rng.integers(0, len(pool), chosen.sum())]
    for i, s in enumerate(signals):
        if s.x0 is not None:
            x0[i] = s.x0
    order = rng.permutation(n)
    return x0[order], [signals[i] for i in order], [names[i] for i in order]
