"""`opfmu operator`: a user's machine from data to FMU in one command, with the shipped recipe.

    opfmu operator --machine m.json --out DIR [--component sm4|genrou] [--recipe machine|grid|case]
                   [--case NAME] [--pm LOW HIGH] [--efd LOW HIGH] [--operating-point PM EFD]
                   [--horizon S] [--epochs N] [--workers N] [--threads N] [--name NAME]

Stages, each resumed where an interrupted run left it (rerun the same command):
1. DIR/data: the recipe's dataset for this machine (`machine`: every co-simulation family of the
   `cosim` preset and the `network` family recorded from the machine itself in a closed loop;
   `grid`: `network` windows only, for a machine in a network with D = 0), with Pm and Efd drawn
   from the given level ranges; `case`: windows recorded from a shipped grid case (--case) run
   through faults at each of its buses, of the units whose machine this is (families.case_family),
   the recipe of any machine component with a drift symmetry (GENROU);
2. DIR/run: the PI-DeepONet of the shipped operator (anchored Unstacked, 3 x 128 tanh, 96 basis
   functions per state, causal training, physics losses), resumed from its last checkpoint;
3. DIR/operator.onnx (export, checked against torch) and the FMUs DIR/<NAME>Surrogate.fmu (checked
   against onnxruntime) and DIR/<NAME>Reference.fmu (native Dormand-Prince 5(4) of the same machine);
4. DIR/report.md: the single-window metrics on the test split and (SM4 recipes) 60 s
   co-simulations of both FMUs under fmpy at h = 10 ms on the built-in scenarios at the machine's
   operating point, with plots; the `case` recipe's operator is checked in its case instead.

With --subsystem FILE (a sub-system's case file, or an FMU of one) instead of --machine, the command
learns a whole sub-system seen through its boundary bus: opfmu/subsystem_command.py.
"""
from __future__ import annotations

import json
import math
import re
import time
from dataclasses import replace
from pathlib import Path

from .subsystem_command import add_subsystem_options, cmd_subsystem, subsystem_options_given

RECIPE_FAMILIES_EXTRA = (("network", 0.14),)  # the `machine` recipe: the families of `cosim`, and this
# the `grid` recipe, for a machine in a network (D = 0, no governor): open-loop bus signals make such
# a machine slip poles within a window (its bus angle stands still while it accelerates), which a
# machine in a network never sees; its bus voltage is what the closed loop of `network` records
# (an infinite bus, as the open-loop families are, leaves its swings undamped: grid recipes with
# drift, governor and avr windows had those at validation MSE 0.3-0.7 against 0.014 for network,
# and selecting by a validation error they dominated chose operators undertrained for the network)
GRID_FAMILIES = (("network", 1.0),)
GRID_TRAINING = {"patience": 10**9}
RECIPES = ("machine", "grid", "case")
SM4_RECIPES = ("machine", "grid")  # their input families drive SM4
RECIPE_WORDS = {"machine": "the cosim families and `network`", "grid": "`network` windows",
                "case": "windows recorded from the case's units through faults at its buses"}  # no early stopping: the best validation epoch is kept all the same
RECIPE_COUNTS = {"train": 3000, "collocation": 1500, "val": 150, "test": 150}
RECIPE_TRAINING = {"physics": True, "epochs": 1500, "time_points": 200, "causal": True, "state_weights": [5, 1, 1, 5],
                   "model": {"anchored": True, "width": 128, "latent": 96}}
REPORT_SCENARIOS = ("mix", "dip", "governor", "drift")
REPORT_STOP_S, REPORT_STEP_S = 60.0, 0.01
MAX_WINDOWS = 10**6  # training windows: 10^6 windows of 1001 sensor times already need 32 GB of float64 states


