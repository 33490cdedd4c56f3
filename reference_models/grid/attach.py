"""Sub-systems attached to a host case at a bus, as one case file ANDES reads: the host's and each
sub-system's devices (ANDES loads both files; needs ANDES, like any case file), merged, so that the
power flow is solved jointly and every runner (native FMUs, the monolithic DAE, ANDES itself) runs
the whole.

A sub-system file (reference_models.grid.subsystems) is a case of its own whose only Slack stands
for the grid at its boundary bus. Attached at host bus B:
* the Slack and the boundary bus are left out, and whatever the sub-system connects to its
  boundary bus connects to B (a line's nominal voltage at that end becomes B's);
* the sub-system's other buses are numbered from the first multiple of 1000 above every bus number
  already taken (ANDES' bus idx are integers), and every other idx (lines, loads, static
  generators, devices) gets the prefix "B:" (ANDES' references between devices follow: each
  IdxParam names the model or group it points into);
* its own events (Toggle, Fault, Alter) come along;
* a transformer between its boundary and the rest (a feeder's substation transformer) settles its
  tap so that its far bus keeps the voltage of the sub-system's own power flow, as an on-load tap
  changer does before a dynamic study; its static generators keep its units at unity power factor
  (`_settle`).
Neither file's ANDES settings (_config) are carried: the merged case runs on ANDES' defaults, which
are what opfmu's conversion asks of a case anyway (reference_models.grid.andes_case).

`attached_file(host, [(bus, file), ...], folder)` writes the merged case as ANDES JSON into
`folder`, named by a hash of the inputs' bytes (a second call finds it), atomically.
"""
from __future__ import annotations

import hashlib
import math
import tempfile
from collections import defaultdict
from pathlib import Path

from ..messages import one_line
from .case import CaseError
from .subsystems import write_case

BUS_BLOCK = 1000  # the sub-system's buses are numbered from a multiple of this
TAP_MIN, TAP_MAX = 0.85, 1.15  # the range of a boundary transformer's settled tap (_settle)
TAP_ITERATIONS, TAP_TOLERANCE = 8, 1e-6  # power flows at most, and the far-bus voltage [pu] they settle to


def case_records(ss) -> dict:
    """{model: [record]} of every model of the loaded ANDES system `ss` with devices (its input data)."""
    import pandas as pd

    out = {}
    for name, model in ss.models.items():
        if model.n == 0:
            continue
        frame = model.as_df(vin=True)
        out[name] = [{k: (None if (isinstance(v, float) and math.isnan(v)) or v is pd.NA else _plain(v))
                      for k, v in row.items() if k != "uid"} for row in frame.to_dict(orient="records")]
    return out


def _plain(value):
    """A JSON value of an ANDES input (numpy scalars made Python ones)."""
    return value.item() if hasattr(value, "item") else value


def device_references(ss) -> dict:
    """{model: {field: the model or group the IdxParam points into}} of every model of `ss`."""
    out = {}
    for name, model in ss.models.items():
        fields = {}
        for field, param in model.params.items():
            target = getattr(param, "model", None)
            if field != "idx" and target is not None and type(param).__name__ == "IdxParam":
                fields[field] = target
        out[name] = fields
    return out


def _boundary(records: dict, path) -> tuple:
    """(boundary bus idx, the Slack record's idx) of a sub-system: its only Slack's bus."""
    slacks = [r for r in records.get("Slack", []) if r.get("u", 1) not in (0, 0.0)]
    if len(slacks) != 1:
        raise CaseError(f"{path}: a sub-system has exactly one Slack in service, at its boundary bus (the grid "
                        f"it is attached to), got {len(slacks)}")
    return slacks[0]["bus"], slacks[0]["idx"]


