"""The `opfmu` command line. User mistakes end in one line on stderr and exit code 2."""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

# numpy's BLAS on one thread unless OPENBLAS_NUM_THREADS says otherwise (set before numpy loads):
# the matrices here are small (a reduced network of some hundred rows, a machine's states), and
# BLAS threads waiting for work spin on the cores: a grid run of npcc spent up to a fifth more CPU
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from opfmu.checks import MAX_COUNT, check_fields, json_object_file, output_file, output_folder
from opfmu.errors import UserError
from reference_models.messages import one_line


class _ScenarioNames:
    """The built-in scenarios' names as argparse choices, looked up when argparse first asks: the
    scenarios module loads scipy, which a command other than compare does not need."""

    @staticmethod
    def _names() -> tuple:
        from reference_models.scenarios import SCENARIOS

        return tuple(SCENARIOS)

    def __contains__(self, name) -> bool:
        return name in self._names()

    def __iter__(self):
        return iter(self._names())


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line instead of usage + message
        raise UserError(f"{self.prog}: {message}")


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system has one)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def cmd_data(args) -> None:
    from surrogate.data import generate
    from surrogate.data.plots import plot_preview
    from surrogate.data.presets import load_preset
    from surrogate.data.runner import SchedulerError, SolveRunner

    if not 0 <= args.workers <= usable_cores():
        raise UserError(f"--workers must lie in [0, {usable_cores()}] (the cores this process may use)")
    if not 0 <= args.seed <= MAX_COUNT:
        raise UserError(f"--seed must lie in [0, {MAX_COUNT}]")
    if args.scheduler is not None:
        from cosim.screening import SchedulerError as AddressError, check_scheduler

        try:
            args.scheduler = check_scheduler(args.scheduler)
        except AddressError as exc:
            raise UserError(str(exc)) from None
    try:
        recipe = load_preset(args.preset)
        params = _machine(args.machine, recipe.component)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    output_folder(args.out)
    try:
        meta = generate(recipe, args.out, seed=args.seed, runner=SolveRunner(args.workers, args.scheduler),
                        progress=not args.quiet, params=params)
    except SchedulerError as exc:
        raise UserError(str(exc)) from None
    preview = plot_preview(args.out)
    print(summary_table(meta))
    print(f"dataset written to {args.out} ({meta['wall_time_s']} s); preview: {preview}")


def _machine(path, component_name: str = "sm4"):
    """The parameters in a machine file (None: the component's defaults); ValueError in one line."""
    from reference_models.components import component

    model = component(component_name)
    return model.params() if path is None else model.load_params(path)


def summary_table(meta: dict) -> str:
    """The dataset's counts and envelope as a small text table."""
    lines = [f"preset {meta['preset']['name']}, seed {meta['seed']}: "
             + ", ".join(f"{k} {v}" for k, v in meta["counts"].items()),
             f"{'quantity':<10}{'min':>10}{'max':>10}   (training envelope: x0 and u)"]
    for group in ("x0", "u"):
        for name, (lo, hi) in meta["envelope"][group].items():
            lines.append(f"{name:<10}{lo:>10.4f}{hi:>10.4f}")
    if "reachable" in meta:
        lines.append(f"reachable states ({meta['reachable']['probes']} probe windows from equilibria):")
        for name, (lo, hi) in meta["reachable"]["all"].items():
            lines.append(f"{name:<10}{lo:>10.4f}{hi:>10.4f}")
    return "\n".join(lines)


