"""A sub-system's surrogate FMU (its operator registered by `opfmu operator --subsystem`) against its
full detail and its hand-made aggregate, side by side in one run, on contingencies of host cases
that training drew none of (issue 35, docs/subsystems.md).

    python benchmarks/subsystem_surrogate.py --subsystem FILE [--at ieee14:9 ieee39:16+25 ...]
                                             [--contingencies 8] [--stop 3] [--seed 100]
                                             [--out benchmarks/subsystem_surrogate]

Per attachment HOST:BUS[+BUS...] (the sub-system at each of those buses), contingencies drawn with --seed (training's seeds are 0 and up: a seed of
100 and its own draw give other faults): faults at the boundary bus (through 0.01-0.1 pu), at a
neighbour or anywhere in the host (through 1e-4j pu or 0.003-0.3 pu), cleared after 50-200 ms, and
one host generator tripped. Each runs to --stop at h = 10 ms as
* the detail in ANDES at 1 ms (the reference of the errors; where ANDES fails, the detail as
  native FMUs takes its place, said in the row), and at 10 ms;
* the detail as native FMUs in opfmu's master;
* the aggregate (reference_models.grid.aggregate) as native FMUs;
* the surrogate: the host's devices as native FMUs, the sub-system one surrogate FMU
  (cosim.subsystem_surrogate.surrogate_in).
Errors outside the fault's own steps: the power and current each sub-system injects at its boundary
(P, Q, |I| in % of its rating; the largest over the boundaries), the boundary voltage [pu] and the host's rotor angles relative to
its first machine [deg]. Writes OUT.json (every number), OUT.md (the tables, the aggregate's errors
over the surrogate's) and OUT.png (the boundary P and Q of the contingency where the aggregate is
furthest off). Needs ANDES.
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
from cosim.runners import MasterRunner  # noqa: E402
from cosim.subsystem_surrogate import registered, surrogate_in  # noqa: E402
from reference_models.grid.aggregate import aggregate_file  # noqa: E402
from reference_models.grid.andes_case import ANDES_CASES, case_from_file  # noqa: E402
from reference_models.grid.attach import attached_file  # noqa: E402
from reference_models.grid.boundary import (boundary_current, equivalent_units, subsystem_buses,  # noqa: E402
                                            subsystem_rating)
from reference_models.grid.case import Event  # noqa: E402
from reference_models.grid.contingency import ANDES_FAULT_IMPEDANCE, Contingency  # noqa: E402

FAULT_START = 1.0  # s


def contingencies(case, buses: list, count: int, rng) -> list:
    """`count` - 1 faults and one generator trip on the host side of `case` (module docstring), near
    the first of the attachment buses `buses`."""
    bus = buses[0]
    behind = set().union(*(subsystem_buses(case.network, b) for b in buses))
    host = [b for b in case.network.buses if b not in behind]
    near = [br.to_bus if br.from_bus == bus else br.from_bus for br in case.network.branches
            if br.connects(bus) and not behind.intersection((br.from_bus, br.to_bus))]
    out = []
    for k in range(count - 1):
        where = k % 3
        fault_bus = bus if where == 0 else near[rng.integers(len(near))] if where == 1 else host[rng.integers(len(host))]
        if fault_bus == bus:
            z = 1j * 10 ** rng.uniform(-2.0, -1.0)
        else:
            z = ANDES_FAULT_IMPEDANCE if rng.uniform() < 0.5 else 1j * 10 ** rng.uniform(-2.5, -0.5)
        clear = FAULT_START + round(rng.uniform(0.05, 0.2), 2)
        out.append(Contingency(fault_bus=int(fault_bus), fault_start=FAULT_START, clear_s=clear, fault_impedance=z,
                               network=case.network))
    gens = [g for g in case.network.generators if g.bus not in behind and g.kind != "slack"]
    g = gens[rng.integers(len(gens))]
    trip = Event(kind="generator", time=FAULT_START, bus=g.bus, generator=g.name, status=0)
    return out + [Contingency(network=case.network, events=(trip,))]


def describe(c) -> str:
    if c.fault_bus is None:
        return f"generator at bus {c.events[0].bus} tripped"
    return f"fault at bus {c.fault_bus} ({abs(c.fault_impedance):.3g} pu), {1000 * (c.clear_s - c.fault_start):.0f} ms"


def on_host(contingency, case):
    """The contingency on another case of the same host (the aggregate's, the surrogate's)."""
    c = contingency
    return Contingency(fault_bus=c.fault_bus, fault_start=c.fault_start, clear_s=c.clear_s,
                       fault_impedance=c.fault_impedance, network=case.network, events=c.events)


def boundary(result, case, bus: int) -> tuple:
    """(S [n] complex, |I| [n], V [n]) at the boundary: from the branches into the sub-system, or for
    a sub-system run as its surrogate from the equivalent's own P and Q."""
    i = case.network.bus_index(bus)
    V = result.V_bus[:, i] * np.exp(1j * result.theta_bus[:, i])
    units = equivalent_units(case, bus)
    if units:
        S = result.P[:, units].sum(axis=1) + 1j * result.Q[:, units].sum(axis=1)
        return S, np.abs(S) / np.maximum(np.abs(V), 1e-9), np.abs(V)
    current = boundary_current(case.network, result.V_bus, result.theta_bus, bus)
    return V * np.conj(current), np.abs(current), np.abs(V)


