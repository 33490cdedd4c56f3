"""`opfmu grid`: network co-simulation of a grid case (the contract of docs/grid.md).

    opfmu grid run    one contingency: DIR/result.csv, DIR/result.png, DIR/report.md, DIR/summary.json
    opfmu grid cct    the critical clearing time of a fault and its clearing action (--json: one object)
    opfmu grid screen many contingencies on dask: CCTs, stable/unstable verdicts, first-swing peaks
    opfmu grid export the case's FMUs and DIR/case.json, which names every device's FMU, bus,
                      parameters, load-flow point, start values and links (cosim.export), for another master
    opfmu grid feeder|plant  a generated sub-system case file (reference_models.grid.subsystems) for --attach

The FMUs of every unit are built from its dynamic data (--dynamic-data, default the case's shipped
file) into a cache (--fmu-cache, default ~/.cache/opfmu/fmus) the first time they are needed. A
case's own events (line toggles, faults, generator trips) apply with the contingency unless
--no-case-events leaves them out; the cases converted from ANDES take ANDES' default fault
impedance (1e-4 pu) where --fault-impedance is not given, wscc9 a bolted fault (1e-6 pu), and their
faults start at 1 s where --fault-start is not given (wscc9's at 0). cct and screen run each
contingency to 4 s after its fault start unless --stop is given; screen faults every bus without a
generator unless --faults names them.
A run needs no --fault where the case has events of its own (they are the run); --trip without a
fault opens the branch at --clear. What ANDES adjusted in a case file (the case's notes,
reference_models.grid.andes_case) and which devices run as surrogate FMUs are printed on stderr
and written into the report (run, screen) and summary.json (run); --fmus surrogate for a case
where no machine has an operator is refused.
--attach BUS=NAME|FILE[:KIND] joins a sub-system at a bus (docs/grid.md, "Sub-systems behind a
bus"): one runner (--fmus) runs host and sub-systems; :monolithic needs --fmus monolithic (or sets
it where --fmus is left out), :reference a run of FMUs; run adds P_attach_<bus>, Q_attach_<bus> to
result.csv and S_attach_<bus> to summary.json.
Everything a command is asked is checked before any work and before anything is printed (one line,
exit code 2): also that --out names a folder (not "", not a file; it is made only when the results
are written, and removed again where that fails and leaves it empty), that screen's --workers are at
most the cores this process may use, and that its --scheduler is a tcp:// address of a dask
scheduler that answers within a few seconds. A result set is written whole or not at all; the FMUs
are extracted under a scratch folder of the command, removed at its end whatever happened (also on
Ctrl-C, which is honoured while screen's local workers start).
"""
from __future__ import annotations

import json
import math
import shutil
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import NamedTuple

from opfmu.errors import UserError
from reference_models.messages import one_line

CASES = ("wscc9", "kundur", "ieee14", "ieee39", "npcc")  # reference_models.grid.case.SHIPPED_CASES
CASE_FILE_SUFFIXES = (".xlsx", ".json", ".raw")  # case files ANDES reads
WSCC9_STABILITY_STOP_S = 3.0  # DESIGN section 8: cct's default stop for wscc9, whose faults start at 0
CASE_TITLES = {"wscc9": "WSCC 9-bus", "kundur": "Kundur two-area", "ieee14": "IEEE 14-bus", "ieee39": "IEEE 39-bus",
               "npcc": "NPCC 140-bus"}
REFERENCE_KINDS = ("monolithic", "andes")  # the runs without FMUs
MAX_STOP_S = 3600.0  # the longest run a grid command takes [s]
ANDES_CASE_FAULT_START_S = 1.0  # s: the default fault start of the cases converted from ANDES (their events start
# at >= 1 s; ANDES applies no fault at t = 0); wscc9's is 0
SCREEN_CLEARING_S = 0.1  # s after the fault start: the default clearing of a screening's verdict runs


def _time(text: str) -> float:
    import argparse

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a time in seconds: {text!r}") from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"a time must be finite and >= 0 s, got {text!r}")
    return value


def _run_kinds() -> tuple:
    from cosim.fmus import FMU_KINDS

    return tuple(k for k in FMU_KINDS if k != "file") + ("monolithic", "andes")


