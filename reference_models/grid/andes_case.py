"""Cases from the files ANDES reads (xlsx, json, PSS/E raw + dyr): ANDES (optional, GPL-3.0-or-later,
imported here only) loads the file and solves its power flow; the result is written as an opfmu
case, a network file and a dynamic-data file (reference_models.grid.case), that runs without ANDES.

    python -m reference_models.grid.andes_case CASE OUT_DIR [--name NAME] [--dyr FILE]
    python -m reference_models.grid.andes_case --shipped     # regenerates the shipped cases
    python -m reference_models.grid.andes_case --compare NAME  # start values against ANDES'

CASE: a file path, or a case ANDES ships (e.g. ieee39/ieee39_full.xlsx).

`case_from_file(path, dyr)` is the Case of a user's file in one call: converted once, kept in a
cache keyed by the files' bytes (case_cache_dir()), loaded from there (without ANDES) afterwards;
Case.source names the file so that ANDES can run the very file as the reference.

What is stored, all on the system base (ANDES' `config.mva`) unless said otherwise:
* buses (ANDES' Bus idx, which must be integers; Vn [kV]); branches from ANDES' Line with its
  series impedance as ANDES uses it (r + 1e-8, x + 1e-8: ANDES adds 1e-8 to both), total charging
  b, and the tap ratio and phase shift [rad] of a transformer at its from side (lines with
  g, g1, b1, g2, b2 not 0 are refused: none of the ANDES cases has them); shunts (Shunt g, b,
  summed per bus); the out-of-service devices (u = 0) are left out.
* loads as ANDES' time-domain simulation treats them by default (PQ config p2p = q2q = 0, p2i =
  q2i = 0, p2z = q2z = 1: constant impedance at the power-flow voltage): the power each PQ draws in
  the power flow (its Ppf, Qpf; p0, q0 unless the power flow converted it to an impedance outside
  [vmin, vmax]), summed per bus; Case.reduced turns them into the admittances conj(S) / V0^2,
  ANDES' Req, Xeq. A case whose PQ config is not (0, 0, 1) is refused.
* the load flow: ANDES' power-flow solution (Bus v, a; PV and Slack p, q), checked here: the
  stored network's bus power mismatch at the stored solution must stay below mismatch_limit (1e-8 pu
  for all but the largest cases).
* the generators: the Slack and PV devices (slack first, then PV, file order each), each named by
  its ANDES idx; units are keyed by generator (a bus may hold several, npcc does). A static
  generator that several machines or converters share (ANDES' gen, each taking its gammap, gammaq
  share of its power: ieee14_pvd1's ten PVD1) is one generator per device, named "GEN/DEVICE", with
  its share of the load-flow power (the shares must sum to 1: otherwise ANDES starts off its own
  load flow, refused); a Toggle of the static generator trips them all. A static generator in
  service that no machine or converter names keeps its own equations in ANDES' time domain (a PV
  holds P and |V|, the slack |V| and angle): its unit is a PV or Slack device
  (reference_models.models.static_generator), stated in the notes.
* the dynamic devices, one unit per synchronous machine (GENROU, GENCLS), linked by ANDES' `gen`
  (machine -> static generator), `syn` (exciter, governor -> machine) and `avr` (stabiliser ->
  exciter): devices "machine", "exciter", "governor", "stabiliser" with their component (the
  reference_models.models model of that name) and parameters as the case file gives them (ANDES'
  input data before its own conversion to the system base: machine and turbine data on the
  machine base Sn, as reference_models.models take them, docs/standard-models.md), plus Sn, Sb,
  fn where the component takes them. Models opfmu does not have are refused with one line naming
  them all; measurement-only models (BusFreq, BusROCOF, ACEc, Area) and the case's description (Summary) are left out.
* the case's own events: Toggle of a Line (a branch event: status 0 open, 1 closed again, each
  toggle flipping the status it finds, all in service at the start), of a machine (GENROU, GENCLS)
  or of its load-flow generator (PV, Slack; a group name such as SynGen or StaticGen resolves to its
  model) (a generator event: its unit tripped), Fault (bus, tf, tc, rf, xf); a disabled one (u = 0)
  is left out; a Toggle of any other model is refused in one line.

Nothing silently wrong (read_back): ANDES' log records at WARNING and above while it reads, sets up
and solves the case are kept (a logging handler on the 'andes' logger), not printed, and read back
with what the file gave each device (System.add's arguments) against what ANDES kept (its vin):
* refused (CaseError, one line naming the file and each model, device, parameter and value): what
  ANDES drops: a dyr model it does not know (a misspelt one, IEEET2, ...: its records are dropped,
  a generator left without a model it had in the file is an error; the generators are named), a
  model (sheet) it does not know, a field (column) of a converted model it does not know that reads as
  a misspelt parameter the file does not give (`_misspelt`: the parameter would take its default); and a value
  ANDES replaces for a parameter the conversion uses of
  a device in service: a value the model cannot take (ANDES' non_zero, non_negative, non_positive
  checks: a zero it divides by such as an inertia M, a time constant TF1 or a Line's x, a negative
  inertia); any other ANDES error record;
* stated (the case's notes, Case.dynamic_data's "notes", case_notes; `opfmu grid` prints them on
  stderr and writes them into its report): a replaced value that the converted case does not use
  (a device out of service, a model left out such as ACEc, a parameter opfmu does not read), a
  power-flow start guess replaced (Bus v0, a0: the solution does not depend on it), an infinite
  limit made 1e8, an empty cell or NaN of a parameter the conversion uses (ANDES' documented default
  is used: the stock files leave many cells empty so), a field (column) ANDES drops that is one of its
  parameters spelt in other case, with the values ANDES uses (kundur_esdc2a's SWITCH: ANDES' Switch), a field
  ANDES drops that is no misspelling (a parameter of another version of the model: kundur_reg's REGCA1
  Iqmax beside the Iqrmax it gives, kundur_wtdta1's WTDTA1 Ht, Hg), and any other ANDES warning
  (PSS/E raw conversion notes, two slack generators on a bus, ...) with ANDES' words;
* an empty cell of a parameter the conversion does not use (TGOV1's Tn: Sn where not given) and a
  parameter the file does not give at all take ANDES' defaults, as ANDES documents, unstated.
The power flow converges to pflow_tolerance (PFLOW_TOLERANCE, or ROUNDING_MARGIN times the rounding
error of the largest bus power balance: eps times the largest row sum of |Y|, for large cases such
as GBnetwork) and the stored network must meet it to mismatch_limit (MISMATCH_LIMIT, or
MISMATCH_MARGIN times that tolerance).
"""
from __future__ import annotations

import argparse
import difflib
import hashlib
import io
import logging
import math
import os
import re
import shutil
import sys
import tempfile
from contextlib import contextmanager, redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np

from ..files import write_json
from ..models import STANDARD_MODELS
from .case import DATA_DIR, Case, CaseError, load_case

#: The shipped cases converted from ANDES' own files: name -> ANDES case.
ANDES_CASES = {"kundur": "kundur/kundur_full.xlsx", "ieee14": "ieee14/ieee14_full.xlsx",
               "ieee39": "ieee39/ieee39_full.xlsx", "npcc": "npcc/npcc.xlsx"}
NETWORK_MODELS = ("Bus", "Line", "PQ", "PV", "Slack", "Shunt", "Toggle", "Fault", "Alter", "Jumper")
# measurements that act on no device of a converted case, and the case's description: left out, each
# measurement stated in the case's notes (a device that reads a BusFreq takes its time constants)
IGNORED_MODELS = ("Area", "BusFreq", "BusROCOF", "ACEc", "COI", "Summary", "FreqDiv", "PMU")
MACHINES = ("GENROU", "GENCLS")
STATIC_GENERATORS = ("PV", "Slack")  # a Toggle of one trips its machine's unit (ANDES passes the status on)
EXCITERS = ("IEEEX1", "EXDC2", "EXST1", "ESST3A", "SEXS", "EXAC1", "EXAC4", "ESAC1A", "ESST1A", "ESST4B",
            "ESDC1A", "ESDC2A", "IEEET1", "IEEET3", "AC8B")
GOVERNORS = ("TGOV1", "TGOV1N", "IEEEG1", "TG2", "GAST", "HYGOV", "HYGOV4", "HYGOVDB", "IEESGO")
STABILISERS = ("IEEEST", "ST2CUT")
LOADS = ("ZIP", "FLoad", "Motor5", "Motor3")  # dynamic and voltage-dependent loads (wired by the conversion: to come)
COMPENSATORS = ("IEEEVC",)  # voltage compensators: an exciter's input voltage
CONVERTERS = ("REGCA1", "PVD1", "ESD1", "REGCP1", "REGF1", "REGF2", "REGF3")  # inverters: a unit's bus device
ELECTRICAL_CONTROLS = ("REECA1", "REECB1")  # inverters' electrical controllers
PLANT_CONTROLS = ("REPCA1",)  # inverters' plant controllers
WIND_CONTROLS = ("WTDTA1", "WTARA1", "WTPTA1", "WTTQA1")  # type-3 wind: drive train, aerodynamics, pitch, torque
DRIVE_TRAINS = ("WTDTA1", "WTDS")  # a wind turbine's drive train, linked by `ree` to its electrical control
SHAFTS = ("SHAFT5",)  # a machine's multi-mass torsional shaft, linked by `syn` to its machine
PLLS = ("PLL1", "PLL2")  # phase-locked loops: a control device of the converter that names them (pll)
CACHE_FORMAT = 6  # version of what convert writes: a new one keys new cache entries (4: shared and static generators, islands)
PFLOW_TOLERANCE = 1e-12  # ANDES' power-flow Newton tolerance at least (its default 1e-6 leaves 4e-7 pu mismatches)
MISMATCH_LIMIT = 1e-8  # pu: the stored network at the stored load flow, at least (mismatch_limit)
ROUNDING_MARGIN = 10  # pflow_tolerance: times the rounding error of the largest bus power balance
MISMATCH_MARGIN = 100  # mismatch_limit: times the power-flow tolerance
#: Parameters ANDES replaces that only start its power flow (the solution does not depend on them).
START_GUESSES = {"Bus": ("v0", "a0")}
# our state name -> ANDES variable where they differ
ANDES_STATE_NAMES = {"ESST3A": {"VR": "LAW1_y", "VM": "LAW2_y"}}


