"""A case's FMUs for another tool (`opfmu grid export`): one FMU file per distinct FMU the case runs
and `case.json`, which names for every device its FMU, bus, parameters, load-flow point, start
values and where each of its inputs comes from. The two are enough for another master.

case.json (format "opfmu-case", version 1):
    case, base_mva [MVA], f_hz [Hz], fmi_version, kind (the FMU kind: reference or surrogate)
    network: buses [{number, kv}], branches [{from, to, r, x, b, kind, tap, phi}] (pu on base_mva,
        tap and phase shift [rad] at the from side), loads [{bus, P, Q}] and shunts [{bus, G, B}]
        (pu; loads are constant impedances at their load-flow voltage), generators [{bus, kind, V,
        P, name}], load_flow {V [pu], theta [rad] per bus; P, Q [pu] per generator}
    events: the case's own events (as the network file gives them)
    devices: [{id "UNIT/DEVICE" (the unit is its load-flow generator's name or "bus N", a load
        unit "load N/..."), unit, bus, role (the dynamic-data key: machine, exciter, ...),
        component, fmu (file name in the folder), parameters {name: value} (the component's, as
        the FMU was built with them), load_flow {V, theta, P, Q} of its unit (generator
        convention, system base; a load unit's P, Q are minus what it draws), start {states
        {name: value}, inputs {name: value}} (the state's start values go into the FMU's
        `<state>0` parameters), ports (the bus port's voltage inputs and current outputs, the
        link signals), inputs {input: source}}], a source being one of
        {"bus": "magnitude" | "angle"} (the device's bus voltage, network frame),
        {"terminal": "magnitude" | "angle"} (the voltage behind the unit machine's external
        impedance Re + j Xep: `external_impedance`),
        {"device": ID, "output": NAME} (another device's output),
        {"measured": {"bus", "branch", "end"}, "quantity": NAME} (a network measurement),
        {"held": VALUE} (a set point: nothing drives it);
        and where its FMU starts itself (fmu_export.self_start, docs/fmu.md "Start from the load flow"),
        self_start {parameters {name: value}, from {name: {"device": ID, "parameter": NAME}}}: the
        start parameters to set (a bus device's V_lf, theta_lf, P_lf, Q_lf; a controller's
        `<output>_init`, the value the device it drives solved), and where a host that lets each FMU
        solve its start reads a controller's `<output>_init` instead: that device's calculated
        parameter `<input>_init` after it was given its own
    Every bus device's current (its bus port's outputs, network frame, system base) goes into its
    bus; a host solves the network with them (or with their Norton equivalents, docs/design.md).

Files are written whole or not at all (cosim.outputs.result_set).
"""
from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

from fmu_export.self_start import INIT_SUFFIX, LOAD_FLOW_VARIABLES
from reference_models.grid.case import (MEASURED, TERMINAL, external_impedance, operating_point, remote_wiring,
                                        unit_wiring)

FORMAT, VERSION = "opfmu-case", 1
LOAD_FLOW_NAMES = tuple(name for name, _, _ in LOAD_FLOW_VARIABLES)


def _unit_name(unit) -> str:
    """A unit's name in case.json: its load-flow generator's name, "bus N" without one, "load N"
    for a load unit."""
    if unit.load is not None:
        return f"load {unit.bus}" + (f" {unit.devices[0].name}" if len(unit.devices) > 1 else "")
    return unit.generator if unit.generator is not None else f"bus {unit.bus}"


def _network(case) -> dict:
    net, flow = case.network, case.flow
    return {"buses": [{"number": b, "kv": net.kv.get(b)} for b in net.buses],
            "branches": [{"from": br.from_bus, "to": br.to_bus, "r": br.r, "x": br.x, "b": br.b, "kind": br.kind,
                          "tap": br.tap, "phi": br.phi} for br in net.branches],
            "loads": [{"bus": b, "P": s.real, "Q": s.imag} for b, s in net.loads.items()],
            "shunts": [{"bus": b, "G": y.real, "B": y.imag} for b, y in net.shunts.items()],
            "generators": [{"bus": g.bus, "kind": g.kind, "V": g.V, "P": g.P, "name": g.name} for g in net.generators],
            "load_flow": {"V": [float(v) for v in flow.V], "theta": [float(v) for v in flow.theta],
                          "P": [float(v) for v in flow.P_gen], "Q": [float(v) for v in flow.Q_gen]}}


def _event(event) -> dict:
    out = {k: v for k, v in vars(event).items() if v is not None}
    for key in ("impedance", "power"):
        if key in out:
            out[key] = [out[key].real, out[key].imag]
    return out


def _source(source, case, k: int, j: int, ids, start: dict, name: str) -> dict:
    """case.json's form of an input's Source (case.unit_wiring)."""
    if source.kind == "bus":
        return {"bus": ("magnitude", "angle")[source.index]}
    if source.kind == "terminal":
        return {"terminal": ("magnitude", "angle")[source.index]}
    if source.kind == "device":
        return {"device": ids[source.unit if source.unit is not None else k][source.device], "output": source.variable}
    if source.kind == "measured":
        m = case.units[k].devices[j].measures
        return {"measured": {"bus": m.bus, "branch": m.branch, "end": m.end}, "quantity": MEASURED[source.index]}
    return {"held": float(start[name])}


