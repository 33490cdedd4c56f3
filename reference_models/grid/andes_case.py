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
  stored network's bus power mismatch at the stored solution must stay below 1e-8 pu.
* the generators: the Slack and PV devices (slack first, then PV, file order each), each named by
  its ANDES idx; units are keyed by generator (a bus may hold several, npcc does).
* the dynamic devices, one unit per synchronous machine (GENROU, GENCLS), linked by ANDES' `gen`
  (machine -> static generator), `syn` (exciter, governor -> machine) and `avr` (stabiliser ->
  exciter): devices "machine", "exciter", "governor", "stabiliser" with their component (the
  reference_models.models model of that name) and parameters as the case file gives them (ANDES'
  input data before its own conversion to the system base: machine and turbine data on the
  machine base Sn, as reference_models.models take them, docs/standard-models.md), plus Sn, Sb,
  fn where the component takes them. A model opfmu does not have is refused with one line naming
  it; measurement-only models (BusFreq, BusROCOF, ACEc, Area) and the case's description (Summary) are left out.
* the case's own events: Toggle of a Line (a branch event: status 0 open, 1 closed again, each
  toggle flipping the status it finds, all in service at the start), of a machine (GENROU, GENCLS)
  or of its load-flow generator (PV, Slack; a group name such as SynGen or StaticGen resolves to its
  model) (a generator event: its unit tripped), Fault (bus, tf, tc, rf, xf); a disabled one (u = 0)
  is left out; a Toggle of any other model is refused in one line.
"""
from __future__ import annotations

import argparse
import hashlib
import io
import logging
import os
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
NETWORK_MODELS = ("Bus", "Line", "PQ", "PV", "Slack", "Shunt", "Toggle", "Fault")
IGNORED_MODELS = ("Area", "BusFreq", "BusROCOF", "ACEc", "Summary")  # measurements and the case's description
MACHINES = ("GENROU", "GENCLS")
STATIC_GENERATORS = ("PV", "Slack")  # a Toggle of one trips its machine's unit (ANDES passes the status on)
EXCITERS = ("IEEEX1", "EXDC2", "EXST1", "ESST3A", "SEXS")
GOVERNORS = ("TGOV1", "TGOV1N", "IEEEG1", "TG2", "GAST", "HYGOV", "HYGOV4", "HYGOVDB", "IEESGO")
STABILISERS = ("IEEEST", "ST2CUT")
LOADS = ("ZIP", "FLoad", "Motor5", "Motor3")  # dynamic and voltage-dependent loads (wired by the conversion: to come)
CONVERTERS = ("REGCA1",)  # inverters' converters: a unit's bus device (wired by the conversion: to come)
ELECTRICAL_CONTROLS = ("REECA1",)  # inverters' electrical controllers (wired by the conversion: to come)
CACHE_FORMAT = 1  # version of what convert writes: a new one keys new cache entries
PFLOW_TOLERANCE = 1e-12  # ANDES' power-flow Newton tolerance (its default 1e-6 leaves 4e-7 pu mismatches)
MISMATCH_LIMIT = 1e-8  # pu: the stored network at the stored load flow
# our state name -> ANDES variable where they differ
ANDES_STATE_NAMES = {"ESST3A": {"VR": "LAW1_y", "VM": "LAW2_y"}}


def load_andes(source, dyr=None):
    """ANDES' System of `source` (a file or a case ANDES ships) after its power flow (Newton
    tolerance PFLOW_TOLERANCE), ANDES' own log output silenced. CaseError (one line) where ANDES is
    missing, cannot read the file or its power flow does not converge."""
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
    with _silenced(andes):
        try:
            ss = andes.load(str(path), setup=True, no_output=True, default_config=True, **kwargs)
        except Exception as exc:  # ANDES' parsers raise anything on a file that is not theirs
            raise CaseError(f"ANDES cannot read {path}{' with ' + str(dyr) if dyr else ''} "
                            f"({type(exc).__name__}: {' '.join(str(exc).split())[:80]})") from None
        if ss is None:
            raise CaseError(f"ANDES cannot read {path}{' with ' + str(dyr) if dyr else ''} (not a case file "
                            "ANDES reads: xlsx, json, PSS/E raw with its dyr)")
        ss.PFlow.config.tol = PFLOW_TOLERANCE
        ss.PFlow.config.max_iter = 50
        if not ss.PFlow.run() or not ss.PFlow.converged:
            raise CaseError(f"{path}: ANDES' power flow does not converge")
    return ss


def configure_andes_logging(andes, level: int = logging.CRITICAL + 1) -> None:
    """ANDES' log messages below `level` off, and no log file: ANDES' config_logger otherwise makes
    an empty folder /tmp/andes-* for a log file at every call."""
    andes.config_logger(stream_level=level, file=False, log_path=tempfile.gettempdir())


@contextmanager
def _silenced(andes):
    """ANDES' log output and whatever it prints off for the block."""
    configure_andes_logging(andes)
    sink = io.StringIO()
    with redirect_stdout(sink), redirect_stderr(sink):
        yield


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


