"""One interface over the ways a grid run is made: the co-simulation master with FMUs of a kind,
or the monolithic reference. `open_runner(kind, ...)` gives an object with
`run(contingency, stop, stop_at_loss=False) -> (GridResult, timing dict)` and `close()`.
"""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

from reference_models.grid import wscc9
from reference_models.grid.monolithic import WSCC9, simulate_contingency

from .fmus import generator_files
from .master import GridMaster, MasterSettings

RUN_KINDS = tuple(k for k in wscc9.FMU_KINDS if k != "file") + ("monolithic",)  # what --fmus may name


class MonolithicRunner:
    """The monolithic DAE (scipy DOP853 at `rtol`, restarted at events), rows every `step` s and at
    the events (the row after each)."""

    def __init__(self, grid: WSCC9, step: float = 0.01, rtol: float = 1e-10):
        self.grid, self.step, self.rtol = grid, step, rtol

    def run(self, contingency, stop: float, stop_at_loss: bool = False):
        import numpy as np

        n = int(np.ceil(stop / self.step - 1e-9))
        times = {min(k * self.step, stop) for k in range(n + 1)}
        times |= {tp.start for tp in contingency.topologies(stop)[1:]}
        started = time.perf_counter()
        result = simulate_contingency(contingency, stop, t_eval=np.array(sorted(times)), rtol=self.rtol,
                                      atol=self.rtol * 1e-2, grid=self.grid, stop_at_loss=stop_at_loss)
        return result, {"total_s": time.perf_counter() - started, "rhs_evaluations": result.n_rhs}

    def close(self):
        pass


class MasterRunner:
    """The co-simulation master over FMU files (fmus.GeneratorFiles per generator)."""

    def __init__(self, files, grid: WSCC9, settings: MasterSettings):
        self.settings = settings
        self.master = GridMaster(files, grid, settings)

    def run(self, contingency, stop: float, stop_at_loss: bool = False):
        self.master.settings = replace(self.settings, stop_at_loss=stop_at_loss)
        run = self.master.run(contingency, stop)
        return run.result, {**run.timing.to_dict(), "messages": run.messages, "notes": list(run.notes)}

    def close(self):
        self.master.close()


def load_grid(dynamic_data=None) -> WSCC9:
    """The WSCC 9-bus system with the generators of a dynamic-data file (None: the shipped one)."""
    return WSCC9(wscc9.dynamic_data(Path(dynamic_data)) if dynamic_data else None)


def open_runner(kind: str | None, grid: WSCC9, settings: MasterSettings = MasterSettings(), cache=None,
                progress=None, monolithic_rtol: float = 1e-10):
    """A runner: `kind` monolithic, one FMU kind for every generator, or None (each generator's kind
    from its dynamic data). FMUs are built into `cache` as needed (progress(text) before each build)."""
    if kind == "monolithic":
        return MonolithicRunner(grid, settings.step, monolithic_rtol)
    files = generator_files(grid.dynamics, kind, cache, progress)
    return MasterRunner(files, grid, settings)
