"""Model Exchange of the native reference FMUs under fmpy's CVode against their co-simulation: for
every standard model (reference_models.models) its FMI 2.0 native reference FMU, driven by the input
run of tests/test_standard_model_fmus.py (RUNS, with that file's PARAMS), simulated by fmpy's
`simulate_fmu` as ModelExchange (solver CVode, relative tolerance 1e-10) and as CoSimulation with
the same piecewise-constant inputs, 10 ms output interval. Compared at the communication points,
over the states and outputs: the largest difference, per variable divided by that variable's scale
max(1, max |co-simulation value|), over all of them. Where Model Exchange has an event at a point it
records rows before and after it: the one nearer co-simulation counts (the row before, as a
co-simulation step ends before the next starts, unless the event falls on the point to rounding);
outputs are not compared at the instants the inputs step (see `compare`).

    python benchmarks/model_exchange.py [--only MODEL ...] [--cache DIR] [--fmi-version 2|3] [--out FILE]

Run from the repository root (PYTHONPATH=. where opfmu is not installed). FMUs are built through the
content-keyed build cache (--cache, default $OPFMU_FMU_CACHE or ~/.cache/opfmu/fmus): a rerun takes a
few seconds per model. Writes the table to stdout and, in full runs, benchmarks/model_exchange.json
(--out to choose; partial runs with --only write only where --out is given). Status: "agrees"
(within 1e-6 of scale, the goal), "differs" (runs, beyond 1e-6) or "fails: <reason>" (either run
raised); a model without continuous states has nothing to integrate and is listed "no states".
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))  # the input runs of the standard models' tests

from fmpy import simulate_fmu  # noqa: E402
from test_standard_model_fmus import PARAMS, RUNS  # noqa: E402

from fmu_export.build_cache import cached_native_reference_fmu, default_cache  # noqa: E402
from reference_models.models import STANDARD_MODELS  # noqa: E402

RTOL = 1e-10  # CVode's relative tolerance (its absolute one: this times the states' nominal, 1)
OUTPUT_INTERVAL = 0.01  # s
GOAL = 1e-6  # of the values' scale


def input_signal(component, pieces) -> np.ndarray:
    """fmpy's input table of a run given as pieces (until [s], {input: value}) from the start inputs:
    each piece's values at its start and its end, so a step is two rows at one instant."""
    start = dict(zip(component.input_names, component.start_inputs))
    rows, begin = [], 0.0
    for until, changes in pieces:
        values = [float({**start, **changes}[n]) for n in component.input_names]
        rows += [(begin, *values), (until, *values)]
        begin = until
    return np.array(rows, dtype=[("time", float)] + [(n, float) for n in component.input_names])


