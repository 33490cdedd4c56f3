"""`opfmu operator --subsystem FILE --boundary BUS`: a sub-system's operator from its detail to its
FMU (cosim.subsystem_operator.learn), resumable; parses and prints only.

    opfmu operator --subsystem FILE --boundary BUS --out DIR [--runs N] [--hosts NAME ...]
                   [--buses N] [--stride S] [--members K] [--frequency-features] [--rollover-share S]
                   [--epochs N] [--seed S]
                   [--workers N] [--threads N] [--name NAME] [--quiet]
    opfmu operator --subsystem BOX.fmu --rating MVA --out DIR [--bus-port SPEC] [the same options]

A case file is learned from its detail, an FMU with the bus port (a black box) from its replies to
host voltages (cosim.black_box_data).
"""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

from reference_models.messages import one_line

from .errors import UserError

# the options of `opfmu operator` that only a machine takes, with their defaults
MACHINE_ONLY = {"machine": None, "component": "sm4", "case": None, "pm": None, "efd": None, "vs": None,
                "operating_point": None, "recipe": "machine", "horizon": 1.0, "windows": 3000}
MAX_RUNS = 100_000
# the options of `opfmu operator` that only a sub-system takes (all default None)
SUBSYSTEM_ONLY = ("boundary", "runs", "hosts", "buses", "stride", "rating", "bus_port", "carry_controller", "memory",
                  "unit_frequency", "voltage_gain", "dip_current", "members", "frequency_features",
                  "rollover_share")
MAX_MEMBERS = 16


def subsystem_options_given(args) -> list:
    """The sub-system-only options given on the command line, as written (--bus-port ...)."""
    return [f"--{k.replace('_', '-')}" for k in SUBSYSTEM_ONLY if getattr(args, k, None) is not None]


def add_subsystem_options(op) -> None:
    """The options of `opfmu operator` for a sub-system."""
    op.add_argument("--subsystem", default=None, metavar="FILE",
                    help="learn the sub-system in this case file (ANDES reads it; its one Slack stands for the grid "
                         "at its boundary) instead of a machine: python -m reference_models.grid.subsystems writes one")
    op.add_argument("--boundary", type=int, default=None, metavar="BUS",
                    help="with --subsystem: its boundary bus (the bus of its Slack)")
    op.add_argument("--runs", type=int, default=None, help="with --subsystem: contingencies recorded (default 240)")
    op.add_argument("--hosts", nargs="+", default=None, metavar="NAME",
                    help="with --subsystem: ANDES cases it is attached to (default ieee14 kundur ieee39)")
    op.add_argument("--buses", type=int, default=None, help="with --subsystem: attachment buses per host (default 3)")
    op.add_argument("--stride", type=float, default=None, metavar="S",
                    help="with --subsystem: seconds between the starts of the windows of a run (default 0.02)")
    op.add_argument("--members", type=int, default=None, metavar="K",
                    help="with --subsystem: operators trained on the data (seeds --seed, --seed + 1, ...) and exported "
                         "as their mean (default 1)")
    op.add_argument("--frequency-features", action="store_true", default=None,
                    help="with --subsystem: the operators also read the boundary's measured frequency at every sensor "
                         "(docs/subsystems.md)")
    op.add_argument("--rollover-share", type=float, default=None, metavar="S",
                    help="with --subsystem: each epoch this share of the windows that start at another's rollover "
                         "start their learned states from the operator's own answer there, so that it learns to "
                         "return from its error at a rollover (0 to 1; default 0: off; docs/subsystems.md)")
    op.add_argument("--carry-controller", action="store_true", default=None,
                    help="with --subsystem FILE of a plant whose REPCA1 read its boundary bus: carry its plant "
                         "controller's states with their own equations (component subsystem_pc; docs/subsystems.md)")
    op.add_argument("--memory", action="store_true", default=None,
                    help="with --subsystem: carry the boundary voltage's recent past, the voltage through lags of "
                         "0.05, 0.25 and 1 s, stepped exactly, which the operators read at each window's start "
                         "(components subsystem_mem, subsystem_pc_mem; not with --voltage-gain; docs/subsystems.md)")
    op.add_argument("--unit-frequency", action="store_true", default=None,
                    help="with --subsystem FILE: carry how far the frequency its devices measure at their own buses "
                         "is off the boundary's, learned, which the operators read at each window's start (component "
                         "subsystem_uf; not with --carry-controller or --memory; docs/subsystems.md)")
    op.add_argument("--voltage-gain", action="store_true", default=None,
                    help="with --subsystem FILE with REGCA1: the devices' active current through their low-voltage "
                         "gain at the boundary voltage, known, of a full-voltage current and a residual, learned, so "
                         "that it falls and returns with the voltage at once (components subsystem_lvg, "
                         "subsystem_pc_lvg; not with --memory or --unit-frequency; docs/subsystems.md)")
    op.add_argument("--dip-current", action="store_true", default=None,
                    help="with --subsystem FILE with REECA1: the reactive current its units inject in a voltage dip, "
                         "from their settings, as two known states stepped exactly (a filter and a lag), the rest of "
                         "the reactive current learned (components subsystem*_dip; not with --memory or "
                         "--unit-frequency; docs/subsystems.md)")
    op.add_argument("--rating", type=float, default=None, metavar="MVA",
                    help="with --subsystem BOX.fmu (a black box): its rating [MVA]")
    op.add_argument("--bus-port", default=None, metavar="SPEC",
                    help="with --subsystem BOX.fmu whose model description declares no bus port (another tool's): "
                         "its variables at the bus, V=NAME,theta=NAME and either I_re=NAME,I_im=NAME or P=NAME,Q=NAME "
                         "(current or power into the bus; -NAME where the box gives what it draws); units from its "
                         "model description: V in pu, theta in rad or deg, P and Q in pu of the system base or "
                         "W, kW, MW (var, kvar, Mvar)")


