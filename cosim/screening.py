"""Contingency screening: many faults and clearing actions as independent runs, on a dask cluster
(a LocalCluster of single-threaded worker processes, or an existing scheduler), with a progress
report (a bar on a terminal, a line every few seconds otherwise: reference_models.progress).

Each task is one contingency: its critical clearing time by bisection (stability.py), its verdict
when cleared at the screening's clearing time, and the first-swing peak of that run; a task runs
FMUs through the master, the monolithic DAE or ANDES' own simulation (kind "andes", where installed).
The default faults of a case (`default_fault_buses`) are its buses without a generator: wscc9's
4-9, Kundur's 5-10 (the two areas and the tie), and for ieee14, ieee39 and npcc every load and
transmission bus; a fault at a generator's own terminal is left out (a screening names it if wanted). FMUs are built
once, before any task is sent; a worker opens them once and reuses them for every task it gets
(the master rewinds them between runs). They are extracted under one scratch folder of the
screening (also the local workers' own folder), removed at its end whatever happened (also on an
interrupt); local workers ignore Ctrl-C, so an interrupt is reported once, by the command.
"""
from __future__ import annotations

import logging
import math
import shutil
import signal
import tempfile
import warnings
from dataclasses import dataclass

from reference_models.grid.contingency import Contingency

from .master import MasterSettings
from .stability import critical_clearing_time, default_stop, first_swing_peak, run_verdict, runner_stable

@dataclass(frozen=True)
class ScreeningTask:
    """What a worker needs: the case, the contingency (its clearing time is the screening's), the run
    kind ("monolithic", "andes" or an FMU kind) and FMU files (cosim.fmus.UnitFiles; () for the
    others), the master's settings (its step is also ANDES' step), the runs' stop [s] (None:
    stability.default_stop of the contingency) and the CCT's resolution [s], the scratch folder
    FMUs are extracted under, and `cct` (False: the verdict run only, no bisection)."""

    case: object
    contingency: Contingency
    kind: str
    files: tuple
    settings: MasterSettings
    stop: float | None
    resolution: float
    scratch: str | None = None
    cct: bool = True


def default_fault_buses(network) -> list:
    """The buses a screening faults unless told otherwise: every bus of `network` (case.Network)
    without a generator, in file order (wscc9: 4-9)."""
    generators = set(network.generator_buses)
    return [b for b in network.buses if b not in generators]


def contingencies(network, buses, trips: str = "each") -> list:
    """Faults at `buses` of `network` (case.Network), each without a trip and (trips "each") with
    every branch at the bus that can open without cutting a generator off; clearing times are set
    per screening. ValueError for an unknown bus."""
    out = []
    for bus in buses:
        network.bus_index(bus)
        out.append((bus, None))
        if trips == "each":
            out += [(bus, t) for t in network.trips_at(bus)]
    return out


_RUNNERS = {}


def _runner(task: ScreeningTask):
    """A runner per (kind, files, settings), opened once per worker process."""
    from .runners import MasterRunner, MonolithicRunner

    key = (task.kind, task.files, task.settings, task.scratch)
    if key not in _RUNNERS:
        if task.kind == "monolithic":
            _RUNNERS[key] = MonolithicRunner(task.case, task.settings.step, 1e-9)
        elif task.kind == "andes":
            from .andes_runner import AndesRunner

            _RUNNERS[key] = AndesRunner(task.case, task.settings.step)
        else:
            _RUNNERS[key] = MasterRunner(task.files, task.case, task.settings, task.scratch)
    return _RUNNERS[key]


def close_runners() -> None:
    """Closes the runners this process opened (their FMUs and extracted files)."""
    while _RUNNERS:
        _, runner = _RUNNERS.popitem()
        runner.close()


def screen_one(task: ScreeningTask) -> dict:
    """The row of one contingency: label, bus, trip, clear_s, stable, first_swing_peak_deg, cct_s,
    bounded, runs (cct_s and bounded None where the task asks for no CCT)."""
    runner = _runner(task)
    c = task.contingency
    stable, _, result = run_verdict(runner, c, task.stop if task.stop is not None else default_stop(c))
    peak = math.degrees(first_swing_peak(result, c.clear_s))
    row = {"label": c.label, "bus": c.fault_bus, "trip": c.trip or "", "clear_s": c.clear_s,
           "stable": stable, "first_swing_peak_deg": peak if stable else None, "cct_s": None, "bounded": None,
           "runs": 1}
    if task.cct:
        cct = critical_clearing_time(runner_stable(runner, task.stop), c, task.resolution)
        row.update(cct_s=cct.cct_s, bounded=cct.bounded, runs=len(cct.runs) + 1)
    return row


def screen(tasks, workers: int = 2, scheduler: str | None = None, progress: bool = True) -> list:
    """The rows of every task (in the tasks' order), run on dask: `scheduler` (an address) or a
    LocalCluster of `workers` processes (0: in this process, no dask); progress: a bar on a terminal,
    a line every few seconds elsewhere (reference_models.progress)."""
    from dataclasses import replace

    from reference_models.progress import progress_bar

    scratch = None if scheduler else tempfile.mkdtemp(prefix="opfmu_screen_")  # remote workers: their own
    tasks = [replace(t, scratch=scratch) for t in tasks]
    report = progress_bar(len(tasks), "contingencies", "runs", enabled=progress)
    rows = [None] * len(tasks)
    try:
        if not scheduler and workers == 0:
            try:
                for i, task in enumerate(tasks):
                    rows[i] = screen_one(task)
                    report.update()
            finally:
                close_runners()
            return rows
        import dask
        from dask.distributed import Client, LocalCluster, as_completed

        cluster = None
        if scheduler:
            client = Client(scheduler, timeout="20s")
        else:
            previous = signal.signal(signal.SIGINT, signal.SIG_IGN)  # inherited by the worker processes
            try:
                with warnings.catch_warnings(), dask.config.set({"temporary-directory": scratch}):
                    warnings.simplefilter("ignore")  # a busy default port: dask takes another and says so
                    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                           dashboard_address=None, silence_logs=logging.CRITICAL,
                                           local_directory=scratch)
            finally:
                signal.signal(signal.SIGINT, previous)
            client = Client(cluster)
        try:
            futures = {client.submit(screen_one, task, pure=False): i for i, task in enumerate(tasks)}
            for future in as_completed(futures):
                rows[futures[future]] = future.result()
                report.update()
        finally:
            try:
                client.run(close_runners)
            except BaseException:
                pass
            client.close()
            if cluster is not None:
                cluster.close()
        return rows
    finally:
        report.close()
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)
