"""What running the grid's FMUs as FMI 3.0 costs in accuracy: native reference FMUs of every device
built as FMI 2.0 and as FMI 3.0, the same contingencies, h = 10 ms, iterated coupling, against the
monolithic DAE.

    python benchmarks/grid_fmi3.py [--stop 5] [--out DIR]

FMI 2.0 co-simulation takes input derivatives (fmi2SetRealInputDerivatives: the master's inputs are
linear over each step); FMI 3.0 co-simulation has no such call, so the master holds each input at
the mean of its start and end values over the step (the midpoint rule it uses for any FMU that
cannot interpolate). Prints per contingency the largest error of the rotor angles relative to
machine 1 [deg] and of the terminal voltages outside the fault's own steps [pu] of both runs, and
their largest difference from each other; writes DIR/grid_fmi3.json.
"""
import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from cosim.fmus import generator_files  # noqa: E402
from cosim.master import GridMaster, MasterSettings  # noqa: E402
from cosim.outputs import errors  # noqa: E402
from reference_models.grid import wscc9  # noqa: E402
from reference_models.grid.contingency import Contingency  # noqa: E402
from reference_models.grid.monolithic import System, simulate  # noqa: E402

CONTINGENCIES = (Contingency(4, 0.08), Contingency(9, 0.07, "6-9"), Contingency(7, 0.06, "7-8"),
                 Contingency(7, 5 / 60, "5-7"), Contingency(5, 0.1, "4-5"))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--stop", type=float, default=5.0)
    parser.add_argument("--out", default=str(Path(__file__).parent))
    args = parser.parse_args()
    case = wscc9.case()
    system = System(case)
    settings = MasterSettings(step=0.01)
    masters = {v: GridMaster(case, generator_files(case, "reference", fmi_version=v), settings) for v in (2, 3)}
    table = []
    try:
        for c in CONTINGENCIES:
            runs = {v: m.run(c, args.stop).result for v, m in masters.items()}
            mono = simulate(system, c, args.stop, t_eval=runs[2].time)
            fault = (c.fault_start, c.clear_s)
            row = {"contingency": c.label}
            for v, run in runs.items():
                e = errors(run, mono, fault)
                row[f"fmi{v}"] = {"angle_deg": e["angle_deg"], "V": e["V"], "stable": run.stable}
            between = errors(runs[3], runs[2], fault)
            row["fmi3_vs_fmi2"] = {"angle_deg": between["angle_deg"], "V": between["V"]}
            table.append(row)
            print(f"{c.label}: FMI 2.0 {row['fmi2']['angle_deg']:.3g} deg / {row['fmi2']['V']:.2g} pu, FMI 3.0 "
                  f"{row['fmi3']['angle_deg']:.3g} deg / {row['fmi3']['V']:.2g} pu", flush=True)
    finally:
        for m in masters.values():
            m.close()
    lines = ["| contingency | FMI 2.0 angle [deg] | FMI 3.0 angle [deg] | FMI 2.0 V [pu] | FMI 3.0 V [pu] | "
             "FMI 3.0 - FMI 2.0 angle [deg] |", "| --- | --- | --- | --- | --- | --- |"]
    for r in table:
        lines.append(f"| {r['contingency']} | {r['fmi2']['angle_deg']:.3g} | {r['fmi3']['angle_deg']:.3g} | "
                     f"{r['fmi2']['V']:.2g} | {r['fmi3']['V']:.2g} | {r['fmi3_vs_fmi2']['angle_deg']:.3g} |")
    print("\n".join(lines))
    Path(args.out, "grid_fmi3.json").write_text(json.dumps(table, indent=1) + "\n")


if __name__ == "__main__":
    main()
