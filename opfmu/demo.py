"""`opfmu demo`: the main job end to end, into one run directory.

1. the operator: the shipped default, or with `train` a fresh one (quick dataset, PI-DeepONet
   training, ONNX export, a check on the dataset's test split);
2. both FMUs: the native surrogate FMU of that operator and the native reference FMU (the same
   machine's equations, Dormand-Prince 5(4) in C), from the FMU build cache (fmu_export.build_cache:
   built once per content, $OPFMU_FMU_CACHE or ~/.cache/opfmu/fmus) and copied into the run directory;
3. `compare` on every built-in scenario (fmpy runs both FMUs on the same inputs);
4. report.md: the operator, one table over all scenarios, each scenario's full table and plots.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from reference_models.files import atomic_path, write_json
from reference_models.scenarios import SCENARIOS

# the goal for a comparison over 10 s at h = 10 ms: MaxAE per state
GOAL_MAXAE = {"delta": 0.01, "omega": 0.01, "Ed_p": 0.005, "Eq_p": 0.005}


@dataclass(frozen=True)
class DemoConfig:
    """out: run directory; train: train an operator instead of using the shipped one (on a dataset of
    `preset`, a name or JSON file; epochs; dask workers for the dataset); seed: scenario (and dataset)
    seed; stop_time [s], step [s]: each comparison."""

    out: Path
    train: bool = False
    preset: str = "quick"
    epochs: int = 300
    workers: int = 0
    seed: int = 0
    stop_time: float = 10.0
    step: float = 0.01
    scenarios: tuple = SCENARIOS


def run_demo(config: DemoConfig, say=print) -> Path:
    """Runs the demo; returns the report's path. `say` gets one line per stage."""
    from fmu_export.build_cache import build_report, cached_native_reference_fmu, cached_surrogate_fmu, default_cache
    from opfmu.compare import operator_machine
    from surrogate.operator import DEFAULT_OPERATOR

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    operator = train_operator(config, say) if config.train else DEFAULT_OPERATOR
    say(f"FMU build cache: {default_cache()} (set OPFMU_FMU_CACHE to use another folder)")

    def building(name: str) -> None:
        say(f"building {name} (not in the cache)")

    cached = cached_surrogate_fmu(operator, "SM4Surrogate", progress=building)
    surrogate_fmu = copied(cached, out / "SM4Surrogate.fmu")
    say(f"{surrogate_fmu}: {surrogate_fmu.stat().st_size / 1e6:.2f} MB; its kernel matched onnxruntime to "
        f"{build_report(cached).get('max_abs_diff', float('nan')):.1e} when it was built")
    reference_fmu = copied(cached_native_reference_fmu("SM4Reference", params=operator_machine(operator),
                                                       progress=building), out / "SM4Reference.fmu")
    say(f"{reference_fmu}: the native reference FMU of the operator's machine")
    results = compare_scenarios(surrogate_fmu, reference_fmu, config, say)
    report = write_report(out, operator, config, results)
    return report


def copied(source: Path, target: Path) -> Path:
    """`source` copied onto `target` atomically; returns target."""
    import shutil

    with atomic_path(target) as tmp:
        shutil.copyfile(source, tmp)
    return target


def train_operator(config: DemoConfig, say) -> Path:
    """Quick dataset, PI-DeepONet training and export into the run directory; returns the .onnx."""
    from surrogate.data import generate
    from surrogate.data.presets import load_preset
    from surrogate.data.runner import SolveRunner
    from surrogate.onnx_export import export_onnx
    from surrogate.operator import Operator
    from surrogate.report import check_operator
    from surrogate.training import TrainConfig, train

    out = Path(config.out)
    generate(load_preset(config.preset), out / "data", seed=config.seed, runner=SolveRunner(config.workers))
    say(f"{config.preset} dataset in {out / 'data'}")
    result = train(out / "data", TrainConfig(epochs=config.epochs, physics=True, time_points=200), out / "train")
    say(f"trained a PI-DeepONet: {result.epochs} epochs in {result.wall_s:.0f} s")
    onnx_path = out / "operator.onnx"
    export_onnx(out / "train", onnx_path)
    say(check_operator(Operator.load(onnx_path), out / "data", out / "check"))
    return onnx_path


def compare_scenarios(surrogate_fmu: Path, reference_fmu: Path, config: DemoConfig, say) -> dict:
    """compare() on every scenario; each writes comparison.json and plots into out/<scenario>/."""
    import tempfile

    from fmpy import extract

    from opfmu.compare import (ComparisonPlots, compare, fmu_machine, format_table, plot_comparison, scenario_inputs,
                               summary)

    results = {}
    with tempfile.TemporaryDirectory(prefix="opfmu_demo_") as tmp, ComparisonPlots() as plots:
        surrogate_dir = extract(str(surrogate_fmu), unzipdir=str(Path(tmp) / "surrogate"))
        reference_dir = extract(str(reference_fmu), unzipdir=str(Path(tmp) / "reference"))
        machine = fmu_machine(surrogate_dir)
        for name in config.scenarios:
            inputs = scenario_inputs(name, config.seed, config.stop_time, config.step, machine)
            result = compare(surrogate_dir, reference_dir, inputs, config.stop_time, config.step)
            directory = Path(config.out) / name
            result["plots"] = [str(p.relative_to(config.out)) for p in plot_comparison(result, directory, name,
                                                                                            plots)]
            write_json(directory / "comparison.json", summary(result))
            results[name] = summary(result)
            say(format_table(result))
    return results