def _values(model, name) -> list:
    return [float(v) for v in getattr(model, name).v]


def _bus(value, where: str) -> int:
    if isinstance(value, (int, np.integer)) or (isinstance(value, (float, str)) and str(value).lstrip("-").isdigit()):
        return int(value)
    raise CaseError(f"{where}: bus {str(value)[:20]!r} is not a number (opfmu numbers buses)")


def _check_supported(ss) -> None:
    known = set(NETWORK_MODELS) | set(IGNORED_MODELS) | set(STANDARD_MODELS)
    for name, model in ss.models.items():
        if model.n > 0 and name not in known:
            raise CaseError(f"the case uses the model {name}, which opfmu does not have "
                            f"(it has {', '.join(STANDARD_MODELS)})")
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
    bus_numbers = [_bus(b, "Bus") for b in ss.Bus.idx.v]
    number = dict(zip(ss.Bus.idx.v, bus_numbers))
    buses = [{"number": n, "kv": float(kv)} for n, kv in zip(bus_numbers, ss.Bus.Vn.v)]
    L = ss.Line
    branches = []
    for i in range(L.n):
        if L.u.v[i] == 0:
            continue
        tap, phi = float(L.tap.v[i]), float(L.phi.v[i])
        transformer = bool(L.trans.v[i]) or tap != 1.0 or phi != 0.0
        branches.append({"from": number[L.bus1.v[i]], "to": number[L.bus2.v[i]], "r": float(L.r.v[i]) + 1e-8,
                         "x": float(L.x.v[i]) + 1e-8, "b": float(L.b.v[i]),
                         "kind": "transformer" if transformer else "line", "tap": tap, "phi": phi,
                         "andes": str(L.idx.v[i])})
    # the power each load draws in the power flow (ANDES' Ppf, Qpf: p0, q0 within [vmin, vmax])
    V = dict(zip(ss.Bus.idx.v, ss.Bus.v.v))
    loads = {}
    for i in range(ss.PQ.n):
        if ss.PQ.u.v[i] == 0:
            continue
        v0, p0, q0 = float(V[ss.PQ.bus.v[i]]), float(ss.PQ.p0.v[i]), float(ss.PQ.q0.v[i])
        vmin, vmax = float(ss.PQ.vmin.v[i]), float(ss.PQ.vmax.v[i])
        if ss.PQ.config.pq2z and not vmin <= v0 <= vmax:  # ANDES' power flow turned it into an impedance
            limit = vmin if v0 < vmin else vmax
            p0, q0 = p0 * (v0 / limit) ** 2, q0 * (v0 / limit) ** 2
        bus = number[ss.PQ.bus.v[i]]
        loads[bus] = loads.get(bus, 0j) + complex(p0, q0)
    shunts = {}
    for i in range(ss.Shunt.n):
        if ss.Shunt.u.v[i] == 0:
            continue
        bus = number[ss.Shunt.bus.v[i]]
        shunts[bus] = shunts.get(bus, 0j) + complex(float(ss.Shunt.g.v[i]), float(ss.Shunt.b.v[i]))
    generators, P, Q = [], [], []
    for model, kind in ((ss.Slack, "slack"), (ss.PV, "pv")):
        for i in range(model.n):
            if model.u.v[i] == 0:
                continue
            generators.append({"bus": number[model.bus.v[i]], "kind": kind, "V": float(model.v0.v[i]),
                               "P": None if kind == "slack" else float(model.p0.v[i]), "name": str(model.idx.v[i])})
            P.append(float(model.p.v[i]))
            Q.append(float(model.q.v[i]))
    data = {"name": name, "source": "converted from ANDES' case by reference_models.grid.andes_case",
            "base_mva": base, "f_hz": float(ss.config.freq), "buses": buses, "branches": branches,
            "loads": [{"bus": b, "P": s.real, "Q": s.imag} for b, s in loads.items()],
            "shunts": [{"bus": b, "G": s.real, "B": s.imag} for b, s in shunts.items()],
            "generators": generators,
            "load_flow": {"V": _values(ss.Bus, "v"), "theta": _values(ss.Bus, "a"), "P": P, "Q": Q},
            "events": events(ss, number)}
    return data


