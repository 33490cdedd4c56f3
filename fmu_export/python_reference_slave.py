"""The reference FMU's model: a pythonfmu slave that integrates a component's ODE with scipy's RK45.

This file runs inside the FMU, not in the repository (it is never imported here: its relative
imports resolve only in the FMU). The builder (python_reference_fmu.py) copies it into the FMU's resources
as `<package>/slave.py`, next to copies of the component definition modules (component.py, sm4.py,
...) and two JSON resources, so the FMU carries every line of model code it runs (it needs numpy,
scipy and pythonfmu in the Python that loads it, and nothing from opfmu):

* `machine.json`: the machine's parameters, name: number (a machine file; validated through the
  component at instantiation);
* `fmu.json`: which module and attribute hold the component, and the FMU's variables in value
  reference order, as fmu_export.variables.fmu_variables wrote them for the model description.

Both are read from the instance's own resources directory (pythonfmu's `resources`), not from this
file's directory: FMUs of different machines loaded into one process share these modules (Python
caches them by name; the package name carries a digest of the code, so only FMUs with the same code
share) but each instance reads its own machine. A missing or corrupt resource is
logged under logStatusError and refuses exitInitializationMode and every step; it never crashes.

pythonfmu passes log messages to the importer only while logging is on (fmi2Instantiate's loggingOn,
or fmi2SetDebugLogging): a refused step then comes with its reason under logStatusError.

Step semantics (docs/design.md, "The FMUs (FMI 2.0 and 3.0 co-simulation)"): the inputs set before
do_step(t, h) hold over [t, t + h]; the step starts from the states after the component's limit
resets at those inputs (Component.reset_states: a state at or beyond a non-windup limit while its
rate pushes outward is placed on the limit); after it the states are those at t + h. The derived outputs are
computed when read, from the states and the inputs as they are then, which is the direct feedthrough
the model description declares. The default initial state is the machine's equilibrium at the
inputs' start values.
"""
import importlib
import json
import math
import sys
from pathlib import Path

import numpy as np
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Initial, Fmi2Status
from scipy.integrate import solve_ivp

MACHINE_FILE = "machine.json"
LAYOUT_FILE = "fmu.json"
SOLVER_PARAMETERS = ("rtol", "atol")  # the variables this slave adds (REFERENCE_EXTRAS)
MAX_RESOURCE_BYTES = 1 << 20
# pythonfmu 0.7's binary, when it instantiates, looks the slave class up in the FMU's script module
# and then releases a reference to that module's namespace that it never took. Left alone, the
# namespace is freed after a few instantiations in one process and the next one fails ("module has
# no attribute ...") or crashes the importer. Every instance therefore keeps one reference here,
# which the next instantiation's release takes back; the script module pins a few more at import.
_NAMESPACE_REFERENCES = []


class ResourceError(Exception):
    """A resource of the FMU that is missing, unreadable or not what the slave needs."""


