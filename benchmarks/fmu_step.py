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


def variables(md) -> tuple[list, list]:
    """(inputs, states): the model description's Real inputs, and its outputs that have an
    initial-state parameter <name>0 (the states), as fmpy ScalarVariables in their order."""
    names = {v.name for v in md.modelVariables}
    reals = [v for v in md.modelVariables if v.type == "Real"]
    return ([v for v in reals if v.causality == "input"],
            [v for v in reals if v.causality == "output" and f"{v.name}0" in names])


def fmpy_loop(directory, md, h: float, steps: int) -> float:
    """fmpy's setReal of the inputs (the first one varied around its start), doStep and getReal of the states."""
    fmu = started(directory, md)
    inputs, states = variables(md)
    input_vrs, state_vrs = [v.valueReference for v in inputs], [v.valueReference for v in states]
    start = [float(v.start) for v in inputs]
    begin = time.perf_counter()
    t = 0.0
    for k in range(steps):
        fmu.setReal(input_vrs, [start[0] + 0.01 * np.sin(k * h), *start[1:]])
        fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        fmu.getReal(state_vrs)
        t += h
    elapsed = time.perf_counter() - begin
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


def kernel_call(directory, md, n: int = 2000) -> float:
    """Microseconds of one opfmu_operator call (the compiled operator) in the FMU's binary, from the
    FMU's default initial state with every sensor at the inputs' start values, at window time T/2."""
    from surrogate.operator import Operator

    op = Operator.load(Path(directory) / "resources" / "model.onnx")
    lib = ctypes.CDLL(str(Path(directory) / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"))
    p = ctypes.POINTER(ctypes.c_double)
    starts = {v.name: float(v.start) for v in md.modelVariables if v.type == "Real" and v.start is not None}
    inputs, states = variables(md)
    x0 = np.array([starts[f"{v.name}0"] for v in states])
    u = np.tile([float(v.start) for v in inputs], op.n_sensors)
    out = np.zeros(len(x0))
    args = (x0.ctypes.data_as(p), u.ctypes.data_as(p), ctypes.c_double(0.5 * op.horizon), out.ctypes.data_as(p))
    times = []
    for _ in range(5):
        begin = time.perf_counter()
        for _ in range(n):
            lib.opfmu_operator(*args)
        times.append((time.perf_counter() - begin) / n * 1e6)
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
              f"{kernel_call(directory, md):.1f} us")
        print(f"{'h [s]':>8}{'fmpy loop [us/step]':>22}{'ctypes DoStep [us/step]':>26}{'corrections off':>18}")
        for h in args.sizes:
            print(f"{h:>8g}{statistics.median(fmpy_loop(directory, md, h, args.steps) for _ in range(3)):>22.1f}"
                  f"{statistics.median(ctypes_loop(directory, md, h, args.steps) for _ in range(3)):>26.1f}"
                  f"{statistics.median(ctypes_loop(directory, md, h, args.steps, CORRECTIONS_OFF) for _ in range(3)):>18.1f}")


if __name__ == "__main__":
    main()
