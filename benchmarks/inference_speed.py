"""The paper's Table III on this machine: trajectories of 1001 points by RK45 and by the operators.

    python benchmarks/inference_speed.py --data runs/paper/data \
        --model unstacked=runs/table/unstacked-deeponet-seed0 --model stacked-n=... --model pinn=... \
        [--sizes 1 10 1000] [--repeats 7] [--out speed.json]

Every row solves the same trajectories (the test split, repeated to size) in this one run: RK45 at
high precision (rtol 1e-9, atol 1e-12) and at scipy's defaults, one trajectory after another on one
core; each operator through torch, through a plain onnxruntime session of the whole graph, and
through `Operator.predict` (trunk basis cached per grid). Times are medians over repeats (RK45 at
1000 trajectories: one pass), each method timed after a pause so that the thread pools of the one
before have stopped spinning; speedups are against high-precision RK45 of the same size. A CUDA
column is added when torch sees a GPU.
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

from reference_models.files import write_json
from reference_models.signals import Signal
from reference_models.simulate import SolverConfig, simulate
from surrogate.data import load_split
from surrogate.onnx_export import export_onnx
from surrogate.operator import EnvelopeWarning, Operator
from surrogate.training import load_model

SOLVERS = {"RK45 (rtol 1e-9, atol 1e-12)": SolverConfig("RK45", 1e-9, 1e-12),
           "RK45 (scipy defaults: rtol 1e-3, atol 1e-6)": SolverConfig("RK45", 1e-3, 1e-6)}


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

    data = load_split(args.data, "test")
    repeats = lambda n: args.repeats if n >= 100 else args.small_repeats  # noqa: E731
    rows, sizes = {}, args.sizes
    for label, solver in SOLVERS.items():
        rows[label] = {}
        for n in sizes:
            b = batch(data, n)
            signals = [Signal.from_dict(json.loads(s)) for s in b["signal"]]
            run = lambda: [simulate(x0, s, b["t"], solver=solver) for x0, s in zip(b["x0"], signals)]  # noqa: E731
            rows[label][n] = median_time(run, 1 if n >= 100 else args.repeats)  # RK45: long enough as it is
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
            rows[f"{name} onnxruntime, whole graph"] = {}
            rows[f"{name} Operator.predict (cached basis)"] = {}
            for n in sizes:
                b = batch(data, n)
                feed = {k: np.asarray(b[k], dtype=np.float32) for k in ("x0", "u", "t")}
                rows[f"{name} onnxruntime, whole graph"][n] = median_time(lambda: op._full.run(["x"], feed), repeats(n))
                rows[f"{name} Operator.predict (cached basis)"][n] = median_time(
                    lambda: op.predict(feed["x0"], feed["u"], feed["t"]), repeats(n))

    reference = rows["RK45 (rtol 1e-9, atol 1e-12)"]
    print(f"{len(data['t'])} points per trajectory; {os.cpu_count()} CPUs, torch threads {torch.get_num_threads()}"
          f"{', GPU: ' + torch.cuda.get_device_name() if cuda else ', no GPU'}; medians of {args.small_repeats} "
          f"(fewer than 100 trajectories) or {args.repeats} calls; RK45 at 1000 trajectories: one pass")
    header = "".join(f"{f'{n} traj [ms]':>15}{'speedup':>10}" for n in sizes)
    print(f"{'method':<48}{header}")
    for label, times in rows.items():
        cells = "".join(f"{times[n] * 1e3:>15.3f}{reference[n] / times[n]:>9.0f}x" for n in sizes)
        print(f"{label:<48}{cells}")
    write_json(args.out, {"sizes": sizes, "seconds": {k: {str(n): v for n, v in t.items()} for k, t in rows.items()},
                          "cpus": os.cpu_count(), "gpu": torch.cuda.get_device_name() if cuda else None})


if __name__ == "__main__":
    main()
