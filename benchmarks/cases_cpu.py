"""Whole-process CPU per shipped case: `opfmu grid run` with native reference FMUs against ANDES'
own time-domain simulation, both at h = 10 ms (issue 33's goal: no shipped case slower than ANDES
in whole-process CPU at the same step).

    python benchmarks/cases_cpu.py [--cases wscc9 kundur ieee14 ieee39 npcc] [--repeats 3]
        [--stop 5] [--step 0.01] [--json benchmarks/cases_cpu.json]

Per case, one contingency: a fault at FAULT_BUS[case] from 1.0 to 1.1 s (each side's default
fault reactance, 1e-4 pu for the cases converted from ANDES), the case's own events as its file has
them, to --stop. Two fresh processes, each timed whole (interpreter start, imports, loading the case,
set-up, power flow, the run, writing its output):

* opfmu: `opfmu grid run --case NAME --fmus reference --step H --stop T --fault B --clear 1.1
  --fault-start 1.0 --compare none --out DIR` (it writes result.csv, result.png, report.md and
  summary.json). Its FMUs come from the build cache: a first, untimed run of each case fills the
  cache, and a timed run that built an FMU (it says "building" on stderr: the builders' sources
  changed meanwhile) is thrown away and run again.
* ANDES: what ANDES' user does, in a Python process of its own (this file with --andes-child):
  `andes.load` of the case file (no output files), a Fault added at the same bus and times, setup,
  power flow, TDS with the implicit trapezoid at the fixed step H (fixt = 1, shrinkt = 0, no
  stability criteria) to T. A first, untimed run lets ANDES generate its code (~/.andes/pycode).

The processes of a case run paired and alternating (opfmu then ANDES, then ANDES then opfmu, ...),
--repeats pairs; each side's CPU time is user + sys of the child from os.wait4, the median over
the repeats is reported, with the wall time and the load average. wscc9 (Anderson & Fouad, two-axis
machines) has no dynamic counterpart in ANDES 2.0.0 (its wscc9 files are power flow only): its
opfmu time is reported alone. Needs ANDES (pip install andes==2.0.0).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASES = ("wscc9", "kundur", "ieee14", "ieee39", "npcc")
FAULT_BUS = {"wscc9": 7, "kundur": 8, "ieee14": 4, "ieee39": 16, "npcc": 30}
FAULT_START, CLEAR = 1.0, 1.1  # s
# ANDES' dynamic case files of the shipped cases (reference_models.grid.andes_case.ANDES_CASES); none for wscc9
ANDES_FILES = {"kundur": "kundur/kundur_full.xlsx", "ieee14": "ieee14/ieee14_full.xlsx",
               "ieee39": "ieee39/ieee39_full.xlsx", "npcc": "npcc/npcc.xlsx"}
OPFMU = "import sys; from opfmu.cli import main; sys.exit(main())"  # what the `opfmu` script runs
# The children keep their modules' bytecode as an installed package does (the untimed first run writes
# it): a shell that sets PYTHONDONTWRITEBYTECODE would make every opfmu process compile its own
# modules again (0.4-0.5 s), where ANDES' come compiled from pip.
CHILD_ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def andes_child(name: str, bus: int, step: float, stop: float) -> None:
    """ANDES' user's run of the shipped case `name` (see the module docstring)."""
    import andes

    andes_run(andes.get_case(ANDES_FILES[name]), bus, step, stop)


def andes_run(path, bus: int, step: float, stop: float) -> None:
    """ANDES' user's run of the case file `path`: a fault at `bus` from FAULT_START to CLEAR, the
    trapezoid at the fixed `step` to `stop` [s]; exits non-zero where it does not reach `stop`."""
    import andes

    andes.config_logger(stream_level=40)
    ss = andes.load(str(path), setup=False, no_output=True, default_config=True)
    idx = next(i for i in ss.Bus.idx.v if int(i) == bus)
    ss.add("Fault", {"bus": idx, "tf": FAULT_START, "tc": CLEAR})
    ss.setup()
    if not ss.PFlow.run():
        sys.exit("ANDES' power flow does not converge")
    ss.TDS.config.tf = stop
    ss.TDS.config.tstep = step
    ss.TDS.config.fixt = 1
    ss.TDS.config.shrinkt = 0
    ss.TDS.config.criteria = 0
    ss.TDS.config.no_tqdm = 1
    ss.TDS.run()
    if ss.dae.t < stop - 0.5 * step:
        sys.exit(f"ANDES stopped at t = {ss.dae.t:.4f} s")


def timed(cmd, cwd) -> dict:
    """One child process: {"cpu_s": user + sys, "wall_s", "rc", "stderr"} (its output to files)."""
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        wall = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=cwd, stdout=out, stderr=err, env=CHILD_ENV)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - wall
        proc.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        text = err.read().decode(errors="replace")
    return {"cpu_s": usage.ru_utime + usage.ru_stime, "user_s": usage.ru_utime, "sys_s": usage.ru_stime,
            "wall_s": wall, "rc": proc.returncode, "stderr": text}


def commands(name: str, step: float, stop: float, out: Path) -> dict:
    """{"opfmu": argv, "andes": argv or None} of one case."""
    b = str(FAULT_BUS[name])
    cmds = {"opfmu": [sys.executable, "-c", OPFMU, "grid", "run", "--case", name, "--fmus", "reference",
                      "--step", repr(step), "--stop", repr(stop), "--fault", b, "--clear", repr(CLEAR),
                      "--fault-start", repr(FAULT_START), "--compare", "none", "--out", str(out)],
            "andes": None}
    if name in ANDES_FILES:
        cmds["andes"] = [sys.executable, str(Path(__file__).resolve()), "--andes-child", name, "--bus", b,
                         "--step", repr(step), "--stop", repr(stop)]
    return cmds


def checked(kind: str, name: str, run: dict) -> dict:
    if run["rc"] != 0:
        tail = " ".join(run["stderr"].split())[-300:]
        raise RuntimeError(f"{kind} on {name} failed (exit {run['rc']}): {tail}")
    return run


def measure(name: str, repeats: int, step: float, stop: float, work: Path) -> dict:
    """The paired runs of one case: per side the runs' CPU and wall times and their medians."""
    cmds = commands(name, step, stop, work / name)
    sides = [k for k in ("opfmu", "andes") if cmds[k] is not None]
    for k in sides:  # untimed: fills the FMU cache, lets ANDES generate its code
        checked(k, name, timed(cmds[k], ROOT))
    runs = {k: [] for k in sides}
    rebuilt, attempts = 0, 0
    while len(runs["opfmu"]) < repeats and attempts < 3 * repeats:
        attempts += 1
        order = sides if len(runs["opfmu"]) % 2 == 0 else sides[::-1]
        pair = {}
        for k in order:
            pair[k] = checked(k, name, timed(cmds[k], ROOT))
        if "\nbuilding " in "\n" + pair["opfmu"]["stderr"]:
            rebuilt += 1  # the builders' sources changed under the benchmark: the pair again
            continue
        for k in sides:
            runs[k].append({key: pair[k][key] for key in ("cpu_s", "user_s", "sys_s", "wall_s")})
        print(f"  {name}: " + ", ".join(f"{k} {pair[k]['cpu_s']:.2f} s CPU ({pair[k]['wall_s']:.1f} s wall)"
                                        for k in order), file=sys.stderr, flush=True)
    out = {"case": name, "fault_bus": FAULT_BUS[name], "runs": runs, "pairs_rebuilt": rebuilt}
    for k in sides:
        out[k] = {"cpu_s": statistics.median(r["cpu_s"] for r in runs[k]),
                  "wall_s": statistics.median(r["wall_s"] for r in runs[k])}
    if "andes" in out:
        out["ratio"] = statistics.median(a["cpu_s"] / b["cpu_s"] for a, b in zip(runs["opfmu"], runs["andes"]))
    return out


