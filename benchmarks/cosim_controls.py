"""Pm and Efd moving: the machine FMU with an IEEE Type I exciter FMU in the loop, the surrogate pair
against the reference pair (issue 16's co-simulation goal).

    python benchmarks/cosim_controls.py [--operator FILE.onnx] [--machine FILE.json] [--exciter FILE.json]
        [--scenarios mix dip governor drift] [--seeds 3] [--stop 60] [--step 0.01] [--quick] [--out-dir DIR]

Two pairs, each coupled by cosim.bus_driven (wired by the FMUs' ports) at the communication step h
(the exciter driven by the machine's terminal voltage Vt = |V + (Re + j Xep) I|, the machine's Efd
from the exciter): the surrogate FMU of the operator with the native reference FMU of IEEE1, and
the native reference FMU of the operator's machine with the same exciter FMU. Both take the same bus
inputs (the scenario's Vs, theta_vs and Pm at each communication point, held over the step: `mix`
and `dip` move the bus voltage, `governor` steps and ramps Pm, `drift` turns the network at up to
12 rad/s with Pm carrying the damping torque D c) and start from the same point: the machine at rest
under the scenario's first input (in its network's turning frame for `drift`), the exciter at rest
holding that Efd at that terminal voltage (cosim.bus_driven.start_at_rest).

Printed per scenario and seed: MaxAE of each machine state and of Efd, surrogate pair minus
reference pair over every communication point; whether the goal (60 s at h = 10 ms: delta, omega
<= 0.01 rad, rad/s; Ed_p, Eq_p <= 0.005 pu) is met; the surrogate's in_envelope over the run; the
coupling error, the reference pair against a monolithic solve of machine + exciter
(reference_models.grid.monolithic.simulate_unit: DOP853, rtol
1e-10, the same zero-order-held bus inputs: what a 10 ms exchange costs either pair); and the seconds
spent inside fmi2DoStep of the surrogate, the reference machine and the exciter. Writes
cosim_controls.json (every row) and cosim_controls_worst.png (the run with the largest error
against the goal: both pairs' trajectories) into --out-dir (default: this directory).

--seeds N runs seeds 0..N-1. --quick: 10 s, seed 0. --machine FILE: a machine other than Table I
(the reference is built for it; the operator must have been trained for the same machine).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from cosim.bus_driven import UnitFMU, couple, same_parameters, start_at_rest
from cosim.fmu import CouplingError
from reference_models.grid.monolithic import simulate_unit
from opfmu.compare import CompareError, operator_machine, scenario_inputs
from opfmu.demo import GOAL_MAXAE
from reference_models.component import ParameterError
from reference_models.files import write_json
from reference_models.ieee1 import IEEE1
from reference_models.sm4 import SM4

SCENARIOS = ("mix", "dip", "governor", "drift")
STATES = SM4.state_names
UNITS = {"delta": "rad", "omega": "rad/s", "Ed_p": "pu", "Eq_p": "pu", "Efd": "pu"}


def maxae(a: np.ndarray, b: np.ndarray) -> list[float]:
    return [float(v) for v in np.abs(a - b).max(axis=0)]


def build(operator: Path, machine_file, exciter_file, tmp: Path) -> tuple[UnitFMU, UnitFMU, UnitFMU]:
    """(surrogate, reference machine, exciter) units: the surrogate FMU of `operator`, the native
    reference of its machine (checked against --machine), the native reference of IEEE1."""
    from fmu_export.surrogate_fmu import build_surrogate_fmu
    from fmu_export.native_reference_fmu import build_native_reference_fmu

    machine = operator_machine(operator)
    if machine_file is not None:
        given = SM4.load_params(machine_file)
        if given != machine:
            differ = [f"{k} {v!r} (operator {machine.to_dict()[k]!r})" for k, v in given.to_dict().items()
                      if v != machine.to_dict()[k]]
            raise CouplingError(f"the operator {operator.name} was trained for another machine than {machine_file}: "
                                f"{', '.join(differ[:5])}")
    exciter = IEEE1.params() if exciter_file is None else IEEE1.load_params(exciter_file)
    build_surrogate_fmu(operator, tmp / "SM4Surrogate.fmu")
    build_native_reference_fmu(tmp / "SM4Reference.fmu", params=machine)
    build_native_reference_fmu(tmp / "IEEE1Reference.fmu", "IEEE1Reference", IEEE1, exciter)
    units = (UnitFMU(tmp / "SM4Surrogate.fmu"), UnitFMU(tmp / "SM4Reference.fmu"), UnitFMU(tmp / "IEEE1Reference.fmu"))
    same_parameters(units[0], units[1])
    return units


def run_one(name: str, seed: int, stop: float, step: float, units) -> tuple[dict, dict]:
    """One scenario and seed: (row, trajectories)."""
    surrogate, reference, exciter = units
    inputs = scenario_inputs(name, seed, stop, step, reference.params)
    bus, times = inputs.values[:, :3], inputs.times
    start = start_at_rest((reference, exciter), inputs.x0, bus[0], {"Efd": inputs.values[0, 3]})
    ref = couple((reference, exciter), times, bus, start)
    sur = couple((surrogate, exciter), times, bus, start)
    began = time.perf_counter()
    mono_x, mono_e = simulate_unit([reference.device(), exciter.device()], start, times, bus)
    mono_s = time.perf_counter() - began
    errors = maxae(sur.machine, ref.machine) + [maxae(sur.states[1], ref.states[1])[0]]
    coupling = maxae(ref.machine, mono_x) + [maxae(ref.states[1], mono_e)[0]]
    met = all(errors[STATES.index(s)] <= limit for s, limit in GOAL_MAXAE.items())
    row = {"scenario": name, "seed": seed, "stop_s": stop, "step_s": step, "speed_rad_s": float(inputs.x0[1]),
           "maxae": dict(zip(STATES + ("Efd",), errors)), "goal_met": met, "in_envelope": sur.in_envelope,
           "max_residual": sur.max_residual, "coupling_maxae": dict(zip(STATES + ("Efd",), coupling)),
           "efd_range": [float(ref.states[1][:, 0].min()), float(ref.states[1][:, 0].max())],
           "vt_range": [float(ref.terminal_voltage.min()), float(ref.terminal_voltage.max())],
           "do_step_s": {"surrogate": sur.do_step_s[0], "reference": ref.do_step_s[0], "exciter": ref.do_step_s[1]},
           "wall_s": {"surrogate_pair": sur.wall_s, "reference_pair": ref.wall_s, "monolithic": mono_s},
           "warnings": sorted({m for status, m in sur.messages[0] if status == 1})[:5]}
    trajectories = {"times": times, "bus": bus, "reference": ref, "surrogate": sur}
    return row, trajectories


def badness(row: dict) -> float:
    """The largest MaxAE as a share of its goal."""
    return max(row["maxae"][s] / limit for s, limit in GOAL_MAXAE.items())


def plot_worst(row: dict, traj: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t, ref, sur = traj["times"], traj["reference"], traj["surrogate"]
    theta = traj["bus"][:, 1]
    panels = [("delta - theta_vs [rad]", ref.machine[:, 0] - theta, sur.machine[:, 0] - theta, "delta"),
              ("omega [rad/s]", ref.machine[:, 1], sur.machine[:, 1], "omega"),
              ("Ed_p [pu]", ref.machine[:, 2], sur.machine[:, 2], "Ed_p"),
              ("Eq_p [pu]", ref.machine[:, 3], sur.machine[:, 3], "Eq_p"),
              ("Efd [pu] (exciter)", ref.states[1][:, 0], sur.states[1][:, 0], "Efd"),
              ("Vt [pu] (terminal voltage)", ref.terminal_voltage, sur.terminal_voltage, None)]
    fig, axes = plt.subplots(3, 2, figsize=(12, 9), sharex=True)
    for ax, (label, a, b, key) in zip(axes.flat, panels):
        ax.plot(t, a, "k-", lw=1.0, label="reference FMU + exciter FMU")
        ax.plot(t, b, "C1--", lw=1.0, label="surrogate FMU + exciter FMU")
        title = label if key is None else f"{label}   MaxAE {row['maxae'][key]:.2e}"
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    fig.suptitle(f"worst run: {row['scenario']} seed {row['seed']}, {row['stop_s']:g} s at h = "
                 f"{row['step_s'] * 1e3:g} ms (goal {'met' if row['goal_met'] else 'missed'}, "
                 f"in_envelope {row['in_envelope']})", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> int:
    from surrogate.operator import DEFAULT_OPERATOR

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--operator", type=Path, default=Path(DEFAULT_OPERATOR), help="operator (default: the shipped one)")
    parser.add_argument("--machine", type=Path, help="the operator's machine as a JSON file (default: Table I)")
    parser.add_argument("--exciter", type=Path, help="IEEE1 parameters as a JSON file (default: the WSCC exciters)")
    parser.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), choices=SCENARIOS)
    parser.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1 per scenario (default 3)")
    parser.add_argument("--stop", type=float, default=60.0, help="seconds per run (default 60)")
    parser.add_argument("--step", type=float, default=0.01, help="communication step [s] (default 0.01)")
    parser.add_argument("--quick", action="store_true", help="10 s, seed 0")
    parser.add_argument("--out-dir", type=Path, default=Path(__file__).parent)
    args = parser.parse_args()
    stop, seeds = (10.0, 1) if args.quick else (args.stop, args.seeds)
    if seeds < 1 or not (stop > 0 and args.step > 0):
        print("error: --seeds, --stop and --step must be positive", file=sys.stderr)
        return 2

    rows, worst = [], None
    try:
        with tempfile.TemporaryDirectory(prefix="opfmu_controls_") as tmp:
            began = time.perf_counter()
            units = build(args.operator, args.machine, args.exciter, Path(tmp))
            print(f"built the three FMUs in {time.perf_counter() - began:.1f} s; operator {args.operator}")
            print(f"{stop:g} s per run at h = {args.step * 1e3:g} ms; MaxAE surrogate pair - reference pair (rad, "
                  "rad/s, pu); coupling: the reference pair - monolithic DOP853, largest over the states (and Efd); "
                  "doStep: seconds inside fmi2DoStep of the surrogate / reference machine / exciter")
            header = (f"{'scenario':<9}{'seed':>5}" + "".join(f"{n:>10}" for n in STATES + ("Efd",))
                      + f"{'goal':>7}{'in_env':>7}{'coupling':>10}{'cpl Efd':>9}{'doStep s/r/e [s]':>20}")
            print(header)
            for name in args.scenarios:
                for seed in range(seeds):
                    row, traj = run_one(name, seed, stop, args.step, units)
                    rows.append(row)
                    if worst is None or badness(row) > badness(worst[0]):
                        worst = (row, traj)
                    c, d = row["coupling_maxae"], row["do_step_s"]
                    print(f"{name:<9}{seed:>5}" + "".join(f"{row['maxae'][n]:>10.2e}" for n in STATES + ("Efd",))
                          + f"{'met' if row['goal_met'] else 'missed':>7}{row['in_envelope']!s:>7}"
                          f"{max(c[s] for s in STATES):>10.2e}{c['Efd']:>9.2e}"
                          f"{d['surrogate']:>8.3f}/{d['reference']:.3f}/{d['exciter']:.3f}", flush=True)
    except (CouplingError, CompareError, ParameterError, ValueError) as exc:
        print(f"error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    n_steps = int(round(stop / args.step))
    total = {k: sum(r["do_step_s"][k] for r in rows) for k in ("surrogate", "reference", "exciter")}
    per_step = {k: v / (n_steps * len(rows)) * 1e6 for k, v in total.items()}
    print(f"goal met in {sum(r['goal_met'] for r in rows)} of {len(rows)} runs; in_envelope in "
          f"{sum(bool(r['in_envelope']) for r in rows)}; worst MaxAE " + ", ".join(
              f"{s} {max(r['maxae'][s] for r in rows):.2e}" for s in STATES + ("Efd",)))
    print("worst coupling error (reference pair - monolithic): " + ", ".join(
        f"{s} {max(r['coupling_maxae'][s] for r in rows):.2e}" for s in STATES + ("Efd",)))
    print("fmi2DoStep per step: " + ", ".join(f"{k} {v:.2f} us" for k, v in per_step.items())
          + f" (surrogate / reference {total['surrogate'] / total['reference']:.2f})")
    args.out_dir.mkdir(parents=True, exist_ok=True)
    write_json(args.out_dir / "cosim_controls.json",
               {"operator": str(args.operator), "stop_s": stop, "step_s": args.step, "goal": GOAL_MAXAE,
                "exciter": units[2].params.to_dict(), "machine": units[1].params.to_dict(),
                "do_step_us_per_step": per_step, "rows": rows})
    plot_worst(*worst, args.out_dir / "cosim_controls_worst.png")
    print(f"wrote {args.out_dir / 'cosim_controls.json'} and {args.out_dir / 'cosim_controls_worst.png'} "
          f"(worst: {worst[0]['scenario']} seed {worst[0]['seed']})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
