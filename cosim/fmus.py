"""Which FMUs a co-simulation runs for each unit of a case (the FMU kinds), and their files, built
from the units' components and parameters and kept in the content-keyed cache (fmu_export.build_cache).

Kinds (`UnitFMU`, from a unit's `fmu` entry in the dynamic data, or one kind for every unit):
`surrogate` builds the machine's surrogate FMU from its operator file (refused unless the operator
was trained for that component and those parameters) with native reference FMUs of the unit's
control components; `reference` builds native reference FMUs of every device; `python` pythonfmu
reference FMUs of every device; `file` takes an FMU file per device as given (`<device>_fmu`, e.g.
machine_fmu, exciter_fmu; paths relative to the dynamic-data file). `fmi_version` 2 or 3 chooses
the FMI version of the native FMUs built.

A native reference FMU reads its component's parameters from the instance (fmu_export.c_parameters),
so one is built per model: per (component, structure, FMI version), the structure being what the
equations decide on parameter values (native_reference_fmu.structure_of). Its model name is the
component's (GENROUReference; with a suffix from the structure where it is not the default
parameters' one), its defaults those of the first device it was built for; the master sets every
device's parameters and start values at initialisation (cosim.fmu.FMU.parameter_values).
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

from .fmu import CouplingError

ROOT = Path(__file__).resolve().parents[1]
SHIPPED_OPERATORS = ROOT / "surrogate" / "default"
FMU_KINDS = ("surrogate", "reference", "python", "file")
_NAMES = {"surrogate": "Surrogate", "reference": "Reference", "python": "Python"}


@dataclass(frozen=True)
class UnitFMU:
    """The FMUs a co-simulation runs for a unit: `kind` (FMU_KINDS), the machine's `operator` file
    (surrogate), the FMU file of each device by device name (`files`, kind file)."""

    kind: str = "reference"
    operator: str | None = None
    files: tuple = ()  # ((device name, path), ...)


@dataclass(frozen=True)
class UnitFiles:
    """The FMU files of one unit: its bus, kind and one path per device (the unit's device order)."""

    bus: int
    kind: str
    paths: tuple


def unit_fmu(unit, dynamic_data: Path | None) -> UnitFMU:
    """The UnitFMU of a unit's `fmu` entry (default: native reference); CouplingError for a malformed
    one. Paths are resolved against the dynamic-data file's folder; an operator not found there is
    looked up among the shipped ones."""
    where = f"{dynamic_data}: generator at bus {unit.bus}"
    entry = unit.fmu if unit.fmu is not None else {"kind": "reference"}
    entry = {"kind": entry} if isinstance(entry, str) else entry
    if not isinstance(entry, dict) or entry.get("kind") not in FMU_KINDS:
        raise CouplingError(f"{where}: fmu kind must be one of {', '.join(FMU_KINDS)}, got {str(entry)[:60]!r}")
    names = [d.name for d in unit.devices]
    known = {"kind", "operator", *(f"{n}_fmu" for n in names)}
    unknown = set(entry) - known
    if unknown:
        raise CouplingError(f"{where}: unknown fmu keys {', '.join(sorted(unknown))} (known: {', '.join(sorted(known))})")
    base = Path(dynamic_data).parent if dynamic_data is not None else Path.cwd()

    def resolved(key):
        value = entry.get(key)
        if value is None:
            return None
        if not isinstance(value, str) or not value:
            raise CouplingError(f"{where}: fmu {key} must be a file name")
        beside = base / value
        return str(beside) if beside.exists() or key != "operator" else value

    kind = entry["kind"]
    files = tuple((n, resolved(f"{n}_fmu")) for n in names if entry.get(f"{n}_fmu") is not None)
    if kind == "surrogate" and entry.get("operator") is None:
        raise CouplingError(f"{where}: a surrogate needs its operator file")
    if kind == "file" and len(files) != len(names):
        raise CouplingError(f"{where}: kind file needs {', '.join(f'{n}_fmu' for n in names)}")
    return UnitFMU(kind, resolved("operator"), files)


def unit_fmus(case, kind: str | None = None) -> tuple:
    """The UnitFMU of every unit of `case`: its own, or `kind` for all (FMU_KINDS but file; surrogate
    only where the unit's dynamic data name an operator, native reference FMUs elsewhere)."""
    if kind is not None and kind not in FMU_KINDS:
        raise CouplingError(f"FMU kind must be one of {', '.join(FMU_KINDS)}, got {kind!r}")
    out = []
    for unit in case.units:
        fmu = unit_fmu(unit, case.dynamic_data)
        if kind is not None:  # surrogate: for the machines the dynamic data name an operator for, native for the rest
            fmu = replace(fmu, kind="reference" if kind == "surrogate" and fmu.operator is None else kind)
        out.append(fmu)
    return tuple(out)


def operator_path(name) -> Path:
    """An operator file: the path as given if it exists, else the shipped operator of that name."""
    path = Path(name)
    if path.is_file():
        return path
    shipped = SHIPPED_OPERATORS / path.name
    if shipped.is_file():
        return shipped
    raise CouplingError(f"no operator file {name} (shipped: {', '.join(p.name for p in sorted(SHIPPED_OPERATORS.glob('*.onnx')))})")


def _check_operator(path: Path, device, bus: int) -> None:
    """Refuses an operator that is not of the device's component with its inputs, or was trained for
    other parameters."""
    from surrogate.contract import ContractError, metadata_of, operator_metadata

    component = device.component
    try:
        meta = operator_metadata(metadata_of(path))
    except ContractError as exc:
        raise CouplingError(f"generator at bus {bus}: {path}: {exc}") from None
    except Exception as exc:
        raise CouplingError(f"generator at bus {bus}: cannot read the operator {path}: {str(exc)[:160]}") from None
    if meta["component"].name != component.name or tuple(meta["input_names"]) != tuple(component.input_names):
        raise CouplingError(f"generator at bus {bus}: {path.name} is not a {component.name} operator with inputs "
                            f"{', '.join(component.input_names)}")
    trained, wanted = meta["params"].to_dict(), device.params.to_dict()
    differ = [f"{k} {trained.get(k)} (machine: {v})" for k, v in wanted.items()
              if abs(float(trained.get(k, float("nan"))) - float(v)) > 1e-9 * max(1.0, abs(float(v)))]
    if differ:
        raise CouplingError(f"generator at bus {bus}: the operator {path.name} was trained for another machine: "
                            + ", ".join(differ[:4]))


def _build(kind: str, device, cache: Path, model_name: str, operator: Path | None = None, progress=None,
           fmi_version: int = 2, operating_point: dict | None = None, start_state=None,
           base_mva: float = 100.0) -> Path:
    """The FMU of `device` (component, parameters) of that kind, from the cache or built into it; a
    native reference FMU's inputs start at `operating_point` ({input: value}: the unit's start inputs)
    and its state at `start_state` (the unit's start states), so that its default start is the
    case's operating point, not the component's generic one; it declares its bus port on the case's
    system base `base_mva` [MVA]."""
    from fmu_export.build_cache import cached_fmu

    payload = operator.read_bytes() if operator is not None else b""

    def build(out: Path) -> None:
        from fmu_export.native_reference_fmu import build_native_reference_fmu
        from fmu_export.python_reference_fmu import build_reference_fmu
        from fmu_export.surrogate_fmu import BuildError, build_surrogate_fmu

        try:
            if kind == "surrogate":
                build_surrogate_fmu(operator, out, model_name=model_name, fmi_version=fmi_version)
            elif kind == "reference":
                build_native_reference_fmu(out, model_name=model_name, component=device.component,
                                           params=device.params, operating_point=operating_point,
                                           fmi_version=fmi_version, start_state=start_state,
                                           system_base_mva=base_mva)
            else:
                build_reference_fmu(out, model_name=model_name, component=device.component, params=device.params)
        except (BuildError, ValueError, RuntimeError) as exc:
            raise CouplingError(f"cannot build {model_name}: {str(exc)[:300]}") from None

    if kind == "reference":  # one FMU per model: the parameters and start values are set per device
        parts = (kind, _structure(device), payload)
    else:
        parts = (kind, device.component.name, device.params.to_dict(), payload)
    if fmi_version != 2:
        parts += (f"fmi{fmi_version}",)
    if kind == "reference" and base_mva != 100.0:
        parts += (f"base {base_mva!r} MVA",)
    return cached_fmu(model_name, parts, build, cache, progress and (lambda name: progress(f"{name} ({kind})")))


def _structure(device) -> dict:
    """The structure a native reference FMU of the device is built for (structure_of)."""
    from fmu_export.native_reference_fmu import NativeReferenceError, structure_of

    try:
        return structure_of(device.component, device.params)
    except NativeReferenceError as exc:
        raise CouplingError(f"{device.name}: {exc}") from None


@lru_cache(maxsize=None)
def _default_structure(component) -> str:
    """The structure of the component's default parameters, as JSON."""
    from fmu_export.native_reference_fmu import structure_of

    return json.dumps(structure_of(component), sort_keys=True)


def reference_model_name(device) -> str:
    """The model name of the native reference FMU of a device's model: <COMPONENT>Reference, with
    _<8 hex digits of its structure> where the structure is not that of the component's defaults."""
    structure = json.dumps(_structure(device), sort_keys=True)
    stem = f"{device.component.name.upper()}Reference"
    if structure == _default_structure(device.component):
        return stem
    return f"{stem}_{hashlib.sha256(structure.encode()).hexdigest()[:8]}"


def _model_name(device, index: int, bus: int, kind: str) -> str:
    """The FMU's model name: a native reference FMU's, its model's (reference_model_name); else
    Gen<bus> for a unit's machine, <MODEL><bus> for another bus device (a converter, a load),
    <Role><bus> for a control device (its dynamic-data key), then the kind."""
    if kind == "reference":
        return reference_model_name(device)
    if index == 0:
        stem = "Gen" if device.component.ports.output("rotor_angle") else device.component.name.upper()
    else:
        stem = device.name[:1].upper() + device.name[1:]
    return f"{stem}{bus}{_NAMES[kind]}"


def check_unit_fmus(case, kind: str | None = None) -> tuple:
    """unit_fmus with every file and operator checked (no build): CouplingError for an FMU file or
    operator that is absent or an operator of another component or machine. Returns the UnitFMUs."""
    fmus = unit_fmus(case, kind)
    for unit, fmu in zip(case.units, fmus):
        if fmu.kind == "file":
            absent = [str(p) for _, p in fmu.files if not Path(p).is_file()]
            if absent:
                raise CouplingError(f"generator at bus {unit.bus}: no FMU file {', '.join(absent)}")
        elif fmu.kind == "surrogate":
            _check_operator(operator_path(fmu.operator), unit.machine, unit.bus)
        elif fmu.kind == "python":
            from fmu_export.python_reference_fmu import ReferenceBuildError, check_packable

            for device in unit.devices:
                try:
                    check_packable(device.component)
                except ReferenceBuildError as exc:
                    raise CouplingError(f"generator at bus {unit.bus}: {exc}") from None
    return fmus


def generator_files(case, kind: str | None = None, cache=None, progress=None, fmi_version: int = 2) -> list:
    """UnitFiles for every unit of `case`, each of its own FMU kind or all of `kind`; `progress(text)`
    is told before each FMU that is not cached is built."""
    from fmu_export.build_cache import default_cache

    cache = Path(cache) if cache is not None else default_cache()
    files = []
    for unit, starts, fmu in zip(case.units, case.starts, check_unit_fmus(case, kind)):
        if fmu.kind == "file":
            by_name = dict(fmu.files)
            files.append(UnitFiles(unit.bus, fmu.kind, tuple(Path(by_name[d.name]) for d in unit.devices)))
            continue
        paths = []
        for j, (device, start) in enumerate(zip(unit.devices, starts)):
            if fmu.kind == "surrogate" and j == 0:
                paths.append(_build("surrogate", device, cache, _model_name(device, j, unit.bus, "surrogate"),
                                    operator_path(fmu.operator), progress, fmi_version))
            else:
                device_kind = "reference" if fmu.kind == "surrogate" else fmu.kind
                paths.append(_build(device_kind, device, cache, _model_name(device, j, unit.bus, device_kind),
                                    progress=progress, fmi_version=fmi_version,
                                    operating_point={n: float(v) for n, v in start.inputs.items()},
                                    start_state=[float(v) for v in start.states],
                                    base_mva=float(case.network.base_mva)))
        files.append(UnitFiles(unit.bus, fmu.kind, tuple(paths)))
    return files
