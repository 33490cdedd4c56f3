"""The hand-made equivalent of a sub-system, as engineers build it today (in the spirit of WECC's
DER_A and composite-load feeder equivalents): one device of each dynamic model with the summed
ratings, behind one equivalent impedance, as a sub-system case file of its own.

From the sub-system's own load flow (ANDES, its boundary at the Slack's voltage), with S_b the power
the boundary sends in and I_b its current:
* the equivalent impedance Z = S_loss / |I_b|^2, S_loss the power its branches consume (S_b plus
  what its static generators give less what its loads draw): the series impedance that loses, at the
  boundary current, what the detail loses. Where |I_b| is below MIN_CURRENT (generation and load
  balanced inside), Z is the impedance of the branches from the boundary to the first bus with a
  device, in series;
* one aggregate bus behind Z, at the voltage V_b - Z I_b, with every load summed (constant impedance
  at the load-flow voltage in the time domain, as each was: the sum is taken at the aggregate bus'
  voltage so that it draws the detail's total power there);
* one static generator with the summed power; one device per dynamic model linked to the static
  generators, directly or through other devices (a PVD1's gen; a REGCA1's gen, its REECA1's reg,
  the REPCA1's ree), linked to the aggregates, with its rating the sum of the units' (Sn), a
  setting split by rating among the units (a plant controller's gains and limits: proportional to
  the ratings) summed, every other numeric setting the rating-weighted mean of the units' (trip
  thresholds included: the equivalent trips all at once, which is what aggregates are known to
  miss), and its share of its static generator 1.
Devices that are neither loads, static generators nor models with a `gen` link (a Toggle, a Fault,
measurements) are left out.

`aggregate(records, path)`: the equivalent's records; `aggregate_file(sub, folder)`: written beside
the others, named by a hash of the sub-system's bytes.
"""
from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np

from .attach import case_records, device_references, own_power_flow
from .case import CaseError
from .subsystems import write_case

MIN_CURRENT = 1e-4  # pu: below it the loss-based impedance is undefined
PROPORTIONAL = 1e-9  # relative spread of value / rating below which a setting counts as split by rating
BUS_GROUPS = ("Bus", "ACNode")  # what ANDES' bus fields point into
TEXT_FIELDS = ("idx", "name", "bus", "gen", "busf", "igreg", "busr", "owner", "coi", "coi2", "zone", "area")


def _boundary_flow(andes, path):
    """(ss, boundary bus idx, S_b [pu into the sub-system], V_b [complex pu]) of the sub-system's own
    load flow; CaseError where it does not solve."""
    ss = own_power_flow(andes, path)
    if ss.Slack.n != 1:
        raise CaseError(f"{path}: a sub-system has exactly one Slack, at its boundary bus")
    bus = ss.Slack.bus.v[0]
    i = ss.Bus.idx2uid(bus)
    V = ss.Bus.v.v[i] * np.exp(1j * ss.Bus.a.v[i])
    return ss, bus, complex(ss.Slack.p.v[0], ss.Slack.q.v[0]), complex(V)


def _weighted(rows: list, weights: np.ndarray) -> dict:
    """One record of the devices `rows` with `weights` (their ratings): each numeric field that is
    proportional to the weights (to PROPORTIONAL; a rating Sn, a plant controller's gains and limits
    split by rating) the sum of the rows' values, any other the weighted mean (integers and flags:
    the most common value); the rest from the first row. Where every weight is the same, only Sn is
    summed (a split gain and a unit's own setting cannot be told apart)."""
    out = dict(rows[0])
    spread = np.ptp(weights) > PROPORTIONAL * np.max(np.abs(weights))
    for field, value in rows[0].items():
        if field in TEXT_FIELDS or not isinstance(value, (int, float)) or isinstance(value, bool):
            continue
        values = np.array([float(r.get(field, value)) for r in rows])
        if isinstance(value, int) or field.endswith("flag"):
            kinds, counts = np.unique(values, return_counts=True)
            out[field] = type(value)(kinds[np.argmax(counts)])
            continue
        ratio = values / weights
        proportional = spread and np.all(values != 0) and np.ptp(ratio) <= PROPORTIONAL * np.max(np.abs(ratio))
        out[field] = float(np.sum(values)) if proportional or field == "Sn" else \
            float(np.sum(weights * values) / np.sum(weights))
    return out