def load_andes(source, dyr=None, notes=None):
    """ANDES' System of `source` (a file or a case ANDES ships) after its power flow (Newton
    tolerance pflow_tolerance), ANDES' own output off and its log records read back (read_back, see
    the module docstring): what it drops or replaces that the case uses is a CaseError, the other
    adjustments are appended to `notes` (a list; None: not kept). CaseError (one line) also where
    ANDES is missing, cannot read the file or its power flow does not converge."""
    try:
        import andes
    except ImportError:
        raise CaseError("reading case files needs ANDES: pip install -e '.[andes]'") from None
    path = Path(source)
    if not path.is_file():
        try:
            path = Path(andes.get_case(str(source)))
        except (FileNotFoundError, ValueError):
            path = None
        if path is None or not path.is_file():
            raise CaseError(f"no case file {source}")
    kwargs = {"addfile": str(dyr)} if dyr else {}
    files = f"{path}{' with ' + str(dyr) if dyr else ''}"
    with _silenced(andes) as records:
        try:
            ss = andes.system.System(str(path), no_output=True, default_config=True, **kwargs)
            inputs = _keep_inputs(ss)
            try:
                parsed = andes.io.parse(ss)
            finally:
                del ss.add  # System.add again
            if parsed:
                ss.setup()
        except Exception as exc:  # ANDES' parsers raise anything on a file that is not theirs
            raise CaseError(f"ANDES cannot read {files} ({type(exc).__name__}: {' '.join(str(exc).split())[:80]})") \
                from None
        if not parsed:
            _refuse_dropped(ss, records, path, dyr)  # what it dropped explains why it failed
            said = _first_error(records)
            raise CaseError(f"ANDES cannot read {files} ("
                            + (f"ANDES: {said}" if said else "not a case file ANDES reads: xlsx, json, PSS/E raw "
                               "with its dyr") + ")")
        read_back(ss, records, inputs, path, dyr, notes)
        del records[:]
        tolerance = pflow_tolerance(ss)
        ss.PFlow.config.tol = tolerance
        ss.PFlow.config.max_iter = 50
        if not ss.PFlow.run() or not ss.PFlow.converged:
            said = _first_error(records)
            raise CaseError(f"{path}: ANDES' power flow does not converge (to {tolerance:.2g} pu"
                            + (f"; ANDES: {said}" if said else "") + ")")
        read_back(ss, records, {}, path, dyr, notes)
    return ss


def pflow_tolerance(ss) -> float:
    """ANDES' power-flow Newton tolerance [pu] for the case of `ss` (set up): PFLOW_TOLERANCE, or
    ROUNDING_MARGIN times the rounding error of the largest bus power balance where that is larger:
    eps times the largest sum over a bus's row of |Y| (the in-service lines' series admittances with
    ANDES' 1e-8 added to r and x, taps, charging; the shunts), |V| about 1 pu. That rounding error:
    kundur 1e-13, ieee39 3e-13, npcc 4e-13, wecc 3e-12 (ANDES' Newton reaches 9e-13 there),
    GBnetwork 9e-11 (2224 buses, branches of 1e-5 pu: ANDES' Newton stalls at 2e-11; tolerance
    9e-10)."""
    L = ss.Line
    position = {b: k for k, b in enumerate(ss.Bus.idx.v)}
    row = np.zeros(ss.Bus.n)
    if L.n:
        on = np.asarray(L.u.v, dtype=float) != 0
        y = np.abs(1.0 / (np.asarray(L.r.v, dtype=float) + 1e-8 + 1j * (np.asarray(L.x.v, dtype=float) + 1e-8)))
        tap = np.abs(np.asarray(L.tap.v, dtype=float))
        half_b = np.abs(np.asarray(L.b.v, dtype=float)) / 2
        one = np.array([position[b] for b in L.bus1.v], dtype=int)
        two = np.array([position[b] for b in L.bus2.v], dtype=int)
        np.add.at(row, one[on], (y / tap ** 2 + y / tap + half_b)[on])
        np.add.at(row, two[on], (y + y / tap + half_b)[on])
    S = ss.Shunt
    if S.n:
        at = np.array([position[b] for b in S.bus.v], dtype=int)
        np.add.at(row, at, np.abs(np.asarray(S.g.v, dtype=float) + 1j * np.asarray(S.b.v, dtype=float))
                  * (np.asarray(S.u.v, dtype=float) != 0))
    floor = float(np.finfo(float).eps * row.max()) if row.size else 0.0
    return max(PFLOW_TOLERANCE, ROUNDING_MARGIN * floor)


def mismatch_limit(tolerance: float) -> float:
    """The largest bus power mismatch [pu] the stored network may have at the stored load flow of a
    power flow solved to `tolerance` [pu]: MISMATCH_LIMIT, or MISMATCH_MARGIN times the tolerance."""
    return max(MISMATCH_LIMIT, MISMATCH_MARGIN * tolerance)


def configure_andes_logging(andes, level: int = logging.CRITICAL + 1) -> None:
    """ANDES' log messages below `level` off, and no log file: ANDES' config_logger otherwise makes
    an empty folder /tmp/andes-* for a log file at every call. Its stream handler writes to the
    sys.stderr of now: ANDES makes it once per process, on the stream of then, which a caller that
    swaps sys.stderr (pytest's capture) may have closed since."""
    andes.config_logger(stream_level=level, file=False, log_path=tempfile.gettempdir())
    for handler in logging.getLogger("andes").handlers:
        if isinstance(handler, logging.StreamHandler) and not isinstance(handler, logging.FileHandler):
            handler.stream = sys.stderr  # not setStream: it flushes the old stream, which may be closed


class _Kept(logging.Handler):
    """Keeps the log records it gets (WARNING and above) in `records`, for read_back."""

    def __init__(self, records: list):
        super().__init__(logging.WARNING)
        self.records = records

    def emit(self, record):
        self.records.append(record)


@contextmanager
def _silenced(andes):
    """ANDES' printed output and its log output off for the block, its log records at WARNING and
    above kept: yields the list they go into (read_back reads them)."""
    configure_andes_logging(andes)
    records = []
    handler = _Kept(records)
    logger = logging.getLogger("andes")
    logger.addHandler(handler)
    sink = io.StringIO()
    try:
        with redirect_stdout(sink), redirect_stderr(sink):
            yield records
    finally:
        logger.removeHandler(handler)


def _keep_inputs(ss) -> dict:
    """Wraps ss.add (until `del ss.add`) so that what the file gives each device is kept: returns
    {model name: {device idx: {parameter: value as given}}}, filled while ANDES parses."""
    inputs = {}
    add = ss.add

    def add_kept(model_name, param_dict=None, **kwargs):
        given = dict(param_dict or {}, **kwargs)
        idx = add(model_name, param_dict, **kwargs)
        if idx is not None:
            inputs.setdefault(model_name, {})[idx] = given
        return idx

    ss.add = add_kept
    return inputs


def _first_error(records) -> str:
    """The first two ERROR records' messages, one line ('' where there is none)."""
    return "; ".join([_said(r, 100) for r in records if r.levelno >= logging.ERROR][:2])


def _said(record, length: int = 120) -> str:
    return " ".join(record.getMessage().split())[:length]


# ANDES' log messages that read_back reads (andes.io.psse.read_add, System.add, ModelData.add and
# report_corrections); any other is stated (WARNING) or refused (ERROR) with ANDES' words.
_DYR_UNKNOWN = (re.compile(r"^Models not yet supported: (.+)$"), re.compile(r"^PSS/E Model <(.+)> is not supported\.$"))
_MODEL_UNKNOWN = re.compile(r"^<(.+)> is not an existing model\.$")
_FIELD_UNKNOWN = re.compile(r"^(\w+): unrecognized field '(.*?)'\.")
_CORRECTED = re.compile(r"^(\w+): \d+ device\(s\) had \w+ param <(\w+)> corrected to .+\. idx=(.+)$")
_LISTED = 6  # items a refusal lists before "and N more"


def _listed(items, most: int = _LISTED) -> str:
    items = list(dict.fromkeys(items))
    return ", ".join(items[:most]) + (f" and {len(items) - most} more" if len(items) > most else "")


def read_back(ss, records, inputs: dict, path, dyr=None, notes=None) -> None:
    """Reads back ANDES' log `records` and what the file gave its devices (`inputs`, _keep_inputs)
    for the case `path` (with `dyr`), set up or with its power flow solved: CaseError (one line) for
    what the module docstring refuses; what it states is appended to `notes` (None: not kept)."""
    rest = _refuse_dropped(ss, records, inputs, path, dyr)
    refused, stated, seen = _replaced(ss, inputs)
    if refused:
        raise CaseError(f"{path}: data ANDES would replace: {_listed(refused)}")
    for r in rest:
        said = r.getMessage()
        corrected = _CORRECTED.match(said)
        if corrected and all((corrected.group(1), idx, corrected.group(2)) in seen
                             for idx in _idx_list(corrected.group(3))):
            continue  # stated by _replaced with the file's value
        field = _FIELD_UNKNOWN.match(said)
        if field:
            same = _same_but_case(ss, *field.groups())
            stated.append(f"ANDES does not know the field {field.group(2)} of {field.group(1)} and drops it: "
                          + (f"its values are those of ANDES' {same}" if same else
                             f"ANDES' {field.group(1)} has no such parameter (a field of another version of "
                             "the model), and the case runs without it as in ANDES"))
            continue
        if r.levelno >= logging.ERROR:
            raise CaseError(f"{path}: ANDES: {_said(r, 200)}")
        stated.append(f"ANDES: {_said(r, 200)}")
    if notes is not None:
        notes += [n for n in dict.fromkeys(stated) if n not in notes]