def events(ss, number) -> list:
    """The case's own enabled Toggle and Fault events as network-file entries."""
    out = []
    for i in range(ss.Toggle.n):
        if ss.Toggle.u.v[i] == 0:
            continue
        target, dev, t = ss.Toggle.model.v[i], ss.Toggle.dev.v[i], float(ss.Toggle.t.v[i])
        if target in ss.groups:  # a group name (SynGen, StaticGen, ...): the model holding the device
            target = ss.groups[target].idx2model(dev).class_name
        if target == "Line":
            out.append({"kind": "branch", "time": t, "branch": _branch_name(ss, dev, number), "status": "toggle"})
        elif target in MACHINES + STATIC_GENERATORS:
            model = getattr(ss, target)
            j = list(model.idx.v).index(dev)
            generator = str(model.gen.v[j]) if target in MACHINES else str(model.idx.v[j])
            out.append({"kind": "generator", "time": t, "bus": number[model.bus.v[j]], "generator": generator,
                        "status": "toggle"})
        else:
            raise CaseError(f"a Toggle of a {target} is not converted (Line, {', '.join(MACHINES + STATIC_GENERATORS)} "
                            "are)")
    for i in range(ss.Fault.n):
        if ss.Fault.u.v[i] == 0:
            continue
        out.append({"kind": "fault", "time": float(ss.Fault.tf.v[i]), "clear": float(ss.Fault.tc.v[i]),
                    "bus": number[ss.Fault.bus.v[i]], "r": float(ss.Fault.rf.v[i]), "x": float(ss.Fault.xf.v[i])})
    out.sort(key=lambda e: e["time"])
    status = {}  # a toggle flips the device's status at its time (all start in service)
    for e in out:
        if e.get("status") == "toggle":
            key = (e["kind"], e.get("branch"), e.get("generator"))
            status[key] = 1 - status.get(key, 1)
            e["status"] = status[key]
    return out


def _branch_name(ss, dev, number) -> str:
    L = ss.Line
    i = list(L.idx.v).index(dev)
    ends = {L.bus1.v[i], L.bus2.v[i]}
    k = sum(1 for j in range(i + 1) if {L.bus1.v[j], L.bus2.v[j]} == ends and L.u.v[j] != 0)
    name = f"{number[L.bus1.v[i]]}-{number[L.bus2.v[i]]}"
    return name + (f":{k}" if k > 1 else "")


def _params(model, name: str, i: int, ss) -> dict:
    """Device i's parameters as the case file gives them (ANDES' vin), with Sn, Sb, fn where the
    component takes them."""
    component = STANDARD_MODELS[name]
    fields = component.params_type.__dataclass_fields__
    values = {}
    for field in fields:
        param = getattr(model, field, None)
        if param is not None and hasattr(param, "vin"):
            values[field] = float(param.vin[i])
    for field, value in (("Sb", float(ss.config.mva)), ("Sn", None), ("fn", None)):
        if field in fields:
            values[field] = value if value is not None else float(getattr(model, field).v[i])
    return values