def add_operator_parser(sub) -> None:
    op = sub.add_parser("operator", help="your machine from data to FMU: data, training, export, FMUs, report",
                        description=__doc__.split("\n\n")[0] + " Resumable: rerun the same command after an "
                        "interruption. Takes about 20-30 minutes on 2 cores.")
    op.add_argument("--machine", default=None, metavar="FILE",
                    help="JSON file of machine parameters (of --component: SM4Params, GENROUParams); or --subsystem")
    op.add_argument("--component", default="sm4", help="the machine's component: sm4 (default) or genrou "
                    "(with --recipe case)")
    op.add_argument("--case", default=None, metavar="NAME", help="the shipped grid case whose windows the case "
                    "recipe records (e.g. kundur); the machine must be one of its units'")
    op.add_argument("--out", required=True, help="run directory")
    op.add_argument("--pm", nargs=2, type=float, default=None, metavar=("LOW", "HIGH"),
                    help="Pm levels [pu] the windows draw from (default: the component's operating range)")
    op.add_argument("--efd", nargs=2, type=float, default=None, metavar=("LOW", "HIGH"),
                    help="Efd levels [pu] the windows draw from (default: the component's operating range)")
    op.add_argument("--vs", nargs=2, type=float, default=None, metavar=("LOW", "HIGH"),
                    help="bus voltage levels [pu] (default: the component's operating range)")
    op.add_argument("--operating-point", nargs=2, type=float, default=None, metavar=("PM", "EFD"),
                    help="Pm and Efd [pu] the report's scenarios hold or move from (default: the middle of the levels)")
    op.add_argument("--recipe", choices=RECIPES, default="machine",
                    help="machine: every co-simulation family and network (a machine on a bus of given "
                         "voltage); grid: network windows only, for a machine in a network with D = 0; "
                         "case: windows of the machine's units in the shipped case --case through faults "
                         "at each bus (default machine)")
    op.add_argument("--horizon", type=float, default=1.0, help="window length T [s] (default 1; 0.3 for a machine "
                    "in a network with D = 0, whose swings within a window are large)")
    op.add_argument("--epochs", type=int, default=None,
                    help="training epochs (default 1500 for a machine, 2000 for a sub-system)")
    op.add_argument("--windows", type=int, default=RECIPE_COUNTS["train"],
                    help=f"training windows (default {RECIPE_COUNTS['train']}; collocation, validation and test "
                         "windows scale with it)")
    op.add_argument("--report-stop", type=float, default=REPORT_STOP_S,
                    help=f"seconds of each report co-simulation (default {REPORT_STOP_S:g})")
    op.add_argument("--seed", type=int, default=0, help="dataset and training seed (default 0)")
    op.add_argument("--workers", type=int, default=2, help="dask workers for the dataset (default 2)")
    op.add_argument("--threads", type=int, default=None, help="torch threads for training (default: torch's)")
    op.add_argument("--name", default=None, help="FMU model name prefix (default: the component's name in capitals, "
                    "e.g. SM4: SM4Surrogate, SM4Reference; GENROU: GENROUSurrogate, GENROUReference)")
    op.add_argument("--quiet", action="store_true", help="no progress bars")
    add_subsystem_options(op)
    op.set_defaults(func=cmd_operator)


class OperatorError(ValueError):
    """A request `opfmu operator` cannot run."""