def _common(p, trip: bool = True) -> None:
    p.add_argument("--case", default="wscc9",
                   help="the shipped case: wscc9 (default; the WSCC 9-bus system, Anderson & Fouad), or one "
                        "converted from ANDES (kundur, ieee14, ieee39, npcc), or a case file ANDES reads (xlsx, "
                        "json, or a PSS/E raw with --dyr; converted once, needs ANDES: pip install -e '.[andes]')")
    p.add_argument("--dyr", default=None, metavar="FILE", help="the PSS/E dyr file of a raw --case")
    p.add_argument("--attach", action="append", default=[], metavar="BUS=NAME|FILE[:KIND]",
                   help="attach a sub-system at the case's bus BUS: the shipped feeder or plant (generated, 30 and "
                        "20 units, seed 0) or a case file ANDES reads whose only Slack is its boundary bus (opfmu "
                        "grid feeder|plant writes one); the power flow is solved jointly; KIND reference (default: "
                        "every device, run by --fmus), monolithic (the same in the monolithic DAE: needs --fmus "
                        "monolithic, or sets it where --fmus is left out) or aggregate (one unit of each model with "
                        "the summed ratings behind an equivalent impedance); result.csv adds P_attach_BUS, "
                        "Q_attach_BUS, summary.json S_attach_BUS; repeatable; needs ANDES")
    p.add_argument("--no-case-events", action="store_true",
                   help="leave the case's own events (line toggles, faults, generator trips) out (default: they "
                        "apply as in the case file, with the contingency)")
    p.add_argument("--dynamic-data", default=None, metavar="FILE",
                   help="the units' dynamic data (machines, exciters, FMU kinds; default: the case's shipped file)")
    p.add_argument("--fmus", choices=_run_kinds(), default=None,
                   help="the FMUs of every unit, monolithic for the DAE reference, or andes for ANDES' own "
                        "simulation (where ANDES is installed; its trapezoid at the smaller of --step and 1 ms, "
                        "its rows every --step) "
                        "(default: each unit's kind in the dynamic data: surrogate for the shipped file)")
    p.add_argument("--fmi-version", type=int, choices=(2, 3), default=2,
                   help="FMI version of the native FMUs built (default 2; FMI 3.0 inputs are held over each step)")
    if trip:
        p.add_argument("--trip", default=None, metavar="FROM-TO", help="the branch opened at clearing, e.g. 5-7")
    p.add_argument("--fault-start", type=_time, default=None,
                   help=f"fault start in s (default {ANDES_CASE_FAULT_START_S:g} for the cases converted from ANDES, "
                        "where their own events start at >= 1 s and ANDES applies no fault at t = 0; 0 for wscc9)")
    p.add_argument("--fault-impedance", type=float, default=None, metavar="PU",
                   help="fault reactance in pu, > 0 (default 1e-6, bolted, for wscc9; 1e-4, ANDES' Fault "
                        "default, for the cases converted from ANDES, where ANDES' Newton fails on a bolted "
                        "fault)")
    p.add_argument("--step", type=float, default=0.01, help="communication step in s (default 0.01)")
    p.add_argument("--coupling", choices=("iterated", "extrapolated", "held"), default="iterated",
                   help="iterated: inputs linear over each step to a consistent end voltage, the step redone "
                        "from a saved FMU state (default); extrapolated: linear to the extrapolated end, one pass; "
                        "held: the start voltages held over the step (a plain master)")
    p.add_argument("--passes", type=int, default=3, help="most passes of an iterated step (default 3)")
    p.add_argument("--fmu-cache", default=None, metavar="DIR", help="where built FMUs are kept")


def add_grid_parser(sub) -> None:
    grid = sub.add_parser("grid", help="network co-simulation of a grid case: run, cct, screen, export; feeder, plant",
                          description="A grid case with one FMU per device (machine, exciter) of each unit, the "
                                      "network solved at every communication point (Newton on the FMUs' directional "
                                      "derivatives), inputs linear over each step and the step iterated with "
                                      "FMU state rollback; or the monolithic DAE reference.")
    gsub = grid.add_subparsers(dest="grid_command", required=True)
    run = gsub.add_parser("run", help="one contingency", description="Simulate one contingency; writes DIR/result.csv "
                          "(one row per communication point), result.png, report.md and summary.json.")
    run.add_argument("--fault", type=int, default=None, metavar="BUS",
                     help="faulted bus (none: the case's own events alone, or --trip opened at --clear)")
    run.add_argument("--clear", type=_time, default=None, metavar="SECONDS",
                     help="clearing time in s (before --stop), with --fault; without it, when --trip opens")
    run.add_argument("--stop", type=_time, default=5.0, help=f"end time in s (default 5, at most {MAX_STOP_S:g})")
    run.add_argument("--compare", default=None,
                     help="runs drawn on the same figure and compared in the report: a comma list of "
                          "surrogate, reference, python, monolithic, andes, or none (default monolithic; none with "
                          "an --attach ...:surrogate, whose learned sub-system neither runs); every run "
                          "is compared with the monolithic and the ANDES run among them")
    run.add_argument("--out", required=True, metavar="DIR", help="output folder")
    run.add_argument("--host", choices=("master", "veragrid"), default="master",
                     help="what runs the FMUs of --fmus: opfmu's own master (default) or VeraGrid's RMS simulation "
                          "(VeraGridEngine, MPL-2.0, where installed: native FMUs through their Norton port; "
                          "docs/veragrid.md); the --compare runs stay on the master")
    _common(run)
    run.set_defaults(func=cmd_run)

    cct = gsub.add_parser("cct", help="critical clearing time", description="Critical clearing time of a fault and "
                          "its clearing action by bisection (stable: no two rotor angles pi apart before --stop).")
    cct.add_argument("--fault", type=int, required=True, metavar="BUS", help="faulted bus")
    cct.add_argument("--stop", type=_time, default=None,
                     help="end of each run in s (default: 3 for wscc9; 4 s after the fault start for the other cases, "
                          "so that a loss on the second swing of an inter-area mode is seen)")
    cct.add_argument("--resolution", type=float, default=1e-3, help="bisection resolution in s (default 0.001)")
    cct.add_argument("--json", action="store_true", help="print one JSON object (with cct_s)")
    _common(cct)
    cct.set_defaults(func=cmd_cct)

    scr = gsub.add_parser("screen", help="contingency screening on dask",
                          description="Faults at many buses, with and without each line trip, as independent runs "
                                      "on dask: CCT, verdict at --clear and first-swing peak per contingency.")
    scr.add_argument("--faults", default=None,
                     help="faulted buses, comma separated (default: every bus without a generator; wscc9: 4-9)")
    scr.add_argument("--trips", choices=("each", "none"), default="each",
                     help="each: also every trip at the faulted bus that keeps the generators connected (default)")
    scr.add_argument("--clear", type=_time, default=None,
                     help=f"clearing time of the verdict runs in s (default: {SCREEN_CLEARING_S:g} s after the fault "
                          "start)")
    scr.add_argument("--stop", type=_time, default=None,
                     help="end of each run in s (default: 3 for wscc9; 4 s after the fault start for the other cases, "
                          "so that a loss on the second swing of an inter-area mode is seen)")
    scr.add_argument("--resolution", type=float, default=1e-3, help="CCT resolution in s (default 0.001)")
    scr.add_argument("--workers", type=int, default=None,
                     help="local dask worker processes, at most the cores this process may use (0: no dask; "
                          "default 2, or 1 on one core)")
    scr.add_argument("--scheduler", default=None, metavar="ADDRESS",
                     help="an existing dask scheduler instead, tcp://HOST:PORT (default port 8786); the FMUs travel "
                          "to its workers, which need no access to this machine's files")
    scr.add_argument("--out", required=True, metavar="DIR", help="output folder")
    scr.add_argument("--quiet", action="store_true", help="no progress report")
    _common(scr, trip=False)
    scr.set_defaults(func=cmd_screen)

    exp = gsub.add_parser("export", help="the case's FMUs and case.json for another tool",
                          description="Writes one FMU file per distinct FMU the case runs and DIR/case.json: every "
                                      "device's FMU, bus, parameters, load-flow point, start values and where each of "
                                      "its inputs comes from (docs/grid.md, cosim/export.py).")
    exp.add_argument("--case", default="wscc9", help="a shipped case (wscc9, kundur, ieee14, ieee39, npcc) or a case "
                     "file ANDES reads (xlsx, json, or a PSS/E raw with --dyr)")
    exp.add_argument("--dyr", default=None, metavar="FILE", help="the PSS/E dyr file of a raw --case")
    exp.add_argument("--dynamic-data", default=None, metavar="FILE", help="the units' dynamic data of a shipped case")
    exp.add_argument("--fmus", choices=("reference", "surrogate"), default="reference",
                     help="native reference FMUs for every device (default), or the surrogate FMUs of the machines "
                          "whose dynamic data name an operator (native for the rest)")
    exp.add_argument("--fmi-version", type=int, choices=(2, 3), default=2, help="FMI version (default 2)")
    exp.add_argument("--fmu-cache", default=None, metavar="DIR", help="where built FMUs are kept")
    exp.add_argument("--out", required=True, metavar="DIR", help="output folder")
    exp.set_defaults(func=cmd_export)

    for name, what, units in (("feeder", "a radial distribution feeder of PVD1 units and loads behind a substation "
                                         "transformer", 30),
                              ("plant", "a utility-scale PV plant of REGCA1/REECA1/REPCA1 units behind a main "
                                        "transformer", 20)):
        sub_p = gsub.add_parser(name, help=f"write a generated {name} (a sub-system for --attach)",
                                description=f"Writes {what}, its settings drawn per unit from --seed, as an ANDES "
                                            "JSON case file whose only Slack is its boundary bus "
                                            "(reference_models.grid.subsystems; docs/grid.md).")
        sub_p.add_argument("--units", type=int, default=units, help=f"number of units (default {units})")
        sub_p.add_argument("--seed", type=int, default=0, help="seed of the units' settings, >= 0 (default 0)")
        sub_p.add_argument("--out", required=True, metavar="FILE", help="the case file to write (.json)")
        sub_p.set_defaults(func=cmd_subsystem, subsystem=name)


