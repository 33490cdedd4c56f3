"""Compiling an FMU's C sources into one binary per platform, for FMI 2.0 or 3.0.

Both native builders (surrogate_fmu.py: the surrogate; native_reference_fmu.py: the reference) hand their
sources here. The FMI API is the only thing that differs between the versions: fmi2_cs.c or
fmi3_cs.c (PLUMBING) is compiled with cosimulation.c (their shared logic) and the same model sources. The host's binary is always built,
since it is the one loaded here (the kernel check, the cross-platform runs); every binary's export
and import tables are checked (platforms.check_linkage) before it goes into an FMU.
"""
from __future__ import annotations

import subprocess
from pathlib import Path

from reference_models.messages import one_line

from .platforms import Platform, PlatformError, by_name, check_linkage, host

PLUMBING = {2: "fmi2_cs.c", 3: "fmi3_cs.c"}  # the FMI plumbing of each version (c/)


class BuildError(ValueError):
    """The FMU cannot be built as asked (bad operator file, compiler failure, kernel mismatch); the
    message is one line."""

    def __init__(self, message: str):
        super().__init__(one_line(message, None))


def fmi_headers() -> Path:
    """fmpy's copy of the FMI 2.0 and 3.0 headers (fmpy/c-code)."""
    import fmpy

    path = Path(fmpy.__file__).parent / "c-code"
    for name in ("fmi2Functions.h", "fmi3Functions.h"):
        if not (path / name).exists():
            raise BuildError(f"FMI header {name} not found in {path} (is fmpy installed?)")
    return path


def check_fmi_version(value) -> int:
    """The FMI major version asked for (2 or 3); BuildError otherwise."""
    if str(value).strip() in ("2", "2.0"):
        return 2
    if str(value).strip() in ("3", "3.0"):
        return 3
    raise BuildError(f"FMI version {str(value)[:20]!r}: 2 or 3")


def targets(platforms=None) -> list[Platform]:
    """The platforms to build: None for the host only, else Platform objects or their names (each
    must have its compiler: BuildError otherwise)."""
    if platforms is None:
        return [host()]
    chosen = []
    try:
        for p in platforms:
            p = by_name(p) if isinstance(p, str) else p
            if not p.compiler_found():
                raise PlatformError(f"cannot build for {p.name}: no {p.compiler} found (Debian package {p.package})")
            if p not in chosen:
                chosen.append(p)
    except PlatformError as exc:
        raise BuildError(str(exc)) from None
    if not chosen:
        raise BuildError("no platform to build for")
    return chosen


def compile_c(output: Path, sources, include: Path, kind: str = "shared", target: Platform | None = None) -> Path:
    """-O3 compile of C sources (and object files) with the target platform's compiler (the host's
    gcc by default) into `output`: a shared library (kind "shared"), one object file ("object") or
    a program ("program"); BuildError with the compiler's first error otherwise."""
    target = target or host()
    mode = {"shared": ["-shared", *target.shared_flags], "object": ["-c", *target.shared_flags],
            "program": list(target.program_flags)}[kind]
    command = [target.compiler, "-O3", *mode, "-std=c99", "-Wall", "-I", str(fmi_headers()), "-I", str(include),
               *map(str, sources), "-o", str(output), *([] if kind == "object" else ["-lm", *target.program_libs])]
    try:
        result = subprocess.run(command, capture_output=True, text=True)
    except OSError as exc:
        raise BuildError(f"cannot run {target.compiler} ({exc.strerror or exc}): a C compiler is needed to build the "
                         "FMU") from None
    if result.returncode != 0:
        lines = result.stderr.strip().splitlines()
        errors = [line for line in lines if "error" in line] or lines or [f"exit code {result.returncode}"]
        raise BuildError(f"{target.compiler} failed: {errors[0][:300]}")
    return output


def compile_binaries(workdir: Path, model_name: str, sources, include: Path, chosen: list[Platform], version: int,
                     objects=None, model_exchange: bool = False) -> dict[Platform, Path]:
    """The FMU's binary for the host and each chosen platform, {platform: path} with the host first:
    the version's plumbing (PLUMBING) and `sources` from `include`, plus `objects(platform)` (object
    files compiled for that platform, e.g. the operator kernel). Each binary's linkage is checked
    (model_exchange: the FMU also offers Model Exchange, whose functions it must export too)."""
    binaries = {}
    for target in dict.fromkeys([host(), *chosen]):
        folder = workdir / f"{target.name}-fmi{version}"
        folder.mkdir(parents=True, exist_ok=True)
        inputs = [include / PLUMBING[version], *sources, *(objects(target) if objects else [])]
        binary = compile_c(folder / f"{model_name}{target.extension}", inputs, include, target=target)
        try:
            check_linkage(binary, target, fmi_headers(), version, model_exchange)
        except PlatformError as exc:
            raise BuildError(str(exc)) from None
        binaries[target] = binary
    return binaries