def recipe(levels: dict, horizon: float, windows: int = RECIPE_COUNTS["train"], name: str = "machine",
           component: str = "sm4", case: str | None = None):
    """The dataset preset of recipe `name`: `machine`, the cosim families and `network`, `grid`
    (GRID_FAMILIES), or `case` (the `case-<case>` family only, for `component`), with input levels
    `levels` [input -> (low, high)] over windows of `horizon` seconds (1 ms sensor spacing),
    `windows` training windows (the other splits in the recipe's proportions)."""
    from reference_models.components import component as find_component
    from surrogate.data.presets import preset

    cosim = preset("cosim")
    n_points = int(round(horizon / 0.001)) + 1
    counts = {split: max(4, int(round(n * windows / RECIPE_COUNTS["train"]))) for split, n in RECIPE_COUNTS.items()}
    probes = max(2, int(round(cosim.probes_per_family * windows / cosim.counts["train"])))
    if name == "case":  # every window brings its own initial state: the box only names the states
        model = find_component(component)
        return replace(cosim, name=name, counts=counts, families=((f"case-{case}", 1.0),), horizon=float(horizon),
                       n_points=n_points, levels=levels, component=model.name, ic="box", reachable_fraction=0.0,
                       probes_per_family=0, ic_box={s: (0.0, 0.0) for s in model.state_names})
    families = cosim.families + RECIPE_FAMILIES_EXTRA if name == "machine" else GRID_FAMILIES
    return replace(cosim, name=name, counts=counts, probes_per_family=probes,
                   families=families, horizon=float(horizon), n_points=n_points, levels=levels)


def _levels(args, model) -> dict:
    """{input: (low, high)} of --pm, --efd and --vs: finite, low <= high, not below the input's minimum."""
    levels = {}
    for name, pair in (("Pm", args.pm), ("Efd", args.efd), ("Vs", args.vs)):
        if pair is not None:
            low, high = pair
            if not (math.isfinite(low) and math.isfinite(high) and low <= high):
                raise OperatorError(f"--{name.lower()} LOW HIGH needs finite numbers with LOW <= HIGH, "
                                    f"got {low:g} {high:g}")
            minimum = model.inputs[model.input_names.index(name)].minimum
            if minimum is not None and low < minimum:
                raise OperatorError(f"--{name.lower()} LOW must be >= {minimum:g}, got {low:g}")
            levels[name] = (low, high)
    return levels


def _operating_point(args, model, params, levels) -> tuple:
    """(Pm, Efd) [pu] the report's scenarios start from: --operating-point, or the middle of the
    levels; OperatorError unless the machine has a stable equilibrium there (at the start bus voltage)."""
    import numpy as np

    if args.operating_point:
        operating = tuple(args.operating_point)
    else:
        operating = tuple(0.5 * sum(levels.get(n) or model.inputs[model.input_names.index(n)].operating_range)
                          for n in ("Pm", "Efd"))
    if not all(math.isfinite(v) for v in operating):
        raise OperatorError(f"--operating-point PM EFD must be finite numbers, got {operating[0]:g} {operating[1]:g}")
    u = np.array(model.start_inputs, dtype=float)
    u[[model.input_names.index("Pm"), model.input_names.index("Efd")]] = operating
    try:
        x = model.steady_state(u, params)
    except ValueError as exc:
        raise OperatorError(f"no operating point at Pm = {operating[0]:g} pu, Efd = {operating[1]:g} pu: "
                            f"{exc}") from None
    if not np.all(np.isfinite(x)):
        raise OperatorError(f"the machine has no equilibrium at Pm = {operating[0]:g} pu, Efd = {operating[1]:g} pu")
    return operating


def cmd_operator(args) -> None:
    from opfmu.errors import UserError
    from reference_models.component import ParameterError

    from surrogate.errors import DatasetError, TrainError

    if args.subsystem is not None:
        return cmd_subsystem(args)
    if args.machine is None:
        raise UserError("opfmu operator needs --machine FILE (a machine) or --subsystem FILE --boundary BUS")
    given = subsystem_options_given(args)
    if given:
        raise UserError(f"{', '.join(given)}: for a sub-system (--subsystem FILE), not a machine (--machine)")
    if args.epochs is None:
        args.epochs = RECIPE_TRAINING["epochs"]
    try:
        _run(args)
    except (OperatorError, ParameterError, DatasetError, TrainError) as exc:
        raise UserError(str(exc)) from None