def merge(host: dict, host_refs: dict, subsystems: list) -> tuple:
    """(the host's records with each (bus, records, refs, path) of `subsystems` attached (module
    docstring), the sub-systems' transformers at their boundaries: [(subsystem index, merged Line
    idx, whether its tap side (bus1) is the boundary, merged far bus, the far bus' idx in the
    sub-system)])."""
    regulated = []
    merged = {model: [dict(r) for r in rows] for model, rows in host.items()}
    buses = {r["idx"]: r for r in merged.get("Bus", [])}
    taken = max(int(b) for b in buses)
    for k, (bus, records, refs, path) in enumerate(subsystems):
        if bus not in buses:
            raise CaseError(f"--attach {bus}=...: the host has no bus {bus}")
        boundary, slack = _boundary(records, path)
        first = (taken // BUS_BLOCK + 1) * BUS_BLOCK
        numbers = {boundary: bus}
        for r in records.get("Bus", []):
            if r["idx"] != boundary:
                numbers[r["idx"]] = first + len(numbers) - 1
        taken = max([taken, *numbers.values()])
        prefix = f"{bus}:"
        bus_group = {"Bus", "ACNode"}  # ANDES: a bus field points into the ACNode group
        for model, rows in records.items():
            if model in ("_config", "Summary"):
                continue
            fields = refs.get(model, {})
            for r in rows:
                if model == "Bus" and r["idx"] == boundary or model == "Slack" and r["idx"] == slack:
                    continue
                r = dict(r)
                if model == "Bus":
                    r["idx"] = numbers[r["idx"]]
                else:
                    r["idx"] = f"{prefix}{r['idx']}"
                    if r.get("name") is not None:
                        r["name"] = f"{prefix}{r['name']}"
                for field, target in fields.items():
                    value = r.get(field)
                    if value is None:
                        continue
                    if target in bus_group:
                        r[field] = numbers.get(value, value)
                    else:
                        r[field] = f"{prefix}{value}"
                if model == "Line":  # an end at the boundary takes the host bus' nominal voltage
                    for end, vn in (("bus1", "Vn1"), ("bus2", "Vn2")):
                        if r.get(end) == bus:
                            r[vn] = buses[bus].get("Vn", r.get(vn))
                    ends = (r.get("bus1"), r.get("bus2"))
                    if r.get("trans") and bus in ends and ends[0] != ends[1]:
                        far = ends[1] if ends[0] == bus else ends[0]
                        original = next(b for b, n in numbers.items() if n == far)
                        regulated.append((k, r["idx"], ends[0] == bus, far, original))
                elif r.get("bus") == bus and "Vn" in r:
                    r["Vn"] = buses[bus].get("Vn", r["Vn"])
                merged.setdefault(model, []).append(r)
    return merged, regulated


def _load(andes, path):
    """The ANDES system of the case file `path`, loaded without setup; CaseError where ANDES cannot."""
    from .andes_case import configure_andes_logging

    configure_andes_logging(andes)
    try:
        ss = andes.load(str(path), setup=False, no_output=True, default_config=True)
    except Exception as exc:  # ANDES raises what its readers raise on a malformed file
        raise CaseError(f"{path}: ANDES cannot read it: {type(exc).__name__}: {exc}") from None
    if ss is None:
        raise CaseError(f"{path}: ANDES cannot read it")
    return ss


def attached_file(host, attachments, folder) -> Path:
    """The case file (ANDES JSON in `folder`) of the host case file `host` with each (bus, sub-system
    file) of `attachments` attached; CaseError for a file ANDES cannot read, a sub-system without
    exactly one Slack, or a bus the host lacks. A file joined before is taken as it is, without ANDES."""
    host = Path(host)
    digest = hashlib.sha256(host.read_bytes())
    for bus, path in attachments:
        digest.update(f"|{bus}|".encode())
        digest.update(Path(path).read_bytes())
    digest.update(Path(__file__).read_bytes())
    out = Path(folder) / f"{host.stem}_attached_{digest.hexdigest()[:16]}.json"
    if out.exists():
        return out
    import andes

    own = [_own_voltages(andes, path) for _, path in attachments]
    ss = _load(andes, host)
    try:
        host_records = case_records(ss)
        subsystems = []
        for bus, path in attachments:
            sub = _load(andes, path)
            subsystems.append((int(bus), case_records(sub), device_references(sub), path))
        merged, regulated = merge(host_records, device_references(ss), subsystems)
        targets = [(idx, tap_at_boundary, far, own[k][original])
                   for k, idx, tap_at_boundary, far, original in regulated]
        pvs = {f"{bus}:{r['idx']}" for bus, records, _, _ in subsystems for r in records.get("PV", [])}
        _settle(andes, merged, pvs, targets, Path(folder))
    except CaseError:
        raise
    except Exception as exc:  # ANDES raises what the files' values make its code raise
        raise CaseError(f"ANDES cannot join {host.name} and its sub-systems: {type(exc).__name__}: {one_line(exc, 160)}") \
            from None
    return write_case(merged, out)


def own_power_flow(andes, path):
    """The ANDES system of the sub-system file `path` with its own power flow solved (its Slack the
    grid); CaseError where ANDES cannot read or set it up, where a bus is not connected to its
    boundary (the Slack's bus) through its lines in service, or where the flow does not converge."""
    ss = _load(andes, path)
    try:
        ss.setup()
        flowed = ss.PFlow.run() and ss.PFlow.converged
    except Exception as exc:  # ANDES' setup and flow raise what the file's values make them raise
        raise CaseError(f"{path}: ANDES cannot set it up: {type(exc).__name__}: {one_line(exc, 160)}") from None
    cut_off = _cut_off(ss)
    if cut_off:
        raise CaseError(f"{path}: its buses {', '.join(map(str, cut_off[:8]))}{' ...' if len(cut_off) > 8 else ''} "
                        "are not connected to its boundary (the bus of its Slack) through its lines in service")
    if not flowed:
        raise CaseError(f"{path}: the sub-system's own power flow does not converge")
    return ss


def _cut_off(ss) -> list:
    """The buses of the set-up ANDES system `ss` that no path of lines in service joins to its
    Slack's bus."""
    links = defaultdict(set)
    for a, b, on in zip(ss.Line.bus1.v, ss.Line.bus2.v, ss.Line.u.v):
        if on:
            links[a].add(b)
            links[b].add(a)
    reached = set(ss.Slack.bus.v)
    todo = list(reached)
    while todo:
        for other in links[todo.pop()] - reached:
            reached.add(other)
            todo.append(other)
    return [b for b in ss.Bus.idx.v if b not in reached]


def _own_voltages(andes, path) -> dict:
    """{bus idx: voltage magnitude [pu]} of the sub-system's own power flow."""
    ss = own_power_flow(andes, path)
    return dict(zip(ss.Bus.idx.v, ss.Bus.v.v))


def _settle(andes, merged: dict, pvs: set, targets: list, folder: Path) -> None:
    """The joint power flow's settled state, written into `merged`:
    * each sub-system transformer at its boundary (`targets`: (Line idx, whether its tap side is the
      boundary, far bus, the far bus' voltage in the sub-system's own power flow)) takes the tap that
      gives its far bus that voltage, as an on-load tap changer settles before a dynamic study (a
      feeder built for 1 pu at its boundary keeps its voltage profile on a host bus at 0.95 pu);
      taps within [TAP_MIN, TAP_MAX], CaseError beyond;
    * the voltage of each sub-system static generator in `pvs` (a PV holds its bus voltage in the
      power flow) is the one the joint flow gives it when it holds its reactive power at 0 instead
      (ANDES' pv2pq with both of its limits 0, every other PV's limits out of reach): the units start
      at unity power factor, as they were built.
    CaseError where that power flow does not converge."""
    if not pvs and not targets:
        return
    taps = {idx: 1.0 for idx, *_ in targets}
    for r in merged.get("Line", []):
        if r["idx"] in taps:
            taps[r["idx"]] = float(r.get("tap", 1.0) or 1.0)
    for _ in range(TAP_ITERATIONS):
        voltage, bus_of = _probe_flow(andes, merged, pvs, taps, folder)
        off = 0.0
        for idx, tap_at_boundary, far, target in targets:
            v = voltage[far]
            # the far bus' voltage goes as 1/tap where the tap sits at the boundary, as tap where at the far bus
            taps[idx] *= v / target if tap_at_boundary else target / v
            off = max(off, abs(v - target))
            if not TAP_MIN <= taps[idx] <= TAP_MAX:
                raise CaseError(f"the sub-system's transformer {idx} would need a tap of {taps[idx]:.3f} to hold "
                                f"its far bus at {target:.4f} pu (beyond [{TAP_MIN}, {TAP_MAX}]): attach it at a bus "
                                f"nearer its boundary voltage")
        if off < TAP_TOLERANCE:
            break
    for r in merged.get("Line", []):
        if r["idx"] in taps:
            r["tap"] = taps[r["idx"]]
    for r in merged.get("PV", []):
        if r["idx"] in pvs:
            r["v0"] = float(voltage[bus_of[r["idx"]]])


def _probe_flow(andes, merged: dict, pvs: set, taps: dict, folder: Path) -> tuple:
    """({bus: voltage [pu]}, {PV idx: its bus}) of the joint power flow with the taps `taps` and the
    static generators `pvs` at zero reactive power (_settle)."""
    probe = {model: [dict(r) for r in rows] for model, rows in merged.items()}
    for r in probe.get("PV", []):
        if r["idx"] in pvs:
            r["qmax"], r["qmin"] = 0.0, 0.0
        else:
            r["qmax"], r["qmin"] = 1e8, -1e8
    for r in probe.get("Line", []):
        if r["idx"] in taps:
            r["tap"] = taps[r["idx"]]
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=folder, prefix=".probe.") as scratch:  # its own: others may probe too
        path = write_case(probe, Path(scratch) / "joint_power_flow_probe.json")
        ss = andes.load(str(path), no_output=True, default_config=True, config_option=["PV.pv2pq=1"])
        converged = ss is not None and ss.PFlow.run() and ss.PFlow.converged
        if not converged:
            raise CaseError("the joint power flow of the host and its sub-systems does not converge")
        return dict(zip(ss.Bus.idx.v, ss.Bus.v.v)), dict(zip(ss.PV.idx.v, ss.PV.bus.v))