def _ports(ports) -> dict:
    out = {"inputs": {link.variable: link.signal for link in ports.inputs},
           "outputs": {link.variable: link.signal for link in ports.outputs}}
    if ports.bus is not None:
        out["bus"] = {"voltage": list(ports.bus.voltage), "current": list(ports.bus.current)}
    return out


def _start_variables(path) -> dict:
    """{name: causality} of an FMU's start variables (fmu_export.self_start): its load flow, the
    `<y>_init` parameters and the `<u>_init` calculated parameters."""
    from fmpy import read_model_description

    return {v.name: v.causality for v in read_model_description(str(path)).modelVariables
            if v.name in LOAD_FLOW_NAMES or v.name.endswith(INIT_SUFFIX)}


def _self_start(k: int, j: int, op: dict, starts, wiring, ids, start_vars) -> dict | None:
    """case.json's self_start of unit k's device j (None where its FMU has none): start_vars[j] are
    the unit's FMUs' start variables (_start_variables)."""
    own = start_vars[j]
    if not own:
        return None
    parameters, sources = {}, {}
    if LOAD_FLOW_NAMES[0] in own:
        parameters.update(zip(LOAD_FLOW_NAMES, (op["V"], op["theta"], op["P"], op["Q"])))
    for taker, wires in enumerate(wiring):
        for name, source in wires.items():
            delivered = f"{source.variable}{INIT_SUFFIX}"
            if (source.kind == "device" and source.unit is None and source.device == j
                    and own.get(delivered) == "parameter"
                    and start_vars[taker].get(f"{name}{INIT_SUFFIX}") == "calculatedParameter"):
                parameters[delivered] = float(starts[taker].inputs[name])
                sources[delivered] = {"device": ids[k][taker], "parameter": f"{name}{INIT_SUFFIX}"}
    return {"parameters": parameters, "from": sources}


def case_description(case, files, kind: str, fmi_version: int, names: dict) -> dict:
    """case.json's content for `case` whose unit k's device j runs the FMU files[k].paths[j], named
    names[path] in the export folder."""
    ids = [[f"{_unit_name(u)}/{d.name}" for d in u.devices] for u in case.units]
    remotes = remote_wiring(case.units)
    start_variables = {}
    devices = []
    for k, (unit, starts, unit_files) in enumerate(zip(case.units, case.starts, files)):
        wiring = unit_wiring([d.component.ports for d in unit.devices], f"generator at bus {unit.bus}", remotes[k])
        op = operating_point(unit, k, case.flow)
        for path in unit_files.paths:
            if Path(path) not in start_variables:
                start_variables[Path(path)] = _start_variables(path)
        start_vars = [start_variables[Path(p)] for p in unit_files.paths]
        for j, (device, start, path) in enumerate(zip(unit.devices, starts, unit_files.paths)):
            comp = device.component
            entry = {"id": ids[k][j], "unit": _unit_name(unit), "bus": unit.bus, "role": device.name,
                     "component": comp.name, "fmu": names[Path(path)], "parameters": device.params.to_dict(),
                     "load_flow": op,
                     "start": {"states": dict(zip(comp.state_names, start.states)), "inputs": dict(start.inputs)},
                     "ports": _ports(comp.ports),
                     "inputs": {name: _source(source, case, k, j, ids, start.inputs, name)
                                for name, source in wiring[j].items()}}
            for name in comp.input_names:  # inputs no port names: held at their start
                entry["inputs"].setdefault(name, {"held": float(start.inputs[name])})
            if j == 0:
                z = external_impedance(device)
                entry["external_impedance"] = [z.real, z.imag]
            self_start = _self_start(k, j, op, starts, wiring, ids, start_vars)
            if self_start is not None:
                entry["self_start"] = self_start
            devices.append(entry)
    return {"format": FORMAT, "version": VERSION, "case": case.name, "base_mva": case.network.base_mva,
            "f_hz": case.network.f_hz, "fmi_version": fmi_version, "kind": kind, "terminal": list(TERMINAL),
            "network": _network(case), "events": [_event(e) for e in case.events], "devices": devices}


def export_names(files) -> dict:
    """{FMU path: its file name in the export folder}: the FMU's name in the cache without its
    content hash where that is unique, one file per distinct content."""
    names, by_digest = {}, {}
    for unit_files in files:
        for path in unit_files.paths:
            path = Path(path)
            if path in names:
                continue
            digest = hashlib.sha256(path.read_bytes()).hexdigest()
            if digest not in by_digest:
                stem = path.stem.split("-")[0] or path.stem
                taken = set(by_digest.values())
                name = f"{stem}.fmu" if f"{stem}.fmu" not in taken else f"{stem}-{digest[:8]}.fmu"
                by_digest[digest] = name
            names[path] = by_digest[digest]
    return names


def export_case(case, out, kind: str = "reference", fmi_version: int = 2, cache=None, progress=None) -> Path:
    """Writes the case's FMUs (built into `cache` as needed) and case.json into the folder `out`;
    returns the path of case.json."""
    from .fmus import generator_files
    from .outputs import result_set

    files = generator_files(case, kind, cache, progress, fmi_version)
    names = export_names(files)
    description = case_description(case, files, kind, fmi_version, names)
    written = sorted(set(names.values())) + ["case.json"]
    with result_set(out, written) as staging:
        for path, name in names.items():
            if not (staging / name).exists():
                shutil.copyfile(path, staging / name)
        (staging / "case.json").write_text(json.dumps(description, indent=1) + "\n", encoding="utf-8")
    return Path(out) / "case.json"