def _check_resumable(out: Path, preset, seed: int, params, config) -> None:
    """OperatorError unless the dataset and the training run already in `out`, if any, are the ones
    this command makes (same recipe, machine and seed; the training settings but for its epochs)."""
    from surrogate.data.datasets import fingerprint
    from surrogate.training import TrainConfig

    key = fingerprint(preset, seed, params)
    for path in (out / "data" / "metadata.json", out / "data" / ".partial" / "plan.json"):
        if path.exists() and _json_object(path).get("fingerprint") != key:
            raise OperatorError(f"{out} holds the dataset of another machine, recipe or seed; choose another --out")
    if (out / "run" / "checkpoint.pt").exists():
        saved = _json_object(out / "run" / "config.json")
        try:
            same = replace(TrainConfig.from_dict(saved.get("train", {})), epochs=config.epochs) == config
        except (TypeError, ValueError, AttributeError):
            same = False
        if not same or saved.get("data", {}).get("fingerprint") != key:
            raise OperatorError(f"{out} holds a training run with other settings; choose another --out")


def _check_case(name: str, model, params) -> None:
    """OperatorError unless `name` is a shipped case with a unit whose machine this is."""
    from reference_models.families import case_units
    from reference_models.grid.case import CaseError, shipped_case

    try:
        case = shipped_case(name)
    except CaseError as exc:
        raise OperatorError(f"--case: {exc}") from None
    if not case_units(case, model, params):
        raise OperatorError(f"no unit of case {name} has this {model.name} machine (the case recipe learns from its "
                            "units' windows): give the parameters of one of its machines")


def _state_weights(model) -> list:
    """Data-loss weights of a non-SM4 machine's states: its rotor angle 5, its speed 2, the rest 1
    (the rotor angle is what a grid study reads; SM4's recipe weighs delta and Eq_p 5)."""
    drift = model.drift
    return [5.0 if i == drift.angle_states[0] else 2.0 if i == drift.speed_state else 1.0 for i in range(model.n_states)]


def _json_object(path: Path) -> dict:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        data = None
    if not isinstance(data, dict):
        raise OperatorError(f"{path} is not a JSON object: remove it, or choose another --out")
    return data