def write_report(out: Path, operator: Path, config: DemoConfig, results: dict) -> Path:
    """report.md in `out`: the operator, the overview table, the goal check, each scenario in full."""
    import onnx

    from fmu_export.variables import REFERENCE_STARTS
    from surrogate.ensemble import describe

    meta = {p.key: p.value for p in onnx.load(str(operator)).metadata_props}
    metrics = json.loads(meta.get("metrics", "{}")).get("physical", {})
    lines = ["# opfmu demo: surrogate FMU against reference FMU", "",
             f"Operator: `{operator}` ({describe(json.loads(meta['architecture']))}, "
             f"{'physics-informed' if json.loads(meta.get('physics_informed', 'false')) else 'data-only'}, "
             f"horizon {float(meta['horizon_s']):g} s); on its dataset's test split MSE {metrics.get('mse', float('nan')):.3g}, "
             f"MAE {metrics.get('mae', float('nan')):.3g}, MaxAE {metrics.get('maxae', float('nan')):.3g}.", "",
             f"Each scenario: {config.stop_time:g} s at a communication step of {config.step * 1e3:g} ms, seed "
             f"{config.seed}, the machine starting at the equilibrium of the first input (in `drift` turning with its "
             "network, whose angle drifts at a constant speed); Pm and Efd held at their start values except in "
             "`governor` (Pm stepped and ramped); fmpy runs both FMUs on the same inputs. Errors are surrogate minus "
             "reference over every communication point.", "",
             "The reference is native C too (the machine's equations, Dormand-Prince 5(4) at rtol "
             f"{REFERENCE_STARTS['rtol']:g}, atol {REFERENCE_STARTS['atol']:g}), so the cost columns compare the surrogate with a compiled solver of the same ODE, not "
             "with Python. Cost ratio: the surrogate's time over the reference's (above 1: the surrogate is slower).",
             "",
             "| scenario | MaxAE delta [rad] | MaxAE omega [rad/s] | MaxAE Ed_p [pu] | MaxAE Eq_p [pu] | MaxAE P [pu] "
             "| fmpy wall: surrogate / reference [s] | cost ratio | in fmi2DoStep per step: surrogate / reference "
             "[us] | cost ratio | in envelope | goal |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for name, r in results.items():
        m = r["metrics"]
        lines.append(f"| {name} | {state_maxae_cells(r)} | {m['P']['maxae']:.2e} "
                     f"| {r['wall_s']['surrogate']:.3f} / {r['wall_s']['reference']:.3f} | {1 / r['speedup']:.2f} "
                     f"| {per_step_us(r, 'surrogate'):.1f} / {per_step_us(r, 'reference'):.1f} "
                     f"| {1 / r['do_step_speedup']:.1f} | {'yes' if r['in_envelope'] else 'no'} "
                     f"| {'met' if meets_goal(r) else 'missed'} |")
    lines += ["", "Goal (per scenario, over 10 s at h = 10 ms): MaxAE delta <= 0.01 rad, omega <= 0.01 rad/s, "
              "Ed_p and Eq_p <= 0.005 pu.", ""]
    for name, r in results.items():
        lines += [f"## {name}", "", "| output | MAE | RMSE | MaxAE |", "| --- | --- | --- | --- |"]
        lines += [f"| {k} | {v['mae']:.3e} | {v['rmse']:.3e} | {v['maxae']:.3e} |" for k, v in r["metrics"].items()]
        lines += ["", f"Max residual {r['max_residual']:.3g}; fmpy wall time surrogate {r['wall_s']['surrogate']:.3f} s, "
                      f"reference {r['wall_s']['reference']:.3f} s; inside fmi2DoStep surrogate "
                      f"{r['do_step_s']['surrogate']:.4f} s, reference {r['do_step_s']['reference']:.3f} s.", ""]
        lines += [f"![{name} {Path(p).stem}]({p})" for p in r["plots"]] + [""]
    report = out / "report.md"
    with atomic_path(report) as tmp:
        tmp.write_text("\n".join(lines))
    return report


def state_maxae_cells(result: dict) -> str:
    """The MaxAE of delta, omega, Ed_p and Eq_p of a comparison as four table cells."""
    m = result["metrics"]
    return " | ".join(f"{m[s]['maxae']:.2e}" for s in GOAL_MAXAE)


def per_step_us(result: dict, fmu: str) -> float:
    """Mean time inside fmi2DoStep per communication step [us] of one FMU of a comparison."""
    steps = round(result["stop_time_s"] / result["step_s"])
    return 1e6 * result["do_step_s"][fmu] / steps


def meets_goal(result: dict) -> bool:
    return all(result["metrics"][name]["maxae"] <= limit for name, limit in GOAL_MAXAE.items())
