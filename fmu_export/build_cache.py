"""A content-keyed cache of built FMUs, shared by the grid, the demo and the tests.

An FMU is named by a hash of everything it is made from: the builders' sources (fmu_export,
reference_models and surrogate: .py, .c, .h), and the parts its caller names (kind, component, parameters, the
operator file's bytes, the FMI version, ...). An entry is reused exactly when a build would give
the same FMU. Builds write atomically, so a cache can be shared by processes; an entry that is not a
readable FMU archive (a truncated or foreign file) is built again.

The folder is $OPFMU_FMU_CACHE, else ~/.cache/opfmu/fmus. `cached_surrogate_fmu` and
`cached_native_reference_fmu` are the two native builders through the cache (the demo and the tests
use them; the grid names its own parts, cosim.fmus).
"""
from __future__ import annotations

import hashlib
import json
import os
import zipfile
from pathlib import Path
from typing import Callable

from reference_models.files import atomic_path

ROOT = Path(__file__).resolve().parents[1]
SOURCES = (ROOT / "fmu_export", ROOT / "reference_models", ROOT / "surrogate")

_SOURCE_HASH: str | None = None


def default_cache() -> Path:
    """$OPFMU_FMU_CACHE, else ~/.cache/opfmu/fmus."""
    return Path(os.environ.get("OPFMU_FMU_CACHE") or Path.home() / ".cache" / "opfmu" / "fmus")


def source_hash() -> str:
    """A hash of the builders' sources (fmu_export, reference_models, surrogate: .py, .c, .h), once per
    process."""
    global _SOURCE_HASH
    if _SOURCE_HASH is None:
        h = hashlib.sha256()
        for folder in SOURCES:
            for path in sorted(folder.rglob("*")):
                if path.suffix in (".py", ".c", ".h") and "__pycache__" not in path.parts:
                    h.update(str(path.relative_to(ROOT)).encode())
                    h.update(path.read_bytes())
        _SOURCE_HASH = h.hexdigest()
    return _SOURCE_HASH


def cache_key(*parts) -> str:
    """16 hex digits from the sources' hash and `parts` (bytes as they are, anything else as sorted JSON)."""
    h = hashlib.sha256(source_hash().encode())
    for part in parts:
        h.update(part if isinstance(part, bytes) else json.dumps(part, sort_keys=True, default=str).encode())
    return h.hexdigest()[:16]


def is_fmu_archive(path: Path) -> bool:
    """True when `path` is a zip archive with a modelDescription.xml whose central directory reads."""
    try:
        with zipfile.ZipFile(path) as archive:
            return "modelDescription.xml" in archive.namelist()
    except (OSError, zipfile.BadZipFile, ValueError):
        return False


def cached_fmu(model_name: str, parts: tuple, build: Callable[[Path], object], cache=None,
               progress: Callable[[str], None] | None = None) -> Path:
    """The FMU `<cache>/<model_name>-<key of parts>.fmu`: reused when present and readable, else built
    by `build(path)` (which must write `path` atomically; a dict it returns is kept beside the FMU,
    for build_report); `progress(model_name)` before a build.
    BuildError (one line) when the cache folder cannot be made."""
    from .binaries import BuildError

    cache = Path(cache) if cache is not None else default_cache()
    try:
        cache.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BuildError(f"cannot use {cache} as the FMU build cache ({exc.strerror or exc}); set OPFMU_FMU_CACHE "
                         "to a writable folder") from None
    out = cache / f"{model_name}-{cache_key(model_name, *parts)}.fmu"
    if out.is_file() and is_fmu_archive(out):
        return out
    if progress:
        progress(model_name)
    report = build(out)
    if isinstance(report, dict):
        with atomic_path(out.with_suffix(".json")) as tmp:
            tmp.write_text(json.dumps(report, default=str))
    return out


def build_report(path) -> dict:
    """What the build of a cached FMU returned (a dict: the builders' guid, checks, binaries, ...),
    as JSON read back; {} when its build returned none or the file does not read."""
    try:
        report = json.loads(Path(path).with_suffix(".json").read_text())
    except (OSError, ValueError):
        return {}
    return report if isinstance(report, dict) else {}


def _platform_names(platforms) -> list[str]:
    """The names of the platforms a build carries (None: the host's only), as the builders choose them."""
    from .binaries import targets

    return [p.name for p in targets(platforms)]


def cached_surrogate_fmu(onnx_path, model_name: str = "SM4Surrogate", platforms=None, fmi_version: int = 2,
                         n_check: int = 32, cache=None, progress: Callable[[str], None] | None = None) -> Path:
    """The surrogate FMU of an operator file (fmu_export.surrogate_fmu.build_surrogate_fmu, same
    arguments), from the cache or built into it. Keyed by the file's bytes, the model name, the
    platforms and the FMI version; n_check (the kernel checks against onnxruntime at build time)
    does not change the FMU, so it is no part of the key."""
    from .surrogate_fmu import build_surrogate_fmu

    onnx_path, names = Path(onnx_path), _platform_names(platforms)
    return cached_fmu(model_name, ("surrogate", onnx_path.read_bytes(), names, fmi_version),
                      lambda out: build_surrogate_fmu(onnx_path, out, model_name=model_name, n_check=n_check,
                                                      platforms=names, fmi_version=fmi_version), cache, progress)


def cached_native_reference_fmu(model_name: str = "SM4Reference", component=None, params=None,
                                operating_point: dict | None = None, platforms=None, fmi_version: int = 2,
                                cache=None, progress: Callable[[str], None] | None = None,
                                system_base_mva: float | None = None) -> Path:
    """The native reference FMU (fmu_export.native_reference_fmu.build_native_reference_fmu, same
    arguments; component None: SM4; system_base_mva None: the builder's default), from the cache or
    built into it. Keyed by the component, its parameters in full (defaults filled in), the operating
    point, the platforms, the FMI version and a system base other than the default: its callers take
    the FMU's defaults (parameters, start values) as the machine, although one FMU of a structure
    serves any parameters set at instantiation (the grid keys its FMUs by the structure alone:
    cosim.fmus)."""
    from reference_models.component import ParameterError
    from reference_models.sm4 import SM4

    from .native_reference_fmu import NativeReferenceError, build_native_reference_fmu
    from .python_reference_fmu import machine_params

    component = component or SM4
    try:
        full = machine_params(component, params)
    except ParameterError as exc:
        raise NativeReferenceError(str(exc)) from None
    names = _platform_names(platforms)
    base = {} if system_base_mva is None else {"system_base_mva": system_base_mva}
    return cached_fmu(model_name, ("reference", component.name, full.to_dict(), operating_point, names, fmi_version,
                                   *base.values()),
                      lambda out: build_native_reference_fmu(out, model_name=model_name, component=component,
                                                             params=full, operating_point=operating_point,
                                                             platforms=names, fmi_version=fmi_version, **base),
                      cache, progress)