def _same_but_case(ss, model: str, field: str) -> str | None:
    """The parameter of `model` spelt as `field` but for case, or None."""
    known = ss.models.get(model)
    return next((p for p in (known.params if known is not None else {}) if p.lower() == field.lower()), None)


def _harmless_field(ss, inputs: dict, model: str, field: str) -> bool:
    """Whether a field ANDES drops from `model` only differs in case from one of its parameters and
    every device's value in the file is the one ANDES uses for that parameter (kundur_esdc2a's SWITCH:
    ANDES' Switch)."""
    param = _same_but_case(ss, model, field)
    known = ss.models.get(model)
    if param is None or known is None:
        return False
    for idx, given in inputs.get(model, {}).items():
        i = known.uid.get(idx)
        try:
            if i is not None and float(given[field]) != float(getattr(known, param).v[i]):
                return False
        except (KeyError, TypeError, ValueError):
            return False
    return True


def _refuse_dropped(ss, records, inputs, path, dyr=None) -> list:
    """CaseError (one line) naming every model, dyr model (with the generators its records name) and
    field that ANDES' `records` say it does not know and drops (a field only spelt with other case
    than a parameter whose values ANDES uses is stated instead: _harmless_field); the other
    records."""
    dyr_models, dropped, rest = [], [], []
    for r in records:
        said = r.getMessage()
        unknown = next((m for m in (p.match(said) for p in _DYR_UNKNOWN) if m), None)
        field = _FIELD_UNKNOWN.match(said)
        if unknown:
            dyr_models += [m.strip() for m in unknown.group(1).split(",") if m.strip()]
        elif _MODEL_UNKNOWN.match(said):
            dropped.append(f"the model {_MODEL_UNKNOWN.match(said).group(1)} with its devices")
        elif field and _uses(ss, field.group(1)) is not None and not _harmless_field(ss, inputs, *field.groups()) \
                and _misspelt(ss, inputs, *field.groups()) is not None:
            dropped.append(f"the field {field.group(2)} of {field.group(1)} with its values (a misspelt "
                           f"{_misspelt(ss, inputs, *field.groups())}, left at ANDES' default?)")
        else:
            rest.append(r)
    if dyr_models:
        dropped.insert(0, _dyr_dropped(ss, dyr_models))
    if dropped:
        raise CaseError(f"{dyr if dyr_models and dyr else path}: ANDES does not know and drops {'; '.join(dropped)}"
                        + ("; a generator left without a model it had in the file is an error" if dyr_models else ""))
    return rest


MISSPELLING_CUTOFF = 0.8  # difflib similarity from which a dropped field reads as a misspelt parameter


def _misspelt(ss, inputs: dict, model: str, field: str) -> str | None:
    """The parameter of `model` that a field ANDES drops looks like a misspelling of (difflib
    similarity MISSPELLING_CUTOFF or more), where the file gives that parameter for none of its
    devices (it then takes ANDES' default); None otherwise (a field of another version of the model,
    such as kundur_reg's Iqmax beside the Iqrmax it gives)."""
    known = ss.models.get(model)
    if known is None:
        return None
    given = set().union(*(set(v) for v in inputs.get(model, {}).values()))
    candidates = [p for p in known.params if p not in given and p not in ("idx", "u", "name")]
    close = difflib.get_close_matches(field, candidates, n=1, cutoff=MISSPELLING_CUTOFF)
    return close[0] if close else None


def _idx_list(text: str) -> list:
    """The device idx of a report_corrections record's list (e.g. "[1, 'GENROU_2']"), as strings."""
    return [t.strip().strip("'\"") for t in text.strip("[]").split(",") if t.strip()]


def _dyr_dropped(ss, models) -> str:
    """The dyr models ANDES does not know, with the generators (bus, ID) their records name."""
    table = getattr(ss, "dyr_dict", None) or {}
    parts = []
    for name in dict.fromkeys(models):
        rows = table.get(name)
        named = []
        if rows is not None and rows.shape[1] >= 2:
            named = [f"bus {_plain(b)} ID {_plain(i)}" for b, i in zip(rows.iloc[:, 0], rows.iloc[:, 1])]
        parts.append(name + (f" ({_listed(named, 3)})" if named else ""))
    return f"the dyr model{'s' if len(parts) > 1 else ''} {', '.join(parts)} with {'their' if len(parts) > 1 else 'its'} records"


def _plain(value) -> str:
    try:
        return f"{float(value):g}"
    except (TypeError, ValueError):
        return str(value)


def _uses(ss, name: str):
    """The parameters of model `name` that the conversion uses (a set), or None where the model is
    not converted (left out, or one opfmu does not have: refused on its own by _check_supported)."""
    model = ss.models.get(name)
    if model is None or name in IGNORED_MODELS:
        return None
    if name in NETWORK_MODELS:
        return set(model.num_params)
    if name in STANDARD_MODELS:
        return set(STANDARD_MODELS[name].params_type.__dataclass_fields__) | {"u"}
    return None


def _replaced(ss, inputs: dict) -> tuple:
    """(refused, stated, seen): the values the file gave that ANDES replaced (a NumParam's non_zero,
    non_negative, non_positive checks) or filled in with its default (empty, NaN), as
    "MODEL idx param = value (why)", refused or stated by the module docstring's rule; `seen`: the
    (model, idx as text, parameter) of each replaced value, to match ANDES' own records."""
    refused, stated, seen = [], [], set()
    for name, devices in inputs.items():
        model = ss.models.get(name)
        if model is None:
            continue
        uses = _uses(ss, name)
        for idx, given in devices.items():
            i = model.uid.get(idx)
            if i is None:
                continue
            in_service = "u" not in model.params or _on(model, i)
            for param, raw in given.items():
                p = model.num_params.get(param)
                if p is None or callable(getattr(p, "iconvert", None)) or p.vin is None:
                    continue
                empty = raw is None or (isinstance(raw, float) and math.isnan(raw))
                try:
                    value, kept = (None if empty else float(raw)), float(p.vin[i])
                except (TypeError, ValueError):
                    continue
                used = uses is not None and param in uses and in_service
                if empty:
                    if used:
                        stated.append(f"{name} {idx}: {param} empty or NaN in the file, ANDES' default {kept:g} used")
                    continue
                if value == kept:
                    continue
                seen.add((name, str(idx), param))
                what = f"{name} {idx}: {param} = {value:g} in the file, ANDES uses {kept:g}"
                if math.isinf(value) and abs(kept) == 1e8:
                    if used:
                        stated.append(f"{what} (no limit either way)")
                elif not used:
                    why = (f"{name} is not converted" if uses is None else "out of service" if param in uses
                           else f"opfmu does not use {param}")
                    stated.append(f"{what} ({why})")
                elif type(p).__name__ == "ExtParam":  # a parameter ANDES takes from the device it links to
                    stated.append(f"{what} (ANDES takes {param} from the device its {p.indexer.name} names, and so "
                                  "does opfmu)")
                elif param in START_GUESSES.get(name, ()):
                    stated.append(f"{what} (a start guess of the power flow)")
                else:
                    sign = "zero" if value == 0 else "negative" if value < 0 else "positive"
                    refused.append(f"{name} {idx} {param} = {value:g} ({sign}, which the model cannot take; ANDES "
                                   f"would use {kept:g})")
    return refused, stated, seen


def stock_case(rpath: str) -> Path:
    """The path of a case file ANDES ships (`rpath` under andes/cases, as andes.get_case takes it),
    found without importing ANDES (0.6 s: a run of a cached case needs no more of it). CaseError where
    ANDES is not installed or ships no such file."""
    import importlib.util

    spec = importlib.util.find_spec("andes")
    if spec is None or not spec.submodule_search_locations:
        raise CaseError("reading case files needs ANDES: pip install -e '.[andes]'")
    path = Path(next(iter(spec.submodule_search_locations))) / "cases" / rpath
    if not path.is_file():
        raise CaseError(f"ANDES ships no case file {rpath}")
    return path


def case_cache_dir() -> Path:
    """$OPFMU_CASE_CACHE, else ~/.cache/opfmu/cases: where case_from_file keeps its conversions."""
    return Path(os.environ.get("OPFMU_CASE_CACHE") or Path.home() / ".cache" / "opfmu" / "cases")


def _cache_key(path: Path, dyr: Path | None) -> str:
    """sha256 of the converter's format version, the case file's name (the case's name; ANDES picks
    its parser by the suffix) and bytes and the dyr file's bytes."""
    digest = hashlib.sha256(f"{CACHE_FORMAT}\0{path.name}\0".encode())
    digest.update(path.read_bytes())
    if dyr is not None:
        digest.update(b"\0dyr\0")
        digest.update(dyr.read_bytes())
    return digest.hexdigest()[:32]