def _check_out(out, names) -> None:
    """UserError unless `out` (--out) names a folder that can take the files `names` (made only when
    they are written: cosim.outputs.result_set)."""
    from cosim import outputs

    try:
        outputs.check_output(out, names)
    except outputs.OutputError as exc:
        raise UserError(str(exc)) from None


@contextmanager
def _scratch():
    """A scratch folder of the command for the FMUs it extracts, removed at its end whatever happened."""
    folder = tempfile.mkdtemp(prefix="opfmu_run_")
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _case(args):
    """The case of --case (a shipped name or a case file) and --dynamic-data / --dyr; UserError for
    what cannot be read."""
    from reference_models.grid import wscc9
    from reference_models.grid.case import DATA_DIR, CaseError, load_case, shipped_case

    if not args.case.strip():
        raise UserError(f"--case must name a case ({', '.join(CASES)}, or a case file ANDES reads)")
    if getattr(args, "attach", None):
        return _attached_case(args)
    if args.case not in CASES:
        if not (Path(args.case).exists() or Path(args.case).suffix.lower() in CASE_FILE_SUFFIXES):
            raise UserError(f"unknown case {args.case!r} (known: {', '.join(CASES)}, or a case file ANDES reads: "
                            f"{', '.join(CASE_FILE_SUFFIXES)})")
        if args.dynamic_data is not None:
            raise UserError("--dynamic-data goes with a shipped case; a case file brings its own dynamic data "
                            "(a PSS/E raw: --dyr)")
        from reference_models.grid.andes_case import case_from_file

        try:
            return case_from_file(args.case, args.dyr)
        except CaseError as exc:
            raise UserError(one_line(exc, 300)) from None
    if args.dyr is not None:
        raise UserError(f"--dyr goes with a PSS/E raw case file, not the shipped case {args.case}")
    try:
        if args.case == "wscc9":
            return wscc9.case(args.dynamic_data)
        if args.dynamic_data is None:
            return shipped_case(args.case)
        return load_case(DATA_DIR / f"{args.case}_network.json", args.dynamic_data, args.case)
    except CaseError as exc:
        raise UserError(f"cannot use the dynamic data: {one_line(exc, 300)}") from None


ATTACH_KINDS = ("reference", "monolithic", "surrogate", "aggregate")  # DESIGN section 11 (not given: reference)
SUBSYSTEM_NAMES = ("feeder", "plant")  # the shipped sub-systems (reference_models.grid.subsystems.SHIPPED)


class Attachment(NamedTuple):
    """One --attach BUS=NAME|FILE[:KIND]: the host bus, the sub-system (a shipped name or a case
    file), its kind (None where not given: the full detail, run by the run's runner) and the text."""

    bus: int
    source: str
    kind: str | None
    text: str


