"""What each WSCC 9-bus machine sees in the grid issue's contingencies: the envelopes to train on.

    python benchmarks/wscc9_envelope.py [--workers 2] [--stop 5] [--out benchmarks/wscc9_envelope.json]

Contingencies (issue 17): a bolted fault at each bus 4..9 from t = 0, cleared after 3, 4, 5 or 6
cycles (50, 67, 83, 100 ms), without a trip and with each branch at the faulted bus opened at
clearing (those that would cut a generator off are skipped), 5 s each, exciters in; the
monolithic reference (reference_models.grid.monolithic, DOP853 at rtol 1e-10), sampled every 1 ms
plus both sides of every event.

Recorded per machine, over the stable runs and separately over all runs (unstable ones included):
* min/max of Vs (its bus voltage magnitude), Efd, Pm (held), omega, delta - theta_vs (the rotor
  angle relative to its bus angle, wrapped to (-pi, pi]) and the largest |omega| (the common drift
  speed, which with no governors and D = 0 the machines keep after a fault);
* in the frame of a window of T = 1 s started at any t0 on a 10 ms grid (both sides of the fault
  at t0 = 0), over s in [0, T] (reference_models/drift.py: a = theta_vs(t0), c = omega(t0)):
  omega(t0+s) - omega(t0) (min/max and max |.|), theta_vs(t0+s) - theta_vs(t0) - omega(t0) s,
  delta(t0+s) - delta(t0) - omega(t0) s, and delta(t0+s) - theta_vs(t0) - omega(t0) s (the
  rotor angle in the window's frame, the state the operator starts from and reaches).

Prints a table per contingency and the envelope per machine; writes the JSON (atomic) that sets
the training envelopes. Runs on a dask LocalCluster of --workers single-threaded processes
(--workers 0: a plain loop in this process).
"""
from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from reference_models.files import write_json
from reference_models.grid import monolithic, wscc9
from reference_models.grid.contingency import BOLTED_FAULT_IMPEDANCE, Contingency
from reference_models.progress import progress_bar
from reference_models.version import __version__

FAULT_BUSES = (4, 5, 6, 7, 8, 9)
CLEARING_CYCLES = (3, 4, 5, 6)
WINDOW_S = 1.0
WINDOW_GRID_S = 0.01
SAMPLE_S = 0.001
STATIC = ("Vs", "Efd", "Pm", "omega", "delta_minus_theta_vs")
WINDOWED = ("omega_change", "theta_vs_frame", "delta_change_frame", "delta_in_window_frame")


def contingencies() -> list:
    """(fault bus, clearing cycles, trip or None) of every run."""
    return [(bus, cycles, trip) for bus in FAULT_BUSES for cycles in CLEARING_CYCLES
            for trip in (None,) + wscc9.NETWORK.trips_at(bus)]


def window_starts(time_s: np.ndarray, stop: float) -> np.ndarray:
    """Rows that start a window: times on the 10 ms grid up to stop - T (both rows where an event
    time is on the grid: the state before and after it)."""
    on_grid = np.abs(time_s / WINDOW_GRID_S - np.round(time_s / WINDOW_GRID_S)) < 1e-6
    return np.nonzero(on_grid & (time_s <= stop - WINDOW_S + 1e-9))[0]


def window_ranges(time_s, omega, theta, delta, stop: float) -> dict:
    """Per machine [3] min and max over all windows of the window-frame quantities (module docstring)."""
    ends = np.searchsorted(time_s, time_s + WINDOW_S + 1e-9, side="right")
    low = {name: np.full(omega.shape[1], np.inf) for name in WINDOWED}
    high = {name: np.full(omega.shape[1], -np.inf) for name in WINDOWED}
    for j in window_starts(time_s, stop):
        rows = slice(j, ends[j])
        s = (time_s[rows] - time_s[j])[:, None]
        drift = omega[j] * s
        values = {"omega_change": omega[rows] - omega[j],
                  "theta_vs_frame": theta[rows] - theta[j] - drift,
                  "delta_change_frame": delta[rows] - delta[j] - drift,
                  "delta_in_window_frame": delta[rows] - theta[j] - drift}
        for name, v in values.items():
            low[name] = np.minimum(low[name], v.min(axis=0))
            high[name] = np.maximum(high[name], v.max(axis=0))
    return {name: (low[name], high[name]) for name in WINDOWED}