def _run(args) -> None:
    from opfmu.checks import MAX_COUNT, output_folder
    from reference_models.components import component

    if args.name is None:
        args.name = re.sub(r"\W", "", str(args.component))[:40].upper() or "SM4"
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]{0,40}", args.name):
        raise OperatorError(f"--name {args.name[:60]!r} must be a C identifier of at most 41 characters")
    if not (0.05 <= args.horizon <= 10.0) or not 1 <= args.epochs <= MAX_COUNT or args.workers < 0 \
            or not 4 <= args.windows <= MAX_WINDOWS:
        raise OperatorError(f"--horizon must lie in [0.05, 10] s, --epochs in [1, {MAX_COUNT}], --workers be >= 0 "
                            f"and --windows in [4, {MAX_WINDOWS}]")
    if not 0 < args.report_stop <= 3600:
        raise OperatorError("--report-stop must lie in (0, 3600] s")
    if not 0 <= args.seed <= MAX_COUNT or (args.threads is not None and args.threads < 1):
        raise OperatorError(f"--seed must lie in [0, {MAX_COUNT}] and --threads be >= 1")
    try:
        model = component(args.component)
        model.require_states()
    except ValueError as exc:
        raise OperatorError(f"--component: {exc}") from None
    if model.name != "sm4" and args.recipe in SM4_RECIPES:
        raise OperatorError(f"the {args.recipe} recipe's input families drive SM4; a {model.name} machine takes "
                            "--recipe case --case NAME (windows of its units in a shipped grid case)")
    if (args.recipe == "case") != (args.case is not None):
        raise OperatorError("--case NAME goes with --recipe case, and --recipe case needs it")
    params = model.load_params(args.machine)
    if args.recipe == "case":
        _check_case(args.case, model, params)
    levels = _levels(args, model)
    operating = _operating_point(args, model, params, levels)
    try:
        preset = recipe(levels, args.horizon, args.windows, args.recipe, model.name, args.case)
    except ValueError as exc:
        raise OperatorError(str(exc)) from None
    from surrogate.training import TrainConfig

    config = TrainConfig.from_dict({**RECIPE_TRAINING, **(GRID_TRAINING if args.recipe != "machine" else {}),
                                    **({} if model.name == "sm4" else {"state_weights": _state_weights(model)}),
                                    "epochs": args.epochs, "seed": args.seed})
    out = output_folder(args.out)
    _check_resumable(out, preset, args.seed, params, config)
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    timings = {}
    say = (lambda text: None) if args.quiet else print

    from surrogate.data import generate
    from surrogate.data.runner import SolveRunner

    t = time.perf_counter()
    meta = generate(preset, out / "data", seed=args.seed, runner=SolveRunner(args.workers), progress=not args.quiet,
                    params=params)
    timings["data"] = time.perf_counter() - t
    say(f"dataset: {out / 'data'} ({sum(meta['counts'].values())} windows of {args.horizon:g} s)")

    from surrogate.training import train

    if args.threads is not None:
        import torch

        torch.set_num_threads(args.threads)
    t = time.perf_counter()
    result = train(out / "data", config, out / "run", progress=not args.quiet)
    timings["training"] = time.perf_counter() - t
    say(f"trained: {result.epochs} epochs, best at {result.best_epoch}")

    from fmu_export.surrogate_fmu import build_surrogate_fmu
    from fmu_export.native_reference_fmu import build_native_reference_fmu
    from surrogate.onnx_export import export_onnx

    point = {"Pm": operating[0], "Efd": operating[1]}
    t = time.perf_counter()
    onnx_path = out / "operator.onnx"
    export_onnx(out / "run", onnx_path, operating_point=point)
    surrogate_fmu, reference_fmu = out / f"{args.name}Surrogate.fmu", out / f"{args.name}Reference.fmu"
    info = build_surrogate_fmu(onnx_path, surrogate_fmu, model_name=f"{args.name}Surrogate")
    build_native_reference_fmu(reference_fmu, f"{args.name}Reference", model, params, point)
    timings["export_and_fmus"] = time.perf_counter() - t
    say(f"built {surrogate_fmu} (kernel within {info['max_abs_diff']:.1e} of onnxruntime) and {reference_fmu}")

    results = {}
    if args.recipe in SM4_RECIPES:
        t = time.perf_counter()
        results = long_runs(surrogate_fmu, reference_fmu, out, operating, args.report_stop, say)
        timings["long_runs"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - started
    report = write_report(out, onnx_path, args, operating, results, timings)
    say(f"report: {report}")


def long_runs(surrogate_fmu: Path, reference_fmu: Path, out: Path, operating: tuple, stop: float, say) -> dict:
    """Both FMUs under fmpy over `stop` seconds at REPORT_STEP_S on each report scenario (seed 0)."""
    import tempfile

    from fmpy import extract

    from opfmu.compare import ComparisonPlots, compare, fmu_machine, plot_comparison, scenario_inputs, summary
    from reference_models.files import write_json

    results = {}
    with tempfile.TemporaryDirectory(prefix="opfmu_operator_") as tmp, ComparisonPlots() as plots:
        surrogate_dir = extract(str(surrogate_fmu), unzipdir=str(Path(tmp) / "surrogate"))
        reference_dir = extract(str(reference_fmu), unzipdir=str(Path(tmp) / "reference"))
        machine = fmu_machine(surrogate_dir)
        for name in REPORT_SCENARIOS:
            try:
                inputs = scenario_inputs(name, 0, stop, REPORT_STEP_S, machine, operating)
            except ValueError as exc:  # no draw keeps this machine in step at this operating point
                say(f"{name}: skipped ({exc})")
                continue
            result = compare(surrogate_dir, reference_dir, inputs, stop, REPORT_STEP_S)
            directory = out / "report" / name
            result["plots"] = [str(p.relative_to(out)) for p in plot_comparison(result, directory, name, plots)]
            results[name] = summary(result)
            write_json(directory / "comparison.json", results[name])
            m = results[name]["metrics"]
            say(f"{name}: MaxAE delta {m['delta']['maxae']:.2e} rad, omega {m['omega']['maxae']:.2e} rad/s, "
                f"Ed_p {m['Ed_p']['maxae']:.2e}, Eq_p {m['Eq_p']['maxae']:.2e} pu")
    return results


def write_report(out: Path, onnx_path: Path, args, operating: tuple, results: dict, timings: dict) -> Path:
    """report.md: recipe, timings, single-window metrics, the long co-simulations against the goal."""
    import onnx

    from opfmu.demo import GOAL_MAXAE, meets_goal, state_maxae_cells
    from reference_models.files import atomic_path

    meta = {p.key: p.value for p in onnx.load(str(onnx_path)).metadata_props}
    metrics = json.loads(meta["metrics"])
    envelope = json.loads(meta["envelope"])
    phys = metrics["physical"]
    lines = [f"# opfmu operator: {Path(args.machine).name}", "",
             f"Machine `{args.machine}`: {meta['params']}.", "",
             f"Recipe: the `{args.recipe}` preset ({RECIPE_WORDS[args.recipe]}; {args.windows} training "
             f"windows of {args.horizon:g} s), an anchored Unstacked PI-DeepONet trained causally for "
             f"{args.epochs} epochs (seed {args.seed}); windows in their own frame (reference_models/drift.py).", "",
             "| stage | wall time [s] |", "| --- | --- |"]
    lines += [f"| {k} | {v:.0f} |" for k, v in timings.items()]
    lines += ["", f"## Single window (test split, {metrics['n_trajectories']} windows, physical units)", "",
              f"MSE {phys['mse']:.3g}, MAE {phys['mae']:.3g}, MaxAE {phys['maxae']:.3g}; MaxAE per state: "
              + ", ".join(f"{k} {v:.3g}" for k, v in metrics["maxae_per_state"].items()) + ".", "",
              "Training envelope (in the window frame):", "", "| quantity | min | max |", "| --- | --- | --- |"]
    for group in ("x0", "u"):
        lines += [f"| {group} {name} | {lo:.4g} | {hi:.4g} |" for name, (lo, hi) in envelope[group].items()]
    lines += ["", f"## {args.report_stop:g} s co-simulation against the native reference (h = {REPORT_STEP_S * 1e3:g} ms)",
              "", f"Scenarios at the operating point Pm = {operating[0]:.4g} pu, Efd = {operating[1]:.4g} pu, seed 0. "
              "Goal: MaxAE delta <= " + f"{GOAL_MAXAE['delta']} rad, omega <= {GOAL_MAXAE['omega']} rad/s, Ed_p, Eq_p "
              f"<= {GOAL_MAXAE['Ed_p']} pu.", "",
              "| scenario | MaxAE delta | MaxAE omega | MaxAE Ed_p | MaxAE Eq_p | in envelope | goal |",
              "| --- | --- | --- | --- | --- | --- | --- |"]
    for name, r in results.items():
        lines.append(f"| {name} | {state_maxae_cells(r)} | {'yes' if r['in_envelope'] else 'no'} "
                     f"| {'met' if meets_goal(r) else 'missed'} |")
    if args.recipe == "grid":
        lines += ["", "These scenarios put the machine on an infinite bus (open loop), which the `grid` recipe does "
                  "not train on: with D = 0 its swings there never decay, and a scenario outside the envelope "
                  "says nothing of the machine in its network. Check it on windows of its network instead "
                  "(for the WSCC 9-bus machines: benchmarks/wscc9_operator_envelopes.py)."]
    lines.append("")
    for name, r in results.items():
        lines += [f"![{name} {Path(p).stem}]({p})" for p in r["plots"]]
    report = out / "report.md"
    with atomic_path(report) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return report