def case_from_file(path, dyr=None, cache_dir=None) -> Case:
    """The Case of a file ANDES reads (xlsx, json, a PSS/E raw with its dyr `dyr`), named by the file's
    stem, with Case.source = (the case file, the dyr file or None) as absolute paths. The file is
    converted once (`convert`): the network and dynamic-data files are kept in cache_dir (default
    case_cache_dir()) under a hash of the file's and the dyr's bytes, written to a folder of their own
    that is renamed into place; a cached entry that does not load is converted again. A cached case
    loads without ANDES. CaseError (one line) for a missing file, a file ANDES cannot read, a model
    opfmu does not have, or ANDES missing."""
    path = Path(path)
    dyr = None if dyr is None else Path(dyr)
    for f, what in ((path, "case file"), (dyr, "dyr file")):
        if f is not None and not f.is_file():
            raise CaseError(f"no {what} {f}")
    if path.suffix.lower() == ".raw" and dyr is None:
        raise CaseError(f"{path} is a PSS/E raw file: its machines come from its dyr file (--dyr FILE)")
    try:
        key = _cache_key(path, dyr)
    except OSError as exc:
        raise CaseError(f"cannot read {exc.filename}: {exc.strerror}") from None
    source = (str(path.resolve()), None if dyr is None else str(dyr.resolve()))
    name = path.stem
    root = Path(cache_dir) if cache_dir is not None else case_cache_dir()
    entry = root / key
    files = entry / f"{name}_network.json", entry / f"{name}.json"
    if entry.is_dir():
        try:
            return load_case(*files, name, source)
        except CaseError:  # a damaged or stale entry: converted again below
            _remove(entry)
    try:
        root.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=root, prefix=f".{key}.", suffix=".tmp"))
    except OSError as exc:
        raise CaseError(f"cannot write the case cache {root}: {exc.strerror}") from None
    try:
        try:
            convert(path, tmp, name, dyr)
        except CaseError as exc:  # name the user's file, not the converted ones in the cache
            message = str(exc)
            for written in (tmp / f"{name}_network.json", tmp / f"{name}.json"):
                message = message.replace(str(written), str(path))
            raise CaseError(message) from None
        try:
            os.rename(tmp, entry)
        except OSError:  # another process put the same conversion in place first
            if not entry.is_dir():
                raise CaseError(f"cannot write the case cache {root}") from None
    finally:
        _remove(tmp)
    return load_case(*files, name, source)


def case_notes(case) -> tuple:
    """What ANDES adjusted in the file of `case` and the conversion states rather than refuses (the
    module docstring): the "notes" of its dynamic-data file, () where it has none."""
    return file_notes(case.dynamic_data) if getattr(case, "dynamic_data", None) is not None else ()


def file_notes(path) -> tuple:
    """The "notes" (strings) of a dynamic-data file; () where it has none or cannot be read."""
    import json

    try:
        notes = json.loads(Path(path).read_text()).get("notes", ())
    except (OSError, ValueError, AttributeError):
        return ()
    return tuple(str(n) for n in notes) if isinstance(notes, list) else ()


def _remove(folder: Path) -> None:
    """Removes a cache folder: renamed aside first, so no reader finds it half removed."""
    if not folder.exists():
        return
    aside = folder.with_name(f".{folder.name}.{os.getpid()}.removed")
    try:
        os.rename(folder, aside)
    except OSError:
        return
    shutil.rmtree(aside, ignore_errors=True)


def _on(model, i: int) -> bool:
    """Whether ANDES' device i of `model` is in service: its effective status `ue` (its own status
    and its bus's, and for a device that names a static generator, that one's: a PV on a bus out of
    service is out of service), else its status u."""
    status = getattr(model, "ue", None)
    return float((status if status is not None and len(status.v) == model.n else model.u).v[i]) != 0


def _values(model, name) -> list:
    return [float(v) for v in getattr(model, name).v]


def _bus(value, where: str) -> int:
    if isinstance(value, (int, np.integer)) or (isinstance(value, (float, str)) and str(value).lstrip("-").isdigit()):
        return int(value)
    raise CaseError(f"{where}: bus {str(value)[:20]!r} is not a number (opfmu numbers buses)")


def _check_supported(ss) -> None:
    known = set(NETWORK_MODELS) | set(IGNORED_MODELS) | set(STANDARD_MODELS)
    if _time_series_without_effect(ss):
        known.add("TimeSeries")
    missing = [name for name, model in ss.models.items() if model.n > 0 and name not in known]
    if missing:  # all of them in one line
        raise CaseError(f"the case uses the model{'s' if len(missing) > 1 else ''} {', '.join(missing)}, which opfmu "
                        f"does not have (it has {len(STANDARD_MODELS)} standard models: docs/standard-models.md)")
    cfg = ss.PQ.config
    if (cfg.p2p, cfg.p2i, cfg.p2z, cfg.q2q, cfg.q2i, cfg.q2z) != (0, 0, 1, 0, 0, 1):
        raise CaseError("only constant-impedance loads in the time domain are converted (ANDES' default PQ "
                        "config p2z = q2z = 1)")
    L = ss.Line
    for extra in ("g", "g1", "b1", "g2", "b2"):
        if np.any(np.asarray(getattr(L, extra).v) != 0):
            raise CaseError(f"a Line with {extra} not 0 is not converted")


def network_data(ss, name: str) -> dict:
    """The network file's content (see the module docstring) of ANDES' System after its power flow."""
    _check_supported(ss)
    base = float(ss.config.mva)
    number = bus_numbers(ss)
    # a bus out of service leaves with its devices; a bus a Jumper ties to another is that one
    live = [i for i, b in enumerate(ss.Bus.idx.v) if _on(ss.Bus, i) and number[b] == _bus(b, "Bus")]
    buses = [{"number": number[ss.Bus.idx.v[i]], "kv": float(ss.Bus.Vn.v[i])} for i in live]
    L = ss.Line
    branches, shorted = [], {}
    for i in range(L.n):
        if not _on(L, i):
            continue
        tap, phi = float(L.tap.v[i]), float(L.phi.v[i])
        transformer = bool(L.trans.v[i]) or tap != 1.0 or phi != 0.0
        if number[L.bus1.v[i]] == number[L.bus2.v[i]]:  # in parallel with a Jumper: its charging stays
            if transformer:
                raise CaseError(f"the transformer {L.idx.v[i]} is shorted by a Jumper")
            shorted[number[L.bus1.v[i]]] = shorted.get(number[L.bus1.v[i]], 0.0) + float(L.b.v[i])
            continue
        branches.append({"from": number[L.bus1.v[i]], "to": number[L.bus2.v[i]], "r": float(L.r.v[i]) + 1e-8,
                         "x": float(L.x.v[i]) + 1e-8, "b": float(L.b.v[i]),
                         "kind": "transformer" if transformer else "line", "tap": tap, "phi": phi,
                         "andes": str(L.idx.v[i])})
    loads = {}
    replaced = _replaced_loads(ss)
    for i in range(ss.PQ.n):
        if not _on(ss.PQ, i) or ss.PQ.idx.v[i] in replaced:
            continue
        bus = number[ss.PQ.bus.v[i]]
        loads[bus] = loads.get(bus, 0j) + _pq_power(ss, i)
    shunts = {bus: complex(0.0, b) for bus, b in shorted.items()}
    for i in range(ss.Shunt.n):
        if not _on(ss.Shunt, i):
            continue
        bus = number[ss.Shunt.bus.v[i]]
        shunts[bus] = shunts.get(bus, 0j) + complex(float(ss.Shunt.g.v[i]), float(ss.Shunt.b.v[i]))
    generators, P, Q = [], [], []
    for model, kind, i, generator, (share_p, share_q) in _network_generators(ss):
        generators.append({"bus": number[model.bus.v[i]], "kind": kind, "V": float(model.v0.v[i]),
                           "P": None if kind == "slack" else share_p * float(model.p0.v[i]), "name": generator})
        P.append(share_p * float(model.p.v[i]))
        Q.append(share_q * float(model.q.v[i]))
    data = {"name": name, "source": "converted from ANDES' case by reference_models.grid.andes_case",
            "base_mva": base, "f_hz": float(ss.config.freq), "buses": buses, "branches": branches,
            "loads": [{"bus": b, "P": s.real, "Q": s.imag} for b, s in loads.items()],
            "shunts": [{"bus": b, "G": s.real, "B": s.imag} for b, s in shunts.items()],
            "generators": generators,
            "load_flow": {"V": [_values(ss.Bus, "v")[i] for i in live], "theta": [_values(ss.Bus, "a")[i] for i in live],
                          "P": P, "Q": Q},
            "events": events(ss, number)}
    return data


def bus_devices(ss) -> dict:
    """{static generator idx (text): [(model name, position, device idx)]}: the machines and
    converters in service that name each static generator (ANDES' gen), in model and file order."""
    out = {}
    for dname in MACHINES + CONVERTERS:
        model = getattr(ss, dname)
        for i in range(model.n):
            if _on(model, i):
                out.setdefault(str(model.gen.v[i]), []).append((dname, i, model.idx.v[i]))
    return out


def device_generators(ss) -> dict:
    """{(model name, position): the network generator's name} of every machine and converter in
    service (the name its unit is keyed by)."""
    return {(dname, i): _generator_name(static, idx, len(devices) > 1)
            for static, devices in bus_devices(ss).items() for dname, i, idx in devices}


def _generator_name(static: str, device, shared: bool) -> str:
    """The network generator's name of a bus device of static generator `static`: the static
    generator's idx, or "STATIC/DEVICE" where several devices share it."""
    return f"{static}/{device}" if shared else str(static)


def _network_generators(ss) -> list:
    """The network's generators (module docstring), in order: (ANDES model, kind, position, name,
    (P share, Q share)); one per bus device where several share a static generator. CaseError where
    the shares of a static generator's devices do not sum to 1."""
    devices = bus_devices(ss)
    out = []
    for model, kind in ((ss.Slack, "slack"), (ss.PV, "pv")):
        for i in range(model.n):
            if not _on(model, i):
                continue
            static = str(model.idx.v[i])
            mine = devices.get(static, [])
            shares = [tuple(float(getattr(getattr(ss, d), k).v[j]) for k in ("gammap", "gammaq")) for d, j, _ in mine]
            total = tuple(map(sum, zip(*shares))) if mine else (1.0, 1.0)
            if any(abs(t - 1.0) > 1e-9 for t in total):
                raise CaseError(f"the devices {_listed([f'{d} {idx}' for d, _, idx in mine], 3)} of static generator "
                                f"{static} take {total[0]:g} of its active and {total[1]:g} of its reactive power "
                                "(gammap, gammaq): ANDES starts them off its own load flow (make each sum 1)")
            if len(mine) <= 1:  # one device (or none: a PV or Slack device) takes all of it
                shares = [(1.0, 1.0)]
            for k, share in enumerate(shares):
                name = _generator_name(static, mine[k][2], True) if len(mine) > 1 else static
                out.append((model, kind, i, name, share))
    return out