def table(rows) -> str:
    lines = ["| case | opfmu CPU [s] | ANDES CPU [s] | opfmu / ANDES | opfmu wall [s] | ANDES wall [s] |",
             "| --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        a = r.get("andes")
        lines.append(f"| {r['case']} | {r['opfmu']['cpu_s']:.2f} | " + (f"{a['cpu_s']:.2f}" if a else "n/a") + " | "
                     + (f"{r['ratio']:.2f}" if a else "-") + f" | {r['opfmu']['wall_s']:.1f} | "
                     + (f"{a['wall_s']:.1f}" if a else "-") + " |")
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    parser.add_argument("--repeats", type=int, default=3, help="paired runs per case (the median is reported)")
    parser.add_argument("--stop", type=float, default=5.0)
    parser.add_argument("--step", type=float, default=0.01)
    parser.add_argument("--json", default=str(ROOT / "benchmarks" / "cases_cpu.json"))
    parser.add_argument("--note", default="", help="a note kept in the JSON (what was measured)")
    parser.add_argument("--andes-child", choices=list(ANDES_FILES), help=argparse.SUPPRESS)
    parser.add_argument("--bus", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.andes_child:
        andes_child(args.andes_child, args.bus, args.step, args.stop)
        return
    load = [os.getloadavg()]
    rows = []
    with tempfile.TemporaryDirectory(prefix="opfmu_cases_cpu_") as work:
        for name in args.cases:
            rows.append(measure(name, args.repeats, args.step, args.stop, Path(work)))
            load.append(os.getloadavg())
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout
    report = {"step_s": args.step, "stop_s": args.stop, "repeats": args.repeats, "cpus": os.cpu_count(),
              "load_average_1min": [round(x[0], 2) for x in load], "commit": commit.strip(), "note": args.note,
              "cases": rows}
    Path(args.json).write_text(json.dumps(report, indent=1))
    print(table(rows))
    print(f"load average (1 min) at the start and after each case: {', '.join(f'{x[0]:.1f}' for x in load)} "
          f"on {os.cpu_count()} CPUs; written: {args.json}")


if __name__ == "__main__":
    main()
