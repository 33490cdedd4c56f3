"""The two FMUs the co-simulation benchmarks compare, extracted: given, or built on the spot."""
from __future__ import annotations

from pathlib import Path

from fmpy import extract


def extracted_pair(surrogate, reference, tmp: Path, operator=None) -> tuple[str, str]:
    """(surrogate dir, reference dir) under tmp; a missing surrogate FMU is built from `operator`
    (default: the shipped one), a missing reference FMU is built too."""
    if surrogate is None:
        from fmu_export.builder import build_surrogate_fmu
        from surrogate.operator import DEFAULT_OPERATOR

        surrogate = tmp / "SM4Surrogate.fmu"
        build_surrogate_fmu(operator or DEFAULT_OPERATOR, surrogate)
    if reference is None:
        from reference_models.reference_fmu import build_reference_fmu

        reference = tmp / "SM4Reference.fmu"
        build_reference_fmu(reference)
    return extract(str(surrogate), unzipdir=str(tmp / "s")), extract(str(reference), unzipdir=str(tmp / "r"))


def surrogate_parameters(specs) -> dict:
    """--param NAME=VALUE strings -> {name: float}."""
    return {name: float(value) for name, value in (spec.split("=", 1) for spec in specs)}