def cmd_train(args) -> None:
    from surrogate.models import OperatorConfig
    from surrogate.training import TrainConfig, TrainError, train

    if args.threads is not None and args.threads < 1:
        raise UserError("--threads must be >= 1")
    base = training_config_file(args.config) if args.config else {}
    flags = {k: v for k, v in (("seed", args.seed), ("epochs", args.epochs), ("optimizer", args.optimizer),
                                ("lr", args.lr), ("time_points", args.time_points)) if v is not None}
    if flags.get("time_points") == 0:
        flags["time_points"] = None
    try:
        config = TrainConfig.from_dict({**base, **flags, "physics": args.physics or base.get("physics", False)})
        config = _with_arch(config, args.arch, OperatorConfig)
    except (ValueError, TypeError) as exc:
        raise UserError(str(exc)) from None
    if not (0 <= config.seed <= MAX_COUNT and 1 <= config.epochs <= MAX_COUNT):
        raise UserError(f"the seed must lie in [0, {MAX_COUNT}] and the epochs in [1, {MAX_COUNT}]")
    if not (math.isfinite(config.lr) and config.lr > 0):
        raise UserError(f"the learning rate must be a finite number > 0, got {config.lr:g}")
    output_folder(args.out)
    import torch

    if args.threads is not None:
        torch.set_num_threads(args.threads)
    try:
        result = train(args.data, config, args.out, progress=not args.quiet)
    except TrainError as exc:
        raise UserError(str(exc)) from None
    print(f"trained {config.model.arch}{' (physics-informed)' if config.physics else ''}: {result.epochs} epochs "
          f"in {result.wall_s:.1f} s, best validation MSE {result.best_val_mse:.3e} (standardised) at epoch "
          f"{result.best_epoch}{', stopped early' if result.stopped_early else ''}; run: {args.out}")


def training_config_file(path) -> dict:
    """The fields of a --config file: a JSON object of TrainConfig fields (`model` an object of
    OperatorConfig fields, `weights` one of LossWeights fields), each of its default's JSON type;
    UserError naming the file and the field otherwise."""
    from surrogate.losses import LossWeights
    from surrogate.models import OperatorConfig
    from surrogate.training import TrainConfig

    data = json_object_file(path, "training config")
    check_fields(data, TrainConfig, f"training config {path}")
    for name, cls in (("model", OperatorConfig), ("weights", LossWeights)):
        if name in data:
            if not isinstance(data[name], dict):
                raise UserError(f"training config {path}: {name} must be a JSON object of {cls.__name__} fields")
            check_fields(data[name], cls, f"training config {path}: {name}")
    return data


def _with_arch(config, arch, operator_config):
    from dataclasses import replace

    return replace(config, model=operator_config.from_dict({**config.model.to_dict(), "arch": arch}))


def cmd_evaluate(args) -> None:
    from surrogate.report import evaluate_runs

    if args.out is not None:
        output_folder(args.out)
    try:
        report = evaluate_runs(args.runs, args.data, args.split, args.out)
    except (ValueError, FileNotFoundError) as exc:
        raise UserError(str(exc)) from None
    print(report)


def cmd_export(args) -> None:
    from surrogate.ensemble import describe
    from surrogate.onnx_export import ExportError, export_onnx
    from surrogate.training import TrainError

    output_file(args.output)
    for run in args.runs:
        _check_run_config(Path(run))
    try:
        meta = export_onnx(args.runs, args.output, data_dir=args.data)
    except (ExportError, TrainError, FileNotFoundError) as exc:
        raise UserError(str(exc)) from None
    metrics = json.loads(meta["metrics"])["physical"]
    print(f"wrote {args.output}: {describe(json.loads(meta['architecture']))} operator, horizon {meta['horizon_s']} s, "
          f"{meta['n_sensors']} sensors; test MSE {metrics['mse']:.3e}, MAE {metrics['mae']:.3e}, "
          f"MaxAE {metrics['maxae']:.3e} (physical units); onnxruntime matches torch")


def _check_run_config(run: Path) -> None:
    """UserError unless the config.json of a trained run (one with model.pt) is the object `opfmu
    train` writes: the objects train and data, data naming the dataset's folder."""
    if not (run / "model.pt").is_file():
        return  # the export names the missing model
    path = run / "config.json"
    if not path.is_file():
        raise UserError(f"{run} has a model.pt but no config.json: not a run of `opfmu train`")
    config = json_object_file(path, "run config")
    train, data = config.get("train"), config.get("data")
    if not (isinstance(train, dict) and isinstance(data, dict) and isinstance(data.get("dir"), str)):
        raise UserError(f"run config {path} must hold the objects train and data (data.dir: the dataset's folder), "
                        "as `opfmu train` writes it")


