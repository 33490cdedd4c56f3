"""The strongest peer of the operator for whole trajectories: the FMU's compiled Dormand-Prince 5(4).

`CompiledSolver(component, params)` compiles the component's generated C equations with
fmu_export/c/dopri5.c and benchmarks/c/batch_solver.c (gcc -O3, the flags of the FMUs) into a
library that solves a batch of trajectories in C, one after another on one core, with dense output
on the query grid (cubic Hermite between the solver's own steps). Inputs are the closed-form
channels scipy's rows integrate (FirstOrder, SecondOrder: the paper's families; constants: Piecewise
channels without breakpoints, which hold SM4's Pm and Efd in them).
"""
from __future__ import annotations

import ctypes
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from fmu_export.c_equations import equations_c_source
from reference_models.signals import FirstOrder, Piecewise, SecondOrder

ROOT = Path(__file__).resolve().parent.parent
DOPRI5 = ROOT / "fmu_export" / "c" / "dopri5.c"
DRIVER = Path(__file__).resolve().parent / "c" / "batch_solver.c"
KINDS = {FirstOrder: (0, ("y0", "k", "A", "w", "y_ref")), SecondOrder: (1, ("y0", "dy0", "zeta", "wn", "y_ref"))}
CONSTANT = 2  # a Piecewise channel without breakpoints: its one value


class CompiledSolver:
    """solve(x0s [N, n_x], signals [N], grid [S]) -> states [N, S, n_x] in C for one machine."""

    def __init__(self, component, params):
        self.component = component
        self._tmp = tempfile.TemporaryDirectory(prefix="opfmu_batch_")
        unit = Path(self._tmp.name) / "batch.c"
        unit.write_text(f"#define N_STATES {component.n_states}\n#define N_INPUTS {component.n_inputs}\n"
                        '#define OPFMU_BENCH_API __attribute__((visibility("default")))\n'
                        + equations_c_source(component, params) + f'\n#include "{DRIVER}"\n')
        library = Path(self._tmp.name) / "libbatch.so"
        subprocess.run(["gcc", "-O3", "-shared", "-fPIC", "-std=c99", "-I", str(DOPRI5.parent), str(unit), str(DOPRI5),
                        "-o", str(library), "-lm"], check=True, capture_output=True, text=True)
        self._lib = ctypes.CDLL(str(library))
        p = ctypes.POINTER(ctypes.c_double)
        self._lib.solve_batch.argtypes = [ctypes.c_int, p, p, ctypes.c_int, p, ctypes.c_double, ctypes.c_double, p,
                                          ctypes.POINTER(ctypes.c_long)]
        self.evaluations = 0

    def channels(self, signals) -> np.ndarray:
        """[N, n_u, 6]: per channel its kind and parameters (ValueError for a kind the driver lacks)."""
        rows = []
        for signal in signals:
            per_input = []
            if signal.hold > 0:
                raise ValueError("the compiled solver takes signals without a zero-order hold")
            for channel in signal.channels.values():
                if isinstance(channel, Piecewise) and not channel.times:
                    per_input.append([CONSTANT, float(channel.values[0]), 0.0, 0.0, 0.0, 0.0])
                    continue
                if type(channel) not in KINDS:
                    raise ValueError(f"the compiled solver takes FirstOrder, SecondOrder and constant channels, "
                                     f"not {type(channel).__name__}")
                kind, names = KINDS[type(channel)]
                per_input.append([kind, *(getattr(channel, n) for n in names)])
            rows.append(per_input)
        return np.ascontiguousarray(rows, dtype=float)

    def solve(self, x0s, channels: np.ndarray, grid, rtol: float, atol: float) -> np.ndarray:
        """States [N, S, n_x] at the grid times; channels from `channels(signals)` (prepared once)."""
        x0s = np.ascontiguousarray(x0s, dtype=float)
        grid = np.ascontiguousarray(grid, dtype=float)
        out = np.empty((len(x0s), len(grid), self.component.n_states))
        count = ctypes.c_long(0)
        p = lambda a: a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))  # noqa: E731
        rc = self._lib.solve_batch(len(x0s), p(x0s), p(channels), len(grid), p(grid), rtol, atol, p(out),
                                   ctypes.byref(count))
        if rc != 0:
            raise RuntimeError(f"the compiled solver failed (dopri5 code {rc})")
        self.evaluations = count.value
        return out