def _attachments(args) -> list:
    """The Attachments of --attach; UserError for one that is malformed, has an unknown kind, or
    names neither a shipped sub-system (SUBSYSTEM_NAMES: the bare name, nothing else) nor a file."""
    out = []
    for text in args.attach:
        bus, sep, source = text.partition("=")
        head, colon, kind = source.rpartition(":")
        if colon and kind in ATTACH_KINDS:
            source = head
        elif colon and (head in SUBSYSTEM_NAMES or Path(head).is_file()) and not Path(source).is_file():
            raise UserError(f"--attach {text}: unknown kind {kind!r} (one of {', '.join(ATTACH_KINDS)})")
        else:
            kind = None
        if not sep or not bus.strip().lstrip("-").isdigit() or not source:
            raise UserError(f"--attach takes BUS=NAME|FILE[:KIND] (a bus number of the case; a shipped sub-system, "
                            f"{' or '.join(SUBSYSTEM_NAMES)}, or a sub-system case file; KIND one of "
                            f"{', '.join(ATTACH_KINDS)}), got {text!r}")
        if source not in SUBSYSTEM_NAMES and not Path(source).is_file():
            raise UserError(f"--attach {text}: no file {source} (nor a shipped sub-system: "
                            f"{', '.join(SUBSYSTEM_NAMES)})")
        out.append(Attachment(int(bus), source, kind, text))
    return out


def _attach_runner(attachments, fmus):
    """--fmus as the kinds of `attachments` leave it. One runner runs the whole run, host and
    sub-systems: --fmus. A kind that names one must agree with it: :monolithic (the DAE) needs
    --fmus monolithic, and where --fmus is left out makes the run monolithic; :reference (native
    FMUs in the master) needs a run of FMUs (--fmus reference, surrogate, python, or left out). No
    kind, or :aggregate, runs in whatever --fmus runs. UserError for a conflict."""
    given = fmus
    if fmus is None and any(a.kind == "monolithic" for a in attachments):
        fmus = "monolithic"
    if any(a.kind == "surrogate" for a in attachments):
        if fmus not in (None, "reference"):
            raise UserError(f"--attach ...:surrogate runs the sub-system as its surrogate FMU beside the host's native "
                            f"FMUs: it conflicts with --fmus {fmus} (give --fmus reference or leave it out)")
        fmus = None  # each unit its own FMU: the host's native, the sub-system's surrogate
    for a in attachments:
        against = f"--fmus {given}" if given is not None else "another --attach's :monolithic"
        if a.kind == "monolithic" and fmus != "monolithic":
            raise UserError(f"--attach {a.text} runs the sub-system in the monolithic DAE, which then runs the whole "
                            f"case: it conflicts with {against} (give --fmus monolithic or leave --fmus out)")
        if a.kind == "reference" and fmus in REFERENCE_KINDS:
            raise UserError(f"--attach {a.text} runs the sub-system as native FMUs in the master, which then runs "
                            f"the whole case: it conflicts with {against} (leave the kind out: the sub-system then "
                            f"runs where the case does)")
    return fmus


def _subsystem_file(attachment, folder: Path) -> Path:
    """The case file attached for `attachment` (cache files under `folder`): a shipped name's
    generated file (folder/subsystems, written once) or the file given, as it is for reference and
    monolithic (the full detail) or its hand-made equivalent for aggregate (folder/attached,
    reference_models.grid.aggregate); for surrogate the detail too, whose joint power flow starts
    the surrogate (_surrogate)."""
    from reference_models.grid.aggregate import aggregate_file
    from reference_models.grid.subsystems import shipped_file

    source = (shipped_file(attachment.source, folder / "subsystems") if attachment.source in SUBSYSTEM_NAMES
              else Path(attachment.source))
    return aggregate_file(source, folder / "attached") if attachment.kind == "aggregate" else source


def _surrogate(case, attachment, path: Path):
    """`case` with the sub-system of `attachment` (attached from the file `path`) run as its surrogate
    FMU (cosim.subsystem_surrogate.surrogate_in); UserError where it has no operator."""
    from cosim.fmu import CouplingError
    from cosim.subsystem_surrogate import surrogate_in

    try:
        return surrogate_in(case, attachment.bus, path)
    except CouplingError as exc:
        raise UserError(f"--attach {attachment.text}: {one_line(exc, 300)}") from None


def _attached_case(args):
    """The case of --case with the sub-systems of --attach attached (reference_models.grid.attach);
    sets args.fmus as the kinds leave it (_attach_runner)."""
    import importlib.util

    attachments = _attachments(args)
    args.fmus = _attach_runner(attachments, args.fmus)
    if args.dynamic_data is not None or args.dyr is not None:
        raise UserError("--attach goes with a shipped case converted from ANDES or a case file ANDES reads, "
                        "without --dynamic-data or --dyr")
    if importlib.util.find_spec("andes") is None:
        raise UserError("--attach needs ANDES to read and join the case files: pip install -e '.[andes]'")
    from reference_models.grid.andes_case import ANDES_CASES, case_cache_dir, case_from_file, stock_case
    from reference_models.grid.attach import attached_file
    from reference_models.grid.case import CaseError

    if args.case in ANDES_CASES:
        try:
            host = stock_case(ANDES_CASES[args.case])
        except CaseError as exc:
            raise UserError(one_line(exc, 300)) from None
    elif args.case in CASES:
        raise UserError(f"--attach needs a case ANDES reads; {args.case} has no ANDES case file "
                        f"(use one of {', '.join(ANDES_CASES)} or a case file)")
    elif Path(args.case).is_file():
        host = Path(args.case)
    else:
        raise UserError(f"unknown case {args.case!r} (known: {', '.join(CASES)}, or a case file ANDES reads)")
    folder = case_cache_dir()
    try:
        files = [(a.bus, _subsystem_file(a, folder)) for a in attachments]
        case = case_from_file(attached_file(host, files, folder / "attached"))
        for a, (bus, path) in zip(attachments, files):
            if a.kind == "surrogate":
                case = _surrogate(case, a, path)
        return case
    except CaseError as exc:
        raise UserError(one_line(exc, 300)) from None
    except OSError as exc:
        raise UserError(f"cannot use the case cache {folder}: {exc.strerror or exc}") from None


