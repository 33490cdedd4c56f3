"""`opfmu grid`: network co-simulation of the WSCC 9-bus system (DESIGN section 8).

    opfmu grid run    one contingency: DIR/result.csv, DIR/result.png, DIR/report.md, DIR/summary.json
    opfmu grid cct    the critical clearing time of a fault and its clearing action (--json: one object)
    opfmu grid screen many contingencies on dask: CCTs, stable/unstable verdicts, first-swing peaks

The FMUs of every generator are built from its dynamic data (--dynamic-data, default the shipped
wscc9 file) into a cache (--fmu-cache, default ~/.cache/opfmu/fmus) the first time they are needed.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

from reference_models.files import atomic_path

CASES = ("wscc9",)


def _positive_time(text: str) -> float:
    import argparse

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a time in seconds: {text!r}") from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"a time must be finite and >= 0 s, got {text!r}")
    return value


def _common(p, kinds_default: str | None, trip: bool = True) -> None:
    from cosim.runners import RUN_KINDS

    p.add_argument("--case", default="wscc9", help="the network (only wscc9: the WSCC 9-bus system, Anderson & Fouad)")
    p.add_argument("--dynamic-data", default=None, metavar="FILE",
                   help="generators' dynamic data (machines, exciters, FMU kinds; default: the shipped wscc9 file)")
    p.add_argument("--fmus", choices=RUN_KINDS, default=kinds_default,
                   help="the FMUs of every generator, or monolithic for the DAE reference "
                        "(default: each generator's kind in the dynamic data: surrogate for the shipped file)")
    if trip:
        p.add_argument("--trip", default=None, metavar="FROM-TO", help="the branch opened at clearing, e.g. 5-7")
    p.add_argument("--fault-start", type=_positive_time, default=0.0, help="fault start in s (default 0)")
    p.add_argument("--fault-impedance", type=float, default=None, metavar="PU",
                   help="fault reactance in pu (default 1e-6: bolted)")
    p.add_argument("--step", type=float, default=0.01, help="communication step in s (default 0.01)")
    p.add_argument("--coupling", choices=("iterated", "extrapolated", "held"), default="iterated",
                   help="iterated: inputs linear over each step to a consistent end voltage, the step redone "
                        "from a saved FMU state (default); extrapolated: linear to the extrapolated end, one pass; "
                        "held: the start voltages held over the step (a plain master)")
    p.add_argument("--passes", type=int, default=3,
                   help="most passes of an iterated step (default 3)")
    p.add_argument("--fmu-cache", default=None, metavar="DIR", help="where built FMUs are kept")


def add_grid_parser(sub) -> None:
    grid = sub.add_parser("grid", help="network co-simulation (WSCC 9-bus): run, cct, screen",
                          description="The WSCC 9-bus system with one FMU per machine and exciter, the network "
                                      "solved at every communication point (Newton on the FMUs' directional "
                                      "derivatives), inputs linear over each step and the step iterated with "
                                      "FMU state rollback; or the monolithic DAE reference.")
    gsub = grid.add_subparsers(dest="grid_command", required=True)
    run = gsub.add_parser("run", help="one contingency", description="Simulate one contingency; writes DIR/result.csv "
                          "(one row per communication point), result.png, report.md and summary.json.")
    run.add_argument("--fault", type=int, required=True, metavar="BUS", help="faulted bus")
    run.add_argument("--clear", type=_positive_time, required=True, metavar="SECONDS", help="clearing time in s")
    run.add_argument("--stop", type=_positive_time, default=5.0, help="end time in s (default 5)")
    run.add_argument("--compare", default="monolithic",
                     help="runs drawn on the same figure and compared in the report: a comma list of "
                          "surrogate, reference, python, monolithic, or none (default monolithic)")
    run.add_argument("--out", required=True, metavar="DIR", help="output folder")
    _common(run, None)
    run.set_defaults(func=cmd_run)

    cct = gsub.add_parser("cct", help="critical clearing time", description="Critical clearing time of a fault and "
                          "its clearing action by bisection (stable: no two rotor angles pi apart before --stop).")
    cct.add_argument("--fault", type=int, required=True, metavar="BUS", help="faulted bus")
    cct.add_argument("--stop", type=_positive_time, default=3.0, help="end of each run in s (default 3)")
    cct.add_argument("--resolution", type=float, default=1e-3, help="bisection resolution in s (default 0.001)")
    cct.add_argument("--json", action="store_true", help="print one JSON object (with cct_s)")
    _common(cct, None)
    cct.set_defaults(func=cmd_cct)

    scr = gsub.add_parser("screen", help="contingency screening on dask",
                          description="Faults at many buses, with and without each line trip, as independent runs "
                                      "on dask: CCT, verdict at --clear and first-swing peak per contingency.")
    scr.add_argument("--faults", default="4,5,6,7,8,9", help="faulted buses, comma separated (default 4-9)")
    scr.add_argument("--trips", choices=("each", "none"), default="each",
                     help="each: also every trip at the faulted bus that keeps the generators connected (default)")
    scr.add_argument("--clear", type=_positive_time, default=0.1, help="clearing time of the verdict runs (default 0.1 s)")
    scr.add_argument("--stop", type=_positive_time, default=3.0, help="end of each run in s (default 3)")
    scr.add_argument("--resolution", type=float, default=1e-3, help="CCT resolution in s (default 0.001)")
    scr.add_argument("--workers", type=int, default=2, help="local dask worker processes (0: no dask; default 2)")
    scr.add_argument("--scheduler", default=None, metavar="ADDRESS", help="an existing dask scheduler instead")
    scr.add_argument("--out", required=True, metavar="DIR", help="output folder")
    scr.add_argument("--quiet", action="store_true", help="no progress bar")
    _common(scr, None, trip=False)
    scr.set_defaults(func=cmd_screen)


class GridUserError(ValueError):
    """A grid request opfmu cannot run as asked (one line)."""


def _setup(args, with_contingency: bool = True):
    """(grid, settings, contingency or None) from the common flags; GridUserError for what is wrong."""
    from reference_models.grid.contingency import Contingency

    from cosim.master import MasterSettings
    from cosim.runners import load_grid

    if args.case not in CASES:
        raise GridUserError(f"unknown case {args.case!r} (known: {', '.join(CASES)})")
    try:
        grid = load_grid(args.dynamic_data)
    except FileNotFoundError as exc:
        raise GridUserError(f"no dynamic-data file {exc.filename}") from None
    except (ValueError, KeyError, TypeError, OSError, AttributeError) as exc:
        raise GridUserError(f"cannot use the dynamic data {args.dynamic_data}: {type(exc).__name__}: "
                            f"{str(exc)[:200]}") from None
    settings = MasterSettings(step=args.step, coupling=args.coupling, passes=args.passes)
    if not with_contingency:
        return grid, settings, None
    z = _fault_impedance(args)
    clear = getattr(args, "clear", None)
    if clear is None:  # cct: a provisional clearing time, replaced by the bisection
        clear = args.fault_start + 0.05
    contingency = Contingency(args.fault, clear, args.trip, args.fault_start, z)
    return grid, settings, contingency


def _progress(text: str) -> None:
    print(f"building {text}", file=sys.stderr)


def cmd_run(args) -> None:
    from cosim import outputs
    from cosim.runners import RUN_KINDS, open_runner

    grid, settings, contingency = _setup(args)
    compare = [] if args.compare.strip() in ("", "none") else [k.strip() for k in args.compare.split(",")]
    unknown = [k for k in compare if k not in RUN_KINDS]
    if unknown:
        raise GridUserError(f"--compare: unknown run kind {unknown[0]!r} (known: {', '.join(RUN_KINDS)}, none)")
    main_kind = args.fmus or "+".join(sorted({g.fmu.kind for g in grid.dynamics}))
    kinds = [args.fmus] + [k for k in compare if k != main_kind]
    runs, timings = {}, {}
    for kind in kinds:
        runner = open_runner(kind, grid, settings, args.fmu_cache, _progress)
        try:
            result, timing = runner.run(contingency, args.stop)
        finally:
            runner.close()
        label = kind or main_kind
        runs[label], timings[label] = result, timing
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    main = runs[main_kind]
    outputs.write_csv(out / "result.csv", main)
    title = f"WSCC 9-bus: {contingency.label}"
    outputs.plot(out / "result.png", runs, title)
    messages = {k: t.pop("messages", {}) for k, t in timings.items()}
    logged = [f"{_label(kind)}, generator {bus}: {text}" for kind, per_bus in messages.items()
              for bus, texts in per_bus.items() for _, text in texts[:3]]
    notes = [f"{_label(kind)}: {note}" for kind, t in timings.items() for note in t.pop("notes", [])]
    outputs.report(out / "report.md", title, runs, timings, contingency,
                   [f"Note: {n}" for n in notes]
                   + ((["", "FMU log (first messages per generator):", ""] + [f"- {n}" for n in logged]) if logged else []))
    summary = {"contingency": contingency.label, "fmus": main_kind, "stable": main.stable,
               "loss_of_synchronism_s": main.loss_of_synchronism_s, "timing": timings, "step_s": settings.step,
               "passes": settings.passes}
    if "monolithic" in runs and main_kind != "monolithic":
        fault = (contingency.fault_start, contingency.clear_s)
        summary["difference_from_monolithic"] = {k: outputs.errors(r, runs["monolithic"], fault)
                                                 for k, r in runs.items() if k != "monolithic"}
    with atomic_path(out / "summary.json") as tmp:
        tmp.write_text(json.dumps(summary, indent=2, default=float) + "\n")
    verdict = "stable" if main.stable else f"unstable (loss of synchronism at {main.loss_of_synchronism_s:.3f} s)"
    print(f"{title}: {verdict}; {_label(main_kind)} in {timings[main_kind]['total_s']:.2f} s")
    for kind, e in summary.get("difference_from_monolithic", {}).items():
        print(f"  {_label(kind)} against the monolithic run: rotor angles {e['angle_deg']:.3f} deg, "
              f"terminal voltages {e['V']:.2g} pu")
    print(f"written: {out / 'result.csv'}, {out / 'result.png'}, {out / 'report.md'}")


def _label(kind) -> str:
    from cosim.outputs import LABELS

    return LABELS.get(kind, kind)


def cmd_cct(args) -> None:
    from cosim.runners import open_runner
    from cosim.stability import critical_clearing_time

    grid, settings, contingency = _setup(args)
    runner = open_runner(args.fmus, grid, settings, args.fmu_cache, None if args.json else _progress,
                         monolithic_rtol=1e-9)
    try:
        cct = critical_clearing_time(lambda c: runner.run(c, args.stop, stop_at_loss=True)[0].stable, contingency,
                                     args.resolution)
    finally:
        runner.close()
    kind = args.fmus or "+".join(sorted({g.fmu.kind for g in grid.dynamics}))
    if args.json:
        print(json.dumps({"case": args.case, "fault": args.fault, "trip": contingency.trip,
                          "fault_start_s": args.fault_start, "fmus": kind, **cct.to_dict()}))
        return
    label = contingency.label.split(", cleared")[0]
    if cct.cct_s is None:
        print(f"{label}: unstable even when cleared {args.resolution * 1e3:g} ms after the fault")
    elif not cct.bounded:
        print(f"{label}: stable for every clearing up to {cct.cct_s:g} s")
    else:
        print(f"{label}{', ' + contingency.trip + ' opened' if contingency.trip else ''}: critical clearing time "
              f"{cct.cct_s:.4f} s (unstable at {cct.unstable_s:.4f} s; {len(cct.runs)} runs, {_label(kind)})")


def cmd_screen(args) -> None:
    from cosim import outputs
    from cosim.fmus import generator_files
    from cosim.screening import ScreeningTask, contingencies, screen
    from reference_models.grid.contingency import Contingency

    grid, settings, _ = _setup(args, with_contingency=False)
    try:
        buses = [int(b) for b in args.faults.split(",") if b.strip()]
    except ValueError:
        raise GridUserError(f"--faults must be bus numbers separated by commas, got {args.faults!r}") from None
    if args.workers < 0:
        raise GridUserError("--workers must be >= 0")
    pairs = contingencies(buses, args.trips)
    files = () if args.fmus == "monolithic" else tuple(generator_files(grid.dynamics, args.fmus, args.fmu_cache, _progress))
    kind = args.fmus or "+".join(sorted({g.fmu.kind for g in grid.dynamics}))
    z = _fault_impedance(args)
    tasks = [ScreeningTask(Contingency(bus, args.clear, trip, args.fault_start, z),
                           "monolithic" if args.fmus == "monolithic" else kind, files,
                           str(args.dynamic_data) if args.dynamic_data else None, settings, args.stop, args.resolution)
             for bus, trip in pairs]
    rows = screen(tasks, args.workers, args.scheduler, progress=not args.quiet)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    outputs.write_screening(out, rows, f"WSCC 9-bus contingency screening ({_label(kind)}, verdicts at "
                                       f"{args.clear:g} s clearing)")
    print(outputs.screening_table(rows))
    print(f"written: {out / 'screening.csv'}, {out / 'screening.md'}, {out / 'screening.png'}")


def _fault_impedance(args) -> complex:
    from reference_models.grid.contingency import BOLTED_FAULT_IMPEDANCE

    return BOLTED_FAULT_IMPEDANCE if args.fault_impedance is None else complex(0.0, args.fault_impedance)
