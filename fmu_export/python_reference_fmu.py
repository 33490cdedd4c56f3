"""Build the pythonfmu reference FMU of a component for any machine: scipy RK45 over each step.

The FMU's resources hold the package `<component>_reference_<digest of its code>` (`sm4_reference_...`
for SM4), so the FMU runs wherever it is copied to:

* `slave.py`: the slave class (python_reference_slave.py);
* copies of the component definition modules it runs: the module that defines the component
  (reference_models/sm4.py) and every sibling module it imports relatively (component.py, ...), so
  `from .component import ...` works inside the FMU;
* `machine.json`: the machine's parameters (every one, name: number), read and validated through
  the component when the FMU is instantiated;
* `fmu.json`: where the component is (module, attribute) and the FMU's variables in value reference
  order, from fmu_variables(component, params, x_start, REFERENCE_EXTRAS, starts): the slave
  registers them in that order, so its value references are the model description's.

Its Python needs numpy, scipy and pythonfmu (pythonfmu's own runtime files are in the resources too).
The default initial state is the machine's equilibrium at the inputs' start values.

pythonfmu writes a modelDescription.xml without output dependencies; it is replaced by ours
(model_description.py, from the same variable table as the surrogate FMU's, with the solver
tolerances instead of the surrogate's diagnostics), keeping pythonfmu's GUID. The pythonfmu build
runs in a subprocess, so building never leaves modules of a temporary directory in the caller's
import cache.
"""
from __future__ import annotations

import ast
import hashlib
import json
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Mapping
from pathlib import Path

from reference_models.component import Component, Parameters, ParameterError
from reference_models.files import atomic_path
from reference_models.sm4 import SM4
from reference_models.version import __version__

from .model_description import model_description, validation_problems
from .pythonfmu_exit import ExitPatchError, without_exit_release
from .variables import REFERENCE_EXTRAS, REFERENCE_STARTS, Variable, fmu_variables, start_state

SLAVE = Path(__file__).with_name("python_reference_slave.py")
SOLVER_STARTS = REFERENCE_STARTS  # defaults of the parameters rtol, atol (variables.py says why)
MACHINE_FILE, LAYOUT_FILE = "machine.json", "fmu.json"  # names the slave reads (python_reference_slave.py)
REPOSITORY_PACKAGES = ("reference_models", "surrogate", "fmu_export", "opfmu")


class ReferenceBuildError(RuntimeError):
    """pythonfmu failed, the machine has no starting equilibrium, or the FMU built does not validate."""


def machine_params(component: Component = SM4, params=None) -> Parameters:
    """The component's parameters from None (its defaults), a mapping of some of them (the rest
    default) or a parameter object of the component; ParameterError when they are refused."""
    if params is None or isinstance(params, Mapping):
        return component.params(params)
    if isinstance(params, component.params_type):
        return params
    raise ParameterError(f"{component.name} parameters must be a mapping or {component.params_type.__name__}, "
                         f"got {type(params).__name__}")


def reference_variables(component: Component = SM4, params=None) -> list[Variable]:
    """The reference FMU's variables for that machine, in value reference (slave registration) order;
    the initial-state parameters default to the equilibrium at the inputs' start values."""
    params = machine_params(component, params)
    return fmu_variables(component, params, _start_state(component, params), REFERENCE_EXTRAS, SOLVER_STARTS)


def build_reference_fmu(out, model_name: str = "SM4Reference", component: Component = SM4, params=None) -> dict:
    """Write the reference FMU of `component` with parameters `params` (None: its defaults; a mapping
    of some of them; or a parameter object) to `out`, atomically.

    Returns {"path", "size_bytes", "guid", "params"} (params: every parameter of the machine built in).
    Raises ValueError for a model name that is not a Python identifier, ParameterError (a ValueError)
    for refused parameters, ReferenceBuildError when the machine has no equilibrium at the start
    inputs, pythonfmu fails or the FMU does not validate.
    """
    if not model_name.isidentifier():
        raise ValueError(f"model name must be a Python identifier (it names the slave class), got {model_name!r}")
    component.require_known_rates("reference FMU")
    params = machine_params(component, params)
    variables = reference_variables(component, params)
    module, attribute = _definition(component)
    sources = _module_closure(Path(module.__file__)) + [SLAVE]
    package_name = _package_name(component, sources)
    out = Path(out)
    with tempfile.TemporaryDirectory(prefix="opfmu_reference_") as tmp:
        tmp = Path(tmp)
        package = tmp / package_name
        package.mkdir()
        (package / "__init__.py").write_text(f'"""{component.name} reference model (copied in by opfmu)."""\n')
        for source in sources:
            shutil.copy2(source, package / ("slave.py" if source == SLAVE else source.name))
        (package / MACHINE_FILE).write_text(json.dumps(params.to_dict(), indent=2) + "\n")
        layout = {"component": {"name": component.name, "module": Path(module.__file__).stem, "attribute": attribute},
                  "opfmu_version": __version__,
                  "variables": [{"name": v.name, "vr": v.vr, "causality": v.causality, "kind": v.kind,
                                 "start": v.start} for v in variables]}
        (package / LAYOUT_FILE).write_text(json.dumps(layout, indent=1) + "\n")
        script = tmp / f"{model_name}.py"
        script.write_text(f'"""The {model_name} FMU\'s slave class (pythonfmu names the FMU after it)."""\n'
                          f"from {package_name}.slave import ReferenceSlave\n\n"
                          f"_PINNED = [globals()] * 4  # see _NAMESPACE_REFERENCES in {package_name}/slave.py\n\n\n"
                          f"class {model_name}(ReferenceSlave):\n"
                          f"    description = {_description(component)!r}\n")
        built = tmp / "build"
        command = [sys.executable, "-m", "pythonfmu", "build", "-f", str(script), "-d", str(built),
                   "--no-external-tool", "--handle-state", "--serialize-state", str(package)]
        result = subprocess.run(command, capture_output=True, text=True, cwd=tmp)
        fmu = built / f"{model_name}.fmu"
        if result.returncode != 0 or not fmu.exists():
            raise ReferenceBuildError(f"pythonfmu build failed: {(result.stderr or result.stdout).strip()[-2000:]}")
        guid = _rewrite_model_description(fmu, model_name, variables, _description(component))
        problems = validation_problems(fmu)
        if problems:
            raise ReferenceBuildError("the reference FMU does not validate: " + "; ".join(problems))
        with atomic_path(out) as target:
            shutil.copy2(fmu, target)
    return {"path": str(out), "size_bytes": out.stat().st_size, "guid": guid, "params": params.to_dict()}


