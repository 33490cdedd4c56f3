"""The FMU files of a grid co-simulation, one machine FMU and one exciter FMU per generator, built
from the generators' dynamic data and kept in a cache folder.

Kinds (reference_models.grid.wscc9.GeneratorFMU): `surrogate` builds the machine's surrogate FMU
from its operator file (refused unless the operator was trained for that machine) with a native
reference IEEE1 exciter; `reference` builds native reference FMUs of both from the component
definitions; `python` builds pythonfmu reference FMUs of both; `file` takes the two files as given.

A built FMU is named by a hash of everything it is made from (kind, component, parameters, the
operator file's bytes and the sources of the builders), so a cache entry is reused exactly when
a build would give the same FMU; builds write atomically, so a cache can be shared.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from fmu_export.build_cache import cached_fmu, default_cache
from reference_models.grid import wscc9
from reference_models.ieee1 import IEEE1
from reference_models.sm4 import SM4

from .fmu import CouplingError

ROOT = Path(__file__).resolve().parents[1]
SHIPPED_OPERATORS = ROOT / "surrogate" / "default"


@dataclass(frozen=True)
class GeneratorFiles:
    """The FMU files of one generator: `kind`, `machine` and `exciter` paths."""

    bus: int
    kind: str
    machine: Path
    exciter: Path


def operator_path(name) -> Path:
    """An operator file: the path as given if it exists, else the shipped operator of that name."""
    path = Path(name)
    if path.is_file():
        return path
    shipped = SHIPPED_OPERATORS / path.name
    if shipped.is_file():
        return shipped
    raise CouplingError(f"no operator file {name} (shipped: {', '.join(p.name for p in sorted(SHIPPED_OPERATORS.glob('*.onnx')))})")


def _check_operator(path: Path, machine, bus: int) -> None:
    """Refuses an operator that is not SM4 with Vs, theta_vs, Pm, Efd or was trained for another machine."""
    import onnx

    from surrogate.contract import ContractError, operator_metadata

    try:
        meta = operator_metadata({p.key: p.value for p in onnx.load(str(path), load_external_data=False).metadata_props})
    except ContractError as exc:
        raise CouplingError(f"generator at bus {bus}: {path}: {exc}") from None
    except Exception as exc:
        raise CouplingError(f"generator at bus {bus}: cannot read the operator {path}: {str(exc)[:160]}") from None
    if meta["component"].name != SM4.name or tuple(meta["input_names"]) != SM4.input_names:
        raise CouplingError(f"generator at bus {bus}: {path.name} is not an SM4 operator with inputs "
                            f"{', '.join(SM4.input_names)}")
    trained, wanted = meta["params"].to_dict(), machine.to_dict()
    differ = [f"{k} {trained.get(k)} (machine: {v})" for k, v in wanted.items()
              if abs(float(trained.get(k, float("nan"))) - float(v)) > 1e-9 * max(1.0, abs(float(v)))]
    if differ:
        raise CouplingError(f"generator at bus {bus}: the operator {path.name} was trained for another machine: "
                            + ", ".join(differ[:4]))


def _build(kind: str, component, params, cache: Path, model_name: str, operator: Path | None = None,
           progress=None) -> Path:
    """The FMU of `component` with `params` of that kind, from the cache or built into it."""
    from fmu_export.surrogate_fmu import BuildError, build_surrogate_fmu
    from fmu_export.native_reference_fmu import build_native_reference_fmu
    from fmu_export.python_reference_fmu import build_reference_fmu

    payload = operator.read_bytes() if operator is not None else b""

    def build(out: Path) -> None:
        try:
            if kind == "surrogate":
                build_surrogate_fmu(operator, out, model_name=model_name)
            elif kind == "reference":
                build_native_reference_fmu(out, model_name=model_name, component=component, params=params)
            else:
                build_reference_fmu(out, model_name=model_name, component=component, params=params)
        except (BuildError, ValueError, RuntimeError) as exc:
            raise CouplingError(f"cannot build {model_name}: {str(exc)[:300]}") from None

    return cached_fmu(model_name, (kind, component.name, params.to_dict(), payload), build, cache,
                      progress and (lambda name: progress(f"{name} ({kind})")))


def generator_files(dynamics, kind: str | None = None, cache=None, progress=None) -> list:
    """GeneratorFiles for every generator of `dynamics` (wscc9.GeneratorDynamics), each of its own
    FMU kind or all of `kind`; `progress(text)` is told before each FMU that is not cached is built."""
    cache = Path(cache) if cache is not None else default_cache()
    files = []
    for g in dynamics:
        fmu = g.fmu if kind is None else replace(g.fmu, kind=kind)
        if fmu.kind not in wscc9.FMU_KINDS:
            raise CouplingError(f"FMU kind must be one of {', '.join(wscc9.FMU_KINDS)}, got {fmu.kind!r}")
        if fmu.kind == "file":
            paths = [Path(fmu.machine_fmu), Path(fmu.exciter_fmu)]
            absent = [str(p) for p in paths if not p.is_file()]
            if absent:
                raise CouplingError(f"generator at bus {g.bus}: no FMU file {', '.join(absent)}")
            files.append(GeneratorFiles(g.bus, fmu.kind, *paths))
            continue
        if fmu.kind == "surrogate":
            if fmu.operator is None:
                raise CouplingError(f"generator at bus {g.bus}: a surrogate needs an operator file (the "
                                    "dynamic data names none)")
            operator = operator_path(fmu.operator)
            _check_operator(operator, g.machine, g.bus)
        name = {"surrogate": "Surrogate", "reference": "Reference", "python": "Python"}[fmu.kind]
        if fmu.kind == "surrogate":
            machine = _build("surrogate", SM4, g.machine, cache, f"Gen{g.bus}{name}", operator, progress)
            exciter = _build("reference", IEEE1, g.exciter, cache, f"Exciter{g.bus}Reference", progress=progress)
        else:
            machine = _build(fmu.kind, SM4, g.machine, cache, f"Gen{g.bus}{name}", progress=progress)
            exciter = _build(fmu.kind, IEEE1, g.exciter, cache, f"Exciter{g.bus}{name}", progress=progress)
        files.append(GeneratorFiles(g.bus, fmu.kind, machine, exciter))
    return files