def cmd_subsystem(args) -> None:
    """Checks the sub-system request, then runs it; UserError (one line) before any work otherwise."""
    given = [f"--{k.replace('_', '-')}" for k, v in MACHINE_ONLY.items() if getattr(args, k, v) != v]
    if given:
        raise UserError(f"{', '.join(given)}: for a machine; a sub-system (--subsystem) takes --boundary, --runs, "
                        "--hosts, --buses, --stride, --carry-controller, --memory, --unit-frequency, --voltage-gain, "
                        "--dip-current, --members, --frequency-features, --rollover-share, --epochs, --seed, --workers, "
                        "--threads, --name")
    if args.members is not None and not 1 <= args.members <= MAX_MEMBERS:
        raise UserError(f"--members {args.members}: from 1 to {MAX_MEMBERS} operators")
    if args.rollover_share is not None and not 0.0 <= args.rollover_share <= 1.0:
        raise UserError(f"--rollover-share {args.rollover_share:g}: a share of the windows, from 0 to 1")
    path = Path(args.subsystem)
    if not path.is_file():
        raise UserError(f"--subsystem: no file {path}")
    if path.suffix.lower() == ".fmu":
        return _black_box(path, args)
    for option, value in (("--rating", args.rating), ("--bus-port", args.bus_port)):
        if value is not None:
            raise UserError(f"{option} is for a black box (--subsystem BOX.fmu); a case file's rating is its units' "
                            "Sn, its bus its Slack's")
    if args.boundary is None:
        raise UserError("--subsystem needs --boundary BUS (the bus of its Slack, where the grid stands)")
    try:
        records = json.loads(path.read_text(encoding="utf-8")) if path.stat().st_size <= 64 * 2**20 else None
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        records = None
    if not isinstance(records, dict) or not isinstance(records.get("Slack"), list):
        raise UserError(f"--subsystem {path}: not a sub-system case (ANDES JSON with one Slack at its boundary)")
    buses = [r.get("bus") for r in records["Slack"] if isinstance(r, dict)]
    if buses != [args.boundary]:
        raise UserError(f"--boundary {args.boundary}: the boundary of {path.name} is the bus of its one Slack "
                        f"({', '.join(map(str, buses)) or 'it has none'})")
    if args.unit_frequency and (args.carry_controller or args.memory or args.voltage_gain or args.dip_current):
        raise UserError("--unit-frequency: not with --carry-controller, --memory, --voltage-gain or --dip-current")
    for option, value in (("--voltage-gain", args.voltage_gain), ("--dip-current", args.dip_current)):
        if value and args.memory:
            raise UserError(f"{option}: not with --memory")
    if args.dip_current and not records.get("REECA1"):
        raise UserError(f"--dip-current: {path.name} has no REECA1, whose reactive dip current it would know")
    if args.voltage_gain and not records.get("REGCA1"):
        raise UserError(f"--voltage-gain: {path.name} has no REGCA1, whose low-voltage gain it would learn through")
    if args.carry_controller and not records.get("REPCA1"):
        raise UserError(f"--carry-controller: {path.name} has no plant controller (REPCA1) whose states it could carry")
    out, plan, name = _output(args), _plan(args), _name(args)
    _check_case(path)
    _learn(path, args.boundary, out, plan, args, name)


def _check_case(path: Path) -> None:
    """UserError unless ANDES reads and sets up the sub-system, its buses all reach its boundary and
    its own power flow converges (reference_models.grid.attach.own_power_flow)."""
    try:
        import andes
    except ImportError:
        raise UserError("--subsystem FILE needs ANDES to read and run the case file: pip install -e '.[andes]'") \
            from None
    from reference_models.grid.attach import own_power_flow
    from reference_models.grid.case import CaseError

    try:
        own_power_flow(andes, path)
    except CaseError as exc:
        raise UserError(one_line(exc, None)) from None