def _static_generator_notes(ss) -> list:
    """The notes of the static generators in service that no machine or converter names: ANDES
    keeps their equations in the time domain, and so does their PV or Slack device."""
    named = bus_devices(ss)
    bare = [f"{kind} {model.idx.v[i]}" for model, kind in ((ss.Slack, "Slack"), (ss.PV, "PV"))
            for i in range(model.n) if _on(model, i) and str(model.idx.v[i]) not in named]
    if not bare:
        return []
    return [f"{_listed(bare)} {'have' if len(bare) > 1 else 'has'} no machine or converter: as in ANDES' time domain, "
            "a PV holds its active power and voltage, a slack its voltage and angle (a static_generator device, "
            "within 1e-5 pu per pu of reactive power or current)"]


def _pq_power(ss, i: int) -> complex:
    """P + jQ [pu] PQ load i draws in the power flow (ANDES' Ppf, Qpf: p0, q0 within [vmin, vmax],
    else the impedance its power flow turned it into at the limit)."""
    v0 = float(ss.Bus.v.v[list(ss.Bus.idx.v).index(ss.PQ.bus.v[i])])
    p0, q0 = float(ss.PQ.p0.v[i]), float(ss.PQ.q0.v[i])
    vmin, vmax = float(ss.PQ.vmin.v[i]), float(ss.PQ.vmax.v[i])
    if ss.PQ.config.pq2z and not vmin <= v0 <= vmax:
        limit = vmin if v0 < vmin else vmax
        p0, q0 = p0 * (v0 / limit) ** 2, q0 * (v0 / limit) ** 2
    return complex(p0, q0)


def events(ss, number) -> list:
    """The case's own enabled Toggle and Fault events as network-file entries."""
    out = []
    devices = bus_devices(ss)
    for i in range(ss.Toggle.n):
        if ss.Toggle.u.v[i] == 0:
            continue
        target, dev, t = ss.Toggle.model.v[i], ss.Toggle.dev.v[i], float(ss.Toggle.t.v[i])
        if target in ss.groups:  # a group name (SynGen, StaticGen, ...): the model holding the device
            target = ss.groups[target].idx2model(dev).class_name
        if target == "Line":
            out.append({"kind": "branch", "time": t, "branch": _branch_name(ss, dev, number), "status": "toggle"})
        elif target == "PQ" and dev not in _replaced_loads(ss):
            j = list(ss.PQ.idx.v).index(dev)
            power = _pq_power(ss, j)
            out.append({"kind": "load", "time": t, "bus": number[ss.PQ.bus.v[j]], "load": str(dev),
                        "P": power.real, "Q": power.imag, "status": "toggle"})
        elif target in MACHINES + CONVERTERS + STATIC_GENERATORS:
            model = getattr(ss, target)
            j = list(model.idx.v).index(dev)
            static = str(model.idx.v[j]) if target in STATIC_GENERATORS else str(model.gen.v[j])
            sharing = devices.get(static, [])
            names = [_generator_name(static, d, len(sharing) > 1) for _, _, d in sharing] or [static]
            if target not in STATIC_GENERATORS:
                names = [_generator_name(static, dev, len(sharing) > 1)]
            out += [{"kind": "generator", "time": t, "bus": number[model.bus.v[j]], "generator": name,
                     "status": "toggle"} for name in names]
        else:
            raise CaseError(f"a Toggle of a {target} is not converted (Line, PQ, "
                            f"{', '.join(MACHINES + CONVERTERS + STATIC_GENERATORS)} are)")
    for i in range(ss.Fault.n):
        if ss.Fault.u.v[i] == 0:
            continue
        out.append({"kind": "fault", "time": float(ss.Fault.tf.v[i]), "clear": float(ss.Fault.tc.v[i]),
                    "bus": number[ss.Fault.bus.v[i]], "r": float(ss.Fault.rf.v[i]), "x": float(ss.Fault.xf.v[i])})
    out.sort(key=lambda e: e["time"])
    status = {}  # a toggle flips the device's status at its time (all start in service)
    for e in out:
        if e.get("status") == "toggle":
            key = (e["kind"], e.get("branch"), e.get("generator"), e.get("load"))
            status[key] = 1 - status.get(key, 1)
            e["status"] = status[key]
    return out


def bus_numbers(ss) -> dict:
    """{ANDES Bus idx: the bus number in the converted network}: its own (an integer), or where a
    Jumper in service ties it to another bus (a zero impedance: ANDES holds both at one voltage),
    the number of the bus it joins (bus1's, followed along chains of jumpers)."""
    number = {b: _bus(b, "Bus") for b in ss.Bus.idx.v}
    jumper = getattr(ss, "Jumper", None)
    joined = {}
    for i in range(jumper.n if jumper is not None else 0):
        if _on(jumper, i):
            joined[jumper.bus2.v[i]] = jumper.bus1.v[i]
    for b in number:
        seen, root = {b}, b
        while root in joined and joined[root] not in seen:
            root = joined[root]
            seen.add(root)
        number[b] = _bus(root, "Bus")
    return number


def _branch_name(ss, dev, number) -> str:
    L = ss.Line
    i = list(L.idx.v).index(dev)
    ends = {number[L.bus1.v[i]], number[L.bus2.v[i]]}
    k = sum(1 for j in range(i + 1) if {number[L.bus1.v[j]], number[L.bus2.v[j]]} == ends and _on(L, j))
    name = f"{number[L.bus1.v[i]]}-{number[L.bus2.v[i]]}"
    return name + (f":{k}" if k > 1 else "")


def _params(model, name: str, i: int, ss) -> dict:
    """Device i's parameters as the case file gives them (ANDES' vin), with Sn, Sb, fn and its bus's
    nominal voltage Vb where the component takes them."""
    component = STANDARD_MODELS[name]
    fields = component.params_type.__dataclass_fields__
    values = {}
    for field in fields:
        param = getattr(model, field, None)
        if param is not None and hasattr(param, "vin"):
            values[field] = float(param.vin[i])
    for field, value in (("Sb", float(ss.config.mva)), ("Sn", None), ("fn", None), ("Sg", None), ("Sg2", None)):
        if field in fields and (value is not None or hasattr(model, field)):
            values[field] = value if value is not None else float(getattr(model, field).v[i])
    if "Vb" in fields:  # the nominal voltage [kV] of the device's bus
        values["Vb"] = float(ss.Bus.Vn.v[list(ss.Bus.idx.v).index(model.bus.v[i])])
    return values


# what an Alter may change without effect on ANDES' time-domain simulation: a PQ load's power, which
# its constant-impedance equivalent (Req, Xeq: computed once at the start) no longer reads
_ALTERS_WITHOUT_EFFECT = {"PQ": ("p0", "q0", "Ppf", "Qpf")}


def _measurements_left_out(ss) -> list:
    """The notes of the measurement models in the case that opfmu leaves out (IGNORED_MODELS but Area
    and Summary): they act on no converted device, and their outputs are not in opfmu's result."""
    return [f"{name} ({model.n} device{'s' if model.n > 1 else ''}: a measurement that acts on no converted device) "
            "is left out: its outputs are not in the result"
            for name, model in ss.models.items() if name in IGNORED_MODELS and name not in ("Area", "Summary")
            and model.n > 0]


def _time_series_without_effect(ss) -> list:
    """The notes of the case's TimeSeries where each one in service plays a PQ's power, which
    ANDES' constant-impedance load never reads in the time domain (ieee14_timeseries: ANDES' bus
    voltages identical with and without it); [] where there is none or one plays anything else
    (then TimeSeries is a model opfmu does not have)."""
    model = getattr(ss, "TimeSeries", None)
    if model is None or model.n == 0:
        return []
    live = [i for i in range(model.n) if model.u.v[i] != 0]
    dests = {i: [str(d).strip() for d in (model.dests.v[i] if not isinstance(model.dests.v[i], str)
                                          else model.dests.v[i].split(","))] for i in live}
    if not all(model.model.v[i] in _ALTERS_WITHOUT_EFFECT and set(dests[i]) <= set(_ALTERS_WITHOUT_EFFECT[model.model.v[i]])
               for i in live):
        return []
    return [f"TimeSeries {model.idx.v[i]} ({model.model.v[i]} {model.dev.v[i]} {', '.join(dests[i])} from "
            f"{model.path.v[i]}) changes nothing in ANDES' simulation (its constant-impedance load keeps the impedance "
            "of the start) and is left out" for i in live] or [f"TimeSeries ({model.n} out of service) left out"]


def _alters(ss) -> list:
    """The notes of the case's Alter events that change nothing in ANDES' simulation (a PQ's power
    under constant-impedance loads); CaseError naming any other enabled Alter (a device parameter or
    set point changed at a time, which opfmu's cases do not carry yet)."""
    notes, refused = [], []
    model = ss.Alter
    for i in range(model.n):
        if not _on(model, i):
            continue
        target, dev, src, t = model.model.v[i], model.dev.v[i], model.src.v[i], float(model.t.v[i])
        what = f"Alter {model.idx.v[i]} ({target} {dev} {src} {model.method.v[i]} {model.amount.v[i]:g} at {t:g} s)"
        if src in _ALTERS_WITHOUT_EFFECT.get(target, ()):
            notes.append(f"{what} changes nothing in ANDES' simulation (its constant-impedance load keeps the "
                         "impedance of the start) and is left out")
        else:
            refused.append(what)
    if refused:
        raise CaseError(f"{_listed(refused)}: a parameter changed during the run is not converted (only a PQ's "
                        "power, which ANDES' constant-impedance loads do not read)")
    return notes


def _replaced_loads(ss) -> dict:
    """{PQ idx: (model, position)} of the PQ loads a load device in service replaces (ANDES' ZIP and
    FLoad: `pq`, whose PQ ANDES switches off in the time domain: the device draws its power)."""
    out = {}
    for dname in LOADS:
        model = getattr(ss, dname)
        if not hasattr(model, "pq") or dname not in STANDARD_MODELS:
            continue
        for i in range(model.n):
            if _on(model, i):
                out[model.pq.v[i]] = (dname, i)
    return out