def cmd_build_fmu(args) -> None:
    from fmu_export.binaries import check_fmi_version
    from fmu_export.surrogate_fmu import BuildError, build_surrogate_fmu, check_model_name, default_state, load_operator
    from surrogate.operator import DEFAULT_OPERATOR

    onnx_path = Path(args.model) if args.model else DEFAULT_OPERATOR
    if not onnx_path.is_file():
        raise UserError(f"no operator file at {onnx_path}")
    try:
        meta = load_operator(onnx_path)[1]
        args.name = args.name or _model_name(meta["component"], "Surrogate")  # SM4Surrogate, GENROUSurrogate, ...
        args.output = args.output or f"{args.name}.fmu"
        check_model_name(args.name)
        check_fmi_version(args.fmi_version)
        default_state(meta, onnx_path)
    except BuildError as exc:
        raise UserError(str(exc)) from None
    output_file(args.output)
    platforms, notes = _platforms(args.platforms)
    try:
        info = build_surrogate_fmu(onnx_path, args.output, model_name=args.name, platforms=platforms,
                                   fmi_version=args.fmi_version)
    except BuildError as exc:
        raise UserError(str(exc)) from None
    _print_notes(notes)
    print(f"wrote {args.output} (FMI {args.fmi_version}, {info['size_bytes'] / 1e6:.2f} MB, model {args.name}, "
          f"guid {info['guid']}); compiled kernel matches onnxruntime to {info['max_abs_diff']:.1e}")
    print(_binaries_report(info))


def cmd_build_reference_fmu(args) -> None:
    from fmu_export.binaries import BuildError, check_fmi_version
    from fmu_export.native_reference_fmu import build_native_reference_fmu
    from fmu_export.python_reference_fmu import ReferenceBuildError, build_reference_fmu
    from fmu_export.surrogate_fmu import check_model_name
    from opfmu.compare import CompareError, operator_component
    from reference_models.components import component as named_component

    if args.python and (args.fmi_version != 2 or args.platforms is not None):
        raise UserError("--python builds an FMI 2.0 FMU for the Python it runs in; --fmi-version 3 and --platforms "
                        "are for the native FMU")
    if args.operator and args.component is not None:
        raise UserError("--operator gives the component (the one it was trained for); drop --component")
    if args.operator and not Path(args.operator).is_file():
        raise UserError(f"no operator file at {args.operator}")
    try:
        if args.operator:
            component, params = operator_component(args.operator, machine=False)
        else:
            component = named_component(args.component or "sm4")
            params = _machine(args.machine, component.name)
        args.name = args.name or _model_name(component, "Reference")  # SM4Reference, GENROUReference, ...
        args.output = args.output or f"{args.name}.fmu"
        if args.python:
            if not args.name.isidentifier():
                raise ValueError(f"model name {args.name[:80]!r} must be a Python identifier "
                                 "(it names the slave class)")
        else:
            check_model_name(args.name)
            check_fmi_version(args.fmi_version)
        point = _operating_point(args.operator) if args.operator and not args.python else None
    except (ValueError, BuildError, CompareError) as exc:
        raise UserError(str(exc)) from None
    output_file(args.output)
    platforms, notes = (None, []) if args.python else _platforms(args.platforms)
    options = {} if args.python else {"platforms": platforms, "fmi_version": args.fmi_version}
    build = build_reference_fmu if args.python else build_native_reference_fmu
    try:
        info = build(args.output, model_name=args.name, component=component, params=params,
                     **({"operating_point": point} if point else {}), **options)
    except (ValueError, ReferenceBuildError) as exc:
        raise UserError(str(exc)) from None
    _print_notes(notes)
    kind = "pythonfmu (scipy RK45)" if args.python else "native (Dormand-Prince 5(4) in C)"
    print(f"wrote {args.output} (FMI {args.fmi_version}, {info['size_bytes'] / 1e3:.0f} kB, {kind}, model {args.name}, "
          f"guid {info['guid']}); fmpy validates it")
    if not args.python:
        print(_binaries_report(info))


def _model_name(component, kind: str) -> str:
    """The default model name of a component's FMU: its name in capitals and the kind (SM4Surrogate,
    GENROUReference)."""
    return f"{component.name.upper()}{kind}"


def _platforms(spec):
    """(the platforms to build, the notes on those skipped) for --platforms (default every one whose
    compiler is found). The notes are printed after the build, so a refusal stays one line."""
    from fmu_export.platforms import PlatformError, select

    try:
        return select(spec)
    except PlatformError as exc:
        raise UserError(str(exc)) from None


def _print_notes(notes) -> None:
    for note in notes:
        print(note, file=sys.stderr)