def _run_events(args, case) -> None:
    """UserError for a run whose events do not add up: --fault without --clear, --trip without the
    time it opens (--clear), --clear with neither, or nothing happening at all (no --fault, no
    --trip and no events of the case's own). A case's own events need neither --fault nor --clear."""
    if args.fault is not None or args.trip is not None:
        if args.clear is None:
            raise UserError("--fault needs --clear SECONDS (its clearing time)" if args.fault is not None else
                            "--trip without --fault opens the branch at --clear SECONDS: give it")
        return
    if args.clear is not None:
        raise UserError("--clear goes with --fault BUS or --trip FROM-TO")
    if args.no_case_events or not case.events:
        raise UserError("nothing happens in this run: give --fault BUS --clear SECONDS or --trip FROM-TO --clear SECONDS"
                        + ("" if args.no_case_events else f" ({case.name} has no events of its own)"))


def _case_notes(case) -> list:
    """What ANDES adjusted in the case's file and its conversion states rather than refuses
    (reference_models.grid.andes_case.case_notes), each printed on stderr."""
    from reference_models.grid.andes_case import case_notes

    notes = list(case_notes(case))
    for note in notes:
        print(f"note: {note}", file=sys.stderr)
    return notes


def _surrogates(case, kind) -> str | None:
    """Which devices of `case` run as surrogate FMUs under `kind` (None: each unit's own), in words;
    None where none does."""
    if kind in REFERENCE_KINDS:
        return None
    from cosim.fmus import unit_fmus

    fmus = unit_fmus(case, kind)
    named = [f"{u.machine.component.name.upper()} at bus {u.bus}" + (f" (generator {u.generator})" if u.generator else "")
             + f" (operator {Path(str(f.operator)).name})" for u, f in zip(case.units, fmus) if f.kind == "surrogate"]
    if not named:
        return None
    others = sum(len(u.devices) for u in case.units) - len(named)
    return (f"surrogate FMUs for {len(named)} bus device{'s' if len(named) > 1 else ''}: {', '.join(named)}; native "
            f"reference FMUs for the other {others} device{'s' if others != 1 else ''}")


def _state(case, kind) -> list:
    """The case's notes and which devices run as surrogates under `kind`, each printed on stderr."""
    stated = _case_notes(case)
    text = _surrogates(case, kind)
    if text:
        stated.append(text)
        print(f"note: {text}", file=sys.stderr)
    return stated


def _settings(args):
    from cosim.master import MasterSettings

    try:
        return MasterSettings(step=args.step, coupling=args.coupling, passes=args.passes)
    except ValueError as exc:
        raise UserError(one_line(exc, 300)) from None


def _fault_start(args) -> None:
    """Sets args.fault_start [s] where --fault-start is not given: ANDES_CASE_FAULT_START_S for the
    cases converted from ANDES, 0 for wscc9."""
    if args.fault_start is None:
        args.fault_start = 0.0 if args.case == "wscc9" else ANDES_CASE_FAULT_START_S


def _stop(stop: float, settings) -> None:
    """UserError for a stop time [s] out of (0, MAX_STOP_S] or with too many steps of `settings`."""
    from cosim.master import check_steps

    if not 0 < stop <= MAX_STOP_S:
        raise UserError(f"--stop must be a time in (0, {MAX_STOP_S:g}] s, got {stop:g}")
    try:
        check_steps(stop, settings.step)
    except ValueError as exc:
        raise UserError(one_line(exc, 300)) from None


def _fault_impedance(args) -> complex:
    from reference_models.grid.contingency import ANDES_FAULT_IMPEDANCE, BOLTED_FAULT_IMPEDANCE

    if args.fault_impedance is None:
        return BOLTED_FAULT_IMPEDANCE if args.case == "wscc9" else ANDES_FAULT_IMPEDANCE
    if not (math.isfinite(args.fault_impedance) and args.fault_impedance > 0):
        raise UserError(f"--fault-impedance must be a finite reactance > 0 pu, got {args.fault_impedance:g}")
    return complex(0.0, args.fault_impedance)


def _contingency(case, bus, clear, trip, args):
    from reference_models.grid.contingency import Contingency

    try:
        return Contingency(bus, clear, trip, args.fault_start, _fault_impedance(args), case.network,
                           () if args.no_case_events else case.events)
    except ValueError as exc:
        raise UserError(one_line(exc, 300)) from None


def _check_fmus(case, kind, fmu_cache=None, contingency=None) -> None:
    """The FMU kinds, FMU files and operators of every unit and the FMU cache folder, checked before
    any build; for andes, that ANDES is there and can run `contingency`."""
    from cosim.fmu import CouplingError
    from opfmu.checks import output_folder
    from cosim.fmus import check_unit_fmus

    if kind == "monolithic":
        return
    if kind == "andes":
        from cosim.andes_runner import ANDES_MISSING, andes_available

        if case.name not in CASES[1:] and case.source is None:
            raise UserError(f"--fmus andes runs the cases converted from ANDES ({', '.join(CASES[1:])}) and case "
                            f"files, not {case.name}")
        if not andes_available():
            raise UserError(ANDES_MISSING)
        if contingency is not None:
            from cosim.andes_runner import check_contingency

            try:
                check_contingency(contingency)
            except ValueError as exc:
                raise UserError(one_line(exc, 300)) from None
        return
    if fmu_cache is not None:
        output_folder(fmu_cache)
    try:
        fmus = check_unit_fmus(case, kind)
    except CouplingError as exc:
        raise UserError(one_line(exc, 300)) from None
    if kind == "surrogate" and not any(f.kind == "surrogate" for f in fmus):
        raise UserError(f"--fmus surrogate: no machine of {case.name} has a surrogate operator in its dynamic data "
                        "(\"fmu\": {\"kind\": \"surrogate\", \"operator\": FILE}); run --fmus reference instead")


