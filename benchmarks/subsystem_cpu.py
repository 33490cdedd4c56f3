"""Whole-process CPU of a host case with generated feeders attached (issue 35's speed goal): the
feeders as one surrogate FMU each, as their hand-made aggregate, as their devices' native FMUs (the
full detail in opfmu's master), and the full detail in ANDES, each a fresh process timed whole.

    python benchmarks/subsystem_cpu.py [--case ieee39] [--at 16 25] [--units 100] [--repeats 3]
        [--stop 3] [--fault 4] [--out benchmarks/subsystem_cpu]

The feeder is the generator's (`opfmu grid feeder --units N --seed 0`; an operator is shipped for
N = 30 and 100), attached at each bus of --at. One contingency: a fault at --fault from 1.0 to 1.1 s
(1e-4 pu, ANDES' and opfmu's default for these cases), to --stop at h = 10 ms. Sides:

* surrogate, aggregate, reference: `opfmu grid run --case CASE --attach BUS=FILE:KIND ... --fault B
  --fault-start 1 --clear 1.1 --stop T --compare none --out DIR` (it writes result.csv, result.png,
  report.md, summary.json). An untimed first run of each fills the case and FMU caches; a timed run
  that built an FMU is thrown away and run again; the children keep their modules' bytecode as an
  installed package does (benchmarks/cases_cpu.py).
* ANDES: what ANDES' user does with the joined case file (the one opfmu's --attach writes, its tap
  settled to the boundary's voltage), in a process of its own: `andes.load`, a Fault at the same bus
  and times, setup, power flow, TDS with the trapezoid at a fixed 10 ms to T.

The sides run in a rotating order, --repeats rounds; CPU is user + sys of the child (os.wait4),
medians reported, with each side's run alone (summary.json's timing: the master's loop, no start-up)
where opfmu runs it. Writes OUT.json and OUT.md. Needs ANDES.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from cases_cpu import CLEAR, FAULT_START, OPFMU, andes_run, checked, timed  # noqa: E402

STEP = 0.01  # s
KINDS = ("surrogate", "aggregate", "reference")


def commands(args, feeder: Path, joined: Path, work: Path) -> dict:
    """{side: argv} of the four sides."""
    cmds = {}
    for kind in KINDS:
        attach = [a for bus in args.at for a in ("--attach", f"{bus}={feeder}:{kind}")]
        cmds[kind] = [sys.executable, "-c", OPFMU, "grid", "run", "--case", args.case, *attach, "--fault", str(args.fault),
                      "--fault-start", repr(FAULT_START), "--clear", repr(CLEAR), "--stop", repr(args.stop),
                      "--step", repr(STEP), "--compare", "none", "--out", str(work / kind)]
    cmds["andes"] = [sys.executable, str(Path(__file__).resolve()), "--andes-child", str(joined), "--bus", str(args.fault),
                     "--stop", repr(args.stop)]
    return cmds


def run_time(folder: Path) -> float:
    """The master's loop time of an opfmu run (summary.json's timing total_s)."""
    timing = json.loads((folder / "summary.json").read_text())["timing"]
    return next(iter(timing.values()))["total_s"]


def measure(args, work: Path) -> dict:
    from reference_models.grid.andes_case import ANDES_CASES, case_cache_dir, stock_case
    from reference_models.grid.attach import attached_file
    from reference_models.grid.subsystems import FeederSpec, feeder, write_case

    feeder_file = work / f"feeder{args.units}.json"
    write_case(feeder(FeederSpec(units=args.units, seed=0)), feeder_file)
    joined = attached_file(stock_case(ANDES_CASES[args.case]), [(bus, feeder_file) for bus in args.at],
                           case_cache_dir() / "attached")
    cmds = commands(args, feeder_file, joined, work)
    sides = list(cmds)
    for side in sides:  # untimed: fills the caches, lets ANDES generate its code
        checked(side, args.case, timed(cmds[side], ROOT))
    runs = {side: [] for side in sides}
    rounds = attempts = 0
    while rounds < args.repeats and attempts < 3 * args.repeats:
        attempts += 1
        order = sides[rounds % len(sides):] + sides[:rounds % len(sides)]
        done = {side: checked(side, args.case, timed(cmds[side], ROOT)) for side in order}
        if any("\nbuilding " in "\n" + done[side]["stderr"] for side in KINDS):
            continue  # the builders' sources changed under the benchmark: the round again
        for side in sides:
            record = {key: done[side][key] for key in ("cpu_s", "wall_s")}
            if side in KINDS:
                record["run_s"] = run_time(work / side)
            runs[side].append(record)
        rounds += 1
        print("  " + ", ".join(f"{side} {done[side]['cpu_s']:.2f} s CPU" for side in order), file=sys.stderr, flush=True)
    medians = {side: {key: statistics.median(r[key] for r in runs[side]) for key in runs[side][0]} for side in sides}
    return {"case": args.case, "at": args.at, "units": args.units, "fault_bus": args.fault, "stop_s": args.stop,
            "step_s": STEP, "runs": runs, "median": medians,
            "over_surrogate": {side: statistics.median(r["cpu_s"] / s["cpu_s"] for r, s in zip(runs[side], runs["surrogate"]))
                               for side in sides}}


def table(result: dict) -> str:
    names = {"surrogate": "surrogate FMU per feeder", "aggregate": "hand-made aggregate, native FMUs",
             "reference": "full detail, native FMUs", "andes": "full detail, ANDES (10 ms)"}
    lines = [f"{result['case']} with a {result['units']}-unit feeder at bus {', '.join(map(str, result['at']))}, "
             f"a fault at bus {result['fault_bus']} from 1.0 to 1.1 s, {result['stop_s']:g} s at h = 10 ms; "
             "whole process, medians:", "",
             "| feeders run as | CPU [s] | over the surrogate's | wall [s] | run alone [s] |",
             "| --- | ---: | ---: | ---: | ---: |"]
    for side, m in result["median"].items():
        alone = f"{m['run_s']:.2f}" if "run_s" in m else "-"
        lines.append(f"| {names[side]} | {m['cpu_s']:.2f} | {result['over_surrogate'][side]:.2f} | {m['wall_s']:.1f} | {alone} |")
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--case", default="ieee39")
    parser.add_argument("--at", type=int, nargs="+", default=[16, 25])
    parser.add_argument("--units", type=int, default=100)
    parser.add_argument("--fault", type=int, default=4)
    parser.add_argument("--stop", type=float, default=3.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "subsystem_cpu"))
    parser.add_argument("--andes-child", help=argparse.SUPPRESS)
    parser.add_argument("--bus", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.andes_child:
        andes_run(args.andes_child, args.bus, STEP, args.stop)
        return
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="opfmu_subsystem_cpu_") as work:
        result = measure(args, Path(work))
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout
    result.update(cpus=os.cpu_count(), commit=commit.strip(), load_average_1min=[round(load, 2), round(os.getloadavg()[0], 2)])
    out = Path(args.out)
    out.with_suffix(".json").write_text(json.dumps(result, indent=1))
    out.with_suffix(".md").write_text(table(result) + "\n")
    print(table(result))
    print(f"written: {out.with_suffix('.json')}, {out.with_suffix('.md')}")


if __name__ == "__main__":
    main()