def run_one(case: tuple, stop: float) -> dict:
    """One contingency: its verdict, first swing and per-machine ranges (plain floats)."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    bus, cycles, trip = case
    started = time.perf_counter()
    t_eval = np.linspace(0.0, stop, int(round(stop / SAMPLE_S)) + 1)
    r = monolithic.simulate(monolithic.System(wscc9.case()), Contingency(bus, cycles / 60.0, trip), stop, t_eval=t_eval,
                            event_rows=True)
    solved = time.perf_counter()
    static = {"Vs": r.Vs, "Efd": r.Efd, "Pm": r.machine_inputs["Pm"], "omega": r.omega,
              "delta_minus_theta_vs": r.delta - r.theta_vs}
    windows = window_ranges(r.time, r.omega, r.theta_vs, r.delta, stop)
    machines = {}
    for k, gen in enumerate(r.gen_buses):
        entry = {name: [float(v[:, k].min()), float(v[:, k].max())] for name, v in static.items()}
        entry["omega_abs_max"] = float(np.abs(r.omega[:, k]).max())
        for name, (lo, hi) in windows.items():
            entry[name] = [float(lo[k]), float(hi[k])]
        entry["omega_change_abs_max"] = float(max(-windows["omega_change"][0][k], windows["omega_change"][1][k]))
        machines[str(gen)] = entry
    differences = np.degrees(r.delta[:, 1:] - r.delta[:, :1])
    until = r.time <= (r.loss_of_synchronism_s if r.loss_of_synchronism_s is not None else stop)
    return {"fault_bus": bus, "clear_cycles": cycles, "clear_s": cycles / 60.0, "trip": trip,
            "stable": r.stable, "loss_of_synchronism_s": r.loss_of_synchronism_s,
            "first_swing_deg": {f"delta{g}-delta1": float(differences[until, i][np.argmax(np.abs(differences[until, i]))])
                                for i, g in enumerate(r.gen_buses[1:])},
            "max_speed_rad_s": float(np.abs(r.omega).max()),
            "machines": machines, "n_rhs": int(r.n_rhs),
            "solve_s": solved - started, "wall_s": time.perf_counter() - started}


def envelope(records: list) -> dict:
    """Per machine, the union of the runs' ranges (maxima for the |.| entries)."""
    out = {}
    for gen in map(str, wscc9.GENERATOR_BUSES):
        entries = [rec["machines"][gen] for rec in records]
        if not entries:
            out[gen] = None
            continue
        merged = {}
        for name, value in entries[0].items():
            if isinstance(value, list):
                merged[name] = [min(e[name][0] for e in entries), max(e[name][1] for e in entries)]
            else:
                merged[name] = max(e[name] for e in entries)
        out[gen] = merged
    return out


def solve_all(cases: list, workers: int, stop: float) -> tuple:
    """(records in case order, seconds to start the cluster)."""
    bar = progress_bar(len(cases), "wscc9 contingencies", "run")
    records = [None] * len(cases)
    if workers <= 0:
        for i, case in enumerate(cases):
            records[i] = run_one(case, stop)
            bar.update(1)
        bar.close()
        return records, 0.0
    from dask.distributed import Client, LocalCluster, as_completed

    os.environ["OMP_NUM_THREADS"] = "1"
    started = time.perf_counter()
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        startup = time.perf_counter() - started
        futures = {client.submit(run_one, case, stop, pure=False): i for i, case in enumerate(cases)}
        for future in as_completed(futures):
            records[futures[future]] = future.result()
            bar.update(1)
    bar.close()
    return records, startup


def _range(values, digits=4) -> str:
    lo, hi = values
    return f"{lo:+.{digits}f} .. {hi:+.{digits}f}"