def compare(name: str, fmi_version: int, cache) -> dict:
    component = STANDARD_MODELS[name]
    path = cached_native_reference_fmu(f"{name}Reference", component, PARAMS.get(name), fmi_version=fmi_version,
                                       cache=cache)
    row = {"model": name, "states": component.n_states}
    if component.n_states == 0:
        return {**row, "difference": None, "worst": None, "at": None, "status": "no states"}
    signal = input_signal(component, RUNS[name])
    names = list(component.state_names) + list(component.output_names)
    runs, began = {}, time.perf_counter()
    for kind in ("CoSimulation", "ModelExchange"):
        try:
            runs[kind] = simulate_fmu(str(path), fmi_type=kind, solver="CVode", relative_tolerance=RTOL,
                                      stop_time=float(signal["time"][-1]), output_interval=OUTPUT_INTERVAL,
                                      input=signal, output=names)
        except Exception as exc:  # fmpy raises plain Exceptions (CVode's flags, the FMU's statuses)
            reason = " ".join(str(exc).split())[:200]
            return {**row, "difference": None, "worst": None, "at": None, "status": f"fails: {kind}: {reason}"}
    cs, me = runs["CoSimulation"], runs["ModelExchange"]
    rows = [np.flatnonzero(np.isclose(me["time"], t, rtol=0, atol=1e-9)) for t in np.round(cs["time"], 9)]
    if any(len(i) == 0 for i in rows):
        return {**row, "difference": None, "worst": None, "at": None, "status": "fails: ME misses output points"}
    scales = {n: max(1.0, float(np.max(np.abs(cs[n])))) for n in names}
    # an output that an input feeds through is not compared where the inputs step: fmpy's output grid
    # (k times the interval) can fall a rounding error past the step, where its Model Exchange loop
    # has already set the inputs after it (REGCP1's vq at 0.7 s: k = 70), its co-simulation not yet
    steps = np.array(signal["time"][1:-1])
    kept = ~np.any(np.isclose(cs["time"][:, None], steps[None, :], rtol=0, atol=1e-9), axis=1)

    def error(k, i, n):
        if n not in component.state_names and not kept[k]:
            return 0.0
        return abs(float(me[n][i]) - float(cs[n][k])) / scales[n]

    # Model Exchange records an event at a communication point before and after it: the row before
    # (as a co-simulation step ends before the next starts), or the one after where the event falls
    # on the point to rounding (ShuntSw's timer runs out at 0.34 s, located within the step ending
    # there): of the rows at the instant, the one nearer co-simulation
    at = [min(i, key=lambda j: max(error(k, j, n) for n in names)) for k, i in enumerate(rows)]
    worst, variable, instant = 0.0, None, None
    for n in names:
        e = np.array([error(k, i, n) for k, i in enumerate(at)])
        if not np.all(np.isfinite(e)):
            return {**row, "difference": None, "worst": n, "at": None, "status": "fails: non-finite values"}
        k = int(np.argmax(e))
        if e[k] > worst or variable is None:
            worst, variable, instant = float(e[k]), n, float(cs["time"][k])
    status = "agrees" if worst <= GOAL else "differs"
    return {**row, "difference": worst, "worst": variable, "at": instant, "status": status,
            "seconds": round(time.perf_counter() - began, 2)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", nargs="+", metavar="MODEL", help="these standard models only")
    parser.add_argument("--cache", default=None, help="FMU build cache (default $OPFMU_FMU_CACHE or ~/.cache/opfmu/fmus)")
    parser.add_argument("--fmi-version", type=int, choices=(2, 3), default=2)
    parser.add_argument("--out", default=None, help="JSON file (default benchmarks/model_exchange.json, full runs)")
    args = parser.parse_args(argv)
    names = sorted(STANDARD_MODELS) if not args.only else args.only
    unknown = [n for n in names if n not in STANDARD_MODELS]
    if unknown:
        parser.error(f"not standard models: {', '.join(unknown)} (known: {', '.join(sorted(STANDARD_MODELS))})")
    cache = args.cache or default_cache()
    rows = []
    print(f"{'model':<8} {'difference':>11}  {'worst':<12} {'at [s]':>7}  status")
    for name in names:
        r = compare(name, args.fmi_version, cache)
        rows.append(r)
        diff = "-" if r["difference"] is None else f"{r['difference']:.1e}"
        at = "-" if r["at"] is None else f"{r['at']:.2f}"
        print(f"{name:<8} {diff:>11}  {r['worst'] or '-':<12} {at:>7}  {r['status']}", flush=True)
    ran = [r for r in rows if r["status"] != "no states"]
    agree = [r for r in ran if r["status"] == "agrees"]
    print(f"\n{len(agree)} of {len(ran)} models with states agree within {GOAL:g} of scale"
          + (f" (largest {max(r['difference'] for r in agree):.1e})" if agree else ""))
    out = args.out or (None if args.only else str(HERE / "model_exchange.json"))
    if out:
        Path(out).write_text(json.dumps({"fmi_version": args.fmi_version, "relative_tolerance": RTOL,
                                         "output_interval": OUTPUT_INTERVAL, "goal": GOAL, "models": rows},
                                        indent=1) + "\n")
    return 0 if len(agree) == len(ran) else 1


if __name__ == "__main__":
    sys.exit(main())