def _binaries_report(info: dict) -> str:
    """One line per binary: platform, size, and how it was checked."""
    lines = []
    for name, binary in info["binaries"].items():
        check = info["checks"].get(name, "built for this machine and loaded here")
        lines.append(f"  {binary['path']} ({binary['size_bytes'] / 1e3:.0f} kB): {check}")
    return "\n".join(lines)


def _build_options(parser) -> None:
    """--platforms and --fmi-version of the native FMU builders."""
    parser.add_argument("--platforms", default=None, metavar="LIST",
                        help="comma-separated platforms to carry binaries for: linux64, win64 (MinGW-w64), "
                             "aarch64-linux (default: every one whose compiler is found; a note for the others). "
                             "Binaries are run and compared with the host's where wine or qemu-user is installed")
    parser.add_argument("--fmi-version", type=int, choices=(2, 3), default=2,
                        help="FMI version of the FMU: 2 (default) or 3 (the same model code)")


def _operating_point(onnx_path):
    """The operating point an operator file's FMUs start at (None: the component's start values)."""
    import onnx

    from surrogate.contract import operator_metadata

    return operator_metadata(onnx.load(str(onnx_path))).get("operating_point")


def _extract(extract, fmu, folder: str) -> str:
    """fmpy's extract of `fmu` into `folder`; UserError naming the FMU for an archive that cannot be
    unpacked (a damaged member, a file where a folder must be)."""
    import zipfile
    import zlib

    try:
        return extract(fmu, unzipdir=folder)
    except (zipfile.BadZipFile, zlib.error, OSError, ValueError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc).replace(folder, "")
        raise UserError(f"{fmu} cannot be unpacked as an FMU: {reason}") from None


def cmd_compare(args) -> None:
    import tempfile
    import zipfile

    from fmpy import extract

    from opfmu.compare import (COMPONENT, CompareError, compare, csv_inputs, fmu_component, format_table,
                               input_starts, plot_comparison, same_machine, scenario_inputs, summary)
    from reference_models.files import write_json

    for path in (args.surrogate, args.reference):
        if not zipfile.is_zipfile(path):
            raise UserError(f"{path} is not an FMU (no such file, or not a zip archive)")
    try:
        with zipfile.ZipFile(args.surrogate) as archive:
            names = archive.namelist()
    except (zipfile.BadZipFile, OSError) as exc:
        raise UserError(f"{args.surrogate} is not a readable FMU ({exc})") from None
    if "resources/model.onnx" not in names:
        raise UserError(f"{args.surrogate} is not a surrogate FMU of opfmu (it has no resources/model.onnx)")
    if args.inputs is not None and not Path(args.inputs).is_file():
        raise UserError(f"no inputs file at {args.inputs}")
    if not 0 <= args.seed <= MAX_COUNT:
        raise UserError(f"--seed must lie in [0, {MAX_COUNT}]")
    _communication_points(args.stop_time, args.step)
    parameters = _parameters(args.param)
    out = output_folder(args.out)
    tmp = None
    try:
        with tempfile.TemporaryDirectory(prefix="opfmu_compare_") as tmp:
            surrogate_dir = _extract(extract, args.surrogate, f"{tmp}/surrogate")
            reference_dir = _extract(extract, args.reference, f"{tmp}/reference")
            component, machine = fmu_component(surrogate_dir)
            same_machine(surrogate_dir, reference_dir, component)
            # SM4 as it always was (its start values); another machine at the surrogate FMU's input starts
            # (its operator's operating point)
            starts = None if component is COMPONENT else input_starts(surrogate_dir, component)
            if args.scenario:
                operating = None if starts is None else (starts["power"], starts["field"])
                inputs = scenario_inputs(args.scenario, args.seed, args.stop_time or 10.0, args.step, machine,
                                         operating, component)
                stop_time = inputs.times[-1]
            else:
                inputs = csv_inputs(args.inputs, machine, component, None if starts is None else starts["inputs"])
                stop_time = args.stop_time or float(inputs.times[-1])
                _communication_points(stop_time, args.step, "--stop-time" if args.stop_time else f"{args.inputs}: time")
            result = compare(surrogate_dir, reference_dir, inputs, stop_time, args.step, parameters)
    except (CompareError, ValueError) as exc:  # paths inside the FMUs named by the FMU, not the temporary folder
        message = str(exc) if tmp is None else str(exc).replace(f"{tmp}/surrogate", f"{args.surrogate}:").replace(
            f"{tmp}/reference", f"{args.reference}:")
        raise UserError(message) from None
    stem = args.scenario or Path(args.inputs).stem
    plots = plot_comparison(result, out, stem)
    write_json(out / f"{stem}.json", summary(result))
    print(format_table(result))
    print(f"plots: {', '.join(str(p) for p in plots)}; summary: {out / f'{stem}.json'}")


