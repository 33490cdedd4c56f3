"""Microseconds per communication step of the surrogate FMU beside the native reference FMU (the same
machine's equations, Dormand-Prince 5(4) in C) and the pythonfmu reference, in one run: through
fmpy and through a direct ctypes loop over fmi2DoStep, at several step sizes.

    python benchmarks/fmu_step.py [SURROGATE_FMU] [--steps 2000] [--sizes 0.001 0.01 0.05]

Without an FMU argument, builds the surrogate FMU of the shipped operator; both references are built
for its machine. Also prints the cost of one operator (kernel) evaluation, the floor a surrogate
step cannot go below, and the surrogate's DoStep cost with the rest and slow-mode corrections and
the exact swing step turned off (rest_radius = slow_weight = swing_weight = 0): what they cost.
Every FMU gets the same inputs (the first input varied around the surrogate's start value) from the
same initial state. Any machine whose surrogate FMU opfmu builds (SM4, GENROU: the shipped
surrogate/default/kundur_gen12.onnx, ...): the references are built for the component, machine and
operating point of its operator; instances are opened through cosim.fmu.FMU.
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

from cosim.fmu import FMU
from fmu_export.surrogate_fmu import build_surrogate_fmu, load_operator
from fmu_export.native_reference_fmu import build_native_reference_fmu
from fmu_export.python_reference_fmu import ReferenceBuildError, build_reference_fmu
from opfmu.compare import fmu_component
from surrogate.operator import DEFAULT_OPERATOR


CORRECTIONS_OFF = {"rest_radius": 0.0, "slow_weight": 0.0, "swing_weight": 0.0}


STARTS: dict = {}  # {variable: start value} every FMU gets (the surrogate's inputs and initial state)


def started(directory, md, parameters=None) -> FMU:
    """An instance (cosim.fmu.FMU; its fmpy FMU2Slave is `.fmu`) in step mode at t = 0, with STARTS
    (where they differ from its own) and `parameters` {name: value} set."""
    instance = FMU((directory, md), name="bench", init=False)
    own = {v.name: v.start for v in md.modelVariables}
    common = {n: v for n, v in STARTS.items() if n in own and float(own[n] or "nan") != v}
    instance.initialise({**common, **(parameters or {})})
    return instance


def variables(md) -> tuple[list, list]:
    """(inputs, states): the model description's Real inputs, and its outputs that have an
    initial-state parameter <name>0 (the states), as fmpy ScalarVariables in their order."""
    names = {v.name for v in md.modelVariables}
    reals = [v for v in md.modelVariables if v.type == "Real"]
    return ([v for v in reals if v.causality == "input"],
            [v for v in reals if v.causality == "output" and f"{v.name}0" in names])


def fmpy_loop(directory, md, h: float, steps: int) -> float:
    """fmpy's setReal of the inputs (the first one varied around its start), doStep and getReal of the states."""
    instance = started(directory, md)
    fmu = instance.fmu
    inputs, states = variables(md)
    input_vrs, state_vrs = [v.valueReference for v in inputs], [v.valueReference for v in states]
    start = [STARTS.get(v.name, float(v.start)) for v in inputs]
    begin = time.perf_counter()
    t = 0.0
    for k in range(steps):
        fmu.setReal(input_vrs, [start[0] + 0.01 * np.sin(k * h), *start[1:]])
        fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        fmu.getReal(state_vrs)
        t += h
    elapsed = time.perf_counter() - begin
    instance.close()
    return elapsed / steps * 1e6


