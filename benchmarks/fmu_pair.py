"""The two FMUs the co-simulation benchmarks compare, extracted: given, or built on the spot."""
from __future__ import annotations

from pathlib import Path

from fmpy import extract


def extracted_pair(surrogate, reference, tmp: Path, operator=None) -> tuple[str, str]:
    """(surrogate dir, reference dir) under tmp; a missing surrogate FMU is built from `operator`
    (default: the shipped one), a missing reference FMU is the native one built for the surrogate's
    machine (the parameters its operator records)."""
    if surrogate is None:
        from fmu_export.surrogate_fmu import build_surrogate_fmu
        from surrogate.operator import DEFAULT_OPERATOR

        surrogate = tmp / "SM4Surrogate.fmu"
        build_surrogate_fmu(operator or DEFAULT_OPERATOR, surrogate)
    surrogate_dir = extract(str(surrogate), unzipdir=str(tmp / "s"))
    if reference is None:
        from fmu_export.native_reference_fmu import build_native_reference_fmu
        from opfmu.compare import fmu_machine

        reference = tmp / "SM4Reference.fmu"
        build_native_reference_fmu(reference, params=fmu_machine(surrogate_dir))
    return surrogate_dir, extract(str(reference), unzipdir=str(tmp / "r"))


def surrogate_parameters(specs) -> dict:
    """--param NAME=VALUE strings -> {name: float}."""
    return {name: float(value) for name, value in (spec.split("=", 1) for spec in specs)}


def surrogate_setting(surrogate_dir, name: str, parameters: dict) -> float:
    """A surrogate parameter as a run uses it: given in `parameters`, else the FMU's default."""
    from fmpy import read_model_description

    if name in parameters:
        return float(parameters[name])
    return float(next(v.start for v in read_model_description(str(surrogate_dir)).modelVariables if v.name == name))