def dynamic_data(ss, name: str) -> dict:
    """The dynamic-data file's content (see the module docstring) of ANDES' System."""
    number = dict(zip(ss.Bus.idx.v, (_bus(b, "Bus") for b in ss.Bus.idx.v)))
    machines = {}  # machine idx -> (model name, position)
    for mname in MACHINES:
        model = getattr(ss, mname)
        for i in range(model.n):
            machines[model.idx.v[i]] = (mname, i)
    units = {}
    for idx, (mname, i) in machines.items():
        model = getattr(ss, mname)
        if model.u.v[i] == 0:
            continue
        units[idx] = {"bus": number[model.bus.v[i]], "generator": str(model.gen.v[i]),
                      "machine": {"component": STANDARD_MODELS[mname].name, "andes": str(idx),
                                  "params": _params(model, mname, i, ss)}}
    exciter_of = {}
    for role, names in (("exciter", EXCITERS), ("governor", GOVERNORS)):
        for dname in names:
            model = getattr(ss, dname)
            for i in range(model.n):
                if model.u.v[i] == 0:
                    continue
                syn = model.syn.v[i]
                if dname == "IEEEG1" and model.syn2.v[i] is not None:
                    raise CaseError(f"IEEEG1 {model.idx.v[i]} drives two machines (syn2), which opfmu does not model")
                unit = units.get(syn)
                if unit is None:
                    raise CaseError(f"{dname} {model.idx.v[i]} names no machine in service ({syn})")
                if role in unit:
                    raise CaseError(f"machine {syn} has two {role}s")
                unit[role] = {"component": STANDARD_MODELS[dname].name, "andes": str(model.idx.v[i]),
                              "params": _params(model, dname, i, ss)}
                if role == "exciter":
                    exciter_of[model.idx.v[i]] = syn
    for dname in STABILISERS:
        model = getattr(ss, dname)
        for i in range(model.n):
            if model.u.v[i] == 0:
                continue
            syn = exciter_of.get(model.avr.v[i])
            if syn is None:
                raise CaseError(f"{dname} {model.idx.v[i]} names no exciter in service ({model.avr.v[i]})")
            units[syn]["stabiliser"] = {"component": STANDARD_MODELS[dname].name, "andes": str(model.idx.v[i]),
                                        "params": _params(model, dname, i, ss)}
    for unit in units.values():
        unit["fmu"] = {"kind": "reference"}
    generators = [str(g) for m in (ss.Slack, ss.PV) for g in m.idx.v]
    in_service = [str(g) for m in (ss.Slack, ss.PV) for g, u in zip(m.idx.v, m.u.v) if u != 0]
    bare = [g for g in in_service if g not in {u["generator"] for u in units.values()}]
    if bare:
        raise CaseError(f"the generator{'s' if len(bare) > 1 else ''} {', '.join(bare[:5])}"
                        f"{' ...' if len(bare) > 5 else ''} {'have' if len(bare) > 1 else 'has'} no machine "
                        "(GENROU, GENCLS) in the case")
    order = sorted(units.values(), key=lambda u: generators.index(u["generator"]))
    return {"case": name, "description": "converted from ANDES' case by reference_models.grid.andes_case: one unit per "
            "machine (machine, exciter, governor, stabiliser), parameters as the case file gives them (machine "
            "base Sn; Sb the system base), keyed by bus and load-flow generator",
            "generators": order}


def mismatch(network: dict) -> float:
    """The largest bus power mismatch [pu] of a network file's content at its stored load flow:
    generation - load - V conj(Y V)."""
    import tempfile

    from .case import load_network

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "network.json"
        write_json(path, network)
        net, flow = load_network(path)
    V = flow.V_complex
    S = V * np.conj(net.ybus() @ V) + flow.S_load
    for k, bus in enumerate(flow.generator_buses):
        S[net.bus_index(bus)] -= complex(flow.P_gen[k], flow.Q_gen[k])
    return float(np.abs(S).max())


def convert(source, out_dir, name: str | None = None, dyr=None) -> tuple:
    """Write NAME_network.json and NAME.json of ANDES' case `source` into out_dir; (network file,
    dynamic-data file). CaseError where the case cannot be converted."""
    name = name or Path(str(source)).stem
    ss = load_andes(source, dyr)
    network, dynamic = network_data(ss, name), dynamic_data(ss, name)
    worst = mismatch(network)
    if worst > MISMATCH_LIMIT:
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
            print(*convert(args.case, args.out, args.name, args.dyr))
        else:
            raise CaseError("give CASE OUT_DIR, --shipped or --compare NAME")
    except CaseError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0

if __name__ == "__main__":
    sys.exit(main())