MAX_POINTS = 10**7  # communication points of one comparison: 10^7 steps of both FMUs take hours


def _communication_points(stop_time, step, stop_name: str = "--stop-time") -> None:
    """UserError unless `stop_time` [s] (None: given by the scenario or the inputs; named `stop_name`)
    and `step` [s] are finite, positive and give at most MAX_POINTS communication points."""
    for name, value in ((stop_name, stop_time), ("--step", step)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise UserError(f"{name} must be a finite number of seconds > 0, got {value:g}")
    if stop_time is not None and stop_time / step > MAX_POINTS:
        raise UserError(f"{stop_name} {stop_time:g} s at --step {step:g} s is {stop_time / step:.3g} communication "
                        f"points, more than {MAX_POINTS:g}")


def _parameters(specs) -> dict:
    """NAME=VALUE strings -> {name: float}."""
    parameters = {}
    for spec in specs:
        name, _, value = spec.partition("=")
        try:
            parameters[name.strip()] = float(value)
        except ValueError:
            raise UserError(f"--param needs NAME=NUMBER, got {spec!r}") from None
    return parameters


def cmd_demo(args) -> None:
    from opfmu.demo import DemoConfig, run_demo

    from opfmu.compare import CompareError, communication_points

    if not 1 <= args.epochs <= MAX_COUNT or args.workers < 0 or not 0 <= args.seed <= MAX_COUNT:
        raise UserError(f"--epochs must lie in [1, {MAX_COUNT}], --workers be >= 0 and --seed in [0, {MAX_COUNT}]")
    _communication_points(args.stop_time, args.step)
    output_folder(args.out)
    try:
        communication_points(args.stop_time, args.step)
        if args.train:
            from surrogate.data.presets import load_preset

            load_preset(args.preset)
    except (CompareError, ValueError) as exc:
        raise UserError(str(exc)) from None
    from fmu_export.surrogate_fmu import BuildError
    from fmu_export.python_reference_fmu import ReferenceBuildError

    try:
        report = run_demo(DemoConfig(Path(args.out), train=args.train, preset=args.preset, epochs=args.epochs,
                                     workers=args.workers, seed=args.seed, stop_time=args.stop_time, step=args.step))
    except (BuildError, ReferenceBuildError, CompareError) as exc:
        raise UserError(f"demo: {exc}") from None
    print(f"report: {report}")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="opfmu", description=__doc__)
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    data = sub.add_parser("data", help="generate labeled and collocation datasets with RK45",
                          description="Generate train/collocation/val/test splits (resumes an interrupted run).")
    data.add_argument("--preset", default="paper",
                      help="paper | cosim | quick, or a JSON file of Preset fields (default: paper)")
    data.add_argument("--out", required=True, help="dataset directory")
    data.add_argument("--machine", default=None, metavar="FILE",
                      help="JSON file of machine parameters (any subset of D, H, Rs, Td0_p, Tq0_p, Xd, Xd_p, Xq, "
                           "Xq_p, Xep, Re, Wb; the rest: paper Table I; Pm and Efd are inputs)")
    data.add_argument("--seed", type=int, default=0, help="base seed; same seed, same files (default 0)")
    data.add_argument("--workers", type=int, default=usable_cores(),
                      help="local dask worker processes; 0 solves in this process (default: all cores)")
    data.add_argument("--scheduler", default=None, help="address of a running dask scheduler to use instead")
    data.add_argument("--quiet", action="store_true", help="no progress bars")
    data.set_defaults(func=cmd_data)

    tr = sub.add_parser("train", help="train an operator (DeepONet or PINN) on a dataset",
                        description="Train, or resume the run in --out, with SOAP and early stopping.")
    tr.add_argument("--data", required=True, help="dataset directory (from `opfmu data`)")
    tr.add_argument("--arch", default="unstacked", help="unstacked | stacked-n | pinn (default unstacked)")
    tr.add_argument("--physics", action="store_true", help="add the physics losses (PI-DeepONet)")
    tr.add_argument("--out", required=True, help="run directory (resumed if it holds a checkpoint)")
    tr.add_argument("--seed", type=int, default=None, help="seed (default 0)")
    tr.add_argument("--epochs", type=int, default=None, help="maximum epochs (default 2000)")
    tr.add_argument("--optimizer", default=None, help="soap | adam (default soap)")
    tr.add_argument("--lr", type=float, default=None, help="learning rate (default 3e-3)")
    tr.add_argument("--time-points", type=int, default=None,
                    help="grid times drawn per epoch (default 200; 0: the whole grid)")
    tr.add_argument("--config", default=None, help="JSON file of TrainConfig fields (flags override it)")
    tr.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's choice)")
    tr.add_argument("--quiet", action="store_true", help="no progress bar")
    tr.set_defaults(func=cmd_train)

    ev = sub.add_parser("evaluate", help="accuracy metrics and figures of trained runs",
                        description="MSE, MAE, MaxAE (physical and standardised; overall, per state, per "
                                    "time step) of one or more runs (e.g. seeds), their mean and spread, "
                                    "and the paper's Fig. 3 and Fig. 4 as PNG.")
    ev.add_argument("runs", nargs="+", help="run directories (several: aggregated, e.g. over seeds)")
    ev.add_argument("--data", required=True, help="dataset directory to evaluate on")
    ev.add_argument("--split", default="test", help="split (default test)")
    ev.add_argument("--out", default=None, help="where metrics.json and figures go (default: the first run)")
    ev.set_defaults(func=cmd_evaluate)

    ex = sub.add_parser("export", help="export a trained run, or the mean of several, to ONNX (checked against torch)")
    ex.add_argument("runs", nargs="+", help="run directory (from `opfmu train`); several: their mean (an ensemble "
                                            "of anchored Unstacked DeepONets of one shape) as one operator")
    ex.add_argument("-o", "--output", required=True, help="the .onnx file to write")
    ex.add_argument("--data", default=None, help="dataset for envelope and test metrics (default: the first run's)")
    ex.set_defaults(func=cmd_export)

    fmu = sub.add_parser("build-fmu", help="build the native FMI 2.0 or 3.0 co-simulation FMU of an operator",
                         description="Generate C from the ONNX graph and the equations of the component the "
                                     "operator names (SM4, GENROU, ...), compile it, check it against onnxruntime "
                                     "and write the FMU (no Python needed to run it).")
    fmu.add_argument("model", nargs="?", default=None, help="operator .onnx (default: the shipped operator)")
    fmu.add_argument("-o", "--output", default=None, help="FMU file (default NAME.fmu)")
    fmu.add_argument("--name", default=None,
                     help="model name and identifier (default: the component and Surrogate, SM4Surrogate)")
    _build_options(fmu)
    fmu.set_defaults(func=cmd_build_fmu)

    ref = sub.add_parser("build-reference-fmu", help="build the reference FMU (native Dormand-Prince 5(4))",
                         description="An FMI 2.0 (or 3.0) co-simulation FMU of a component (SM4 unless --component "
                                     "or --operator names another) that integrates the ODE over each step "
                                     "with an adaptive Dormand-Prince 5(4) (RK45) compiled from the component's "
                                     "equations (--python: scipy's RK45 under pythonfmu instead); same variables as "
                                     "the surrogate FMU. The machine: --machine FILE, or that of an operator file "
                                     "(--operator), or the component's defaults (SM4: paper Table I).")
    ref.add_argument("--python", action="store_true",
                     help="the pythonfmu FMU (scipy RK45; needs Python, numpy and scipy where it runs)")
    machine = ref.add_mutually_exclusive_group()
    machine.add_argument("--machine", default=None, metavar="FILE", help="JSON file of machine parameters")
    machine.add_argument("--operator", default=None, metavar="ONNX",
                         help="take the component and machine an exported operator was trained for")
    ref.add_argument("--component", default=None, metavar="NAME",
                     help="the component (a registered name: sm4, genrou, ...; default sm4)")
    ref.add_argument("-o", "--output", default=None, help="FMU file (default NAME.fmu)")
    ref.add_argument("--name", default=None,
                     help="model name and identifier (default: the component and Reference, SM4Reference)")
    _build_options(ref)
    ref.set_defaults(func=cmd_build_reference_fmu)

    cmp = sub.add_parser("compare", help="run the surrogate and the reference FMU on the same inputs",
                         description="fmpy simulates both FMUs on one input signal; prints MAE, RMSE and MaxAE "
                                     "per output, wall times and the speedup, and writes plots. The machine (any "
                                     "with a bus port and mechanical power and field voltage links: SM4, GENROU, "
                                     "...) is the one the surrogate FMU's operator names.")
    cmp.add_argument("--surrogate", required=True, help="surrogate FMU")
    cmp.add_argument("--reference", required=True, help="reference FMU")
    source = cmp.add_mutually_exclusive_group(required=True)
    source.add_argument("--scenario", choices=_ScenarioNames(), help="built-in scenario")
    source.add_argument("--inputs", help="CSV with columns time, Vs, theta_vs and optionally Pm, Efd (absent: held "
                                         "at their start values); another machine's: its bus voltage inputs and "
                                         "optionally its others")
    cmp.add_argument("--seed", type=int, default=0, help="scenario seed (default 0)")
    cmp.add_argument("--stop-time", type=float, default=None,
                     help="seconds (default: 10 for a scenario, the last CSV time for --inputs)")
    cmp.add_argument("--step", type=float, default=0.01, help="communication step in seconds (default 0.01)")
    cmp.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                     help="a surrogate parameter, e.g. restart_jump=0 or rollover_horizon=0.5 (repeatable)")
    cmp.add_argument("--out", default="comparison", help="directory for plots and the summary (default comparison)")
    cmp.set_defaults(func=cmd_compare)

    demo = sub.add_parser("demo", help="run the main job end to end on defaults",
                          description="Build the surrogate FMU (shipped operator, or --train a quick one) and the "
                                      "reference FMU, compare them on every built-in scenario and write report.md.")
    demo.add_argument("--out", default="runs/demo", help="run directory (default runs/demo)")
    demo.add_argument("--train", action="store_true", help="generate a quick dataset and train the operator first")
    demo.add_argument("--preset", default="quick", help="dataset preset (name or JSON file) with --train (default quick)")
    demo.add_argument("--epochs", type=int, default=300, help="training epochs with --train (default 300)")
    demo.add_argument("--workers", type=int, default=0,
                      help="dask workers for the --train dataset (default 0: in this process)")
    demo.add_argument("--seed", type=int, default=0, help="scenario (and --train dataset) seed (default 0)")
    demo.add_argument("--stop-time", type=float, default=10.0, help="seconds per scenario (default 10)")
    demo.add_argument("--step", type=float, default=0.01, help="communication step in seconds (default 0.01)")
    demo.set_defaults(func=cmd_demo)

    from opfmu.grid_command import add_grid_parser
    from opfmu.init_command import add_init_parser
    from opfmu.operator_command import add_operator_parser

    add_init_parser(sub)
    add_operator_parser(sub)
    add_grid_parser(sub)
    return parser


