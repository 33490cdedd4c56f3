"""Runs reference solves chunk by chunk: in-process, on a local dask cluster, or on a dask scheduler."""
from __future__ import annotations

import logging
import warnings
from contextlib import contextmanager

import numpy as np

from reference_models.components import component
from reference_models.interrupts import interrupts_held
from reference_models.signals import Signal
from reference_models.simulate import SolverConfig, simulate


def solve_chunk(x0s: np.ndarray, signal_dicts: list, t: np.ndarray, solver: dict, component_name: str,
                params: dict) -> np.ndarray:
    """States [n, S, n_x] for one chunk of the component `component_name` with parameters `params`;
    takes plain data so it travels to any dask worker."""
    config = SolverConfig(**solver)
    model = component(component_name)
    p = model.params(params)
    states = []
    for x0, s in zip(x0s, signal_dicts):
        try:
            states.append(simulate(x0, Signal.from_dict(s), t, p, config, model))
        except RuntimeError as exc:
            raise RuntimeError(f"{exc} (x0 = {np.array2string(x0, precision=6)}, signal = {s})") from None
    return np.stack(states)


class SchedulerError(ValueError):
    """A dask scheduler address that cannot be used (unreachable, or not an address)."""


@contextmanager
def _distributed_logs_silenced():
    """No dask log line while the block closes the client and cluster: after an interrupt the
    scheduler logs, at CRITICAL and with a traceback, the results it can no longer send to the
    closed client; what went wrong is the caller's to report, in one line."""
    handlers = logging.getLogger("distributed").handlers
    levels = [h.level for h in handlers]
    for h in handlers:
        h.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for h, level in zip(handlers, levels):
            h.setLevel(level)


class SolveRunner:
    """Context manager that solves chunks and hands each result to a callback as it finishes.

    workers = 0 solves in this process; otherwise a dask LocalCluster of `workers` single-threaded
    processes is started, unless `scheduler` gives the address of a running dask scheduler (its
    workers must have opfmu installed).
    """

    def __init__(self, workers: int = 2, scheduler: str | None = None):
        self.workers = workers
        self.scheduler = scheduler
        self._client = None
        self._cluster = None

    def __enter__(self):
        if self.scheduler:
            from dask.distributed import Client

            try:
                self._client = Client(self.scheduler, timeout="20s")
            except (OSError, ValueError, TypeError) as exc:  # unreachable, or not an address
                raise SchedulerError(f"cannot use the dask scheduler {self.scheduler!r}: "
                                     f"{' '.join(str(exc).split())[:200]}") from None
        elif self.workers > 0:
            from dask.distributed import Client, LocalCluster

            # the workers start with SIGINT blocked: a Ctrl-C reaches this process alone, whose
            # KeyboardInterrupt closes the cluster, instead of each worker printing its own traceback
            try:
                with interrupts_held(), warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # a busy default port: dask takes another and says so
                    self._cluster = LocalCluster(
                        n_workers=self.workers, threads_per_worker=1, processes=True,
                        # CRITICAL: a worker's heartbeat failing while the cluster shuts down is logged as
                        # an error with a traceback; a failing solve still raises through its future
                        dashboard_address=None, silence_logs=logging.CRITICAL,
                    )
                self._client = Client(self._cluster)
            except BaseException:  # a Ctrl-C held while the cluster started: __exit__ is not called
                self.__exit__()
                raise
        return self

    def __exit__(self, *exc):
        with _distributed_logs_silenced():
            if self._client is not None:
                self._client.close()
            if self._cluster is not None:
                self._cluster.close()

    def run(self, chunks: dict, t: np.ndarray, solver: SolverConfig, on_done, model, params) -> None:
        """Solve chunks {key: (x0s [n, n_x], signal dicts [n])} of component `model` with `params`;
        on_done(key, x [n, S, n_x]) per chunk."""
        solver_dict, machine = solver.to_dict(), (model.name, params.to_dict())
        if self._client is None:
            for key, (x0s, signal_dicts) in chunks.items():
                on_done(key, solve_chunk(x0s, signal_dicts, t, solver_dict, *machine))
            return
        from dask.distributed import as_completed

        futures = {
            self._client.submit(solve_chunk, x0s, sigs, t, solver_dict, *machine, pure=False, key=f"solve-{key}"): key
            for key, (x0s, sigs) in chunks.items()
        }
        try:
            for future in as_completed(futures):
                on_done(futures[future], future.result())
        except BaseException:
            self._client.cancel(list(futures))
            raise