def _package_name(component: Component, sources: list[Path]) -> str:
    """`<component>_reference_<digest>`: the digest of the code it carries. Python caches modules by
    name, so FMUs loaded into one process share a package of one name: FMUs whose code differs (built
    by different opfmu versions) get different names and each runs its own."""
    digest = hashlib.sha256()
    for source in sources:
        digest.update(source.name.encode() + b"\0" + source.read_bytes())
    name = f"{component.name}_reference_{digest.hexdigest()[:10]}"
    if not name.isidentifier():
        raise ReferenceBuildError(f"component name {component.name!r} does not make a Python package name")
    return name


def check_packable(component: Component) -> None:
    """ReferenceBuildError (one line) where the pythonfmu FMU cannot carry the module that defines
    `component` (a module-level object whose module imports only its siblings), before any build."""
    module, _ = _definition(component)
    try:
        _module_closure(Path(module.__file__))
    except ReferenceBuildError as exc:
        raise ReferenceBuildError(f"a pythonfmu reference FMU cannot carry {component.name}: {exc} "
                                  "(use the native reference FMU: --fmus reference)") from None


def _description(component: Component) -> str:
    return f"{component.description}: reference RK45 integration over each communication step"


def _start_state(component: Component, params):
    """The equilibrium at the inputs' start values [n_x]; ReferenceBuildError where there is none."""
    try:
        return start_state(component, params)
    except ValueError as exc:
        raise ReferenceBuildError(str(exc)) from None


def _definition(component: Component):
    """(module, attribute name) of the module-level object `component`."""
    module = sys.modules.get(getattr(component.derivatives, "__module__", ""))
    for name, value in vars(module or object()).items():
        if value is component:
            return module, name
    raise ReferenceBuildError(f"component {component.name!r} is not a module-level object of the module "
                              "defining its equations, so the FMU cannot carry it")


def _module_closure(path: Path) -> list[Path]:
    """`path` and every sibling module it imports relatively (`from .x import`), transitively.
    ReferenceBuildError for an import the FMU cannot satisfy: a subpackage or a repository package."""
    todo, seen = [path], {}
    while todo:
        current = todo.pop()
        if current.name in seen:
            continue
        seen[current.name] = current
        for node in ast.walk(ast.parse(current.read_text(encoding="utf-8"), str(current))):
            if isinstance(node, ast.ImportFrom) and node.level:
                if node.level != 1:
                    raise ReferenceBuildError(f"{current.name} imports from outside its package (level {node.level})")
                names = [node.module] if node.module else [a.name for a in node.names]
                for name in names:
                    sibling = current.with_name(f"{name}.py")
                    if "." in name or not sibling.exists():
                        raise ReferenceBuildError(f"{current.name} imports .{name}, which is not a sibling module")
                    todo.append(sibling)
            elif isinstance(node, (ast.Import, ast.ImportFrom)):
                tops = [a.name.split(".")[0] for a in node.names] if isinstance(node, ast.Import) \
                    else [(node.module or "").split(".")[0]]
                inside = [t for t in tops if t in REPOSITORY_PACKAGES]
                if inside:
                    raise ReferenceBuildError(f"{current.name} imports {inside[0]}, which the FMU does not carry")
    return sorted(seen.values())


def _rewrite_model_description(fmu: Path, model_name: str, variables: list[Variable], description: str) -> str:
    """Replace pythonfmu's modelDescription.xml with ours (same GUID) and its linux64 binary with one
    without the exit-time double release (pythonfmu_exit); returns the GUID."""
    with zipfile.ZipFile(fmu) as source:
        entries = {info.filename: source.read(info) for info in source.infolist()}
    guid = ET.fromstring(entries["modelDescription.xml"]).get("guid")
    entries["modelDescription.xml"] = model_description(model_name, guid, variables, description)
    for name in entries:
        if name.startswith("binaries/linux64/") and name.endswith(".so"):
            try:
                entries[name] = without_exit_release(entries[name])
            except ExitPatchError as exc:
                raise ReferenceBuildError(str(exc)) from None
    rewritten = fmu.with_suffix(".rewritten")
    with zipfile.ZipFile(rewritten, "w", zipfile.ZIP_DEFLATED) as target:
        for name, data in entries.items():
            target.writestr(name, data)
    rewritten.replace(fmu)
    return guid