# the share of its PQ's load-flow power a load device draws: (active, reactive) percentage parameters
LOAD_SHARES = {"FLoad": ("kp", "kq"), "ZIP": (("kpp", "kpi", "kpz"), ("kqp", "kqi", "kqz"))}


def _share(model, name: str, i: int) -> tuple:
    """(active, reactive) fraction of its PQ's load-flow power a load device draws (ANDES: the
    percentages of the device; the rest of the PQ is dropped)."""
    return tuple(sum(float(getattr(model, k).v[i]) for k in ((keys,) if isinstance(keys, str) else keys)) / 100.0
                 for keys in LOAD_SHARES[name])


def _bus_frequency(ss, bus, prefix: str = "") -> dict:
    """Tf, Tw, fn of the BusFreq measuring `bus` (ANDES' own, else the defaults of the one it adds),
    under the names `prefix`Tf, ... of the device that takes them."""
    model = ss.BusFreq
    for i in range(model.n):
        if model.bus.v[i] == bus and _on(model, i):
            values = (model.Tf.v[i], model.Tw.v[i], model.fn.v[i])
            break
    else:
        values = (model.Tf.default, model.Tw.default, model.fn.default)
    return {f"{prefix}{k}": float(v) for k, v in zip(("Tf", "Tw", "fn"), values)}


# the devices that measure their bus frequency with ANDES' BusFreq as their own states: the prefix of
# their parameters that take the BusFreq's Tf, Tw, fn
BUS_FREQUENCY_PARAMETERS = {"FLoad": "", "PVD1": "busf_", "ESD1": "busf_"}


def _load_units(ss, number) -> list:
    """The dynamic-data entries of the load devices (module docstring): a unit per device at its bus
    with the power P, Q it draws at the load flow: a device that replaces a PQ (FLoad) its share of
    the PQ's power-flow power Ppf, Qpf (ANDES drops the rest: _dropped_loads), a motor what ANDES'
    power flow gives it. An FLoad measures
    its bus frequency with the BusFreq of its bus (Tf, Tw) at the case's frequency."""
    out = []
    for pq, (dname, i) in _replaced_loads(ss).items():
        model = getattr(ss, dname)
        j = list(ss.PQ.idx.v).index(pq)
        share = _share(model, dname, i)
        entry = _entry(model, dname, i, ss)
        power = _pq_power(ss, j)
        out.append({"bus": number[ss.PQ.bus.v[j]], "load": str(pq), "P": share[0] * power.real,
                    "Q": share[1] * power.imag, "load_device": entry, "fmu": {"kind": "reference"}})
    out += _switched_shunts(ss, number)
    for dname in LOADS:
        model = getattr(ss, dname)
        if hasattr(model, "pq") or dname not in STANDARD_MODELS:
            continue
        for i in range(model.n):
            if _on(model, i):
                out.append({"bus": number[model.bus.v[i]], "load": str(model.idx.v[i]), "P": float(model.p.v[i]),
                            "Q": float(model.q.v[i]), "load_device": _entry(model, dname, i, ss),
                            "fmu": {"kind": "reference"}})
    return out


def _switched_shunts(ss, number) -> list:
    """The dynamic-data "loads" entries of ANDES' switched shunts in service (ShuntSw): a unit at
    its bus drawing, at the load flow, what its steps in after ANDES' power flow draw; its tables
    of the admittance with k steps in (ANDES' SwBlock, system base), its band and its delay."""
    from reference_models.models.shuntsw import MAX_STEPS

    model = getattr(ss, "ShuntSw", None)
    out = []
    for i in range(model.n if model is not None else 0):
        if not _on(model, i):
            continue
        B, G = (np.asarray(block.bcs[i], dtype=float) for block in (model.beff, model.geff))
        steps = int(model.beff.maxsel[i])
        if steps > MAX_STEPS:
            raise CaseError(f"ShuntSw {model.idx.v[i]} has {steps} steps (opfmu takes {MAX_STEPS} at most)")
        sel = int(model.beff.sel[i])
        V = float(ss.Bus.v.v[list(ss.Bus.idx.v).index(model.bus.v[i])])
        params = {**{f"B{k}": float(B[k]) for k in range(len(B))}, **{f"G{k}": float(G[k]) for k in range(len(G))},
                  "n": float(steps), **{k: float(getattr(model, k).v[i]) for k in ("vref", "dv", "dt")}}
        out.append({"bus": number[model.bus.v[i]], "load": str(model.idx.v[i]), "P": float(G[sel]) * V * V,
                    "Q": -float(B[sel]) * V * V, "load_device": {"component": STANDARD_MODELS["ShuntSw"].name,
                                                                 "andes": str(model.idx.v[i]), "params": params},
                    "fmu": {"kind": "reference"}})
    return out


def _dropped_loads(ss, number) -> tuple:
    """(notes, [(bus, P, Q)]): the part of a PQ's power-flow load that the device replacing it does
    not draw (its percentages short of 100: ANDES drops the rest and its simulation starts off its
    own load flow, as opfmu's then does), stated, with that power per bus."""
    notes, dropped = [], []
    for pq, (dname, i) in _replaced_loads(ss).items():
        model = getattr(ss, dname)
        share = _share(model, dname, i)
        if all(abs(f - 1.0) <= 1e-9 for f in share):
            continue
        j = list(ss.PQ.idx.v).index(pq)
        power = _pq_power(ss, j)
        rest = complex((1 - share[0]) * power.real, (1 - share[1]) * power.imag)
        dropped.append((number[ss.PQ.bus.v[j]], rest.real, rest.imag))
        notes.append(f"{dname} {model.idx.v[i]} draws {100 * share[0]:g} % of the active and {100 * share[1]:g} % of "
                     f"the reactive power of PQ {pq}: ANDES drops the rest ({rest.real:.4g} + j{rest.imag:.4g} pu), so "
                     "the simulation starts off its own load flow, in ANDES as here (percentages summing to 100 avoid it)")
    return notes, dropped


def _plant_measures(ss, model, i, number) -> dict:
    """A plant controller's (REPCA1's) measurement and the parameters ANDES fills in for it: the
    measured bus (busr, else its converter's bus), the monitored line from the converter's bus,
    the line-drop compensation Rc, Xc (the line's r, x where the case gives none: ANDES' Rcs, Xcs),
    the BusFreq it reads (CaseError where it measures another bus than the voltage), and ANDES'
    configuration constants kqs, ksg, freeze."""
    bus = model.buss.v[i]
    entry = {"measures": {"bus": number[bus]}}
    line = model.line.v[i]
    if line is not None:
        entry["measures"].update(branch=_branch_name(ss, line, number), end=number[model.bus.v[i]])
    frequency = model.busfreq.v[i]
    j = list(ss.BusFreq.idx.v).index(frequency)
    if ss.BusFreq.bus.v[j] != bus:
        raise CaseError(f"{type(model).__name__} {model.idx.v[i]} measures its frequency at bus {ss.BusFreq.bus.v[j]} "
                        f"and its voltage at bus {bus}: opfmu measures both at one bus")
    entry["params"] = {"Rc": float(model.Rcs.v[i]), "Xc": float(model.Xcs.v[i]),
                       "busf_Tf": float(ss.BusFreq.Tf.v[j]), "busf_Tw": float(ss.BusFreq.Tw.v[j]),
                       "busf_fn": float(ss.BusFreq.fn.v[j]),
                       **{k: float(getattr(model.config, k)) for k in ("kqs", "ksg", "freeze")}}
    return entry


# the devices that measure the network: how their measurement and ANDES' filled-in values are read
MEASURING = {"REPCA1": _plant_measures}


def _control_roles() -> tuple:
    """(role, ANDES models, the IdxParam naming the device it controls, that device's role; None: the
    unit's bus device), each role after the one it links to."""
    return (("exciter", EXCITERS, "syn", None), ("governor", GOVERNORS, "syn", None),
            ("electrical_control", ELECTRICAL_CONTROLS, "reg", None),
            ("stabiliser", STABILISERS, "avr", "exciter"), ("compensator", COMPENSATORS, "avr", "exciter"),
            ("plant_control", PLANT_CONTROLS, "ree", "electrical_control"),
            ("drive_train", DRIVE_TRAINS, "ree", "electrical_control"), ("shaft", SHAFTS, "syn", None),
            ("aerodynamics", WIND_CONTROLS[1:2], "rego", "drive_train"),
            ("pitch_control", WIND_CONTROLS[2:3], "rea", "aerodynamics"),
            ("torque_control", WIND_CONTROLS[3:], "rep", "pitch_control"))


def _entry(model, name: str, i: int, ss) -> dict:
    """A device's dynamic-data entry: its component, ANDES idx and parameters (with those of the
    BusFreq at its bus where it measures its bus frequency as ANDES does)."""
    params = _params(model, name, i, ss)
    if name in BUS_FREQUENCY_PARAMETERS:
        params.update(_bus_frequency(ss, model.bus.v[i], BUS_FREQUENCY_PARAMETERS[name]))  # FLoad's: its PQ's
    return {"component": STANDARD_MODELS[name].name, "andes": str(model.idx.v[i]), "params": params}


def _own_pll(ss, entry: dict) -> tuple:
    """The PLL2 a REGF2 reads (the one its `pll` names, or the one ANDES adds at its bus where it names
    none), whose gains Kp, Ki go into the REGF2's parameters (opfmu's REGF2 carries its PLL2);
    CaseError for a PLL of another kind or at another bus. Returns its (model, idx)."""
    model = ss.REGF2
    i = list(map(str, model.idx.v)).index(entry["andes"])
    named = model.pllidx.v[i]
    if named not in list(ss.PLL2.idx.v):
        raise CaseError(f"REGF2 {model.idx.v[i]} takes the PLL {named}, which is not a PLL2: opfmu's REGF2 carries "
                        "a PLL2")
    j = list(ss.PLL2.idx.v).index(named)
    if ss.PLL2.bus.v[j] != model.bus.v[i]:
        raise CaseError(f"REGF2 {model.idx.v[i]} takes the angle of PLL2 {named} at bus {ss.PLL2.bus.v[j]}, not at "
                        f"its own bus {model.bus.v[i]}: opfmu's REGF2 measures its own bus")
    entry["params"].update({"Kp": float(ss.PLL2.Kp.vin[j]), "Ki": float(ss.PLL2.Ki.vin[j])})
    return ("PLL2", named)


