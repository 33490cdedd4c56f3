"""Do the WSCC 9-bus machine operators cover what their machines see in the grid issue's faults?

    python benchmarks/wscc9_operator_envelopes.py [--operators surrogate/default] [--stop 5]

For every contingency of benchmarks/wscc9_envelope.py (bolted faults at buses 4-9 cleared after
3-6 cycles, with and without a line trip at clearing; exciters in; the monolithic reference at
1 ms) and every machine, every window an FMU could start (every 10 ms, and on both sides of the
fault and of its clearing, where the surrogate FMU restarts its window) is taken into that
machine's operator's window frame (reference_models/drift.py) exactly as the FMU does: the start
state and the inputs at the operator's sensor times over its horizon. A window is covered when its
start state and every input value lie inside the operator's training envelope (the file's
`envelope`). Every window is also evaluated: the operator from the monolithic state under the
monolithic inputs against the monolithic states over the window, up to the rollover horizon the
FMU uses (its open-loop single-window error on the grid's own windows). Prints per machine the
share of covered windows (stable runs; and all runs), the window errors (median and worst of the
per-window MaxAE), and, per quantity, the range met against the range trained; writes
benchmarks/wscc9_operator_envelopes.json.
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from reference_models.drift import to_frame
from reference_models.files import write_json
from reference_models.grid import monolithic, wscc9
from reference_models.grid.contingency import Contingency
from reference_models.grid.windows import machine_windows, window_starts
from reference_models.progress import progress_bar
from reference_models.sm4 import SM4

sys.path.insert(0, str(Path(__file__).resolve().parent))
from wscc9_envelope import contingencies  # noqa: E402

OPERATORS = {1: "wscc9_gen1.onnx", 2: "wscc9_gen2.onnx", 3: "wscc9_gen3.onnx"}
SAMPLE_S = 0.001
STARTS_EVERY_S = 0.01


def load(directory: Path) -> dict:
    """{generator bus: (Operator, its envelope bounds (low [n_x + n_u], high))}."""
    from surrogate import Operator

    out = {}
    for bus, name in OPERATORS.items():
        op = Operator.load(directory / name)
        low = np.array([op.envelope["x0"][n][0] for n in op.state_names] + [op.envelope["u"][n][0] for n in op.input_names])
        high = np.array([op.envelope["x0"][n][1] for n in op.state_names] + [op.envelope["u"][n][1] for n in op.input_names])
        out[bus] = (op, low, high, op.rollover_horizon)
    return out


def windows_of(case: tuple, stop: float, operators: dict) -> dict:
    """Per machine: (covered [n_windows] bool, low [n_x + n_u], high, window MaxAE [n_windows, n_x]
    up to the rollover horizon) of the windows of one run."""
    bus, cycles, trip = case
    clear = cycles / 60.0
    t = np.round(np.arange(0.0, stop + 1e-9, SAMPLE_S), 9)
    r = monolithic.simulate(monolithic.System(wscc9.case()), Contingency(bus, clear, trip), stop, t_eval=t, event_rows=True)
    out = {"stable": bool(r.stable)}
    for k, gen in enumerate(r.gen_buses):
        op, low, high, rollover = operators[gen]
        grid = np.linspace(0.0, op.horizon, op.n_sensors)
        starts = window_starts(r, op.horizon, STARTS_EVERY_S, events=(clear,))
        t_used = grid[grid <= rollover + 1e-9]
        x0, u, truth = machine_windows(r, k, starts, grid, t_used, SM4.state_names, SM4.input_names)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # windows outside the envelope are counted, not warned about
            predicted = op.predict(x0, u, t_used).astype(np.float64)
        errors = np.abs(predicted - truth).max(axis=1)
        x0_f, u_f, _, _ = to_frame(op.frame, x0, u, grid)
        values_low = np.concatenate([x0_f, u_f.min(axis=1)], axis=1)
        values_high = np.concatenate([x0_f, u_f.max(axis=1)], axis=1)
        covered = np.all((values_low >= low - 1e-6) & (values_high <= high + 1e-6), axis=1)
        out[gen] = (covered, values_low.min(0), values_high.max(0), errors)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--operators", default="surrogate/default", help="directory of wscc9_gen{1,2,3}.onnx")
    parser.add_argument("--stop", type=float, default=5.0, help="seconds per contingency (default 5)")
    parser.add_argument("--out", default="benchmarks/wscc9_operator_envelopes.json")
    args = parser.parse_args()
    missing = [name for name in OPERATORS.values() if not (Path(args.operators) / name).exists()]
    if missing:
        sys.exit(f"no {', '.join(missing)} in {args.operators}: train them with `opfmu operator --recipe grid` "
                 "(docs/results.md, WSCC 9-bus machine operators) and point --operators there")
    operators = load(Path(args.operators))
    started = time.perf_counter()
    cases = contingencies()
    runs = []
    bar = progress_bar(total=len(cases), desc="contingencies", unit="run")
    for case in cases:
        runs.append((case, windows_of(case, args.stop, operators)))
        bar.update(1)
    bar.close()
    op0 = operators[1][0]
    names = list(op0.state_names) + list(op0.input_names)
    report = {"stop_s": args.stop, "contingencies": len(cases), "wall_s": round(time.perf_counter() - started, 1),
              "machines": {}}
    for gen, (op, low, high, rollover) in operators.items():
        entry = {}
        for subset in ("stable", "all"):
            chosen = [w[gen] for _, w in runs if w["stable"] or subset == "all"]
            covered = np.concatenate([c for c, _, _, _ in chosen])
            errors = np.concatenate([e for _, _, _, e in chosen])
            met_low = np.min([lo for _, lo, _, _ in chosen], axis=0)
            met_high = np.max([hi for _, _, hi, _ in chosen], axis=0)
            entry[subset] = {
                "windows": int(covered.size), "covered_share": float(covered.mean()),
                "met": {n: [float(a), float(b)] for n, a, b in zip(names, met_low, met_high)},
                "window_maxae_median": dict(zip(op.state_names, map(float, np.median(errors, axis=0)))),
                "window_maxae_p99": dict(zip(op.state_names, map(float, np.percentile(errors, 99, axis=0)))),
                "window_maxae_worst": dict(zip(op.state_names, map(float, errors.max(axis=0)))),
            }
        entry["trained"] = {n: [float(a), float(b)] for n, a, b in zip(names, low, high)}
        entry["horizon_s"], entry["rollover_horizon_s"] = op.horizon, rollover
        report["machines"][str(gen)] = entry
        print(f"\nmachine {gen} (operator horizon {op.horizon:g} s): windows covered "
              f"{100 * entry['stable']['covered_share']:.1f} % of {entry['stable']['windows']} (stable runs), "
              f"{100 * entry['all']['covered_share']:.1f} % of {entry['all']['windows']} (all runs)")
        for label, key in (("median", "window_maxae_median"), ("99th percentile", "window_maxae_p99"),
                           ("worst", "window_maxae_worst")):
            print(f"window MaxAE over {rollover:g} s, {label} (stable runs): " + ", ".join(
                f"{n} {v:.2e}" for n, v in entry["stable"][key].items()))
        print(f"{'quantity':<10}{'met (stable) min':>18}{'max':>10}{'trained min':>14}{'max':>10}")
        for n in names:
            a, b = entry["stable"]["met"][n]
            c, d = entry["trained"][n]
            flag = "" if c - 1e-6 <= a and b <= d + 1e-6 else "   <- outside"
            print(f"{n:<10}{a:>18.4g}{b:>10.4g}{c:>14.4g}{d:>10.4g}{flag}")
    write_json(Path(args.out), report)
    print(f"\nwrote {args.out} ({report['wall_s']} s)")


if __name__ == "__main__":
    main()
