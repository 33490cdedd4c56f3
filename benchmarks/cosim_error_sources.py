"""Where the surrogate FMU's error comes from, per scenario: one run split into its sources.

    python benchmarks/cosim_error_sources.py [--operator OP.onnx] [--surrogate A.fmu] [--reference B.fmu]
        [--stop-time 10] [--step 0.01] [--scenarios ...] [--seeds 0] [--out error_sources.json]

For each run (both FMUs under fmpy, as `opfmu compare`), the operator is also evaluated in Python
(onnxruntime) window by window, windows of the FMU's rollover_horizon, each restarted from the
reference state at its start:

* FMU: the surrogate FMU as a user runs it (errors carried over from window to window);
* restarted, held future: every communication point evaluated as the FMU does (the FMU's step
  semantics, fmu_export.step_mirror, corrections off: sensor slots after the current step hold its
  input, in the window frame), but from the reference window-start state, as an FMU initialised
  there with the window's first input (its frame's origin): the error the FMU would have without
  what earlier windows left behind;
* restarted, known future: the same windows with every sensor slot at the input that really comes
  (hindsight): the operator's own error on that input.

The FMU's rest and slow-mode corrections and its exact swing step act in the first only: pass
--param rest_radius=0 --param slow_weight=0 --param swing_weight=0 to split the operator alone. So
FMU - restarted/held is the error carried over the rollovers, held - known is the error from not
knowing the future input, and known is the operator's accuracy on these inputs. Also reported: the
first window alone (the start from rest), and how many windows left the training envelope (their
reference start state or their inputs, in the window frame: angles from the window's first bus angle,
speeds from its start speed).
"""
from __future__ import annotations

import argparse
import tempfile
import warnings
from pathlib import Path

import numpy as np

from fmu_export.step_mirror import StepMirror
from opfmu.compare import compare, fmu_machine, scenario_inputs
from fmu_pair import extracted_pair, surrogate_parameters, surrogate_setting
from reference_models.files import write_json
from reference_models.scenarios import SCENARIOS
from reference_models.sm4 import STATE_NAMES
from surrogate.operator import DEFAULT_OPERATOR, EnvelopeWarning, Operator, OperatorInputError


def zoh(inputs_times: np.ndarray, inputs: np.ndarray, times: np.ndarray) -> np.ndarray:
    """The input held from each communication point to the next, at `times` [T] -> [T, n_u]."""
    index = np.searchsorted(inputs_times, times + 1e-9, side="right") - 1
    return inputs[np.clip(index, 0, len(inputs) - 1)]


def restarted(mirror: StepMirror, times: np.ndarray, inputs: np.ndarray, reference: np.ndarray, h: float,
              horizon: float):
    """(held, known): states [T, n_x] at the communication points times [T], windows of `horizon`
    seconds each restarted from the reference [T, n_x] at its start; inputs [T, n_u] held over each
    step of h. held: the FMU's step semantics without corrections; known: every sensor slot at the true
    input."""
    op = mirror.operator
    sensor_t = np.linspace(0.0, op.horizon, op.n_sensors)
    per_window = int(round(horizon / h))
    held, known = reference.copy(), reference.copy()
    for start in range(0, len(times) - 1, per_window):
        steps = np.arange(start, min(start + per_window, len(times) - 1))  # steps whose end is in this window
        t0, x0 = times[start], reference[start]
        held[steps + 1] = mirror.run(x0, [(h, *inputs[i]) for i in steps], rollover_horizon=horizon,
                                     u_init=inputs[start])
        u_true = zoh(times, inputs, t0 + sensor_t)
        known[steps + 1] = op.predict(x0[None].astype(np.float32), u_true[None], times[steps + 1] - t0)[0]
    return held, known


def windows_outside(op: Operator, times: np.ndarray, inputs: np.ndarray, reference: np.ndarray,
                    per_window: int) -> int:
    """How many windows (every per_window communication points) start from a reference state [T, n_x]
    or see inputs (held from each point to the next) outside the operator's envelope, in their frame."""
    sensor_t = np.linspace(0.0, op.horizon, op.n_sensors)
    return sum(bool(op.outside_envelope(reference[start][None], zoh(times, inputs, times[start] + sensor_t)[None]))
               for start in range(0, len(times) - 1, per_window))


def maxae(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs(a - b).max(axis=0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--operator", default=str(DEFAULT_OPERATOR))
    parser.add_argument("--surrogate", help="surrogate FMU of that operator (default: build it)")
    parser.add_argument("--reference", help="reference FMU (default: build it)")
    parser.add_argument("--stop-time", type=float, default=10.0)
    parser.add_argument("--step", type=float, default=0.01)
    parser.add_argument("--scenarios", nargs="+", default=list(SCENARIOS))
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                        help="a surrogate parameter, e.g. rollover_horizon=0.5 or restart_jump=0.02 (repeatable)")
    parser.add_argument("--out", default="error_sources.json")
    args = parser.parse_args()
    warnings.simplefilter("ignore", EnvelopeWarning)
    try:
        op = Operator.load(args.operator)
    except (OSError, OperatorInputError) as exc:
        parser.error(str(exc))

    with tempfile.TemporaryDirectory(prefix="opfmu_sources_") as tmp:
        tmp = Path(tmp)
        dirs = extracted_pair(args.surrogate, args.reference, tmp, args.operator)
        parameters = surrogate_parameters(args.param)
        horizon = surrogate_setting(dirs[0], "rollover_horizon", parameters)
        machine = fmu_machine(dirs[0])
        mirror = StepMirror(op, params=machine)
        per_window = int(round(horizon / args.step))
        print(f"{args.stop_time:g} s at h = {args.step * 1e3:g} ms; MaxAE of delta [rad] / omega [rad/s] / Eq_p [pu]")
        print(f"{'scenario':<8}{'seed':>5}{'FMU':>26}{'restarted, held':>26}{'restarted, known':>26}"
              f"{'first window':>26}{'outside':>9}")
        rows = []
        for name in args.scenarios:
            for seed in args.seeds:
                inputs = scenario_inputs(name, seed, args.stop_time, args.step, machine)
                result = compare(*dirs, inputs, args.stop_time, args.step, parameters)
                ref = np.stack([result["trajectories"]["reference"][s] for s in STATE_NAMES], axis=1)
                fmu = np.stack([result["trajectories"]["surrogate"][s] for s in STATE_NAMES], axis=1)
                held, known = restarted(mirror, inputs.times, inputs.values, ref, args.step, horizon)
                first = per_window + 1
                outside = windows_outside(op, inputs.times, inputs.values, ref, per_window)
                parts = {"fmu": maxae(fmu, ref), "held": maxae(held, ref), "known": maxae(known, ref),
                         "first_window": maxae(fmu[:first], ref[:first])}
                cells = "".join(f"{p[0]:>9.2e}/{p[1]:.2e}/{p[3]:.1e}" for p in parts.values())
                print(f"{name:<8}{seed:>5}{cells}{outside:>9}", flush=True)
                rows.append({"scenario": name, "seed": seed, "outside": outside,
                             **{k: dict(zip(STATE_NAMES, v.tolist())) for k, v in parts.items()}})
        write_json(args.out, {"stop_time_s": args.stop_time, "step_s": args.step, "operator": args.operator,
                              "rollover_horizon_s": horizon, "rows": rows})


if __name__ == "__main__":
    main()
