"""Speed side by side on the large ANDES cases, in one process on one machine: native reference FMUs
through the co-simulation master (h = 10 ms), the monolithic DAE, and ANDES' own simulation at
h = 10 ms and at the step of the same accuracy as the FMU run (issue 26's goal: IEEE 39 with
native FMUs in no more wall time than ANDES at h = 10 ms).

    python benchmarks/cases_speed.py [--cases ieee39 npcc] [--stop 5] [--screening 3]
        [--out runs/benchmarks/cases_speed.png]

Per case: one contingency (a fault at FAULT_BUS from 1.0 to 1.1 s, reactance 1e-4 pu, no trip, the
case's own events left out) to --stop, run by
* ANDES at h = 1 ms: the reference of the angle errors (not timed against the others);
* native FMUs at h = 10 ms (built before, into the FMU cache; the build is not timed): wall time
  split by the master's Timing into FMU steps, network solves, rollback (FMU state get/set) and
  the rest;
* the monolithic DAE (scipy DOP853, rtol 1e-9), rows every 10 ms;
* ANDES (implicit trapezoid, fixed step) at h = 10 ms, and at every step of ANDES_STEPS: the largest
  whose angle error is no larger than the FMU run's is "ANDES at equal accuracy".
The angle error of a run is the largest error of any rotor-angle difference to the first machine
against ANDES at 1 ms, at the run's rows [deg]. Wall and CPU time [s] of each run (CPU: this
process, all threads; the machine may be shared) and the ratio of each wall time to the FMUs'.
Then a screening of --screening contingencies (faults at the case's first buses without a
generator, from 1.0 s, cleared at 1.1 s; verdict runs, no CCT bisection) with each kind in this
process (cosim.screening.screen, 0 workers). The PNG draws the wall times, the FMU run's split
stacked. Needs ANDES (pip install andes==2.0.0).
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

FAULT_BUS = {"kundur": 8, "ieee14": 4, "ieee39": 16, "npcc": 30}
ANDES_STEPS = (1 / 30, 0.02, 0.01, 0.005, 0.002)  # s, largest first (1/30: ANDES' default)
FMU_STEP = 0.01
SPLIT = ("fmu_step_s", "network_s", "rollback_s", "overhead_s")


def angle_error_deg(result, reference) -> float:
    """Largest |(delta_i - delta_1) - reference's| over the units and `result`'s rows [deg]."""
    import numpy as np

    from cosim.outputs import on_times

    d = result.angles
    r = on_times(reference, result.time, reference.angles)
    return math.degrees(float(np.nanmax(np.abs((d - d[:, :1]) - (r - r[:, :1])))))


def timed(runner, contingency, stop):
    """(GridResult, timing dict with wall_s and cpu_s) of one run."""
    wall, cpu = time.perf_counter(), time.process_time()
    result, timing = runner.run(contingency, stop)
    return result, {**{k: v for k, v in timing.items() if isinstance(v, (int, float))},
                    "wall_s": time.perf_counter() - wall, "cpu_s": time.process_time() - cpu}


def screening_time(case, kind, files, settings, contingencies, stop) -> dict:
    """Wall and CPU time [s] of a verdict screening of `contingencies` by one kind in this process."""
    from cosim.screening import ScreeningTask, screen

    tasks = [ScreeningTask(case, c, kind, files, settings, stop, 1e-3, cct=False) for c in contingencies]
    wall, cpu = time.perf_counter(), time.process_time()
    rows = screen(tasks, workers=0, progress=False)
    return {"wall_s": time.perf_counter() - wall, "cpu_s": time.process_time() - cpu,
            "stable": sum(bool(r["stable"]) for r in rows)}


def measure(name: str, stop: float, n_screen: int) -> dict:
    """Every number of one case (see the module docstring); a kind that fails is {"error": text}."""
    from dataclasses import replace

    from cosim.andes_runner import AndesRunner
    from cosim.fmus import generator_files
    from cosim.master import MasterSettings
    from cosim.runners import MasterRunner, MonolithicRunner
    from cosim.screening import default_fault_buses
    from reference_models.grid.case import shipped_case
    from reference_models.grid.contingency import Contingency

    case = shipped_case(name)
    fault = complex(0.0, 1e-4)
    c = Contingency(FAULT_BUS[name], 1.1, None, 1.0, fault, case.network)
    screened = [Contingency(b, 1.1, None, 1.0, fault, case.network)
                for b in default_fault_buses(case.network)[:n_screen]]
    settings = MasterSettings(step=FMU_STEP)
    out = {"case": name, "units": len(case.units), "buses": len(case.buses), "runs": {}, "screening": {}}

    def note(text):
        print(f"  {name}: {text}", file=sys.stderr, flush=True)

    reference, t = timed(AndesRunner(case, 0.001), c, stop)
    out["runs"]["ANDES h=1 ms (reference)"] = {**t, "angle_deg": 0.0}
    note(f"ANDES 1 ms {t['wall_s']:.1f} s")
    files = None
    try:
        started = time.perf_counter()
        files = tuple(generator_files(case, "reference"))
        out["build_s"] = time.perf_counter() - started
        runner = MasterRunner(files, case, settings)
        try:
            result, t = timed(runner, c, stop)
        finally:
            runner.close()
        out["runs"]["native FMUs h=10 ms"] = {**t, "angle_deg": angle_error_deg(result, reference)}
    except Exception as exc:  # a case the FMUs cannot run yet: reported in its row
        out["runs"]["native FMUs h=10 ms"] = {"error": " ".join(str(exc).split())[:160]}
    note(f"FMUs {out['runs']['native FMUs h=10 ms']}")
    try:
        result, t = timed(MonolithicRunner(case, FMU_STEP, 1e-9), c, stop)
        out["runs"]["monolithic DAE"] = {**t, "angle_deg": angle_error_deg(result, reference)}
    except Exception as exc:
        out["runs"]["monolithic DAE"] = {"error": " ".join(str(exc).split())[:160]}
    note(f"monolithic {out['runs']['monolithic DAE']}")
    andes = {}
    for h in ANDES_STEPS:
        try:
            result, t = timed(AndesRunner(case, h), c, stop)
            andes[h] = {**t, "angle_deg": angle_error_deg(result, reference), "step_s": h}
        except Exception as exc:
            andes[h] = {"error": " ".join(str(exc).split())[:160], "step_s": h}
        note(f"ANDES {h * 1e3:.3g} ms {andes[h]}")
    out["runs"]["ANDES h=10 ms"] = andes[0.01]
    fmu = out["runs"]["native FMUs h=10 ms"]
    if "error" not in fmu:
        equal = [h for h in ANDES_STEPS if "error" not in andes[h] and andes[h]["angle_deg"] <= fmu["angle_deg"]]
        h_eq = max(equal) if equal else 0.001
        out["runs"][f"ANDES equal accuracy (h={h_eq * 1e3:.3g} ms)"] = (
            andes[h_eq] if h_eq in andes else out["runs"]["ANDES h=1 ms (reference)"])
        out["equal_step_s"] = h_eq
    out["andes_steps"] = andes
    kinds = [("native FMUs h=10 ms", "reference", files, settings), ("monolithic DAE", "monolithic", (), settings),
             ("ANDES h=10 ms", "andes", (), replace(settings, step=0.01))]
    if "equal_step_s" in out and out["equal_step_s"] != 0.01:
        kinds.append(("ANDES equal accuracy", "andes", (), replace(settings, step=out["equal_step_s"])))
    for label, kind, kind_files, kind_settings in kinds:
        if kind == "reference" and files is None:
            continue
        try:
            out["screening"][label] = screening_time(case, kind, kind_files, kind_settings, screened, stop)
        except Exception as exc:
            out["screening"][label] = {"error": " ".join(str(exc).split())[:160]}
        note(f"screening {label} {out['screening'][label]}")
    out["n_screen"] = len(screened)
    return out


def table(r: dict) -> str:
    """The printed table of one case."""
    fmu = r["runs"].get("native FMUs h=10 ms", {})
    base = fmu.get("wall_s")
    lines = [f"{r['case']} ({r['units']} units, {r['buses']} buses), one 5 s contingency"
             + (f"; FMU build (cached) {r['build_s']:.1f} s" if "build_s" in r else ""),
             f"  {'run':38} {'wall [s]':>9} {'CPU [s]':>8} {'/ FMUs':>7} {'angle err [deg]':>16}"]
    for label, t in r["runs"].items():
        if "error" in t:
            lines.append(f"  {label:38} n/a: {t['error']}")
            continue
        ratio = f"{t['wall_s'] / base:7.2f}" if base else f"{'-':>7}"
        lines.append(f"  {label:38} {t['wall_s']:9.2f} {t['cpu_s']:8.2f} {ratio} {t['angle_deg']:16.3f}")
    if base:
        lines.append("  FMU run split [s]: " + ", ".join(f"{k[:-2].replace('_', ' ')} {fmu[k]:.2f}" for k in SPLIT)
                     + f" ({fmu.get('steps', 0)} steps, {fmu.get('passes', 0)} passes)")
    lines.append("  ANDES steps: " + ", ".join(
        f"{h * 1e3:.3g} ms {t['angle_deg']:.3f} deg {t['wall_s']:.1f} s" if "error" not in t else f"{h * 1e3:.3g} ms n/a"
        for h, t in r["andes_steps"].items()))
    lines.append(f"  screening of {r['n_screen']} contingencies (verdict runs, one process):")
    sbase = r["screening"].get("native FMUs h=10 ms", {}).get("wall_s")
    for label, t in r["screening"].items():
        if "error" in t:
            lines.append(f"    {label:36} n/a: {t['error']}")
        else:
            ratio = f"{t['wall_s'] / sbase:7.2f}" if sbase else f"{'-':>7}"
            lines.append(f"    {label:36} {t['wall_s']:9.2f} {t['cpu_s']:8.2f} {ratio}  ({t['stable']} stable)")
    return "\n".join(lines)


def plot(results, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(5.5 * len(results), 4.0), squeeze=False)
    for ax, r in zip(axes[0], results):
        labels = [k for k, t in r["runs"].items() if "error" not in t and not k.startswith("ANDES h=1 ms")]
        for i, label in enumerate(labels):
            t = r["runs"][label]
            if label.startswith("native"):
                bottom = 0.0
                for key in SPLIT:
                    ax.bar(i, t[key], bottom=bottom, label=key[:-2].replace("_", " "))
                    bottom += t[key]
            else:
                ax.bar(i, t["wall_s"], color="0.5")
        ax.set_xticks(range(len(labels)), [l.replace(" (", "\n(").replace(" h=", "\nh=") for l in labels], fontsize=7)
        ax.set_ylabel("wall time [s]")
        ax.set_title(f"{r['case']}: one 5 s contingency", fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    from reference_models.files import write_png

    write_png(path, fig)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", default=["ieee39", "npcc"], choices=list(FAULT_BUS))
    parser.add_argument("--stop", type=float, default=5.0)
    parser.add_argument("--screening", type=int, default=3, help="contingencies in each screening")
    parser.add_argument("--out", default="runs/benchmarks/cases_speed.png")
    args = parser.parse_args(argv)
    results = []
    for name in args.cases:
        r = measure(name, args.stop, args.screening)
        results.append(r)
        print(table(r), flush=True)
    plot(results, Path(args.out))
    print(f"written: {args.out}")


if __name__ == "__main__":
    main()
