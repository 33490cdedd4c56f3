"""One interface over the ways a grid run is made: the co-simulation master with FMUs of a kind,
the monolithic reference, or ANDES' own simulation of a case converted from it (cosim.andes_runner).
`open_runner(kind, case, ...)` gives an object with `run(contingency, stop, stop_at_loss=False) -> (GridResult, timing dict)` and `close()`.
"""
from __future__ import annotations

import time
from dataclasses import replace

from .fmus import FMU_KINDS, generator_files
from .master import GridMaster, MasterSettings, check_steps

RUN_KINDS = tuple(k for k in FMU_KINDS if k != "file") + ("monolithic", "andes")  # what --fmus may name


class MonolithicRunner:
    """The monolithic DAE of the case (scipy DOP853 at `rtol`, restarted at events), rows every `step` s
    and at the events (the row after each)."""

    def __init__(self, case, step: float = 0.01, rtol: float = 1e-10):
        from reference_models.grid.monolithic import System

        self.system, self.step, self.rtol = System(case), step, rtol

    def run(self, contingency, stop: float, stop_at_loss: bool = False):
        import numpy as np

        from reference_models.grid.monolithic import simulate

        check_steps(stop, self.step)
        n = int(np.ceil(stop / self.step - 1e-9))
        times = {min(k * self.step, stop) for k in range(n + 1)}
        times |= {tp.start for tp in contingency.topologies(stop)[1:]}
        started = time.perf_counter()
        result = simulate(self.system, contingency, stop, t_eval=np.array(sorted(times)), rtol=self.rtol,
                          atol=self.rtol * 1e-2, stop_at_loss=stop_at_loss)
        return result, {"total_s": time.perf_counter() - started, "rhs_evaluations": result.n_rhs}

    def close(self):
        pass


class MasterRunner:
    """The co-simulation master over FMU files (fmus.UnitFiles per unit)."""

    def __init__(self, files, case, settings: MasterSettings, scratch=None):
        self.settings = settings
        self.master = GridMaster(case, files, settings, scratch)

    def run(self, contingency, stop: float, stop_at_loss: bool = False):
        self.master.settings = replace(self.settings, stop_at_loss=stop_at_loss)
        run = self.master.run(contingency, stop)
        return run.result, {**run.timing.to_dict(), "messages": run.messages, "notes": list(run.notes)}

    def close(self):
        self.master.close()


def open_runner(kind: str | None, case, settings: MasterSettings = MasterSettings(), cache=None,
                progress=None, monolithic_rtol: float = 1e-10, fmi_version: int = 2, scratch=None,
                host: str = "master"):
    """A runner: `kind` monolithic, one FMU kind for every unit, or None (each unit's kind from its
    dynamic data). FMUs are built into `cache` as needed (progress(text) before each build). `host`
    "veragrid": the FMUs run in VeraGrid's RMS simulation at the settings' step (cosim.veragrid)."""
    if kind == "monolithic":
        return MonolithicRunner(case, settings.step, monolithic_rtol)
    if kind == "andes":
        from .andes_runner import AndesRunner

        return AndesRunner(case, settings.step)
    files = generator_files(case, kind, cache, progress, fmi_version)
    if host == "veragrid":
        from .veragrid import VeraGridRunner

        return VeraGridRunner(case, files, settings.step)
    return MasterRunner(files, case, settings, scratch)
