"""Writing an FMU file: modelDescription.xml, one binary per platform, resources and sources, zipped,
validated by fmpy, and moved onto its path atomically (a reader sees the old file or the new one)."""
from __future__ import annotations

import shutil
import zipfile
from pathlib import Path

from reference_models.files import atomic_path

from .binaries import BuildError
from .model_description import validation_problems
from .platforms import Platform


def write_fmu(out: Path, workdir: Path, xml: bytes, model_name: str, version: int, binaries: dict[Platform, Path],
              resources: dict, sources: Path) -> dict:
    """Zip the FMU in workdir, check it with fmpy's validator, then move it onto `out`.

    binaries: {platform: binary} of the platforms the FMU carries; resources: {name in resources/:
    bytes or a file}; sources: a folder whose files go into sources/. Returns {"size_bytes",
    "binaries": {platform name: {"path", "size_bytes"}}}; BuildError (one line) when the FMU does not
    validate or cannot be written."""
    staged = workdir / f"{model_name}.fmu"
    listing = {}
    with zipfile.ZipFile(staged, "w", zipfile.ZIP_DEFLATED) as fmu:
        fmu.writestr("modelDescription.xml", xml)
        for target, binary in binaries.items():
            path = target.binary_path(model_name, version)
            fmu.write(binary, path)
            listing[target.name] = {"path": path, "size_bytes": binary.stat().st_size}
        for name, content in resources.items():
            if isinstance(content, bytes):
                fmu.writestr(f"resources/{name}", content)
            else:
                fmu.write(content, f"resources/{name}")
        for path in sorted(sources.iterdir()):
            fmu.write(path, f"sources/{path.name}")
    problems = validation_problems(staged)
    if problems:
        raise BuildError(f"the FMU does not validate: {'; '.join(problems)[:500]}")
    try:
        with atomic_path(out) as target_path:
            shutil.copyfile(staged, target_path)
    except OSError as exc:
        raise BuildError(f"cannot write {out}: {exc.strerror or exc}") from None
    return {"size_bytes": Path(out).stat().st_size, "binaries": listing}