def _main_kind(case, fmus) -> str:
    from cosim.fmus import unit_fmus

    if fmus in REFERENCE_KINDS:
        return fmus
    return fmus or "+".join(sorted({f.kind for f in unit_fmus(case)}))


def _progress(text: str) -> None:
    print(f"building {text}", file=sys.stderr)


def _open(kind, case, settings, args, progress, **options):
    """The runner of `kind` (options: open_runner's, e.g. the scratch folder FMUs are extracted
    under); ANDES integrates at min(--step, REFERENCE_STEP), its rows every --step."""
    from cosim.fmu import CouplingError
    from cosim.runners import open_runner

    if kind == "andes":
        from cosim.andes_runner import REFERENCE_STEP, AndesRunner

        return AndesRunner(case, min(settings.step, REFERENCE_STEP), rows=settings.step)
    try:
        return open_runner(kind, case, settings, args.fmu_cache, progress, fmi_version=args.fmi_version, **options)
    except CouplingError as exc:
        raise UserError(one_line(exc, 300)) from None


def cmd_export(args) -> None:
    from cosim.export import export_case
    from cosim.fmu import CouplingError

    _check_out(args.out, ["case.json"])
    case = _case(args)
    _check_fmus(case, args.fmus, args.fmu_cache)
    stated = _case_notes(case)
    surrogates = _surrogates(case, args.fmus)
    if surrogates:
        print(f"note: {surrogates}", file=sys.stderr)
    cache = Path(args.fmu_cache) if args.fmu_cache else None
    try:
        path = export_case(case, args.out, args.fmus, args.fmi_version, cache, _progress)
    except CouplingError as exc:
        raise UserError(one_line(exc, 300)) from None
    count = len({d["fmu"] for d in json.loads(path.read_text(encoding="utf-8"))["devices"]})
    print(f"{case.name}: {count} FMU files and {path}" + (f" ({len(stated)} notes on the case above)" if stated else ""))


def cmd_subsystem(args) -> None:
    """opfmu grid feeder|plant: the generated sub-system written to --out (reference_models.grid.
    subsystems); UserError before any work for --units or --seed out of the generator's range, or an
    --out that is no .json file path in a folder that exists."""
    from opfmu.checks import output_file
    from reference_models.grid.subsystems import FeederSpec, PlantSpec, describe, records, write_case

    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise UserError(f"--out must name a .json file (an ANDES JSON case), got {args.out!r}")
    output_file(out)
    if not out.parent.is_dir():
        raise UserError(f"--out {out}: no folder {out.parent}")
    spec_type = PlantSpec if args.subsystem == "plant" else FeederSpec
    try:
        spec = spec_type(units=args.units, seed=args.seed)
        data = records(spec)
    except ValueError as exc:
        raise UserError(f"{args.subsystem}: {one_line(exc, 300)}") from None
    try:
        path = write_case(data, out)
    except OSError as exc:
        raise UserError(f"cannot write {out}: {exc.strerror or exc}") from None
    print(f"{describe(spec)}: {path}")