def aggregate(records: dict, ss, boundary, S_b: complex, V_b: complex) -> dict:
    """The equivalent's records (module docstring) of the sub-system `records` whose load flow is `ss`
    (ANDES), with its boundary bus idx, S_b and V_b."""
    refs = device_references(ss)
    groups = {name: model.group for name, model in ss.models.items()}
    loads = [r for r in records.get("PQ", []) if r.get("u", 1)]
    gens = [r for r in records.get("PV", []) if r.get("u", 1)]
    S_load = sum(complex(ss.PQ.Ppf.v[ss.PQ.idx2uid(r["idx"])], ss.PQ.Qpf.v[ss.PQ.idx2uid(r["idx"])]) for r in loads)
    S_gen = sum(complex(ss.PV.p.v[ss.PV.idx2uid(r["idx"])], ss.PV.q.v[ss.PV.idx2uid(r["idx"])]) for r in gens)
    I_b = (S_b / V_b).conjugate()
    if abs(I_b) >= MIN_CURRENT:
        Z = (S_b + S_gen - S_load) / abs(I_b) ** 2
    else:
        Z = _path_impedance(records, boundary)
    if not (Z.real >= 0.0 and Z.imag > 0.0):
        Z = complex(max(Z.real, 0.0), max(Z.imag, 1e-4))  # a lossless or capacitive net: a small series reactance
    V_a = V_b - Z * I_b
    bus_rows = {r["idx"]: r for r in records["Bus"]}
    slack = records["Slack"][0]
    first_device_bus = (loads + gens)[0]["bus"] if loads + gens else boundary
    vn = bus_rows[first_device_bus].get("Vn", bus_rows[boundary].get("Vn"))
    out = {"Bus": [dict(bus_rows[boundary]),
                   {"idx": 2 if boundary != 2 else 3, "name": "aggregate", "Vn": vn, "v0": abs(V_a),
                    "a0": math.atan2(V_a.imag, V_a.real)}],
           "Slack": [dict(slack)]}
    agg = out["Bus"][1]["idx"]
    out["Line"] = [{"idx": "equivalent", "name": "equivalent", "bus1": boundary, "bus2": agg, "Sn": 100.0,
                    "fn": 60.0, "Vn1": bus_rows[boundary].get("Vn"), "Vn2": vn, "r": Z.real, "x": Z.imag,
                    "b": 0.0, "trans": 1 if vn != bus_rows[boundary].get("Vn") else 0, "tap": 1.0, "phi": 0.0}]
    if loads:
        # each load's impedance at its own voltage, summed at the aggregate bus' voltage: the detail's total
        Y = sum(complex(ss.PQ.Ppf.v[ss.PQ.idx2uid(r["idx"])], -ss.PQ.Qpf.v[ss.PQ.idx2uid(r["idx"])])
                / ss.Bus.v.v[ss.Bus.idx2uid(r["bus"])] ** 2 for r in loads)
        S = (Y * abs(V_a) ** 2).conjugate()
        out["PQ"] = [{"idx": "load", "name": "load", "bus": agg, "Vn": vn, "p0": S.real, "q0": S.imag}]
    if gens:
        p = sum(r["p0"] for r in gens)
        out["PV"] = [{**gens[0], "idx": "generation", "name": "generation", "bus": agg, "Vn": vn, "p0": p,
                      "q0": S_gen.imag, "v0": abs(V_a), "Sn": sum(r.get("Sn", 100.0) for r in gens),
                      "pmax": sum(r.get("pmax", p) for r in gens), "pmin": sum(r.get("pmin", 0.0) for r in gens),
                      "qmax": sum(r.get("qmax", 0.0) for r in gens), "qmin": sum(r.get("qmin", 0.0) for r in gens)}]
        out.update(_devices(records, refs, groups, gens, boundary, agg))
    return out