def _black_box(path: Path, args) -> None:
    """Checks a black box's request (its rating; the bus port is checked on opening it), then runs it."""
    for option, value in (("--boundary", args.boundary), ("--carry-controller", args.carry_controller),
                          ("--unit-frequency", args.unit_frequency), ("--voltage-gain", args.voltage_gain),
                          ("--dip-current", args.dip_current)):
        if value is not None:
            raise UserError(f"{option} is for a case file; a black box (an FMU) is its bus port, never read inside")
    if args.rating is None or not (math.isfinite(args.rating) and 0 < args.rating <= 1e6):
        raise UserError("--subsystem BOX.fmu needs --rating MVA, its rating (a number in (0, 1e6])")
    if args.bus_port is not None:
        from cosim.black_box_data import parse_bus_port

        try:
            parse_bus_port(args.bus_port)
        except ValueError as exc:
            raise UserError(f"--bus-port {args.bus_port[:80]!r}: {exc}") from None
    _learn(path, None, _output(args), _plan(args), args, _name(args))


def _plan(args):
    """The dataset plan of --hosts, --runs, --buses; UserError for one out of range."""
    from cosim.subsystem_data import Plan
    from reference_models.grid.andes_case import ANDES_CASES

    from .checks import MAX_COUNT

    hosts = tuple(args.hosts or Plan.hosts)
    unknown = [h for h in hosts if h not in ANDES_CASES]
    if unknown:
        raise UserError(f"--hosts {' '.join(unknown)}: not a host case (known: {', '.join(ANDES_CASES)})")
    if args.epochs is None:
        from cosim.subsystem_operator import TRAINING

        args.epochs = TRAINING.epochs
    plan = Plan(hosts=hosts, runs=Plan.runs if args.runs is None else args.runs,
                buses=Plan.buses if args.buses is None else args.buses,
                stride=Plan.stride if args.stride is None else args.stride,
                carry_controller=bool(args.carry_controller), memory=bool(args.memory),
                unit_frequency=bool(args.unit_frequency), voltage_gain=bool(args.voltage_gain),
                dip_current=bool(args.dip_current))
    steps = plan.stride / plan.step
    if not (10 <= plan.runs <= MAX_RUNS and 1 <= plan.buses <= 100 and 1 <= args.epochs <= MAX_COUNT
            and 0 <= args.seed <= MAX_COUNT and 1 <= args.workers <= 256
            and (args.threads is None or args.threads >= 1)
            and math.isfinite(steps) and 1 <= round(steps) <= 100 and abs(steps - round(steps)) < 1e-9):
        raise UserError(f"--runs must lie in [10, {MAX_RUNS}], --buses in [1, 100], --epochs in [1, {MAX_COUNT}], "
                        f"--seed in [0, {MAX_COUNT}], --workers in [1, 256], --threads be >= 1 and --stride be 1 "
                        f"to 100 steps of {plan.step:g} s")
    return plan


def _name(args) -> str:
    name = args.name if args.name is not None else "Subsystem"
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]{0,40}", name):
        raise UserError(f"--name {name[:60]!r} must be a C identifier of at most 41 characters")
    return name


def _output(args) -> Path:
    from .checks import output_folder

    return output_folder(args.out)


def _learn(path: Path, boundary: int, out: Path, plan, args, name: str) -> None:
    from cosim.fmu import CouplingError
    from cosim.subsystem_operator import learn
    from reference_models.grid.case import CaseError
    from surrogate.data import DatasetError
    from surrogate.training import TrainError

    if args.threads is not None:
        import torch

        torch.set_num_threads(args.threads)
    try:
        done = learn(path, boundary, out, plan, args.epochs, args.seed, args.workers, name, not args.quiet,
                     args.rating, args.bus_port, **({} if args.members is None else {"members": args.members}),
                     features=bool(args.frequency_features), rollover_share=args.rollover_share or 0.0)
    except (DatasetError, TrainError, CouplingError, CaseError) as exc:
        raise UserError(str(exc)) from None
    meta = done["data"]
    print(f"data: {sum(meta['counts'].values())} windows from {sum(len(v) for v in meta['runs'].values())} runs "
          f"({len(meta['failed_runs'])} runs the detail did not finish) in {out / 'data'}")
    for k, result in enumerate(done["training"], start=1):
        member = f" (operator {k} of {len(done['training'])})" if len(done["training"]) > 1 else ""
        print(f"training{member}: {result.epochs} epochs, best validation MSE {result.best_val_mse:.3g} at epoch "
              f"{result.best_epoch}")
    print(f"operator: {done['operator']}\nFMU: {done['fmu']}")
    if path.suffix.lower() != ".fmu":
        print(f"registered for {path.name}: --attach BUS={path}:surrogate runs it")
