"""Build the reference SM4 FMU: scipy RK45 over each communication step, packaged with pythonfmu.

The FMU's resources hold the slave (fmu_slave.py) and a copy of the model equations (sm4.py) as the package `sm4_reference`, so it runs wherever it is copied to. Its
Python needs numpy and scipy (and finds pythonfmu's own runtime files in the resources too).

pythonfmu writes a modelDescription.xml without output dependencies; it is replaced by the one the
surrogate FMU also uses (model_description.py: same variables and value references, less `residual`
and `in_envelope`, plus the solver tolerances), keeping pythonfmu's GUID. The pythonfmu build runs in
a subprocess, so building never leaves modules of a temporary directory in the caller's import cache.
"""
from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

from fmu_export.model_description import Variable, model_description, sm4_variables
from reference_models.files import atomic_path

from . import sm4

SLAVE = Path(__file__).with_name("fmu_slave.py")
DESCRIPTION = "SM4 synchronous machine: reference RK45 integration of the two-axis model over each step"


class ReferenceBuildError(RuntimeError):
    """pythonfmu failed, or the FMU it built does not validate."""


def reference_variables() -> list[Variable]:
    """The reference FMU's variables, in the slave's registration (value reference) order."""
    extra = (Variable("rtol", 16, "parameter", "relative tolerance of RK45 over each step", start=1e-8),
             Variable("atol", 17, "parameter", "absolute tolerance of RK45 over each step", start=1e-10))
    return sm4_variables(sm4.steady_state(1.0, 0.0), None, surrogate=False, extra=extra)


def build_reference_fmu(out, model_name: str = "SM4Reference") -> dict:
    """Write the reference FMU to `out` (atomically); returns {"path", "size_bytes", "guid"}."""
    if not model_name.isidentifier():
        raise ValueError(f"model name must be a Python identifier (it names the slave class), got {model_name!r}")
    out = Path(out)
    with tempfile.TemporaryDirectory(prefix="opfmu_reference_") as tmp:
        tmp = Path(tmp)
        package = tmp / "sm4_reference"
        package.mkdir()
        (package / "__init__.py").write_text('"""SM4 reference model (copied in by opfmu)."""\n')
        shutil.copy2(sm4.__file__, package / "sm4.py")
        shutil.copy2(SLAVE, package / "slave.py")
        script = tmp / f"{model_name}.py"
        script.write_text(f'"""The {model_name} FMU\'s slave class (pythonfmu names the FMU after it)."""\n'
                          "from sm4_reference.slave import SM4ReferenceSlave\n\n"
                          "_PINNED = [globals()] * 4  # see _NAMESPACE_REFERENCES in sm4_reference/slave.py\n\n\n"
                          f"class {model_name}(SM4ReferenceSlave):\n    pass\n")
        built = tmp / "build"
        command = [sys.executable, "-m", "pythonfmu", "build", "-f", str(script), "-d", str(built),
                   "--no-external-tool", "--handle-state", "--serialize-state", str(package)]
        result = subprocess.run(command, capture_output=True, text=True, cwd=tmp)
        fmu = built / f"{model_name}.fmu"
        if result.returncode != 0 or not fmu.exists():
            raise ReferenceBuildError(f"pythonfmu build failed: {(result.stderr or result.stdout).strip()[-2000:]}")
        guid = _rewrite_model_description(fmu, model_name)
        problems = _validate(fmu)
        if problems:
            raise ReferenceBuildError("the reference FMU does not validate: " + "; ".join(problems))
        with atomic_path(out) as target:
            shutil.copy2(fmu, target)
    return {"path": str(out), "size_bytes": out.stat().st_size, "guid": guid}


def _rewrite_model_description(fmu: Path, model_name: str) -> str:
    """Replace pythonfmu's modelDescription.xml with ours (same GUID); returns the GUID."""
    with zipfile.ZipFile(fmu) as source:
        entries = {info.filename: source.read(info) for info in source.infolist()}
    guid = ET.fromstring(entries["modelDescription.xml"]).get("guid")
    entries["modelDescription.xml"] = model_description(model_name, guid, reference_variables(), DESCRIPTION)
    rewritten = fmu.with_suffix(".rewritten")
    with zipfile.ZipFile(rewritten, "w", zipfile.ZIP_DEFLATED) as target:
        for name, data in entries.items():
            target.writestr(name, data)
    rewritten.replace(fmu)
    return guid


def _validate(fmu: Path) -> list[str]:
    from fmpy.validation import validate_fmu

    return list(validate_fmu(str(fmu)))
