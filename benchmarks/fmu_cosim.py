"""The co-simulation table: the surrogate FMU against the reference FMU, per scenario and step size.

    python benchmarks/fmu_cosim.py [--surrogate A.fmu] [--reference B.fmu] [--steps 0.001 0.01 0.05]
        [--stop-time 10] [--seeds 0] [--scenarios slow fast dip step ramp] [--out fmu_cosim.json]

Without FMU arguments both are built first (the shipped operator for the surrogate). Every row runs
both FMUs under fmpy on the same inputs (opfmu.compare): MaxAE per state, the largest MaxAE of the
derived outputs, wall times of the whole fmpy simulation and of fmi2DoStep alone, and the speedup
ratios of the same run. Also printed: how many rows meet the goal (MaxAE delta, omega <= 0.01;
Ed_p, Eq_p <= 0.005) and the worst error at the rollovers against the worst elsewhere.
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from opfmu.compare import compare, fmu_machine, scenario_inputs, summary
from opfmu.demo import GOAL_MAXAE
from fmu_pair import extracted_pair, surrogate_parameters, surrogate_setting
from reference_models.files import write_json
from reference_models.scenarios import SCENARIOS
from reference_models.sm4 import OUTPUT_NAMES, STATE_NAMES


def rollover_share(result: dict, horizon: float) -> tuple[float, float]:
    """(max |error| of delta within 20 ms after a rollover, max elsewhere) [rad]; rollovers every
    `horizon` seconds (the surrogate's rollover_horizon; windows restarted by an input jump are not told
    apart)."""
    t = result["trajectories"]["reference"]["time"]
    err = np.abs(result["trajectories"]["surrogate"]["delta"] - result["trajectories"]["reference"]["delta"])
    phase = np.mod(t, horizon)
    near = (phase < 0.02 + 1e-9) & (t > horizon / 2)
    return float(err[near].max(initial=0.0)), float(err[~near].max(initial=0.0))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--surrogate", help="surrogate FMU (default: build the shipped operator's)")
    parser.add_argument("--reference", help="reference FMU (default: build it)")
    parser.add_argument("--steps", type=float, nargs="+", default=[0.001, 0.01, 0.05])
    parser.add_argument("--stop-time", type=float, default=10.0)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--scenarios", nargs="+", default=list(SCENARIOS))
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                        help="a surrogate parameter, e.g. rollover_horizon=0.5 or restart_jump=0.02 (repeatable)")
    parser.add_argument("--out", default="fmu_cosim.json")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="opfmu_cosim_") as tmp:
        tmp = Path(tmp)
        dirs = extracted_pair(args.surrogate, args.reference, tmp)
        parameters = surrogate_parameters(args.param)
        horizon = surrogate_setting(dirs[0], "rollover_horizon", parameters)
        machine = fmu_machine(dirs[0])
        rows = []
        header = (f"{'scenario':<8}{'seed':>5}{'h [ms]':>7}" + "".join(f"{'MaxAE ' + n:>13}" for n in STATE_NAMES)
                  + f"{'derived':>10}{'rollover':>10}{'elsewhere':>10}{'fmpy x':>8}{'doStep x':>9}{'goal':>7}")
        print(f"{args.stop_time:g} s per run; MaxAE in rad, rad/s, pu; derived: largest MaxAE of "
              f"{', '.join(OUTPUT_NAMES)}; rollover/elsewhere: MaxAE delta within 20 ms after a rollover / elsewhere")
        print(header)
        for name in args.scenarios:
            for seed in args.seeds:
                for h in args.steps:
                    inputs = scenario_inputs(name, seed, args.stop_time, h, machine)
                    result = compare(*dirs, inputs, args.stop_time, h, parameters)
                    m = result["metrics"]
                    near, far = rollover_share(result, horizon)
                    met = all(m[s]["maxae"] <= limit for s, limit in GOAL_MAXAE.items())
                    derived = max(m[n]["maxae"] for n in OUTPUT_NAMES)
                    print(f"{name:<8}{seed:>5}{h * 1e3:>7g}" + "".join(f"{m[s]['maxae']:>13.2e}" for s in STATE_NAMES)
                          + f"{derived:>10.2e}{near:>10.2e}{far:>10.2e}{result['speedup']:>7.1f}x"
                          f"{result['do_step_speedup']:>8.1f}x{'met' if met else 'missed':>7}", flush=True)
                    rows.append({"scenario": name, "seed": seed, "step_s": h, **summary(result),
                                 "rollover_maxae_delta": near, "elsewhere_maxae_delta": far, "goal_met": met})
        print(f"goal met in {sum(r['goal_met'] for r in rows)} of {len(rows)} runs")
        write_json(args.out, {"stop_time_s": args.stop_time, "rows": rows})


if __name__ == "__main__":
    main()
