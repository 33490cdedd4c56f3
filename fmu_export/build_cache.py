"""A content-keyed cache of built FMUs, shared by the grid, the demo and the tests.

An FMU is named by a hash of everything it is made from: the builders' sources (fmu_export and
reference_models: .py, .c, .h), and the parts its caller names (kind, component, parameters, the
operator file's bytes, the FMI version, ...). An entry is reused exactly when a build would give
the same FMU. Builds write atomically, so a cache can be shared by processes; an entry that is not a
readable FMU archive (a truncated or foreign file) is built again.

The folder is $OPFMU_FMU_CACHE, else ~/.cache/opfmu/fmus.
"""
from __future__ import annotations

import hashlib
import json
import os
import zipfile
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parents[1]
SOURCES = (ROOT / "fmu_export", ROOT / "reference_models")

_SOURCE_HASH: str | None = None


def default_cache() -> Path:
    """$OPFMU_FMU_CACHE, else ~/.cache/opfmu/fmus."""
    return Path(os.environ.get("OPFMU_FMU_CACHE") or Path.home() / ".cache" / "opfmu" / "fmus")


def source_hash() -> str:
    """A hash of the builders' sources (fmu_export, reference_models: .py, .c, .h), once per process."""
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
    by `build(path)` (which must write `path` atomically); `progress(model_name)` before a build."""
    cache = Path(cache) if cache is not None else default_cache()
    cache.mkdir(parents=True, exist_ok=True)
    out = cache / f"{model_name}-{cache_key(model_name, *parts)}.fmu"
    if out.is_file() and is_fmu_archive(out):
        return out
    if progress:
        progress(model_name)
    build(out)
    return out
