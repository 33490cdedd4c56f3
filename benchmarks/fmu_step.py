"""Microseconds per communication step of the surrogate FMU: through fmpy and through a direct
ctypes loop over the FMI functions, at several step sizes, in one run.

    python benchmarks/fmu_step.py [FMU] [--steps 2000] [--sizes 0.001 0.01]

Without an FMU argument, builds one from the shipped operator. Also prints the cost of one
operator (kernel) evaluation, the floor a step cannot go below, and the DoStep cost with the rest
and slow-mode corrections and the exact swing step turned off (rest_radius = slow_weight = swing_weight
= 0): what the corrections cost.
"""
from __future__ import annotations

import argparse
import ctypes
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from fmu_export.builder import build_surrogate_fmu
from surrogate.operator import DEFAULT_OPERATOR


CORRECTIONS_OFF = {"rest_radius": 0.0, "slow_weight": 0.0, "swing_weight": 0.0}


def started(directory, md, parameters=None) -> FMU2Slave:
    """An instance in step mode at t = 0, with `parameters` {name: value} set."""
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=directory, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="bench")
    fmu.instantiate()
    vr = {v.name: v.valueReference for v in md.modelVariables}
    for name, value in (parameters or {}).items():
        fmu.setReal([vr[name]], [value])
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    return fmu


def fmpy_loop(directory, md, h: float, steps: int) -> float:
    fmu = started(directory, md)
    start = time.perf_counter()
    t = 0.0
    for k in range(steps):
        fmu.setReal([0, 1], [1.0 + 0.01 * np.sin(k * h), 0.0])
        fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        fmu.getReal([2, 3, 4, 5])
        t += h
    elapsed = time.perf_counter() - start
    fmu.terminate()
    fmu.freeInstance()
    return elapsed / steps * 1e6


def ctypes_loop(directory, md, h: float, steps: int, parameters=None) -> float:
    """DoStep alone, called through ctypes on the loaded binary (no fmpy wrappers)."""
    fmu = started(directory, md, parameters)
    do_step = fmu.dll.fmi2DoStep
    do_step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
    component = fmu.component
    start = time.perf_counter()
    for k in range(steps):
        do_step(component, k * h, h, 1)
    elapsed = time.perf_counter() - start
    fmu.terminate()
    fmu.freeInstance()
    return elapsed / steps * 1e6


def kernel_call(directory, n: int = 2000) -> float:
    lib = ctypes.CDLL(str(Path(directory) / "binaries" / "linux64" / "SM4Surrogate.so"))
    p = ctypes.POINTER(ctypes.c_double)
    x0, u, out = np.zeros(4), np.ones(2002), np.zeros(4)
    x0[:] = (1.06, 0.0, 0.33, 0.63)
    args = (x0.ctypes.data_as(p), u.ctypes.data_as(p))
    times = []
    for _ in range(5):
        start = time.perf_counter()
        for _ in range(n):
            lib.opfmu_operator(*args, ctypes.c_double(0.5), out.ctypes.data_as(p))
        times.append((time.perf_counter() - start) / n * 1e6)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("fmu", nargs="?", default=None)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--sizes", type=float, nargs="+", default=[0.001, 0.01])
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = args.fmu or str(Path(tmp) / "SM4Surrogate.fmu")
        if not args.fmu:
            build_surrogate_fmu(DEFAULT_OPERATOR, path)
        directory, md = extract(path), read_model_description(path)
        print(f"{Path(path).name}: {Path(path).stat().st_size / 1e6:.2f} MB; one operator evaluation "
              f"{kernel_call(directory):.1f} us")
        print(f"{'h [s]':>8}{'fmpy loop [us/step]':>22}{'ctypes DoStep [us/step]':>26}{'corrections off':>18}")
        for h in args.sizes:
            print(f"{h:>8g}{statistics.median(fmpy_loop(directory, md, h, args.steps) for _ in range(3)):>22.1f}"
                  f"{statistics.median(ctypes_loop(directory, md, h, args.steps) for _ in range(3)):>26.1f}"
                  f"{statistics.median(ctypes_loop(directory, md, h, args.steps, CORRECTIONS_OFF) for _ in range(3)):>18.1f}")


if __name__ == "__main__":
    main()