class ReferenceSlave(Fmi2Slave):
    """A component on its inputs, integrated by RK45 over each communication step."""

    author = "opfmu"
    description = "reference RK45 integration of a component over each communication step"
    log_categories = {"logStatusWarning": "warnings", "logStatusError": "errors: invalid calls and values",
                      "logAll": "everything"}

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        _NAMESPACE_REFERENCES.append(vars(sys.modules[type(self).__module__]))
        self._values = {}  # every variable that holds a value (not the derived outputs), by name
        self._problem = ""  # why this instance cannot run ("" when it can)
        self.component, self.params = None, None
        try:
            directory = self._resource_directory()
            layout = _read_json(directory / LAYOUT_FILE)
            if not isinstance(layout, dict):
                raise ResourceError(f"{LAYOUT_FILE} is not a JSON object")
            self.component = self._component(layout)
            variables = layout.get("variables")
            if not isinstance(variables, list):
                raise ResourceError(f"{LAYOUT_FILE} lacks its list of variables")
        except ResourceError as exc:
            self._refuse(f"cannot start the reference FMU: {exc}")
            return
        try:
            self.params = self.component.load_params(directory / MACHINE_FILE)
            start = self.component.steady_state(None, self.params)
        except ValueError as exc:  # ParameterError is a ValueError; so is "no equilibrium"
            self._refuse(f"cannot start the reference FMU: {' '.join(str(exc).split())[:500]}")
            start = np.full(self.component.n_states, math.nan)
        self._x_start = {name: float(v) for name, v in zip(self.component.state_names, start)}
        try:
            for entry in variables:
                self._register(entry)
            c = self.component
            needed = [*c.input_names, *c.state_names, *c.output_names, *(f"{s}0" for s in c.state_names),
                      *SOLVER_PARAMETERS]
            missing = [n for n in needed if n not in {v.name for v in self.vars.values()}]
            if missing:
                raise ResourceError(f"no variable {', '.join(missing)}")
        except ResourceError as exc:
            self._refuse(f"cannot start the reference FMU: {LAYOUT_FILE}: {exc}")

    # --- resources -----------------------------------------------------------------------------

    def _resource_directory(self) -> Path:
        """This FMU's copy of the package directory (resources/<package>)."""
        if not self.resources:
            raise ResourceError("the importer gave no resources location")
        return Path(self.resources) / __package__

    def _component(self, layout: dict):
        """The component object named by the layout, from this package's copy of its module."""
        where = layout.get("component")
        if not (isinstance(where, dict) and isinstance(where.get("module"), str)
                and isinstance(where.get("attribute"), str)):
            raise ResourceError(f"{LAYOUT_FILE} does not name the component's module and attribute")
        try:
            module = importlib.import_module(f".{where['module']}", __package__)
        except ImportError as exc:
            raise ResourceError(f"cannot import the component module {where['module']!r}: {exc}") from None
        component = getattr(module, where["attribute"], None)
        if component is None or not hasattr(component, "load_params"):
            raise ResourceError(f"module {where['module']!r} has no component {where['attribute']!r}")
        return component

    def _register(self, entry) -> None:
        """Registers one variable of the table; its value reference is the registration order."""
        if not (isinstance(entry, dict) and isinstance(entry.get("name"), str) and isinstance(entry.get("vr"), int)):
            raise ResourceError(f"malformed variable entry {str(entry)[:80]}")
        name, vr, causality = entry["name"], entry["vr"], entry.get("causality")
        if entry.get("kind", "Real") != "Real":
            raise ResourceError(f"variable {name} is {entry.get('kind')}; this slave has Reals only")
        if vr != len(self.vars):
            raise ResourceError(f"variable {name} has value reference {vr}, registered as {len(self.vars)}")
        c = self.component
        start = entry.get("start")
        if (causality == "input" or name in SOLVER_PARAMETERS) and not isinstance(start, (int, float)):
            raise ResourceError(f"variable {name} has no start value")
        if causality == "input" and name in c.input_names:
            self._values[name] = float(start)
            self.register_variable(Real(name, causality=Fmi2Causality.input, variability=Fmi2Variability.continuous,
                                        getter=self._getter(name), setter=self._setter(name)))
        elif causality == "output" and name in c.state_names:
            self._values[name] = self._x_start[name]
            self.register_variable(Real(name, causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                                        initial=Fmi2Initial.calculated, getter=self._getter(name)))
        elif causality == "output" and name in c.output_names:
            self.register_variable(Real(name, causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                                        initial=Fmi2Initial.calculated,
                                        getter=self._derived_getter(c.output_names.index(name))))
        elif causality == "parameter" and (name[:-1] in c.state_names and name.endswith("0")
                                           or name in SOLVER_PARAMETERS):
            self._values[name] = self._x_start[name[:-1]] if name not in SOLVER_PARAMETERS else float(start)
            self.register_variable(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                                        getter=self._getter(name), setter=self._setter(name)))
        else:
            raise ResourceError(f"variable {name} ({causality}) is not one this slave provides")

    def _refuse(self, problem: str) -> None:
        """Records why this instance cannot run (the first reason) and logs it."""
        self._problem = self._problem or problem
        self.log(problem, Fmi2Status.error)

    # --- values --------------------------------------------------------------------------------

    def _getter(self, name: str):
        return lambda: self._values[name]

    def _setter(self, name: str):
        def set_value(value):
            self._values[name] = float(value)
        return set_value

    def _derived_getter(self, i: int):
        return lambda: float(self._derived()[i])

    def _inputs(self) -> np.ndarray:
        return np.array([self._values[n] for n in self.component.input_names])

    def _state(self) -> np.ndarray:
        return np.array([self._values[n] for n in self.component.state_names])

    def _derived(self) -> np.ndarray:
        """The component's derived outputs [n_y] from the current states and inputs (NaN without a machine)."""
        if self.params is None:
            return np.full(len(self.component.outputs), math.nan)
        return self.component.output_values(self._state(), self._inputs(), self.params)

    def _get_fmu_state(self):
        return dict(self._values)

    def _set_fmu_state(self, state):
        if not isinstance(state, dict) or set(state) != set(self._values):
            self.log("the FMU state to restore is not one of this FMU's", Fmi2Status.error)
            raise ValueError("the FMU state to restore is not one of this FMU's")
        self._values.update({name: float(value) for name, value in state.items()})

    # --- FMI calls -----------------------------------------------------------------------------

    def exit_initialization_mode(self):
        """The states start at the initial-state parameters. An instance that cannot run logs why
        (pythonfmu turns an exception here into fmi2Fatal, so it returns; every step is refused)."""
        if self._problem:
            self.log(self._problem, Fmi2Status.error)
            return
        for name in self.component.state_names:
            self._values[name] = self._values[f"{name}0"]

    def do_step(self, current_time: float, step_size: float) -> bool:
        problem = self._problem or self._invalid_step(step_size)
        if problem:
            self.log(problem, Fmi2Status.error)
            return False
        u = self._inputs()
        start = self.component.reset_states(self._state(), u, self.params)  # states placed on their limits
        solution = solve_ivp(lambda _t, x: self.component.rhs(x, u, self.params),
                             (current_time, current_time + step_size), start, method="RK45",
                             rtol=self._values["rtol"], atol=self._values["atol"])
        if not solution.success or not np.all(np.isfinite(solution.y[:, -1])):
            self.log(f"RK45 failed over [{current_time}, {current_time + step_size}]: {solution.message}",
                     Fmi2Status.error)
            return False
        for name, value in zip(self.component.state_names, solution.y[:, -1]):
            self._values[name] = float(value)
        return True

    def _invalid_step(self, step_size: float) -> str:
        """Why this step cannot be taken, or "" when it can."""
        if not (math.isfinite(step_size) and step_size > 0):
            return f"communication step size must be positive and finite, got {step_size}"
        checked = list(self.component.input_names) + [f"{s}0" for s in self.component.state_names]
        bad = [f"{n} = {self._values[n]}" for n in checked if not math.isfinite(self._values[n])]
        if bad:
            return f"non-finite value: {', '.join(bad)}"
        rtol, atol = self._values["rtol"], self._values["atol"]
        if not (rtol > 0 and atol > 0):
            return f"rtol and atol must be positive, got rtol = {rtol}, atol = {atol}"
        return ""


def _read_json(path: Path):
    """The JSON document in `path`; ResourceError naming the file when it is missing or corrupt."""
    try:
        if path.stat().st_size > MAX_RESOURCE_BYTES:
            raise ResourceError(f"{path.name} is larger than {MAX_RESOURCE_BYTES} bytes")
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise ResourceError(f"cannot read {path.name}: {' '.join(str(exc).split())[:200]}") from None