def ctypes_loop(directory, md, h: float, steps: int, parameters=None) -> float:
    """DoStep alone, called through ctypes on the loaded binary (no fmpy wrappers), under the same
    inputs as fmpy_loop set before each step (also through ctypes; outside the timing)."""
    instance = started(directory, md, parameters)
    fmu = instance.fmu
    do_step, set_real = fmu.dll.fmi2DoStep, fmu.dll.fmi2SetReal
    do_step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
    inputs, _ = variables(md)
    vrs = (ctypes.c_uint * len(inputs))(*[v.valueReference for v in inputs])
    start_values = [STARTS.get(v.name, float(v.start)) for v in inputs]
    values = [(ctypes.c_double * len(inputs))(start_values[0] + 0.01 * np.sin(k * h), *start_values[1:])
              for k in range(steps)]
    component, elapsed = fmu.component, 0.0
    for k in range(steps):
        set_real(component, vrs, len(inputs), values[k])
        begin = time.perf_counter()
        do_step(component, k * h, h, 1)
        elapsed += time.perf_counter() - begin
    instance.close()
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
    parser.add_argument("fmu", nargs="?", default=None, help="surrogate FMU (default: built from the shipped operator)")
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--sizes", type=float, nargs="+", default=[0.001, 0.01, 0.05])
    args = parser.parse_args()
    median = lambda fn: statistics.median(fn() for _ in range(3))  # noqa: E731
    with tempfile.TemporaryDirectory() as tmp:
        path = args.fmu or str(Path(tmp) / "SM4Surrogate.fmu")
        if not args.fmu:
            build_surrogate_fmu(DEFAULT_OPERATOR, path)
        surrogate = extract(path, unzipdir=str(Path(tmp) / "s")), read_model_description(path)
        component, machine = fmu_component(surrogate[0])
        point = load_operator(Path(surrogate[0]) / "resources" / "model.onnx")[1].get("operating_point")
        STARTS.update({v.name: float(v.start) for v in surrogate[1].modelVariables if v.type == "Real"
                       and v.start is not None and (v.causality == "input" or v.name[:-1] in component.state_names
                                                    and v.name.endswith("0"))})
        references = {}
        for label, build in (("native", build_native_reference_fmu), ("pythonfmu", build_reference_fmu)):
            ref_path = Path(tmp) / f"{label}.fmu"
            extra = {"operating_point": point} if point and label == "native" else {}
            try:
                build(ref_path, model_name=f"{component.name.upper()}Reference", component=component, params=machine,
                      **extra)
            except ReferenceBuildError as exc:  # pythonfmu packs only components whose module stands alone
                print(f"no pythonfmu reference of {component.name}: {exc}")
                continue
            references[label] = extract(str(ref_path), unzipdir=str(Path(tmp) / label)), read_model_description(str(ref_path))
        print(f"{Path(path).name}: {Path(path).stat().st_size / 1e6:.2f} MB; one operator evaluation "
              f"{kernel_call(*surrogate):.1f} us; medians of 3 runs of {args.steps} steps; us per step")
        print(f"{'h [s]':>7} | {'surrogate: fmpy':>15}{'DoStep':>8}{'no corr.':>9} | {'native ref.: fmpy':>17}"
              f"{'DoStep':>8} | {'pythonfmu: fmpy':>15}{'DoStep':>8} | {'DoStep surrogate / native':>26}")
        for h in args.sizes:
            s_fmpy, s_step = median(lambda: fmpy_loop(*surrogate, h, args.steps)), \
                median(lambda: ctypes_loop(*surrogate, h, args.steps))
            s_off = median(lambda: ctypes_loop(*surrogate, h, args.steps, CORRECTIONS_OFF))
            n_fmpy, n_step = median(lambda: fmpy_loop(*references["native"], h, args.steps)), \
                median(lambda: ctypes_loop(*references["native"], h, args.steps))
            few = max(50, args.steps // 20)  # scipy under pythonfmu: 100-1000 times slower
            p_fmpy, p_step = (median(lambda: fmpy_loop(*references["pythonfmu"], h, few)),
                              median(lambda: ctypes_loop(*references["pythonfmu"], h, few))) \
                if "pythonfmu" in references else (float("nan"), float("nan"))
            print(f"{h:>7g} | {s_fmpy:>15.1f}{s_step:>8.1f}{s_off:>9.1f} | {n_fmpy:>17.1f}{n_step:>8.2f} | "
                  f"{p_fmpy:>15.0f}{p_step:>8.0f} | {s_step / n_step:>25.1f}x")


if __name__ == "__main__":
    main()
