"""Reference-solve throughput: serial in-process vs a local dask cluster, on the same trajectories.

    python benchmarks/datagen.py [--n 120] [--workers 1 2] [--preset paper]

Prints trajectories per second (cluster start-up excluded and included) and the speedup over
serial, all measured in this one run.
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

from reference_models.sm4 import SM4
from surrogate.data.datasets import time_grid
from surrogate.data.envelope import equilibria
from surrogate.data.presets import preset
from surrogate.data.runner import SolveRunner
from surrogate.data.sampling import sample_split


def timed_run(workers: int, chunks: dict, t, solver) -> tuple[float, float, np.ndarray]:
    """(seconds solving, seconds including start-up, states) for one runner."""
    results = {}
    start = time.perf_counter()
    with SolveRunner(workers) as runner:
        ready = time.perf_counter()
        runner.run(chunks, t, solver, lambda key, x: results.__setitem__(key, x), SM4, SM4.params())
        solved = time.perf_counter()
    return solved - ready, solved - start, np.concatenate([results[k] for k in sorted(results)])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=120, help="trajectories (default 120)")
    parser.add_argument("--preset", default="paper", help="families and box of this preset (default paper)")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="dask cluster sizes")
    parser.add_argument("--chunk", type=int, default=10, help="trajectories per task (default 10)")
    args = parser.parse_args()

    recipe = preset(args.preset)
    if recipe.ic == "box":
        box = recipe.ic_box
    else:  # initial states among the equilibria: enough to time the solves without a probe run
        rest = equilibria(SM4, SM4.params(), recipe.levels)
        box = {name: (rest[:, i].min(), rest[:, i].max()) for i, name in enumerate(SM4.state_names)}
    x0, signals, _ = sample_split(args.n, recipe.families, box, recipe.horizon, np.random.default_rng(0),
                                  levels=recipe.levels)
    t = time_grid(recipe)
    chunks = {f"c{k:05d}": (x0[i:i + args.chunk], [s.to_dict() for s in signals[i:i + args.chunk]])
              for k, i in enumerate(range(0, args.n, args.chunk))}

    rows = []
    serial_s, _, reference = timed_run(0, chunks, t, recipe.solver)
    rows.append(("serial (in process)", serial_s, serial_s))
    for w in args.workers:
        solve_s, total_s, x = timed_run(w, chunks, t, recipe.solver)
        if not np.array_equal(x, reference):
            raise SystemExit(f"dask with {w} workers gave different states than serial")
        rows.append((f"dask LocalCluster, {w} worker{'s' * (w > 1)}", solve_s, total_s))

    print(f"{args.n} trajectories of the {args.preset!r} families, T = {recipe.horizon} s, {t.size} points, "
          f"{recipe.solver.method} rtol {recipe.solver.rtol:g} atol {recipe.solver.atol:g}, "
          f"{os.cpu_count()} CPUs")
    print(f"{'runner':<28}{'traj/s':>9}{'traj/s incl. start':>20}{'speedup':>9}")
    for name, solve_s, total_s in rows:
        print(f"{name:<28}{args.n / solve_s:>9.1f}{args.n / total_s:>20.1f}{serial_s / solve_s:>8.2f}x")


if __name__ == "__main__":
    main()