def cmd_run(args) -> None:
    from cosim import outputs

    _check_out(args.out, outputs.RUN_FILES)
    case = _case(args)
    attached = tuple(dict.fromkeys(a.bus for a in _attachments(args)))  # the host buses with sub-systems
    _fault_start(args)
    settings = _settings(args)
    _stop(args.stop, settings)
    _run_events(args, case)
    contingency = _contingency(case, args.fault, args.clear, args.trip, args)
    if contingency.clear_s is not None and contingency.clear_s >= args.stop:
        raise UserError(f"the clearing at {args.clear:g} s must come before the stop at {args.stop:g} s")
    kinds_known = _run_kinds()
    learned = any(a.kind == "surrogate" for a in _attachments(args))
    text = args.compare if args.compare is not None else "none" if learned else "monolithic"
    compare = [] if text.strip() in ("", "none") else [k.strip() for k in text.split(",")]
    if learned and set(compare) & set(REFERENCE_KINDS):
        raise UserError("--compare: an --attach ...:surrogate runs its sub-system as a learned FMU, which neither the "
                        "monolithic DAE nor ANDES runs; compare with the detail in a run of its own (--attach BUS=FILE)")
    unknown = [k for k in compare if k not in kinds_known]
    if unknown:
        raise UserError(f"--compare: unknown run kind {unknown[0]!r} (known: {', '.join(kinds_known)}, none)")
    main_kind = _main_kind(case, args.fmus)
    if args.host == "veragrid":
        from cosim.veragrid import VERAGRID_MISSING, veragrid_available

        if not veragrid_available():
            raise UserError(VERAGRID_MISSING)
        if args.fmus not in (None, "reference"):
            raise UserError(f"--host veragrid runs native FMUs (--fmus reference), not --fmus {args.fmus}")
        if not learned:  # with an --attach ...:surrogate each unit keeps its own FMU
            main_kind = args.fmus = "reference"
    kinds = [args.fmus] + [k for k in compare if k != main_kind]
    for kind in kinds:
        _check_fmus(case, kind, args.fmu_cache, contingency)
    stated = _case_notes(case)  # on stderr and into the report and summary
    for text in dict.fromkeys(_surrogates(case, kind) for kind in kinds):
        if text:
            stated.append(text)
            print(f"note: {text}", file=sys.stderr)
    runs, timings = {}, {}
    with _scratch() as scratch:
        for kind in kinds:
            host = {"host": "veragrid"} if args.host == "veragrid" and kind == kinds[0] else {}
            runner = _open(kind, case, settings, args, _progress, scratch=scratch, **host)
            try:
                result, timing = runner.run(contingency, args.stop)
            except RuntimeError as exc:
                if kind != "andes" and not host:
                    raise
                raise UserError(one_line(exc, 300)) from None
            finally:
                runner.close()
            label = kind or main_kind
            runs[label], timings[label] = result, timing
    main = runs[main_kind]
    title = f"{CASE_TITLES.get(args.case, args.case)}: {contingency.label}"
    messages = {k: t.pop("messages", {}) for k, t in timings.items()}
    logged = [f"{_label(kind)}, generator {bus}: {text}" for kind, per_bus in messages.items()
              for bus, texts in per_bus.items() for _, text in texts[:3]]
    notes = [f"{_label(kind)}: {note}" for kind, t in timings.items() for note in t.pop("notes", [])]
    summary = {"contingency": contingency.label, "case_events": list(contingency.case_event_labels(args.stop + 1e-9)),
               "fmus": main_kind, "stable": main.stable,
               "loss_of_synchronism_s": main.loss_of_synchronism_s, "timing": timings, "step_s": settings.step,
               "passes": settings.passes, "fmi_version": args.fmi_version, "notes": stated,
               **_attach_ratings(case, attached)}
    fault, trips = contingency.fault_intervals(args.stop), contingency.trip_times(args.stop)
    for reference in outputs.REFERENCES:
        if reference in runs and len(runs) > 1:
            summary[f"difference_from_{reference}"] = {k: outputs.errors(r, runs[reference], fault, case, trips)
                                                       for k, r in runs.items() if k != reference}
    out = Path(args.out)
    try:
        with outputs.result_set(out, outputs.RUN_FILES) as staging:
            outputs.write_csv(staging / "result.csv", main, case, attached)
            outputs.plot(staging / "result.png", runs, title, case)
            outputs.report(staging / "report.md", title, runs, timings, contingency, case,
                           [f"Note: {n}" for n in stated + notes]
                           + ((["", "FMU log (first messages per generator):", ""] + [f"- {n}" for n in logged])
                              if logged else []))
            (staging / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    except (outputs.OutputError, OSError) as exc:
        raise UserError(f"cannot write the results into {out}: {getattr(exc, 'strerror', None) or exc}") from None
    verdict = "stable" if main.stable else f"unstable (loss of synchronism at {main.loss_of_synchronism_s:.3f} s)"
    print(f"{title}: {verdict}; {_label(main_kind)} in {timings[main_kind]['total_s']:.2f} s")
    for reference in outputs.REFERENCES:
        for kind, e in summary.get(f"difference_from_{reference}", {}).items():
            power = (f", inverter and load P {e['P']:.2g} pu, Q {e['Q']:.2g} pu"
                     if e['P'] == e['P'] or e['Q'] == e['Q'] else "")  # NaN where none
            print(f"  {_label(kind)} against the {outputs.REFERENCES[reference]} run: rotor angles "
                  f"{e['angle_deg']:.3f} deg, terminal voltages {e['V']:.2g} pu{power}")
    print(f"written: {out / 'result.csv'}, {out / 'result.png'}, {out / 'report.md'}")


def _attach_ratings(case, buses) -> dict:
    """{"S_attach_<bus>": the rating [MVA] of the sub-system attached at each host bus of `buses`}
    (reference_models.grid.boundary.subsystem_rating: the sum of its generating devices' Sn)."""
    from reference_models.grid.boundary import subsystem_rating

    return {f"S_attach_{bus}": subsystem_rating(case, bus) for bus in buses}


def _label(kind) -> str:
    from cosim.outputs import LABELS

    return LABELS.get(kind, kind)


def _resolution(args) -> None:
    if not (math.isfinite(args.resolution) and 0 < args.resolution <= 0.1):
        raise UserError(f"--resolution must be a time in (0, 0.1] s, got {args.resolution:g}")


def _default_stop(case, contingency) -> float:
    """The stop [s] of cct and screen runs where --stop is not given: 3 s for wscc9 (DESIGN), else
    stability.default_stop (the fault start + 4 s: a second-swing loss of an inter-area mode)."""
    from cosim.stability import default_stop

    return WSCC9_STABILITY_STOP_S if case.name == "wscc9" and case.source is None else default_stop(contingency)


def _stop_after_fault(stop: float, contingency) -> None:
    """UserError where the runs end [s] no later than the fault start of `contingency`."""
    if stop <= contingency.fault_start:
        raise UserError(f"--stop ({stop:g} s) must come after the fault start at {contingency.fault_start:g} s")


def cmd_cct(args) -> None:
    from cosim.stability import critical_clearing_time, runner_stable

    case = _case(args)
    _fault_start(args)
    settings = _settings(args)
    _resolution(args)
    contingency = _contingency(case, args.fault, args.fault_start + 0.05, args.trip, args)  # clearing: bisected
    stop = args.stop if args.stop is not None else _default_stop(case, contingency)
    _stop(stop, settings)
    _stop_after_fault(stop, contingency)
    _check_fmus(case, args.fmus, args.fmu_cache, contingency)
    _state(case, args.fmus)
    with _scratch() as scratch:
        runner = _open(args.fmus, case, settings, args, None if args.json else _progress, monolithic_rtol=1e-9,
                       scratch=scratch)
        try:
            cct = critical_clearing_time(runner_stable(runner, stop), contingency, args.resolution)
        finally:
            runner.close()
    kind = _main_kind(case, args.fmus)
    after = None if cct.cct_s is None else round(cct.cct_s - args.fault_start, 9)  # the critical fault duration [s]
    if args.json:
        print(json.dumps({"case": args.case, "fault": args.fault, "trip": contingency.trip,
                          "fault_start_s": args.fault_start, "stop_s": stop, "fmus": kind, **cct.to_dict(),
                          "cct_after_fault_start_s": after}))
        return
    label = contingency.label.split(", cleared")[0]
    start = f"the fault start at {args.fault_start:g} s"
    if cct.cct_s is None:
        print(f"{label}: unstable even when cleared {args.resolution * 1e3:g} ms after the fault")
    elif not cct.bounded:
        print(f"{label}: stable for every clearing up to {cct.cct_s:g} s ({after:g} s after {start})")
    else:
        print(f"{label}{', ' + contingency.trip + ' opened' if contingency.trip else ''}: critical clearing time "
              f"{cct.cct_s:.4f} s, CCT {after:.4f} s after {start} (unstable at {cct.unstable_s:.4f} s; "
              f"{len(cct.runs)} runs, {_label(kind)})")


def _workers(workers) -> int:
    """--workers (None: 2, or 1 on one core); UserError outside [0, the cores this process may use]:
    each worker is a single-threaded process, and more than the cores gain nothing."""
    from opfmu.cli import usable_cores

    cores = usable_cores()
    if workers is None:
        return min(2, cores)
    if not 0 <= workers <= cores:
        raise UserError(f"--workers must lie in [0, {cores}] (the cores this process may use), got {workers}")
    return workers


def cmd_screen(args) -> None:
    from cosim import outputs
    from cosim.fmu import CouplingError
    from cosim.fmus import generator_files
    from cosim.screening import SchedulerError, ScreeningTask, contingencies, default_fault_buses, screen

    _check_out(args.out, outputs.SCREENING_FILES)
    workers = _workers(args.workers)
    scheduler = None
    if args.scheduler is not None:
        from cosim.screening import check_scheduler

        try:
            scheduler = check_scheduler(args.scheduler)
        except SchedulerError as exc:
            raise UserError(one_line(exc, 300)) from None
    case = _case(args)
    _fault_start(args)
    settings = _settings(args)
    _resolution(args)
    if args.faults is None:
        buses = default_fault_buses(case.network)
    else:
        parts = [b.strip() for b in args.faults.split(",")]
        if not all(parts) or not all(p.lstrip("-").isdigit() for p in parts):
            raise UserError(f"--faults must be bus numbers separated by commas, got {args.faults!r}")
        buses = [int(b) for b in parts]
    try:
        pairs = contingencies(case.network, buses, args.trips)
    except ValueError as exc:
        raise UserError(one_line(exc, 300)) from None
    clear = args.clear if args.clear is not None else round(args.fault_start + SCREEN_CLEARING_S, 9)
    tasks_contingencies, left_out = [], []
    for bus, trip in pairs:
        try:
            tasks_contingencies.append(_contingency(case, bus, clear, trip, args))
        except UserError as exc:
            if trip is None:
                raise
            left_out.append(f"fault at bus {bus}, {trip} opened: {exc}")  # a trip the case's own events forbid
    stop = args.stop if args.stop is not None else _default_stop(case, tasks_contingencies[0])  # one fault start
    _stop(stop, settings)
    if clear >= stop:
        raise UserError(f"the clearing at {clear:g} s must come before the stop at {stop:g} s")
    for c in tasks_contingencies if args.fmus == "andes" else tasks_contingencies[:1]:
        _check_fmus(case, args.fmus, args.fmu_cache, c)
    stated = _state(case, args.fmus)
    try:
        files = () if args.fmus in REFERENCE_KINDS else tuple(generator_files(case, args.fmus, args.fmu_cache,
                                                                               _progress, args.fmi_version))
    except CouplingError as exc:
        raise UserError(one_line(exc, 300)) from None
    kind = _main_kind(case, args.fmus)
    if kind == "andes":  # ANDES integrates at min(--step, REFERENCE_STEP), as in grid run and cct
        from dataclasses import replace

        from cosim.andes_runner import REFERENCE_STEP

        settings = replace(settings, step=min(settings.step, REFERENCE_STEP))
    tasks = [ScreeningTask(case, c, kind, files, settings, stop, args.resolution) for c in tasks_contingencies]
    started = time.perf_counter()
    try:
        rows = screen(tasks, workers, scheduler, progress=not args.quiet)
    except SchedulerError as exc:  # the scheduler went away since it was checked
        raise UserError(one_line(exc, 300)) from None
    out = Path(args.out)
    try:
        with outputs.result_set(out, outputs.SCREENING_FILES) as staging:
            outputs.write_screening(staging, rows, f"{CASE_TITLES.get(args.case, args.case)} contingency screening "
                                                   f"({_label(kind)}, faults from {args.fault_start:g} s, verdicts "
                                                   f"at {clear:g} s clearing)",
                                    [f"Note: {n}" for n in stated] + [f"Left out: {n}." for n in left_out],
                                    args.fault_start)
    except (outputs.OutputError, OSError) as exc:
        raise UserError(f"cannot write the results into {out}: {getattr(exc, 'strerror', None) or exc}") from None
    print(outputs.screening_table(rows))
    for note in left_out:
        print(f"left out: {note}")
    print(f"{len(rows)} contingencies in {time.perf_counter() - started:.1f} s; written: {out / 'screening.csv'}, "
          f"{out / 'screening.md'}, {out / 'screening.png'}")
