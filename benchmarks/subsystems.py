"""A generated feeder attached to a host case, run side by side in one process: its full detail as
native FMUs in opfmu's master, in the monolithic DAE and in ANDES, its hand-made aggregate
(reference_models.grid.aggregate) as native FMUs, and where an operator is registered for the
generated file (`opfmu operator --subsystem FILE`), its surrogate FMU; their errors against the
detail, and every run's wall and CPU time, for feeders of N units (issue 35).

    python benchmarks/subsystems.py [--host ieee14] [--bus 9 [BUS ...]] [--fault 4] [--kind feeder|plant]
                                    [--units 10 30 100 300] [--clear 0.1] [--stop 3] [--seed 0]
                                    [--out benchmarks/subsystems]

Per N: reference_models.grid.subsystems.feeder(FeederSpec(units=N, seed)) (or plant(PlantSpec(...)))
attached at each --bus of --host (one sub-system per bus, seeds seed, seed + 1, ...;
reference_models.grid.attach), a fault of 1e-4j pu at --fault from 1.0 s, cleared --clear s
later, each run to --stop at h = 10 ms (ANDES: its trapezoid at 10 ms, and at 1 ms as the reference
of the errors). Errors outside the fault's own steps: the power each sub-system injects into its
boundary bus (P, Q in % of the sub-systems' total unit rating, the largest over the boundaries;
reference_models.grid.boundary, from the bus voltages and the branches between the bus and its
sub-system),
the host's rotor angles relative to its first machine [deg], the boundary bus voltages [pu]. The FMUs are built (and cached) before a run
is timed; the monolithic DAE runs up to --monolithic-units units. Writes OUT.json (every number), OUT.md (the tables) and OUT.png (cost against N).
Needs ANDES.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from cosim.andes_runner import AndesRunner  # noqa: E402
from cosim.fmus import generator_files  # noqa: E402
from cosim.master import MasterSettings  # noqa: E402
from cosim.runners import MasterRunner, MonolithicRunner  # noqa: E402
from reference_models.grid.aggregate import aggregate_file  # noqa: E402
from reference_models.grid.andes_case import ANDES_CASES, case_from_file  # noqa: E402
from reference_models.grid.attach import attached_file  # noqa: E402
from cosim.subsystem_surrogate import registered, surrogate_in  # noqa: E402
from reference_models.grid.boundary import boundary_power, equivalent_units  # noqa: E402
from reference_models.grid.contingency import ANDES_FAULT_IMPEDANCE, Contingency  # noqa: E402
from reference_models.grid.subsystems import FeederSpec, PlantSpec, feeder, plant, write_case  # noqa: E402


def _common(a, b) -> tuple:
    """Row indices of a and b at common times (rounded to 1e-9 s)."""
    ta, tb = np.round(a.time, 9), np.round(b.time, 9)
    common = np.intersect1d(ta, tb)
    return np.searchsorted(ta, common), np.searchsorted(tb, common), common


def errors(run, case_run, ref, case_ref, buses, rating: float, fault: tuple) -> dict:
    """The errors of `run` (its case `case_run`) against `ref` (module docstring)."""
    a, b, t = _common(run, ref)
    keep = ~((t >= fault[0] - 1e-9) & (t < fault[1] + 1e-9))
    a, b = a[keep], b[keep]
    S = [(injected(run, case_run, bus)[a], injected(ref, case_ref, bus)[b]) for bus in buses]
    machines = np.isfinite(ref.rotor_angle[0])
    host = [k for k, u in enumerate(case_ref.units) if u.bus < 1000 and machines[k]]
    host_run = [k for k, u in enumerate(case_run.units) if u.bus < 1000 and np.isfinite(run.rotor_angle[0, k])
                and not u.machine.component.learned_states]
    da = (run.rotor_angle[a][:, host_run] - run.rotor_angle[a][:, host_run[:1]]) \
        - (ref.rotor_angle[b][:, host] - ref.rotor_angle[b][:, host[:1]])
    V = [np.abs(run.V_bus[a, case_run.network.bus_index(bus)] - ref.V_bus[b, case_ref.network.bus_index(bus)])
         for bus in buses]
    return {"P_percent": float(100 * max(np.max(np.abs(x.real - y.real)) for x, y in S) / rating),
            "Q_percent": float(100 * max(np.max(np.abs(x.imag - y.imag)) for x, y in S) / rating),
            "angle_deg": float(np.degrees(np.max(np.abs(da)))),
            "V_boundary": float(max(np.max(v) for v in V))}


def injected(result, case, bus: int) -> np.ndarray:
    """[n] complex: the power the sub-system behind `bus` injects into it: from the branches into it,
    or for one run as its surrogate, the equivalent's own P + jQ."""
    units = equivalent_units(case, bus)
    if units:
        return result.P[:, units].sum(axis=1) + 1j * result.Q[:, units].sum(axis=1)
    return boundary_power(case.network, result.V_bus, result.theta_bus, bus)


def with_surrogates(detail, subs):
    """The detail case with each sub-system run as its surrogate FMU, or None where an operator is
    not registered for one of them (opfmu operator --subsystem FILE)."""
    if any(registered(path) is None for _, path in subs):
        return None
    case = detail
    for bus, path in subs:
        case = surrogate_in(case, bus, path)
    return case


def timed(runner, contingency, stop):
    wall, cpu = time.perf_counter(), time.process_time()
    result, _ = runner.run(contingency, stop)
    return result, time.perf_counter() - wall, time.process_time() - cpu


