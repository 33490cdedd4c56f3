"""The paper's Table III on this machine: trajectories of 1001 points by RK45 and by the operators.

    python benchmarks/inference_speed.py --data runs/paper/data \
        --model unstacked=runs/table/unstacked-deeponet-seed0 --model stacked-n=... --model pinn=... \
        [--sizes 1 10 1000] [--repeats 7] [--out speed.json]

Every row solves the same trajectories (the test split, repeated to size) in this one run: scipy's
RK45 at high precision (rtol 1e-9, atol 1e-12) and at its defaults, and the same two tolerances by
the compiled Dormand-Prince 5(4) of the native reference FMU (benchmarks/compiled_solver.py: C, dense
output on the grid), one trajectory after another on one core; each operator through torch, through
a plain onnxruntime session of the whole graph, and through `Operator.predict` (trunk basis cached
per grid). Times are medians over repeats (scipy at 1000 trajectories: one pass), each method timed
after a pause so that the thread pools of the one before have stopped spinning; speedups are against
scipy's high-precision RK45 and against the compiled solver at the same tolerance (the strongest
peer). The error column is the max abs error over the test split's states against DOP853 at
rtol = atol = 1e-12. A CUDA column is added when torch sees a GPU.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import torch

from compiled_solver import CompiledSolver
from reference_models.files import write_json
from reference_models.signals import Signal
from reference_models.simulate import SolverConfig, simulate
from surrogate.data import load_metadata, load_split, machine_of
from surrogate.onnx_export import export_onnx
from surrogate.operator import EnvelopeWarning, Operator
from surrogate.training import load_model

SOLVERS = {"scipy RK45 (rtol 1e-9, atol 1e-12)": SolverConfig("RK45", 1e-9, 1e-12),
           "scipy RK45 (its defaults: rtol 1e-3, atol 1e-6)": SolverConfig("RK45", 1e-3, 1e-6)}
COMPILED = {"compiled DOPRI5 (rtol 1e-9, atol 1e-12)": (1e-9, 1e-12),
            "compiled DOPRI5 (rtol 1e-3, atol 1e-6)": (1e-3, 1e-6)}
EXACT = SolverConfig("DOP853", 1e-12, 1e-12)


def median_time(fn, repeats: int) -> float:
    """Median wall time of fn over `repeats` calls, after a warm-up call (sessions, caches, allocator)
    and a pause in which the thread pools of the previous method stop spinning."""
    time.sleep(0.5)
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def batch(data: dict, n: int) -> dict:
    idx = np.arange(n) % len(data["x0"])
    return {"x0": data["x0"][idx], "u": data["u"][idx], "t": data["t"], "signal": data["signal"][idx]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="dataset whose test split gives the inputs")
    parser.add_argument("--model", action="append", default=[], metavar="NAME=RUN_DIR",
                        help="a trained run to time (repeatable)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 10, 1000])
    parser.add_argument("--repeats", type=int, default=7, help="repeats at 100 trajectories or more (default 7)")
    parser.add_argument("--small-repeats", type=int, default=101, help="repeats below 100 trajectories (default 101)")
    parser.add_argument("--out", default="inference_speed.json")
    args = parser.parse_args()
    warnings.simplefilter("ignore", EnvelopeWarning)

    data = load_split(args.data, "test", frame=False)  # as solved: what the solvers and Operator.predict take
    component, params = machine_of(load_metadata(args.data))
    signals = [Signal.from_dict(json.loads(s)) for s in data["signal"]]
    exact = np.stack([simulate(x0, s, data["t"], params, EXACT, component) for x0, s in zip(data["x0"], signals)])
    error = lambda x: float(np.max(np.abs(np.asarray(x, dtype=float)[:len(exact)] - exact)))  # noqa: E731
    repeats = lambda n: args.repeats if n >= 100 else args.small_repeats  # noqa: E731
    rows, errors, sizes = {}, {}, args.sizes
    for label, solver in SOLVERS.items():
        rows[label] = {}
        for n in sizes:
            b = batch(data, n)
            chosen = [signals[i % len(signals)] for i in range(n)]
            run = lambda: [simulate(x0, s, b["t"], params, solver, component) for x0, s in zip(b["x0"], chosen)]  # noqa: E731
            rows[label][n] = median_time(run, 1 if n >= 100 else args.repeats)  # long enough as it is
        errors[label] = error([simulate(x0, s, data["t"], params, solver, component)
                               for x0, s in zip(data["x0"], signals)])
    compiled = CompiledSolver(component, params)
    evaluations = {}
    for label, (rtol, atol) in COMPILED.items():
        rows[label] = {}
        for n in sizes:
            b = batch(data, n)
            channels = compiled.channels([signals[i % len(signals)] for i in range(n)])
            rows[label][n] = median_time(lambda: compiled.solve(b["x0"], channels, b["t"], rtol, atol), repeats(n))
        errors[label] = error(compiled.solve(data["x0"], compiled.channels(signals), data["t"], rtol, atol))
        evaluations[label] = compiled.evaluations / len(signals)
    cuda = torch.cuda.is_available()
    with tempfile.TemporaryDirectory() as tmp:
        for spec in args.model:
            name, run_dir = spec.split("=", 1)
            model = load_model(run_dir)
            onnx_path = Path(tmp) / f"{name}.onnx"
            export_onnx(run_dir, onnx_path, data_dir=args.data)
            op = Operator.load(onnx_path)
            devices = ["cpu"] + (["cuda"] if cuda else [])
            for device in devices:
                m = model.to(device)
                rows[f"{name} torch ({device})"] = {}
                for n in sizes:
                    b = batch(data, n)
                    tensors = [torch.as_tensor(b[k], dtype=torch.float32, device=device) for k in ("x0", "u", "t")]

                    def run():
                        with torch.no_grad():
                            m(*tensors)
                        if device == "cuda":
                            torch.cuda.synchronize()
                    rows[f"{name} torch ({device})"][n] = median_time(run, repeats(n))
            whole, cached = f"{name} onnxruntime, whole graph", f"{name} Operator.predict (cached basis)"
            rows[whole], rows[cached] = {}, {}
            for n in sizes:
                b = batch(data, n)
                feed = {k: np.asarray(b[k], dtype=np.float32) for k in ("x0", "u", "t")}
                rows[whole][n] = median_time(lambda: op._full.run(["x"], feed), repeats(n))
                rows[cached][n] = median_time(lambda: op.predict(feed["x0"], feed["u"], feed["t"]), repeats(n))
            errors[whole] = errors[cached] = error(op.predict(data["x0"], data["u"], data["t"]))
            for device in devices:  # the same network: the same answer to float32 round-off
                errors[f"{name} torch ({device})"] = errors[cached]

    scipy_ref, compiled_ref = rows["scipy RK45 (rtol 1e-9, atol 1e-12)"], rows["compiled DOPRI5 (rtol 1e-9, atol 1e-12)"]
    print(f"{len(data['t'])} points per trajectory; {os.cpu_count()} CPUs, torch threads {torch.get_num_threads()}"
          f"{', GPU: ' + torch.cuda.get_device_name() if cuda else ', no GPU'}; medians of {args.small_repeats} "
          f"(fewer than 100 trajectories) or {args.repeats} calls; scipy at 100 trajectories or more: one pass; "
          f"speedups against scipy RK45 and against the compiled DOPRI5, both at rtol 1e-9, atol 1e-12")
    print("compiled DOPRI5, right-hand side evaluations per trajectory: "
          + ", ".join(f"{label.split('(')[1][:-1]}: {v:.0f}" for label, v in evaluations.items()))
    header = "".join(f"{f'{n} traj [ms]':>14}{'vs scipy':>10}{'vs C':>8}" for n in sizes)
    print(f"{'method':<48}{header}{'max error':>11}")
    for label, times in rows.items():
        cells = "".join(f"{times[n] * 1e3:>14.3f}{scipy_ref[n] / times[n]:>9.0f}x{compiled_ref[n] / times[n]:>7.2f}x"
                        for n in sizes)
        print(f"{label:<48}{cells}{errors.get(label, float('nan')):>11.1e}")
    write_json(args.out, {"sizes": sizes, "seconds": {k: {str(n): v for n, v in t.items()} for k, t in rows.items()},
                          "max_error": errors, "compiled_evaluations_per_trajectory": evaluations,
                          "cpus": os.cpu_count(), "gpu": torch.cuda.get_device_name() if cuda else None})


if __name__ == "__main__":
    main()
