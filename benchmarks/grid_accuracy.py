"""Accuracy of the grid co-simulation against the monolithic DAE, per contingency and FMU kind, and
the critical clearing times of every fault/trip pair.

    python benchmarks/grid_accuracy.py [--clear 0.05,0.083,0.1] [--stop 5] [--no-cct] [--out DIR]

Contingencies: bolted faults at buses 4-9, without a trip and with each line at the bus that can
open without cutting a generator off, cleared at each --clear time. Each runs 5 s at h = 10 ms with
native reference FMUs and with surrogate FMUs (the shipped WSCC operators), exciters in, and is
compared with the monolithic DAE (DOP853, rtol 1e-10) at every communication point: rotor angles
relative to machine 1 [deg], terminal voltages outside the rows with the fault on [pu], the
stable/unstable verdict. Then the CCT of each fault/trip pair by bisection to 1 ms (3 s runs) with
each. Prints Markdown tables; writes DIR/grid_accuracy.json, grid_accuracy.md and grid_cct.png
(default DIR: benchmarks/).
"""
import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim.fmus import generator_files  # noqa: E402
from cosim.master import GridMaster, MasterSettings  # noqa: E402
from cosim.outputs import errors  # noqa: E402
from cosim.runners import MonolithicRunner  # noqa: E402
from cosim.stability import critical_clearing_time  # noqa: E402
from reference_models.grid import wscc9  # noqa: E402
from reference_models.grid.contingency import Contingency  # noqa: E402

KINDS = ("reference", "surrogate")


def pairs():
    return [(bus, trip) for bus in range(4, 10) for trip in (None, *wscc9.NETWORK.trips_at(bus))]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--clear", default="0.05,0.083,0.1")
    parser.add_argument("--stop", type=float, default=5.0)
    parser.add_argument("--no-cct", action="store_true")
    parser.add_argument("--out", default=str(Path(__file__).parent))
    args = parser.parse_args()
    clears = [float(c) for c in args.clear.split(",")]
    grid = wscc9.case()
    masters = {k: GridMaster(grid, generator_files(grid, k), MasterSettings()) for k in KINDS}
    mono = MonolithicRunner(grid)
    rows = []
    started = time.perf_counter()
    for bus, trip in pairs():
        for clear in clears:
            c = Contingency(bus, clear, trip)
            ref, _ = mono.run(c, args.stop)
            row = {"bus": bus, "trip": trip or "", "clear_s": clear, "monolithic_stable": ref.stable}
            for kind, master in masters.items():
                run = master.run(c, args.stop)
                e = errors(run.result, ref, (c.fault_start, c.clear_s))
                row[kind] = {"stable": run.result.stable, "angle_deg": e["angle_deg"], "V": e["V"],
                             "omega": e["omega"], "Efd": e["Efd"], "wall_s": run.timing.total_s}
            rows.append(row)
            print(f"{c.label}: " + ", ".join(f"{k} {row[k]['angle_deg']:.3f} deg" for k in KINDS), flush=True)
    ccts = []
    if not args.no_cct:
        mono_cct = MonolithicRunner(grid, rtol=1e-9)
        for bus, trip in pairs():
            c = Contingency(bus, 0.1, trip)
            entry = {"bus": bus, "trip": trip or ""}
            stable = {"monolithic": lambda x: mono_cct.run(x, 3.0, stop_at_loss=True)[0].stable}
            for kind, master in masters.items():
                master.settings = MasterSettings(stop_at_loss=True)
                stable[kind] = (lambda m: lambda x: m.run(x, 3.0).result.stable)(master)
            for kind, fn in stable.items():
                entry[kind] = critical_clearing_time(fn, c).cct_s
            ccts.append(entry)
            print(f"CCT bus {bus} {trip or '-'}: " + ", ".join(f"{k} {entry[k]}" for k in ("monolithic",) + KINDS),
                  flush=True)
    for master in masters.values():
        master.close()
    report = markdown(rows, ccts)
    print(report)
    out = Path(args.out)
    (out / "grid_accuracy.json").write_text(json.dumps({"contingencies": rows, "cct": ccts,
                                                         "wall_s": time.perf_counter() - started}, indent=1) + "\n")
    (out / "grid_accuracy.md").write_text(report + "\n")
    if ccts:
        plot_ccts(out / "grid_cct.png", ccts)


def markdown(rows, ccts) -> str:
    lines = ["| fault | trip | clear [s] | verdict (mono/ref/sur) | reference: angle [deg], V [pu] | "
             "surrogate: angle [deg], V [pu] |", "| --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        verdict = "/".join("S" if v else "U" for v in (r["monolithic_stable"], r["reference"]["stable"],
                                                        r["surrogate"]["stable"]))
        cells = []
        for kind in KINDS:
            k = r[kind]
            cells.append(f"{k['angle_deg']:.3f}, {k['V']:.2g}" if r["monolithic_stable"] else "(unstable)")
        lines.append(f"| {r['bus']} | {r['trip'] or '-'} | {r['clear_s']:g} | {verdict} | {cells[0]} | {cells[1]} |")
    stable = [r for r in rows if r["monolithic_stable"]]
    if stable:
        lines += ["", f"Stable contingencies: {len(stable)} of {len(rows)}; verdicts agree: "
                  + ", ".join(f"{k} {sum(r[k]['stable'] == r['monolithic_stable'] for r in rows)}/{len(rows)}" for k in KINDS)]
        for kind in KINDS:
            a = [r[kind]["angle_deg"] for r in stable]
            v = [r[kind]["V"] for r in stable]
            lines.append(f"- {kind}: angle error median {np.median(a):.3f}, worst {max(a):.3f} deg; terminal voltage "
                         f"worst {max(v):.3g} pu; wall time per 5 s run median "
                         f"{np.median([r[kind]['wall_s'] for r in rows]):.2f} s")
    if ccts:
        lines += ["", "| fault | trip | CCT monolithic [s] | reference [s] | surrogate [s] | surrogate - monolithic [ms] |",
                  "| --- | --- | --- | --- | --- | --- |"]
        for c in ccts:
            diff = "-" if None in (c["surrogate"], c["monolithic"]) else f"{1e3 * (c['surrogate'] - c['monolithic']):+.1f}"
            lines.append(f"| {c['bus']} | {c['trip'] or '-'} | {c['monolithic']} | {c['reference']} | {c['surrogate']} | {diff} |")
    return "\n".join(lines)


def plot_ccts(path, ccts):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 4))
    x = np.arange(len(ccts))
    for i, kind in enumerate(("monolithic",) + KINDS):
        ax.bar(x + (i - 1) * 0.27, [np.nan if c[kind] is None else 1e3 * c[kind] for c in ccts], 0.27, label=kind)
    ax.set_xticks(x, [f"{c['bus']}\n{c['trip'] or '-'}" for c in ccts], fontsize=7)
    ax.set_xlabel("fault bus / line opened at clearing")
    ax.set_ylabel("critical clearing time [ms]")
    ax.legend()
    ax.set_title("WSCC 9-bus critical clearing times: monolithic DAE, native reference FMUs, surrogate FMUs")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