def _devices(records: dict, refs: dict, groups: dict, gens: list, boundary, agg) -> dict:
    """{model: [one aggregate record]} of every dynamic model linked, directly or through other
    devices (ANDES' IdxParam links: a converter's gen, its electrical control's reg, a plant
    controller's ree, ...), to the static generators `gens`; each linked to the aggregates of what its
    devices link to, its bus fields on the aggregate bus (the boundary where they name it). Each
    device's weight is its rating (Sn, times its share gammap of its static generator), or that of
    the device it links to."""
    aggregate_of = {}  # (model or group, idx) -> the aggregate's idx
    weight_of = {}
    for r in gens:
        for key in (("PV", r["idx"]), (groups.get("PV"), r["idx"])):
            aggregate_of[key] = "generation"
            weight_of[key] = float(r.get("Sn", 1.0))
    out, changed = {}, True
    skip = {"Bus", "PV", "PQ", "Slack", "Line", "Summary", "Toggle", "Fault", "Alter", "BusFreq", "BusROCOF"}
    while changed:
        changed = False
        for model, rows in records.items():
            if model in skip or model in out:
                continue
            links = {f: t for f, t in refs.get(model, {}).items() if t not in BUS_GROUPS}
            linked = [r for r in rows if r.get("u", 1) and any((t, r.get(f)) in aggregate_of for f, t in links.items())]
            if not linked:
                continue
            weights = []
            for r in linked:
                via = next(weight_of[(t, r[f])] for f, t in links.items() if (t, r.get(f)) in weight_of)
                weights.append(float(r["Sn"]) * float(r.get("gammap", 1.0)) if "Sn" in r and r["Sn"] else via)
            weights = np.array(weights)
            unit = _weighted(linked, weights)
            name = f"aggregate {model}"
            unit.update({"idx": name, "name": name})
            for f, t in links.items():
                value = linked[0].get(f)
                unit[f] = aggregate_of.get((t, value)) if value is not None else None
            for f, t in refs.get(model, {}).items():
                if t in BUS_GROUPS and linked[0].get(f) is not None:
                    unit[f] = boundary if linked[0][f] == boundary else agg
            for f in ("gammap", "gammaq"):
                if f in unit:
                    unit[f] = 1.0
            out[model] = [unit]
            for r, w in zip(linked, weights):
                for key in ((model, r["idx"]), (groups.get(model), r["idx"])):
                    aggregate_of[key] = name
                    weight_of[key] = float(w)
            changed = True
    return out


def _path_impedance(records: dict, boundary) -> complex:
    """The series impedance of the branches from `boundary` to the first bus with a load or a generator."""
    devices = {r["bus"] for model in ("PQ", "PV") for r in records.get(model, [])}
    edges = {}
    for r in records.get("Line", []):
        z = complex(r.get("r", 0.0), r.get("x", 0.0))
        edges.setdefault(r["bus1"], []).append((r["bus2"], z))
        edges.setdefault(r["bus2"], []).append((r["bus1"], z))
    seen, frontier = {boundary}, [(boundary, 0j)]
    while frontier:
        bus, z = frontier.pop(0)
        if bus in devices:
            return z
        for other, dz in edges.get(bus, []):
            if other not in seen:
                seen.add(other)
                frontier.append((other, z + dz))
    return 1e-4j


def aggregate_file(path, folder) -> Path:
    """The equivalent of the sub-system file `path` as a sub-system file in `folder` (cached by the
    file's bytes, taken from there without ANDES); CaseError where ANDES cannot read or solve it."""
    path = Path(path)
    digest = hashlib.sha256(path.read_bytes())
    digest.update(Path(__file__).read_bytes())
    out = Path(folder) / f"{path.stem}_aggregate_{digest.hexdigest()[:16]}.json"
    if out.exists():
        return out
    import andes

    ss, boundary, S_b, V_b = _boundary_flow(andes, path)
    return write_case(aggregate(case_records(ss), ss, boundary, S_b, V_b), out)
