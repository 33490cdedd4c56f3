"""Critical clearing times of the cases converted from ANDES, by native reference FMUs or surrogate
FMUs through the co-simulation master, by the monolithic DAE and by ANDES' own simulation, each
bisected to the same resolution (issue 26's goal: the FMUs at h = 10 ms within 5 ms of ANDES'
bisection). The surrogate kind puts a surrogate FMU on every machine its dynamic data name an operator
for (kundur's four) and native FMUs on the rest.

    python benchmarks/cases_cct.py [--cases kundur ieee14] [--kinds reference surrogate monolithic andes]
        [--fmu-step 0.01] [--andes-step 0.001] [--resolution 0.001] [--fault-impedance 1e-4]
        [--faults 7,5:5-6] [--out runs/benchmarks/cases_cct.png]

Per case a few faults from FAULTS (or --faults: BUS or BUS:TRIP, for every case given), with and without a line opened at clearing, each from 1.0 s (the
cases' own events start at 1 s or later; they are not applied here) with the reactance
--fault-impedance [pu] (ANDES' Newton stalls at a bolted fault). Every run lasts until
cosim.stability.default_stop (the fault start + 4 s: a second-swing loss is seen); a run is stable
when no two rotor angles get pi apart (ANDES' own criterion, ddelta_limit 180 deg). The native FMUs
bisect from the 50 ms bracket (cosim.stability.critical_clearing_time); the monolithic DAE (rtol
1e-9, rows every --fmu-step) and ANDES (implicit trapezoid at --andes-step) bisect on the grid of
whole resolutions from a bracket around the FMUs' CCT (the same answer, fewer runs). Printed per
fault: the CCTs [s], their differences from ANDES' [ms], the runs and wall time of each bisection,
and the latest loss of synchronism after the fault start among the runs (how long a run must last).
The PNG draws the CCTs side by side. Needs ANDES for the andes kind (pip install andes==2.0.0).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

FAULTS = {"kundur": [(7, None), (5, "5-6")],
          "ieee14": [(4, None), (4, "4-5")],
          "ieee39": [(16, None), (16, "16-17")],
          "npcc": [(30, None), (30, "29-30")]}
FAULT_START_S = 1.0
LABELS = {"reference": "native FMUs", "surrogate": "surrogate FMUs", "monolithic": "monolithic", "andes": "ANDES"}


def _runner(kind, case, fmu_step, andes_step):
    from cosim.master import MasterSettings
    from cosim.runners import open_runner

    step = andes_step if kind == "andes" else fmu_step
    return open_runner(kind, case, MasterSettings(step=step), monolithic_rtol=1e-9)


def cct_of(runner, contingency, resolution, guess=None) -> dict:
    """One bisection: cct_s, unstable_s, runs, wall_s and the latest loss of synchronism after the fault
    start [s] among its unstable runs."""
    from cosim.stability import critical_clearing_time, default_stop, run_verdict

    losses = []

    def stable(c):
        ok, lost, _ = run_verdict(runner, c, default_stop(c))
        if lost is not None:
            losses.append(lost - c.fault_start)
        return ok

    started = time.perf_counter()
    cct = critical_clearing_time(stable, contingency, resolution, guess=guess)
    return {"cct_s": cct.cct_s, "unstable_s": cct.unstable_s, "bounded": cct.bounded, "runs": len(cct.runs),
            "wall_s": time.perf_counter() - started, "latest_loss_s": max(losses) if losses else None}


def measure(name: str, kinds, fmu_step: float, andes_step: float, resolution: float, reactance: float,
            faults=None) -> list:
    """The rows of one case: per fault {case, bus, trip, kind: cct_of(...) or {"error": text}}."""
    from reference_models.grid.case import shipped_case
    from reference_models.grid.contingency import Contingency

    case = shipped_case(name)
    runners, errors = {}, {}
    for kind in kinds:
        try:
            runners[kind] = _runner(kind, case, fmu_step, andes_step)
        except Exception as exc:  # a kind that cannot run this case yet: reported in its cell
            errors[kind] = " ".join(str(exc).split())[:120]
    rows = []
    try:
        for bus, trip in faults or FAULTS[name]:
            c = Contingency(bus, FAULT_START_S + 0.05, trip, FAULT_START_S, complex(0.0, reactance), case.network)
            row = {"case": name, "bus": bus, "trip": trip or ""}
            guess = None
            for kind in kinds:
                if kind in errors:
                    row[kind] = {"error": errors[kind]}
                    continue
                try:
                    row[kind] = cct_of(runners[kind], c, resolution, guess)
                except Exception as exc:
                    row[kind] = {"error": " ".join(str(exc).split())[:120]}
                    continue
                print(f"  {name} bus {bus} {trip or '-'} {kind}: {row[kind]}", file=sys.stderr, flush=True)
                if guess is None and row[kind]["bounded"] and row[kind]["cct_s"] is not None:
                    guess = row[kind]["cct_s"]
            rows.append(row)
            print(line(row, kinds), flush=True)
    finally:
        for runner in runners.values():
            runner.close()
    return rows


def _cell(r) -> str:
    if "error" in r:
        return "n/a"
    if r["cct_s"] is None:
        return "<res"
    return f"{r['cct_s']:.3f}" + ("" if r["bounded"] else "+")


def header(kinds) -> str:
    diffs = [f"{LABELS[k][:10]}-ANDES" for k in kinds if k != "andes"] if "andes" in kinds else []
    return (f"{'case':7} {'bus':>4} {'trip':>6} " + " ".join(f"{LABELS[k][:11] + ' [s]':>15}" for k in kinds)
            + "".join(f" {d + ' [ms]':>22}" for d in diffs) + "   runs / wall [s] / latest loss after fault [s]")


def line(row, kinds) -> str:
    text = f"{row['case']:7} {row['bus']:>4} {row['trip'] or '-':>6} " + " ".join(f"{_cell(row[k]):>15}" for k in kinds)
    if "andes" in kinds:
        a = row["andes"]
        for k in kinds:
            if k == "andes":
                continue
            r = row[k]
            ok = "error" not in r and "error" not in a and r["cct_s"] is not None and a["cct_s"] is not None
            text += f" {(r['cct_s'] - a['cct_s']) * 1e3:>22.1f}" if ok else f" {'n/a':>22}"
    for k in kinds:
        r = row[k]
        if "error" in r:
            text += f"  {k}: {r['error']}"
        else:
            loss = "-" if r["latest_loss_s"] is None else f"{r['latest_loss_s']:.2f}"
            text += f"  {r['runs']}/{r['wall_s']:.0f}/{loss}"
    return text


def plot(rows, kinds, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(max(6.0, 1.1 * len(rows) + 2), 4.0))
    x = np.arange(len(rows))
    width = 0.8 / len(kinds)
    for j, kind in enumerate(kinds):
        ms = [(r[kind]["cct_s"] - FAULT_START_S) * 1e3 if "error" not in r[kind] and r[kind]["cct_s"] is not None
              else np.nan for r in rows]
        ax.bar(x + (j - (len(kinds) - 1) / 2) * width, ms, width, label=LABELS[kind])
    ax.set_xticks(x, [f"{r['case']}\nbus {r['bus']}" + (f"\n{r['trip']} open" if r["trip"] else "") for r in rows],
                  fontsize=8)
    ax.set_ylabel("critical fault duration [ms]")
    ax.set_title("CCT of the ANDES cases: native FMUs and monolithic DAE against ANDES")
    ax.legend(fontsize=8)
    fig.tight_layout()
    from reference_models.files import write_png

    write_png(path, fig)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", default=["kundur", "ieee14"], choices=list(FAULTS))
    parser.add_argument("--kinds", nargs="+", default=["reference", "monolithic", "andes"], choices=list(LABELS))
    parser.add_argument("--fmu-step", type=float, default=0.01)
    parser.add_argument("--andes-step", type=float, default=0.001)
    parser.add_argument("--resolution", type=float, default=0.001)
    parser.add_argument("--fault-impedance", type=float, default=1e-4)
    parser.add_argument("--faults", default=None, help="BUS or BUS:TRIP, comma separated (default: FAULTS)")
    parser.add_argument("--out", default="runs/benchmarks/cases_cct.png")
    args = parser.parse_args(argv)
    faults = None
    if args.faults:
        faults = [(int(f.split(":")[0]), f.split(":")[1] if ":" in f else None) for f in args.faults.split(",")]
    print(f"faults from {FAULT_START_S:g} s (x = {args.fault_impedance:g} pu), resolution "
          f"{args.resolution * 1e3:g} ms; FMUs and monolithic rows every {args.fmu_step * 1e3:g} ms, ANDES at "
          f"h = {args.andes_step * 1e3:g} ms ('+': stable up to 1 s of fault)")
    print(header(args.kinds), flush=True)
    rows = []
    for name in args.cases:
        rows += measure(name, args.kinds, args.fmu_step, args.andes_step, args.resolution, args.fault_impedance,
                        faults)
    plot(rows, args.kinds, Path(args.out))
    print(f"written: {args.out}")


if __name__ == "__main__":
    main()
