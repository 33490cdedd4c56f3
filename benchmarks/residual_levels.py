"""When does the surrogate FMU's residual signal trouble? Residual against error, per run.

    python benchmarks/residual_levels.py [--surrogate A.fmu] [--reference B.fmu] [--seeds 0 1 2]
        [--stop-time 10] [--step 0.01] [--out residual_levels.json]

Runs both FMUs (as `opfmu compare`) on the built-in scenarios, which stay inside the training
envelope, and on stress cases that leave it (a fault to 0.05 pu for 0.5 s, an overvoltage of 1.35 pu,
a 1 rad angle jump). Per run: the largest residual, the largest errors, how often the residual went
above the FMU's residual_limit (the warnings an importer gets) and whether in_envelope stayed true.
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from fmpy import read_model_description

from opfmu.compare import Inputs, communication_points, compare, fmu_machine, scenario_inputs
from fmu_pair import extracted_pair
from reference_models.files import write_json
from reference_models.scenarios import SCENARIOS, rest_state
from reference_models.sm4 import SM4


def stress(name: str, stop_time: float, step: float, machine) -> Inputs:
    """A run of `machine` (SM4Params) from rest at the start inputs (Vs = 1, theta_vs = 0, Pm and Efd at
    their start values, held) with one event of the bus voltage at t = 2 s that leaves the envelope."""
    t = communication_points(stop_time, step)
    vs, theta = np.ones_like(t), np.zeros_like(t)
    event = t >= 2.0 - 1e-9
    if name == "deep fault":
        vs[event & (t < 2.5 - 1e-9)] = 0.05
    elif name == "overvoltage":
        vs[event] = 1.35
    else:  # angle jump
        theta[event] = 1.0
    Pm, Efd = (np.full_like(t, q.start) for q in SM4.inputs[2:])
    return Inputs(name, t, np.stack([vs, theta, Pm, Efd], axis=1), rest_state(1.0, 0.0, machine))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--surrogate")
    parser.add_argument("--reference")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--stop-time", type=float, default=10.0)
    parser.add_argument("--step", type=float, default=0.01)
    parser.add_argument("--out", default="residual_levels.json")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="opfmu_residual_") as tmp:
        tmp = Path(tmp)
        dirs = extracted_pair(args.surrogate, args.reference, tmp)
        md = read_model_description(dirs[0])
        limit = next(float(v.start) for v in md.modelVariables if v.name == "residual_limit")
        machine = fmu_machine(dirs[0])
        runs = [scenario_inputs(n, seed, args.stop_time, args.step, machine) for n in SCENARIOS for seed in args.seeds]
        runs += [stress(n, args.stop_time, args.step, machine) for n in ("deep fault", "overvoltage", "angle jump")]
        print(f"residual_limit {limit:.3g}; {args.stop_time:g} s at h = {args.step * 1e3:g} ms")
        print(f"{'run':<18}{'max residual':>13}{'MaxAE delta':>13}{'MaxAE omega':>13}{'MaxAE Eq_p':>12}"
              f"{'warnings':>10}{'envelope':>10}")
        rows = []
        for inputs in runs:
            result = compare(*dirs, inputs, args.stop_time, args.step)
            m = result["metrics"]
            warnings = sum("residual" in message for message in result["messages"]["surrogate"])
            print(f"{inputs.label:<18}{result['max_residual']:>13.3g}{m['delta']['maxae']:>13.2e}"
                  f"{m['omega']['maxae']:>13.2e}{m['Eq_p']['maxae']:>12.2e}{warnings:>10}"
                  f"{'in' if result['in_envelope'] else 'left':>10}", flush=True)
            rows.append({"run": inputs.label, "max_residual": result["max_residual"], "warnings": warnings,
                         "in_envelope": result["in_envelope"], "maxae": {k: v["maxae"] for k, v in m.items()}})
        write_json(args.out, {"residual_limit": limit, "rows": rows})


if __name__ == "__main__":
    main()