def _add_plls(ss, units: dict) -> set:
    """Puts the PLL each converter names (ANDES' REGCP1 `pll`) into that converter's unit as its
    "pll" device (CaseError where it measures another bus); a REGCP1 without one is ANDES' REGCA1
    (the exact bus angle) and is converted as one; a REGF2's PLL2 becomes part of it (_own_pll).
    Returns the (model, idx) of the PLLs placed."""
    placed = set()
    for unit in units.values():
        entry = unit.get("converter")
        if entry is not None and entry["component"] == STANDARD_MODELS["REGF2"].name:
            placed.add(_own_pll(ss, entry))
            continue
        if entry is None or "REGCP1" not in CONVERTERS or entry["component"] != STANDARD_MODELS["REGCP1"].name:
            continue
        model = ss.REGCP1
        i = list(map(str, model.idx.v)).index(entry["andes"])
        named = model.pll.v[i]
        if named is None:
            entry["component"] = STANDARD_MODELS["REGCA1"].name
            entry["params"] = _params(model, "REGCA1", i, ss)
            continue
        for pname in PLLS:
            pll = getattr(ss, pname)
            if named in pll.idx.v:
                j = list(pll.idx.v).index(named)
                if pll.bus.v[j] != model.bus.v[i]:
                    raise CaseError(f"REGCP1 {model.idx.v[i]} takes the angle of {pname} {named} at bus {pll.bus.v[j]}, "
                                    f"not at its own bus {model.bus.v[i]}: opfmu's PLL measures its converter's bus")
                unit["pll"] = _entry(pll, pname, j, ss)
                placed.add((pname, named))
                break
        else:
            raise CaseError(f"REGCP1 {model.idx.v[i]} names no PLL in service ({named})")
    return placed


def _plls_left_out(ss, placed: set) -> list:
    """The note of the PLLs no converter takes: measurements acting on nothing, left out."""
    left = [f"{name} {idx}" for name in PLLS for i, idx in enumerate(getattr(ss, name).idx.v)
            if _on(getattr(ss, name), i) and (name, idx) not in placed]
    return [f"{_listed(left)} (a phase-locked loop no converter takes: a measurement that acts on no converted "
            "device) left out: its outputs are not in the result"] if left else []


# the controls that may drive a second machine: model -> (the link naming it, the signal it gives that
# machine, the signal that machine takes): IEEEG1's syn2, on its low-pressure stages
SECOND_MACHINE_LINKS = {"IEEEG1": ("syn2", "second_mechanical_power", "mechanical_power")}


def _second_machine(units: dict, key, model, i: int, link: str, gives: str, takes: str) -> None:
    """Where device i of `model` (a control of the unit `key`) names a second machine by `link`, that
    machine's unit takes the signal `takes` from it (the unit's "takes": the device's signal `gives`
    of the generator of unit `key`); CaseError where it names no machine in service or one that
    already takes the signal."""
    second = getattr(model, link).v[i]
    if second is None:
        return
    found = [k for k in units if k[0] == "SynGen" and k[1] == second]
    if len(found) != 1:
        raise CaseError(f"{model.class_name} {model.idx.v[i]} names no machine in service as {link} ({second})")
    unit = units[found[0]]
    if found[0] == key or "governor" in unit or takes in unit.get("takes", {}):
        raise CaseError(f"{model.class_name} {model.idx.v[i]} drives machine {second} ({link}), which has its own "
                        "governor or another turbine")
    unit.setdefault("takes", {})[takes] = {"generator": units[key]["generator"], "signal": gives}


def dynamic_data(ss, name: str) -> dict:
    """The dynamic-data file's content (see the module docstring) of ANDES' System: a unit per bus
    device of a static generator (a machine, or an inverter's converter, linked by `gen`) with the
    control devices linked to it (exciter, governor, electrical control by `syn` or `reg`;
    stabiliser and compensator to the exciter by `avr`; plant control and a wind turbine's drive
    train to the electrical control by `ree`, its aerodynamics, pitch and torque controls each to the
    one before)."""
    number = bus_numbers(ss)
    units = {}  # (ANDES group, bus device idx) -> its unit's entry
    owner = {None: {}}  # role -> {(ANDES group, device idx): the unit's key}
    named = bus_devices(ss)
    for static, devices in named.items():
        for dname, i, idx in devices:
            model = getattr(ss, dname)
            role = "machine" if dname in MACHINES else "converter"
            units[(model.group, idx)] = {"bus": number[model.bus.v[i]],
                                         "generator": _generator_name(static, idx, len(devices) > 1),
                                         role: _entry(model, dname, i, ss)}
            owner[None][(model.group, idx)] = (model.group, idx)
    for model, dname in ((ss.Slack, "Slack"), (ss.PV, "PV")):
        for i in range(model.n):
            static = model.idx.v[i]
            if _on(model, i) and str(static) not in named:
                units[("static", static)] = {"bus": number[model.bus.v[i]], "generator": str(static),
                                             "static_generator": {"component": STANDARD_MODELS[dname].name,
                                                                  "andes": str(static), "params": {}}}
    used = _add_plls(ss, units)
    drives = []  # the controls that may drive a second machine: (their unit's key, model, index)
    for role, names, link, target in _control_roles():
        owner[role] = {}
        for dname in names:
            model = getattr(ss, dname)
            for i in range(model.n):
                if not _on(model, i):
                    continue
                controlled = getattr(model, link).v[i]
                named = getattr(model, link).model  # the group (or model) the link names: idx are unique in a group
                group = ss.models[named].group if named in ss.models else named
                found = [k for (g, idx), k in owner.get(target, {}).items()
                         if idx == controlled and (group is None or g == group)]
                key = found[0] if len(found) == 1 else None
                if key is None:
                    raise CaseError(f"{dname} {model.idx.v[i]} names no {target or 'machine or converter'} in "
                                    f"service ({controlled})")
                if role in units[key]:
                    raise CaseError(f"{target or 'the bus device'} {controlled} has two {role.replace('_', ' ')}s")
                units[key][role] = _entry(model, dname, i, ss)
                if dname in MEASURING:
                    extra = MEASURING[dname](ss, model, i, number)
                    units[key][role]["measures"] = extra["measures"]
                    units[key][role]["params"].update(extra["params"])
                owner[role][(model.group, model.idx.v[i])] = key
                if dname in SECOND_MACHINE_LINKS:
                    drives.append((key, model, i))
    for key, model, i in drives:
        _second_machine(units, key, model, i, *SECOND_MACHINE_LINKS[model.class_name])
    for unit in units.values():
        unit["fmu"] = {"kind": "reference"}
    generators = [name for _, _, _, name, _ in _network_generators(ss)]
    order = sorted((u for u in units.values() if u["generator"] in generators),
                   key=lambda u: generators.index(u["generator"]))
    loads = _load_units(ss, number)
    notes = _plls_left_out(ss, used)
    return {"case": name, "description": "converted from ANDES' case by reference_models.grid.andes_case: one unit per "
            "machine or converter (with its exciter, governor, stabiliser, compensator, electrical and plant "
            "controls), parameters as the case file gives them (machine base Sn; Sb the system base), keyed by bus "
            "and load-flow generator; a unit per load device with the power it draws (\"loads\", where there are any)",
            "generators": order, **({"loads": loads} if loads else {}), **({"notes": notes} if notes else {})}


def _limits_widened(ss, dynamic: dict) -> list:
    """The limits ANDES' time-domain initialisation widens to a start beyond them (its limiters'
    allow_adjust, told at INFO level only: kundur_wtdta1's WTTQA1 Temax 1.2 -> 7): TDS.init is run
    on ss (after the conversion has read it: it switches the static generators off), each converted
    device's parameters compared before and after, a changed one set in `dynamic`'s device entry
    (the file's value scaled as ANDES scaled it) and stated; the notes. Nothing where TDS.init
    fails (ANDES cannot run the case then either)."""
    import andes

    names = {c.name: n for n, c in STANDARD_MODELS.items()}
    entries = {}
    for unit in dynamic.get("generators", []) + dynamic.get("loads", []):
        for entry in unit.values():
            if isinstance(entry, dict) and entry.get("component") in names and "andes" in entry:
                entries[(names[entry["component"]], entry["andes"])] = entry
    before = {}
    for (name, idx), entry in entries.items():
        model = getattr(ss, name, None)
        if model is None or idx not in map(str, model.idx.v):
            continue
        i = list(map(str, model.idx.v)).index(idx)
        for field in entry["params"]:
            param = model.num_params.get(field)
            if param is not None and isinstance(param.v, np.ndarray) and param.v.dtype != object:
                before[(name, idx, field)] = (i, float(param.v[i]))
    try:
        with _silenced(andes):
            ss.TDS.init()
    except Exception:  # noqa: BLE001 - ANDES' own failure: it does not run the case, nothing to read
        return []
    notes = []
    for (name, idx, field), (i, old) in before.items():
        new = float(getattr(ss, name).num_params[field].v[i])
        if new == old or not math.isfinite(new):
            continue
        entry = entries[(name, idx)]
        given = entry["params"][field]
        entry["params"][field] = given * new / old if old != 0 else new
        notes.append(f"{name} {idx}: {field} = {given:g} in the file, which ANDES widens to {entry['params'][field]:g} "
                     "at its initialisation (the start lies beyond it; ANDES tells it at INFO level only), and so "
                     "does opfmu")
    return notes