def _version() -> str:
    from reference_models.version import __version__

    return f"opfmu {__version__}"


def interrupted_message(args) -> str:
    """The one line a Ctrl-C ends a command with: "rerun to resume" only where a rerun does (the
    finished chunks of a dataset and the last checkpoint of a training are kept)."""
    command = getattr(args, "command", None)
    if command in ("data", "train", "operator") or (command == "demo" and args.train):
        return "interrupted: rerun the same command to resume"
    return "interrupted"


def _dataset_error(exc: Exception) -> bool:
    """True for surrogate.data's DatasetError (raised only by commands that imported that package,
    so it is looked up, not imported: most commands never load it)."""
    datasets = sys.modules.get("surrogate.data.datasets")
    return datasets is not None and isinstance(exc, datasets.DatasetError)


def main(argv=None) -> int:
    from reference_models.interrupts import ctrl_c_taken

    args = None
    try:
        with ctrl_c_taken():
            args = build_parser().parse_args(argv)
            args.func(args)
    except UserError as exc:
        print(f"error: {one_line(exc, None)}", file=sys.stderr)
        return 2
    except ValueError as exc:
        if not _dataset_error(exc):
            raise
        print(f"error: {one_line(exc, None)}", file=sys.stderr)
        return 2
    except RuntimeError as exc:  # a failed reference solve: finished work is kept for the rerun
        print(f"failed: {one_line(exc, None)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(interrupted_message(args), file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