def print_tables(records: list, env: dict) -> None:
    print(f"\n{'bus':>3} {'clear':>6} {'trip':>5} {'stable':>6} {'d2-d1 peak':>10} {'d3-d1 peak':>10} "
          f"{'max|w|':>7} {'lost at':>7} {'solve':>6}")
    for rec in records:
        swing = rec["first_swing_deg"]
        lost = f"{rec['loss_of_synchronism_s']:.3f}" if rec["loss_of_synchronism_s"] is not None else "-"
        print(f"{rec['fault_bus']:>3} {1000 * rec['clear_s']:>4.0f}ms {rec['trip'] or '-':>5} "
              f"{'yes' if rec['stable'] else 'NO':>6} {swing['delta2-delta1']:>10.1f} {swing['delta3-delta1']:>10.1f} "
              f"{rec['max_speed_rad_s']:>7.2f} {lost:>7} {rec['solve_s']:>5.2f}s")
    names = [("Vs [pu]", "Vs"), ("Efd [pu]", "Efd"), ("Pm [pu]", "Pm"), ("omega [rad/s]", "omega"),
             ("delta - theta_vs [rad]", "delta_minus_theta_vs"),
             ("window: omega(t0+s) - omega(t0)", "omega_change"),
             ("window: theta_vs - theta_vs(t0) - omega(t0)s", "theta_vs_frame"),
             ("window: delta - delta(t0) - omega(t0)s", "delta_change_frame"),
             ("window: delta - theta_vs(t0) - omega(t0)s", "delta_in_window_frame")]
    for subset in ("stable", "all"):
        print(f"\nEnvelope per machine, {subset} runs (window T = {WINDOW_S} s, t0 every {1000 * WINDOW_GRID_S:.0f} ms)")
        print(f"{'quantity':<46}" + "".join(f"{'machine ' + g:>26}" for g in env[subset]))
        for label, key in names:
            print(f"{label:<46}" + "".join(f"{_range(env[subset][g][key]):>26}" for g in env[subset]))
        for label, key in (("max |omega| [rad/s]", "omega_abs_max"),
                           ("window: max |omega(t0+s) - omega(t0)|", "omega_change_abs_max")):
            print(f"{label:<46}" + "".join(f"{env[subset][g][key]:>26.4f}" for g in env[subset]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2, help="dask worker processes (0: a plain loop; default 2)")
    parser.add_argument("--stop", type=float, default=5.0, help="simulated seconds per run (default 5)")
    parser.add_argument("--out", type=Path, default=Path(__file__).with_suffix(".json"), help="JSON written")
    args = parser.parse_args()

    started = time.perf_counter()
    cases = contingencies()
    records, startup = solve_all(cases, args.workers, args.stop)
    wall = time.perf_counter() - started
    stable = [r for r in records if r["stable"]]
    env = {"stable": envelope(stable), "all": envelope(records)}
    print_tables(records, env)
    print(f"\n{len(records)} runs ({len(stable)} stable) of {args.stop:g} s in {wall:.1f} s wall "
          f"({args.workers} workers, cluster start {startup:.1f} s; {sum(r['wall_s'] for r in records):.1f} s in runs)")
    case = wscc9.case()
    grid = monolithic.System(case)
    write_json(args.out, {
        "description": "What each WSCC 9-bus machine sees in the grid issue's contingencies (see "
                       "benchmarks/wscc9_envelope.py): per machine (generator bus) min/max over the stable runs "
                       "and over all runs; angles rad, speeds rad/s deviation, voltages pu.",
        "settings": {"case": "wscc9", "fault_buses": list(FAULT_BUSES), "clearing_cycles": list(CLEARING_CYCLES),
                     "clearing_s": [c / 60.0 for c in CLEARING_CYCLES], "fault_start_s": 0.0,
                     "fault_impedance_pu": BOLTED_FAULT_IMPEDANCE, "trips": "none, or each branch at the "
                     "faulted bus that keeps every generator connected", "stop_s": args.stop, "exciters": True,
                     "solver": "DOP853 rtol 1e-10 atol 1e-12", "sample_s": SAMPLE_S, "window_s": WINDOW_S,
                     "window_start_grid_s": WINDOW_GRID_S,
                     "stability": "no rotor-angle difference between two machines exceeds pi before stop"},
        "operating_point": {str(g.bus): {"Pm": case.starts[k][0].inputs["Pm"], "Efd0": case.starts[k][0].inputs["Efd"],
                                         "Vref": case.starts[k][1].inputs["Vref"],
                                         "x0": [float(v) for v in grid.x0[grid.slices[k][0]]],
                                         "machine_file": f"reference_models/grid/data/{g.machine.source.name}"}
                            for k, g in enumerate(case.units)},
        "envelope": env,
        "counts": {"runs": len(records), "stable": len(stable)},
        "contingencies": records,
        "timing": {"wall_s": wall, "cluster_start_s": startup, "workers": args.workers,
                   "sum_run_s": sum(r["wall_s"] for r in records)},
        "environment": {"opfmu_version": __version__, "python": sys.version.split()[0],
                        "machine": platform.machine(), "cpus": os.cpu_count()},
    })
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