def mismatch(network: dict, device_loads=()) -> float:
    """The largest bus power mismatch [pu] of a network file's content at its stored load flow:
    generation - load - V conj(Y V), the loads including `device_loads` ((bus, P, Q) drawn by load
    devices: the dynamic-data file's "loads")."""
    return float(np.abs(list(_imbalance(network, device_loads).values())).max())


def _imbalance(network: dict, device_loads=()) -> dict:
    """{bus: V conj(Y V) + load - generation [pu]} of a network file's content at its stored load
    flow (`mismatch`)."""
    import tempfile

    from .case import load_network

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "network.json"
        write_json(path, network)
        net, flow = load_network(path)
    V = flow.V_complex
    S = V * np.conj(net.ybus() @ V) + flow.S_load
    for bus, P, Q in device_loads:
        S[net.bus_index(bus)] += complex(P, Q)
    for k, bus in enumerate(flow.generator_buses):
        S[net.bus_index(bus)] -= complex(flow.P_gen[k], flow.Q_gen[k])
    return dict(zip(net.buses, S.tolist()))


def _hold_islands(ss, network: dict, dynamic: dict, device_loads) -> list:
    """Holds the buses of the islands without a slack at the voltages ANDES freezes them at (its
    power flow leaves them out and its time domain keeps their voltage equations off: Bus
    islanded_a, islanded_v): a Slack device at each, a generator of the network named "island BUS"
    supplying what the bus lacks there (its imbalance at the stored load flow), appended to
    `network` and `dynamic`; the note."""
    number = bus_numbers(ss)
    kept = {i for island in ss.Bus.island_sets for i in island}
    held = [number[ss.Bus.idx.v[i]] for i in range(ss.Bus.n) if i not in kept and _on(ss.Bus, i)]
    in_network = {e["number"] for e in network["buses"]}
    held = list(dict.fromkeys(b for b in held if b in in_network))
    if not held:
        return []
    lacking = _imbalance(network, device_loads)
    for bus in held:
        i = [e["number"] for e in network["buses"]].index(bus)
        network["generators"].append({"bus": bus, "kind": "slack", "V": network["load_flow"]["V"][i], "P": None,
                                      "name": f"island {bus}"})
        network["load_flow"]["P"].append(lacking[bus].real)
        network["load_flow"]["Q"].append(lacking[bus].imag)
        dynamic["generators"].append({"bus": bus, "generator": f"island {bus}",
                                      "static_generator": {"component": STANDARD_MODELS["Slack"].name,
                                                           "andes": f"Bus {bus}", "params": {}},
                                      "fmu": {"kind": "reference"}})
    return [f"bus{'es' if len(held) > 1 else ''} {_listed(map(str, held))} {'lie' if len(held) > 1 else 'lies'} in "
            "islands without a slack: ANDES leaves them out of its power flow and freezes their voltages in its time "
            "domain; opfmu holds them there with a Slack device each (a generator named \"island BUS\")"]


def convert(source, out_dir, name: str | None = None, dyr=None) -> tuple:
    """Write NAME_network.json and NAME.json of ANDES' case `source` into out_dir; (network file,
    dynamic-data file). CaseError where the case cannot be converted."""
    name = name or Path(str(source)).stem
    notes = []
    ss = load_andes(source, dyr, notes)
    network, dynamic = network_data(ss, name), dynamic_data(ss, name)
    dropped_notes, dropped = _dropped_loads(ss, bus_numbers(ss))
    dropped_notes += _hold_islands(ss, network, dynamic, [(u["bus"], u["P"], u["Q"]) for u in dynamic.get("loads", ())]
                                   + dropped)
    notes += (_alters(ss) + _time_series_without_effect(ss) + _measurements_left_out(ss) + _static_generator_notes(ss)
              + dynamic.pop("notes", [])
              + dropped_notes + _limits_widened(ss, dynamic))
    if notes:  # what ANDES adjusted, stated (case_notes)
        dynamic["notes"] = notes
    worst = mismatch(network, [(u["bus"], u["P"], u["Q"]) for u in dynamic.get("loads", ())] + dropped)
    if worst > mismatch_limit(float(ss.PFlow.config.tol)):
        raise CaseError(f"{source}: the converted network misses ANDES' load flow by {worst:.3g} pu")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = out / f"{name}_network.json", out / f"{name}.json"
    write_json(files[0], network)
    write_json(files[1], dynamic)
    load_case(*files, name)  # what was written loads
    return files


def _machine_signals(ss, model, i) -> tuple:
    k = float(ss.config.mva) / float(model.Sn.v[i])
    return k, float(model.tm.v[i]) * k, float(model.vf.v[i])


def compare_starts(case, ss) -> dict:
    """{model: {"devices", "state", "set_point"}}: the largest absolute differences between the
    Case's start values and ANDES' time-domain initialisation (ss after TDS.init()) of the same
    devices: states (governor powers on the machine base), and set points (a machine's Pm, Efd,
    an exciter's Vref, a governor's Pref)."""
    import json

    data = json.loads(Path(case.dynamic_data).read_text())
    results = {}
    for unit, start, entry in zip(case.units, case.starts, data["generators"]):
        for device, ds in zip(unit.devices, start):
            idx = entry[device.name]["andes"]
            mname = next(n for n, c in STANDARD_MODELS.items() if c is device.component)
            model = getattr(ss, mname)
            if idx not in map(str, model.idx.v):  # a device of opfmu's own (an island's Slack): none in ANDES
                continue
            i = list(model.idx.v).index(next(v for v in model.idx.v if str(v) == idx))
            names = ANDES_STATE_NAMES.get(mname, {})
            theirs = np.array([float(getattr(model, names.get(s, s)).v[i]) for s in device.component.state_names])
            ours = np.array(ds.states)
            if mname in MACHINES:
                _, Pm, Efd = _machine_signals(ss, model, i)
                set_diff = max(abs(ds.inputs["Pm"] - Pm), abs(ds.inputs["Efd"] - Efd))
            elif mname in EXCITERS:
                set_diff = abs(ds.inputs["Vref"] - float(model.vref.v[i]))
            elif mname in GOVERNORS:
                k = float(ss.config.mva) / float(model.Sn.v[i])
                scale = np.array([1.0 if s == "LL_x" and mname == "IEEEG1" else k
                                  for s in device.component.state_names])
                theirs = theirs * scale
                pref = {"TGOV1": float(model.pref.v[i]), "TGOV1N": float(model.pref.v[i]) * k,
                        "IEEEG1": float(model.tm012.v[i]) * k if mname == "IEEEG1" else 0.0}[mname]
                set_diff = abs(ds.inputs["Pref"] - pref)
            else:
                set_diff = 0.0
            r = results.setdefault(mname, {"devices": 0, "state": 0.0, "set_point": 0.0})
            r["devices"] += 1
            r["state"] = max(r["state"], float(np.abs(ours - theirs).max()))
            r["set_point"] = max(r["set_point"], float(set_diff))
    return results


def compare_shipped(name: str) -> dict:
    """compare_starts of the shipped case `name` against ANDES' initialisation of its source, plus
    "load_flow": the largest differences of V [pu], theta [rad], P, Q [pu] from ANDES' power flow
    and of the loads' admittances [pu] from ANDES' time-domain ones (Req - j Xeq)."""
    from .case import shipped_case

    case = shipped_case(name)
    ss = load_andes(ANDES_CASES[name])
    lf = case.flow
    P = np.array([float(v) for m in (ss.Slack, ss.PV) for v in m.p.v])
    Q = np.array([float(v) for m in (ss.Slack, ss.PV) for v in m.q.v])
    flow = {"V": float(np.abs(lf.V - ss.Bus.v.v).max()), "theta": float(np.abs(lf.theta - ss.Bus.a.v).max()),
            "P": float(np.abs(lf.P_gen - P).max()), "Q": float(np.abs(lf.Q_gen - Q).max())}
    ss.TDS.init()
    # ANDES' time-domain loads: conductance Req and susceptance -Xeq at each PQ's bus
    Y = {}
    for i in range(ss.PQ.n):
        bus = list(ss.Bus.idx.v).index(ss.PQ.bus.v[i])
        Y[bus] = Y.get(bus, 0j) + complex(float(ss.PQ.Req.v[i]), -float(ss.PQ.Xeq.v[i])) * ss.PQ.u.v[i]
    ours = case.flow.load_admittances()
    flow["load_admittance"] = float(max(abs(ours[b] - y) for b, y in Y.items()))
    return {"load_flow": flow, **compare_starts(case, ss)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m reference_models.grid.andes_case",
                                     description="Convert a case ANDES reads into an opfmu case.")
    parser.add_argument("case", nargs="?", help="case file, or a case ANDES ships (e.g. ieee39/ieee39_full.xlsx)")
    parser.add_argument("out", nargs="?", help="output directory")
    parser.add_argument("--name", help="case name (default: the file's stem)")
    parser.add_argument("--dyr", help="PSS/E dyr file for a raw case")
    parser.add_argument("--shipped", action="store_true", help="regenerate the shipped cases in place")
    parser.add_argument("--compare", metavar="NAME", help="start values of a shipped case against ANDES'")
    args = parser.parse_args(argv)
    try:
        if args.shipped:
            for name, source in ANDES_CASES.items():
                print(*convert(source, DATA_DIR, name))
        elif args.compare:
            if args.compare not in ANDES_CASES:
                raise CaseError(f"--compare takes one of {', '.join(ANDES_CASES)}")
            for model, r in compare_shipped(args.compare).items():
                print(model, " ".join(f"{k}={v:.3g}" for k, v in r.items()))
        elif args.case and args.out:
            files = convert(args.case, args.out, args.name, args.dyr)
            print(*files)
            for note in file_notes(files[1]):
                print(f"note: {note}", file=sys.stderr)
        else:
            raise CaseError("give CASE OUT_DIR, --shipped or --compare NAME")
    except CaseError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0

if __name__ == "__main__":
    sys.exit(main())