def timed(make, contingency, stop):
    wall, cpu = time.perf_counter(), time.process_time()
    runner = make()
    try:
        result, _ = runner.run(contingency, stop)
    finally:
        runner.close()
    return result, time.perf_counter() - wall, time.process_time() - cpu


def errors(run, ref, buses: list, rating: float, contingency) -> dict:
    """Errors of run (result, case) against ref outside the fault's steps (module docstring); rating
    [pu]: each sub-system's."""
    (a_res, a_case), (b_res, b_case) = run, ref
    ta, tb = np.round(a_res.time, 9), np.round(b_res.time, 9)
    t = np.intersect1d(ta, tb)
    a, b = np.searchsorted(ta, t), np.searchsorted(tb, t)
    if contingency.fault_bus is not None:
        keep = ~((t >= contingency.fault_start - 1e-9) & (t < contingency.clear_s + 1e-9))
        a, b = a[keep], b[keep]
    behind = set().union(*(_behind(b_case, bus) for bus in buses))
    host_a = [k for k, u in enumerate(a_case.units) if u.bus in b_case.network.buses and u.bus not in behind
              and not a_case.units[k].machine.component.learned_states and np.isfinite(a_res.rotor_angle[0, k])]
    host_b = [k for k, u in enumerate(b_case.units) if u.bus not in behind and np.isfinite(b_res.rotor_angle[0, k])]
    da = (a_res.rotor_angle[a][:, host_a] - a_res.rotor_angle[a][:, host_a[:1]]) \
        - (b_res.rotor_angle[b][:, host_b] - b_res.rotor_angle[b][:, host_b[:1]])
    out = {"P_percent": 0.0, "Q_percent": 0.0, "I_percent": 0.0, "V_boundary": 0.0,
           "angle_deg": float(np.degrees(np.nanmax(np.abs(da)))) if da.size else None}
    for bus in buses:
        (Sa, Ia, Va), (Sb, Ib, Vb) = boundary(a_res, a_case, bus), boundary(b_res, b_case, bus)
        out["P_percent"] = max(out["P_percent"], float(100 * np.nanmax(np.abs(Sa[a].real - Sb[b].real)) / rating))
        out["Q_percent"] = max(out["Q_percent"], float(100 * np.nanmax(np.abs(Sa[a].imag - Sb[b].imag)) / rating))
        out["I_percent"] = max(out["I_percent"], float(100 * np.nanmax(np.abs(Ia[a] - Ib[b])) / rating))
        out["V_boundary"] = max(out["V_boundary"], float(np.nanmax(np.abs(Va[a] - Vb[b]))))
    return out


def _behind(case, bus) -> set:
    try:
        return set(subsystem_buses(case.network, bus))
    except ValueError:
        return set()


