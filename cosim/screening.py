"""Contingency screening: many faults and clearing actions as independent runs, on a dask cluster
(a LocalCluster of single-threaded worker processes, or an existing scheduler), with a progress bar.

Each task is one contingency: its critical clearing time by bisection (stability.py), its verdict
when cleared at the screening's clearing time, and the first-swing peak of that run. FMUs are built
once, before any task is sent; a worker opens them once and reuses them for every task it gets
(the master rewinds them between runs).
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass

from reference_models.grid import wscc9
from reference_models.grid.contingency import Contingency

from .master import MasterSettings
from .stability import critical_clearing_time, first_swing_peak


@dataclass(frozen=True)
class ScreeningTask:
    """What a worker needs: the contingency (its clearing time is the screening's), the run kind
    and FMU files, the dynamic-data file, the master's settings and the CCT's stop and resolution."""

    contingency: Contingency
    kind: str
    files: tuple
    dynamic_data: str | None
    settings: MasterSettings
    stop: float
    resolution: float


def contingencies(buses, trips: str = "each") -> list:
    """Faults at `buses`, each without a trip and (trips "each") with every branch at the bus that
    can open without cutting a generator off; clearing times are set per screening."""
    out = []
    for bus in buses:
        wscc9.bus_index(bus)
        out.append((bus, None))
        if trips == "each":
            out += [(bus, t) for t in wscc9.trips_at(bus)]
    return out


_RUNNERS = {}


def _runner(task: ScreeningTask):
    """A runner per (kind, files, dynamic data, settings), opened once per worker process."""
    from .runners import MasterRunner, MonolithicRunner, load_grid

    key = (task.kind, task.files, task.dynamic_data, task.settings)
    if key not in _RUNNERS:
        grid = load_grid(task.dynamic_data)
        _RUNNERS[key] = (MonolithicRunner(grid, task.settings.step, 1e-9) if task.kind == "monolithic"
                         else MasterRunner(task.files, grid, task.settings))
    return _RUNNERS[key]


def screen_one(task: ScreeningTask) -> dict:
    """The row of one contingency: label, bus, trip, clear_s, stable, first_swing_peak_deg, cct_s,
    bounded, runs."""
    runner = _runner(task)
    c = task.contingency
    result, _ = runner.run(c, task.stop, stop_at_loss=True)
    peak = math.degrees(first_swing_peak(result, c.clear_s))

    def stable(contingency):
        return runner.run(contingency, task.stop, stop_at_loss=True)[0].stable

    cct = critical_clearing_time(stable, c, task.resolution)
    return {"label": c.label, "bus": c.fault_bus, "trip": c.trip or "", "clear_s": c.clear_s,
            "stable": bool(result.stable), "first_swing_peak_deg": peak if result.stable else None,
            "cct_s": cct.cct_s, "bounded": cct.bounded, "runs": len(cct.runs) + 1}


def screen(tasks, workers: int = 2, scheduler: str | None = None, progress: bool = True) -> list:
    """The rows of every task (in the tasks' order), run on dask: `scheduler` (an address) or a
    LocalCluster of `workers` processes (0: in this process, no dask)."""
    from tqdm import tqdm

    bar = tqdm(total=len(tasks), desc="contingencies", unit="run", disable=not progress)
    rows = [None] * len(tasks)
    try:
        if not scheduler and workers == 0:
            for i, task in enumerate(tasks):
                rows[i] = screen_one(task)
                bar.update()
            return rows
        from dask.distributed import Client, LocalCluster, as_completed

        cluster = None
        if scheduler:
            client = Client(scheduler, timeout="20s")
        else:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                                   silence_logs=logging.CRITICAL)
            client = Client(cluster)
        try:
            futures = {client.submit(screen_one, task, pure=False): i for i, task in enumerate(tasks)}
            for future in as_completed(futures):
                rows[futures[future]] = future.result()
                bar.update()
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
        return rows
    finally:
        bar.close()