def main(argv=None) -> int:
    import andes

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--host", default="ieee14")
    parser.add_argument("--bus", type=int, nargs="+", default=[9])
    parser.add_argument("--kind", choices=("feeder", "plant"), default="feeder")
    parser.add_argument("--fault", type=int, default=4)
    parser.add_argument("--units", type=int, nargs="+", default=[10, 30, 100, 300])
    parser.add_argument("--clear", type=float, default=0.1)
    parser.add_argument("--stop", type=float, default=3.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "subsystems"))
    parser.add_argument("--monolithic-units", type=int, default=10,
                        help="the largest N the monolithic DAE runs (default 10: beyond, minutes per run)")
    args = parser.parse_args(argv)
    host = Path(andes.get_case(ANDES_CASES[args.host])) if args.host in ANDES_CASES else Path(args.host)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for n in args.units:
            subs, rating = [], 0.0
            for k, bus in enumerate(args.bus):
                if args.kind == "feeder":
                    records = feeder(FeederSpec(units=n, seed=args.seed + k))
                    rating += sum(u["Sn"] for u in records["PVD1"]) / 100.0
                else:
                    records = plant(PlantSpec(units=n, seed=args.seed + k))
                    rating += sum(u["Sn"] for u in records["REGCA1"]) / 100.0
                subs.append((bus, write_case(records, tmp / f"{args.kind}_{n}_{bus}.json")))
            detail = case_from_file(attached_file(host, subs, tmp / "attached"))
            agg = case_from_file(attached_file(host, [(bus, aggregate_file(path, tmp / "aggregates"))
                                                      for bus, path in subs], tmp / "attached"))
            fault = (1.0, 1.0 + args.clear)
            surrogate = with_surrogates(detail, subs)
            contingency = {name: Contingency(fault_bus=args.fault, fault_start=1.0, clear_s=fault[1],
                                             fault_impedance=ANDES_FAULT_IMPEDANCE, network=c.network,
                                             events=c.events)
                           for name, c in (("detail", detail), ("aggregate", agg), ("surrogate", surrogate or detail))}
            runs = {}
            for label, case, runner in (
                    ("detail, native FMUs", detail,
                     lambda: MasterRunner(generator_files(detail, "reference", tmp / "fmus"), detail,
                                          MasterSettings(step=0.01))),
                    ("detail, monolithic DAE", detail,
                     lambda: MonolithicRunner(detail, 0.01, 1e-8) if n <= args.monolithic_units else None),
                    ("detail, ANDES 10 ms", detail, lambda: AndesRunner(detail, 0.01)),
                    ("detail, ANDES 1 ms", detail, lambda: AndesRunner(detail, 0.001, rows=0.01)),
                    ("aggregate, native FMUs", agg,
                     lambda: MasterRunner(generator_files(agg, "reference", tmp / "fmus"), agg,
                                          MasterSettings(step=0.01))),
                    ("surrogate FMU", surrogate,
                     lambda: surrogate and MasterRunner(generator_files(surrogate, None, tmp / "fmus"), surrogate,
                                                        MasterSettings(step=0.01)))):
                kind = "aggregate" if case is agg else "surrogate" if case is surrogate else "detail"
                try:
                    made = runner()
                    if made is None:
                        continue
                    result, wall, cpu = timed(made, contingency[kind], args.stop)
                    made.close()
                    runs[label] = (result, case, wall, cpu, None)
                except (RuntimeError, ValueError) as exc:
                    runs[label] = (None, case, None, None, str(exc).splitlines()[0][:160])
                print(f"N = {n}: {label}: " + (f"{runs[label][2]:.2f} s wall, {runs[label][3]:.2f} s CPU"
                                               if runs[label][4] is None else f"failed: {runs[label][4]}"),
                      flush=True)
            ref_label = "detail, ANDES 1 ms" if runs["detail, ANDES 1 ms"][0] is not None else "detail, native FMUs"
            ref = runs[ref_label]
            for label, (result, case, wall, cpu, failed) in runs.items():
                row = {"units": n, "run": label, "wall_s": wall, "cpu_s": cpu, "failed": failed,
                       "reference": ref_label, "rating_pu": rating}
                if result is not None and ref[0] is not None and label != ref_label:
                    row.update(errors(result, case, ref[0], ref[1], args.bus, rating, fault))
                rows.append(row)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps({"args": vars(args), "rows": rows}, indent=1))
    lines = [f"{args.host}, a {args.kind} at bus {', '.join(map(str, args.bus))}, fault at bus {args.fault} cleared "
             f"after {args.clear:g} s, "
             f"{args.stop:g} s at h = 10 ms; errors against {ref_label} outside the fault's steps", "",
             "| N | run | wall [s] | CPU [s] | P [% rating] | Q [% rating] | host angles [deg] | V boundary [pu] |",
             "| ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in rows:
        def f(key, fmt):
            return format(r[key], fmt) if r.get(key) is not None else ""
        lines.append(f"| {r['units']} | {r['run']} | {f('wall_s', '.2f')} | {f('cpu_s', '.2f')} | "
                     f"{f('P_percent', '.2f')} | {f('Q_percent', '.2f')} | {f('angle_deg', '.3f')} | "
                     f"{f('V_boundary', '.4f')} |" + (f" failed: {r['failed']}" if r["failed"] else ""))
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    _plot(rows, out.with_suffix(".png"))
    return 0


def _plot(rows, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for label in dict.fromkeys(r["run"] for r in rows):
        points = [(r["units"], r["cpu_s"]) for r in rows if r["run"] == label and r["cpu_s"] is not None]
        if points:
            ax.plot(*zip(*points), marker="o", label=label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("PV units in the feeder")
    ax.set_ylabel("CPU of the run [s]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