def main(argv=None) -> int:
    import andes

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--subsystem", required=True)
    parser.add_argument("--at", nargs="+", default=["ieee14:9", "ieee39:16"], metavar="HOST:BUS")
    parser.add_argument("--contingencies", type=int, default=8)
    parser.add_argument("--stop", type=float, default=3.0)
    parser.add_argument("--seed", type=int, default=100)
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "subsystem_surrogate"))
    args = parser.parse_args(argv)
    sub = Path(args.subsystem)
    if registered(sub) is None:
        parser.error(f"no operator is registered for {sub}: opfmu operator --subsystem {sub} --boundary BUS --out DIR")
    rng = np.random.default_rng(args.seed)
    rows, traces = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        aggregate = aggregate_file(sub, tmp / "aggregates")
        for spec in args.at:
            name, buses = spec.split(":")
            buses = [int(b) for b in buses.split("+")]
            host = Path(andes.get_case(ANDES_CASES[name])) if name in ANDES_CASES else Path(name)
            detail = case_from_file(attached_file(host, [(b, sub) for b in buses], tmp / "attached"))
            agg = case_from_file(attached_file(host, [(b, aggregate) for b in buses], tmp / "attached"))
            surrogate = detail
            for b in buses:
                surrogate = surrogate_in(surrogate, b, sub)
            rating = subsystem_rating(detail, buses[0]) / detail.network.base_mva
            fmus = {label: generator_files(case, kind, tmp / "fmus") for label, case, kind in
                    (("detail", detail, "reference"), ("aggregate", agg, "reference"), ("surrogate", surrogate, None))}
            runners = {
                "detail, ANDES 1 ms": (detail, lambda: AndesRunner(detail, 0.001, rows=0.01)),
                "detail, ANDES 10 ms": (detail, lambda: AndesRunner(detail, 0.01)),
                "detail, native FMUs": (detail, lambda: MasterRunner(fmus["detail"], detail, MasterSettings(step=0.01))),
                "aggregate, native FMUs": (agg, lambda: MasterRunner(fmus["aggregate"], agg, MasterSettings(step=0.01))),
                "surrogate FMU": (surrogate, lambda: MasterRunner(fmus["surrogate"], surrogate,
                                                                  MasterSettings(step=0.01))),
            }
            for contingency in contingencies(detail, buses, args.contingencies, rng):
                runs = {}
                for label, (case, make) in runners.items():
                    try:
                        result, wall, cpu = timed(make, on_host(contingency, case), args.stop)
                        runs[label] = (result, case, wall, cpu, None)
                    except (RuntimeError, ValueError) as exc:
                        runs[label] = (None, case, None, None, str(exc).splitlines()[0][:160])
                ref_label = next(k for k in ("detail, ANDES 1 ms", "detail, native FMUs") if runs[k][0] is not None) \
                    if any(runs[k][0] is not None for k in ("detail, ANDES 1 ms", "detail, native FMUs")) else None
                what = f"{name} at bus {'+'.join(map(str, buses))}: {describe(contingency)}"
                print(what, {k: (f"{v[2]:.2f} s" if v[4] is None else v[4][:60]) for k, v in runs.items()}, flush=True)
                for label, (result, case, wall, cpu, failed) in runs.items():
                    row = {"attachment": f"{name}:{'+'.join(map(str, buses))}", "contingency": describe(contingency), "run": label,
                           "wall_s": wall, "cpu_s": cpu, "failed": failed, "reference": ref_label, "rating_pu": rating}
                    if result is not None and ref_label is not None and label != ref_label:
                        row.update(errors((result, case), runs[ref_label][:2], buses, rating, contingency))
                    rows.append(row)
                if ref_label is not None:
                    traces[what] = {label: (np.asarray(v[0].time), boundary(v[0], v[1], buses[0])[0])
                                    for label, v in runs.items() if v[0] is not None}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps({"args": vars(args), "rows": rows}, indent=1))
    text = _tables(rows, args)
    out.with_suffix(".md").write_text(text)
    print(text)
    _plot(rows, traces, out.with_suffix(".png"))
    return 0


def _tables(rows, args) -> str:
    def f(r, key, fmt):
        return format(r[key], fmt) if r.get(key) is not None else ""

    lines = [f"{Path(args.subsystem).name} against its detail (ANDES at 1 ms where it runs), {args.stop:g} s at "
             "h = 10 ms, errors outside the fault's steps", "",
             "| attachment | contingency | run | wall [s] | CPU [s] | P [% rating] | Q [% rating] | I [% rating] | "
             "V boundary [pu] | host angles [deg] |", "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in rows:
        lines.append(f"| {r['attachment']} | {r['contingency']} | {r['run']} | {f(r, 'wall_s', '.2f')} | "
                     f"{f(r, 'cpu_s', '.2f')} | {f(r, 'P_percent', '.2f')} | {f(r, 'Q_percent', '.2f')} | "
                     f"{f(r, 'I_percent', '.2f')} | {f(r, 'V_boundary', '.4f')} | {f(r, 'angle_deg', '.3f')} |"
                     + (f" failed: {r['failed']}" if r["failed"] else ""))
    lines += ["", "Largest error over the contingencies, and the aggregate's over the surrogate's:", "",
              "| error | aggregate | surrogate | ratio |", "| --- | ---: | ---: | ---: |"]
    for key in ("P_percent", "Q_percent", "I_percent", "V_boundary", "angle_deg"):
        worst = {}
        for run in ("aggregate, native FMUs", "surrogate FMU"):
            values = [r[key] for r in rows if r["run"] == run and r.get(key) is not None]
            worst[run] = max(values) if values else None
        a, s = worst["aggregate, native FMUs"], worst["surrogate FMU"]
        lines.append(f"| {key} | {'' if a is None else f'{a:.3f}'} | {'' if s is None else f'{s:.3f}'} | "
                     f"{'' if not (a and s) else f'{a / s:.1f}'} |")
    return "\n".join(lines) + "\n"


def _plot(rows, traces, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scored = [r for r in rows if r["run"] == "aggregate, native FMUs" and r.get("P_percent") is not None]
    if not scored:
        return
    worst = max(scored, key=lambda r: r["P_percent"])
    what = next(k for k in traces if k.startswith(worst["attachment"].replace(":", " at bus ")) and
                k.endswith(worst["contingency"]))
    fig, axes = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    for label, (t, S) in traces[what].items():
        axes[0].plot(t, S.real, label=label, lw=1)
        axes[1].plot(t, S.imag, label=label, lw=1)
    axes[0].set_ylabel("P into the bus [pu]")
    axes[1].set_ylabel("Q into the bus [pu]")
    axes[1].set_xlabel("time [s]")
    axes[0].set_title(what, fontsize=9)
    axes[0].legend(fontsize=7)
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
