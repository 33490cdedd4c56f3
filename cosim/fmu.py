"""One FMU instance over fmpy, FMI 2.0 (FMU2Slave) or 3.0 (FMU3Slave) co-simulation, with its ports.

`FMU(source, name, ...)` opens an FMU: `source` is an .fmu file (extracted, but for its sources and
documentation, into a temporary folder that is removed on close, on a failed open and when the
object is collected or the interpreter exits), an extracted folder, or a pair (extracted folder,
fmpy model description). It is instantiated, and (unless `init=False`) initialised with the start
values given by variable name. The model description of an FMU another tool generated is checked
against the FMI schema (fmpy's validation, 1 ms an FMU); one opfmu generated is not (its builders'
tests check it).

Two ways to drive it:
* by name, for scripts and tests: `set(**values)`, `get(*names)`, `get_boolean(name)`,
  `step(h, *inputs, **named)` (inputs positional in `inputs` order, the others at their start
  values; returns the states), `state()`;
* bound, for a master's every-step calls (ctypes arrays built once): `bind(inputs, outputs)`, then
  `set_inputs(values)`, `set_input_derivatives(rates)`, `outputs()`, `output_jacobian(rows,
  columns)`, `do_step(t, h)`, `save()` / `restore(state)` / `free(state)`, `rewind()`; and the
  calls a master makes most in one: `advance(t, h, values, rates)` (inputs, their rates, the step,
  the outputs), `evaluate()` (the inputs as `inputs_now` holds them set, the outputs read into
  `outputs_now`), `step_inputs(t, h)` (advance with the inputs and rates as their buffers hold
  them), `share(...)` (the buffers moved into a master's numpy arrays), `checkpoint()` /
  `rollback()` (one kept state, its memory reused). For FMI 2.0 these call the
  binary's functions through plain C function pointers with their arguments built at bind (fmpy's
  prototypes convert every argument on every call: about half of a call's cost).

Its capabilities come from the model description: `interpolates` (FMI 2.0 canInterpolateInputs:
fmi2SetRealInputDerivatives; FMI 3.0 co-simulation has no input derivatives, so never),
`input_order` (the highest order of input derivatives it takes: 2 where an opfmu FMU's own
sources say so, OPFMU_INPUT_ORDER in its config.h, as FMI 2.0 declares no such capability; 1 for
another that interpolates; 0 for none),
`rolls_back` (can get and set its FMU state), `directional` (provides directional derivatives).
Its `ports` (reference_models.ports.Ports) are the <Ports> element of the model description;
for an FMU opfmu built without one, those of the component its model description names; None
otherwise. A failed call raises CouplingError (one line, with the FMU's last logged message; where
fmpy could not load or instantiate the FMU, its exception is the CouplingError's __context__);
what the FMU logs is kept in `messages` as (status, text), and passed to `on_message(status,
category, text)` where one is given (compare keeps each message with its category).
"""
from __future__ import annotations

import ctypes
import shutil
import tempfile
import weakref
import xml.etree.ElementTree as ET
from pathlib import Path

from reference_models.interrupts import called_from_c
from reference_models.messages import one_line

LOG_KEPT = 10_000  # log messages kept per instance (the latest)
FD_STEP = 1e-6  # relative step of the finite-difference Jacobian for FMUs without directional derivatives


class CouplingError(RuntimeError):
    """An FMU that cannot play its role in the co-simulation, or an FMU call that failed; one line."""


def _array(kind, values):
    return (kind * len(values))(*values)


def _needed(member: str) -> bool:
    """What an instance needs of an FMU archive: all but its sources and documentation (the binaries,
    the model description, the resources), its sources' config.h aside (`input_order`)."""
    return member == "sources/config.h" or not member.startswith(("sources/", "documentation/"))


def _true(value) -> bool:
    return str(value).lower() in ("true", "1")


def ports_of_fmu(root: ET.Element):
    """The Ports of a parsed model description: its <Ports> element, else (an FMU opfmu generated)
    those of the registered component whose description begins its description, else None.
    CouplingError for a malformed <Ports> element."""
    from reference_models.ports import PortError, ports_of_model_description

    try:
        ports = ports_of_model_description(root)
    except PortError as exc:
        raise CouplingError(f"the model {root.get('modelName')!r} declares malformed ports: {exc}") from None
    if ports is not None:
        return ports
    if not str(root.get("generationTool") or "").startswith("opfmu"):
        return None
    component = component_described(root.get("description"))
    return None if component is None else component.ports


def component_described(description):
    """The registered component whose description begins the model description's `description`
    (the longest that does: the builders write the component's description first), or None."""
    from reference_models.components import COMPONENTS

    text = str(description or "")
    found = [c for c in COMPONENTS.values() if c.description and text.startswith(c.description)]
    return max(found, key=lambda c: len(c.description)) if found else None


def extracted(path, directory=None, name: str = "a") -> tuple:
    """(folder, fmpy model description) of the FMU file `path` extracted into `directory` (the
    files an instance needs), or of `path` itself where it is an extracted FMU's folder; an FMU
    opfmu did not generate is checked against the FMI schema. CouplingError for an unreadable one.
    Several FMU instances may share one extraction (FMU's source as the tuple)."""
    from fmpy import extract, read_model_description

    path = Path(path)
    try:
        if path.is_dir():
            directory = path
        else:
            extract(str(path), unzipdir=str(directory), include=_needed)
        md = read_model_description(str(directory), validate=False)
        if not str(md.generationTool or "").startswith("opfmu"):
            md = read_model_description(str(directory))  # checked against the FMI schema
    except Exception as exc:  # fmpy raises plain Exceptions for unreadable files
        said = one_line(exc)
        if directory is not None:  # where it was extracted to: gone with it
            said = said.replace(str(directory), path.name)
        raise CouplingError(f"{name}: {path.name} is not a readable FMU ({said})") from None
    return Path(directory), md


class FMU:
    """An FMU instance (see the module docstring). name: the instance name (also in messages);
    logging_on: the FMU's debug logging; component: a reference_models Component whose input and
    state names `inputs` and `states` take (default: the model description's inputs in order, and
    the outputs that have an initial-state parameter `<name>0`); start and further keywords: start
    values set in initialisation mode by variable name; on_message: called with (status, category,
    text) for every message the FMU logs."""

    def __init__(self, source, name: str = "a", init: bool = True, logging_on: bool = False, component=None,
                 start: dict | None = None, scratch=None, on_message=None, **values):
        self.name = name
        self.messages = []
        self._on_message = on_message
        self.fmu = None
        self._log_key = None
        self._initial = None
        self._checkpoint = self._checkpoint_ref = None
        self._fast = None
        self._directory = None
        if isinstance(source, tuple):
            directory, md = source
            directory = Path(directory)
        else:
            path = Path(source)
            if not path.is_dir():
                directory = Path(tempfile.mkdtemp(prefix="opfmu_fmu_", dir=scratch))
                self._directory = directory
                self._cleanup = weakref.finalize(self, shutil.rmtree, str(directory), True)
            try:
                directory, md = extracted(path, directory if not path.is_dir() else None, name)
            except CouplingError:
                self.close()
                raise
        self.directory, self.md = directory, md
        try:
            self._open(md, component, init, logging_on, {**(start or {}), **values})
        except BaseException:
            self.close()
            raise

    def _open(self, md, component, init, logging_on, start) -> None:
        cs = md.coSimulation
        if cs is None:
            raise CouplingError(f"{self.name}: the model {md.modelName} has no co-simulation interface")
        try:
            root = ET.parse(self.directory / "modelDescription.xml").getroot()
        except (OSError, ET.ParseError) as exc:
            raise CouplingError(f"{self.name}: cannot read the model description ({one_line(exc)})") from None
        self.version = 3 if str(md.fmiVersion).startswith("3") else 2
        self.model_name = md.modelName
        self.ports = ports_of_fmu(root)
        cs_element = root.find("CoSimulation")
        attrs = cs_element.attrib if cs_element is not None else {}
        if self.version == 2:
            self.interpolates = _true(attrs.get("canInterpolateInputs"))
            self.rolls_back = _true(attrs.get("canGetAndSetFMUstate"))
            self.directional = _true(attrs.get("providesDirectionalDerivative"))
        else:
            self.interpolates = False
            self.rolls_back = _true(attrs.get("canGetAndSetFMUState"))
            self.directional = _true(attrs.get("providesDirectionalDerivatives"))
        self.input_order = _input_order(self.directory) if self.interpolates else 0
        self.variables = {v.name: v for v in md.modelVariables}
        self.vr = {n: v.valueReference for n, v in self.variables.items()}
        self.starts = {v.name: float(v.start) for v in md.modelVariables
                       if v.type in ("Real", "Float64") and v.start is not None}
        if component is not None:
            self.inputs, self.states = tuple(component.input_names), tuple(component.state_names)
        else:
            self.inputs = tuple(v.name for v in md.modelVariables if v.causality == "input")
            self.states = tuple(v.name for v in md.modelVariables
                                if v.causality == "output" and getattr(self.variables.get(f"{v.name}0"), "causality", None) == "parameter")
        self.t = 0.0
        if self.version == 2:
            from fmpy.fmi2 import FMU2Slave

            from cosim import fmi2_logging

            self._callbacks, self._log_key = fmi2_logging.callbacks(self._log)
            try:
                self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=str(self.directory),
                                     modelIdentifier=cs.modelIdentifier, instanceName=self.name)
                self.fmu.instantiate(callbacks=self._callbacks, loggingOn=logging_on)
            except Exception as exc:
                self.fmu = None
                raise CouplingError(f"{self.name}: cannot instantiate {md.modelName}: {self._said(exc)}") from None
        else:
            from fmpy.fmi3 import FMU3Slave

            try:
                self.fmu = FMU3Slave(guid=md.guid, unzipDirectory=str(self.directory),
                                     modelIdentifier=cs.modelIdentifier, instanceName=self.name)
                self.fmu.instantiate(loggingOn=logging_on, logMessage=self._log3)
            except Exception as exc:
                self.fmu = None
                raise CouplingError(f"{self.name}: cannot instantiate {md.modelName}: {self._said(exc)}") from None
        self._c = self.fmu.component
        self._dll = self.fmu.dll
        if self.version == 2:
            from fmpy.fmi2 import fmi2Real as Real
        else:
            from fmpy.fmi3 import fmi3Boolean, fmi3Float64 as Real

            self._flags = [fmi3Boolean() for _ in range(3)]
            self._last = Real()
            self._flag_refs = [ctypes.byref(f) for f in self._flags] + [ctypes.byref(self._last)]
        self._Real = Real
        if init:
            self.initialise(start)

    def initialise(self, start: dict | None = None, keep: bool = False) -> None:
        """Initialisation (start time 0) with the start values `start` set by variable name; `keep`:
        the state after it is kept for rewind() (where the FMU can restore states)."""
        start = dict(start or {})
        unknown = [n for n in start if n not in self.vr]
        if unknown:
            raise CouplingError(f"{self.name}: the model {self.model_name} has no variable {', '.join(unknown[:6])}")
        try:
            if self.version == 2:
                self.fmu.setupExperiment(startTime=0.0)
                self.fmu.enterInitializationMode()
            else:
                self.fmu.enterInitializationMode(startTime=0.0)
            self.set(**start)
            self.fmu.exitInitializationMode()
        except Exception:
            raise CouplingError(f"{self.name}: {self.model_name} refused its start values: {self.last_message()}") from None
        if keep and self.rolls_back:
            self._initial = self.save()

    def parameter_values(self, params) -> dict:
        """{name: value} of a component's parameter object `params` (reference_models Parameters)
        for each that this FMU declares as a parameter of that name (as start values are matched by
        name): what a master sets at initialisation so that one FMU of a model serves each device
        with its own parameters."""
        return {name: float(value) for name, value in params.to_dict().items()
                if getattr(self.variables.get(name), "causality", None) == "parameter"}

    # what the FMU logs

    def _log(self, status, category, message) -> None:
        """The fmi2_logging sink: keeps (status, text)."""
        text = message.decode(errors="replace") if message else ""
        self.messages.append((int(status), text))
        if len(self.messages) > LOG_KEPT:
            del self.messages[:-LOG_KEPT]
        if self._on_message is not None:
            self._on_message(int(status), category.decode(errors="replace") if category else "", text)

    @called_from_c
    def _log3(self, env, status, category, message) -> None:
        """fmi3LogMessageCallback (no instance argument): as _log."""
        self._log(status, category, message)

    def last_message(self) -> str:
        return self.messages[-1][1] if self.messages else "(no message logged)"

    def _said(self, exc) -> str:
        return one_line(exc) + (f" ({self.messages[-1][1]})" if self.messages else "")

    def _check(self, status: int, what: str) -> None:
        if status > 1:  # Discard, Error, Fatal
            raise CouplingError(f"{self.name} ({self.model_name}): {what} failed: {self.last_message()}")

    # by name

    def set(self, **values) -> None:
        """Sets the named Real (Float64) variables."""
        if not values:
            return
        vrs, numbers = [self.vr[n] for n in values], [float(v) for v in values.values()]
        if self.version == 2:
            self.fmu.setReal(vrs, numbers)
        else:
            self.fmu.setFloat64(vrs, numbers)

    def get(self, *names):
        """The named Real (Float64) variables now, as a numpy array."""
        import numpy as np

        vrs = [self.vr[n] for n in names]
        return np.array(self.fmu.getReal(vrs) if self.version == 2 else self.fmu.getFloat64(vrs))

    def get_boolean(self, name: str) -> bool:
        return bool(self.fmu.getBoolean([self.vr[name]])[0])

    def state(self):
        """The states [n_x] now."""
        return self.get(*self.states)

    def step(self, h: float, *values, **named):
        """Sets the inputs, positional in `inputs` order or by name (an input not given: its start
        value), steps by h from the FMU's own clock `t` and returns the states at the end."""
        if len(values) > len(self.inputs):
            raise TypeError(f"at most {len(self.inputs)} input values ({', '.join(self.inputs)})")
        unknown = set(named) - set(self.inputs)
        if unknown:
            raise TypeError(f"not an input: {', '.join(sorted(unknown))}")
        inputs = {n: self.starts[n] for n in self.inputs if n in self.starts}
        inputs.update(zip(self.inputs, values))
        inputs.update(named)
        self.set(**inputs)
        if self.version == 2:
            self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=h)
        else:
            self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=h,
                            noSetFMUStatePriorToCurrentPoint=False)
        self.t += h
        return self.state()

    # bound, for a master

    def bind(self, inputs, outputs) -> None:
        """Fixes the inputs set and the outputs read every step (names, in the master's order).
        CouplingError for a name the model lacks or an input that is not an input."""
        missing = [n for n in (*inputs, *outputs) if n not in self.vr]
        if missing:
            raise CouplingError(f"{self.name}: the model {self.model_name} has no variable {', '.join(missing)}")
        not_inputs = [n for n in inputs if self.variables[n].causality != "input"]
        if not_inputs:
            raise CouplingError(f"{self.name}: {', '.join(not_inputs)} of {self.model_name} are not inputs")
        if self.version == 2:
            from fmpy.fmi2 import fmi2Integer as Int, fmi2Real as Real, fmi2ValueReference as VR
        else:
            from fmpy.fmi3 import fmi3Float64 as Real, fmi3Int32 as Int, fmi3ValueReference as VR
        self.input_names, self.output_names = tuple(inputs), tuple(outputs)
        self._in_vr = _array(VR, [self.vr[n] for n in inputs])
        self._in = (Real * len(inputs))()
        self._order = _array(Int, [1] * len(inputs))
        self._order2 = _array(Int, [2] * len(inputs))
        self._du = (Real * len(inputs))()
        self._d2u = (Real * len(inputs))()
        self._out_vr = _array(VR, [self.vr[n] for n in outputs])
        self._out = (Real * len(outputs))()
        self._seed = _array(Real, [1.0])
        self._dd = (Real * len(outputs))()
        self._known = [_array(VR, [self.vr[n]]) for n in inputs]
        self._fast = _Calls(self) if self.version == 2 else None

    def set_inputs(self, values) -> None:
        """Sets the bound inputs (bind order)."""
        self._in[:] = values
        fast = self._fast
        if fast is not None:
            if fast.set_real(*fast.set_args) > 1:
                self._check(2, "fmi2SetReal")
            return
        n = len(self._in)
        if self.version == 2:
            self._check(self._dll.fmi2SetReal(self._c, self._in_vr, n, self._in), "fmi2SetReal")
        else:
            self._check(self._dll.fmi3SetFloat64(self._c, self._in_vr, n, self._in, n), "fmi3SetFloat64")

    def set_input_derivatives(self, rates, curvatures=None) -> None:
        """fmi2SetRealInputDerivatives of the bound inputs: their rates over the next step (first
        order; only where `interpolates`) and, where given and input_order is 2, their second
        derivatives (order 2)."""
        self._du[:] = rates
        if curvatures is not None:
            self._d2u[:] = curvatures
        self._set_derivatives(curvatures is not None)

    def _set_derivatives(self, second: bool) -> None:
        """The rates' buffer set as first derivatives and, where `second` and input_order is 2, the
        curvatures' buffer as second derivatives."""
        second = second and self.input_order > 1
        fast = self._fast
        if fast is not None:
            if fast.set_derivatives(*fast.derivative_args) > 1 or (
                    second and fast.set_derivatives(*fast.curvature_args) > 1):
                self._check(2, "fmi2SetRealInputDerivatives")
            return
        n = len(self._du)
        self._check(self._dll.fmi2SetRealInputDerivatives(self._c, self._in_vr, n, self._order, self._du),
                    "fmi2SetRealInputDerivatives")
        if second:
            self._check(self._dll.fmi2SetRealInputDerivatives(self._c, self._in_vr, n, self._order2, self._d2u),
                        "fmi2SetRealInputDerivatives")

    def outputs(self) -> list:
        """The bound outputs now (bind order)."""
        fast = self._fast
        if fast is not None:
            if fast.get_real(*fast.get_args) > 1:
                self._check(2, "fmi2GetReal")
            return self._out[:]
        n = len(self._out)
        if self.version == 2:
            self._check(self._dll.fmi2GetReal(self._c, self._out_vr, n, self._out), "fmi2GetReal")
        else:
            self._check(self._dll.fmi3GetFloat64(self._c, self._out_vr, n, self._out, n), "fmi3GetFloat64")
        return self._out[:]

    def evaluate(self) -> None:
        """The bound inputs as they stand in `inputs_now` set, and the bound outputs read into
        `outputs_now`: a master's Newton iteration, which changes a few entries of `inputs_now`
        between calls."""
        fast = self._fast
        if fast is None:
            self.set_inputs(self._in[:])
            self.outputs()
            return
        if fast.set_real(*fast.set_args) > 1:
            self._check(2, "fmi2SetReal")
        if fast.get_real(*fast.get_args) > 1:
            self._check(2, "fmi2GetReal")

    @property
    def inputs_now(self):
        """The bound inputs' buffer (a ctypes array, bind order): what set_inputs last set, or what
        evaluate() and step_inputs() set next."""
        return self._in

    @property
    def outputs_now(self):
        """The bound outputs' buffer (a ctypes array, bind order): what the last call read."""
        return self._out

    def share(self, inputs, rates, outputs, derivatives, curvatures=None) -> None:
        """The buffers of the bound inputs, their rates, the bound outputs, the directional
        derivatives and (where given) the inputs' second derivatives moved into `inputs`, `rates`,
        `outputs`, `derivatives`, `curvatures` (float64 numpy arrays of the bound lengths, e.g. views
        into a master's arrays of all its FMUs, which then sets and reads them in one numpy
        operation each), their present values kept."""
        shared = (("_in", inputs), ("_du", rates), ("_out", outputs), ("_dd", derivatives), ("_d2u", curvatures))
        for name, memory in ((n, m) for n, m in shared if m is not None):
            buffer = getattr(self, name)
            if memory.shape != (len(buffer),) or memory.dtype.itemsize != ctypes.sizeof(self._Real):
                raise ValueError(f"{self.name}: {name[1:]} needs {len(buffer)} float64 values, got {memory.shape}")
            memory[:] = buffer[:]
            setattr(self, name, (self._Real * len(buffer)).from_buffer(memory))
        self._fast = _Calls(self) if self.version == 2 else None

    def step_inputs(self, t: float, h: float, rates: bool | None = None, curvatures: bool = False) -> None:
        """A step from t [s] by h [s] with the bound inputs as `inputs_now` holds them and, where
        `rates` (default: where the FMU interpolates), their rates as the rates' buffer holds them
        (fmi2SetRealInputDerivatives; see share), and where `curvatures` and input_order is 2 their
        second derivatives as the curvatures' buffer holds them; the bound outputs read into
        `outputs_now`."""
        if rates is None:
            rates = self.interpolates
        fast = self._fast
        if fast is None:
            self.set_inputs(self._in[:])
            if rates:
                self._set_derivatives(curvatures)
            self.do_step(t, h)
            self.outputs()
            return
        if fast.set_real(*fast.set_args) > 1:
            self._check(2, "fmi2SetReal")
        if rates:
            self._set_derivatives(curvatures)
        fast.t.value, fast.h.value = t, h
        if fast.do_step(*fast.step_args) > 1:
            self._check(2, f"the step at t = {t:.6g} s")
        if fast.get_real(*fast.get_args) > 1:
            self._check(2, "fmi2GetReal")

    def advance(self, t: float, h: float, values, rates=None) -> list:
        """set_inputs(values), set_input_derivatives(rates) unless None, do_step(t, h), and the bound
        outputs at the step's end (outputs()), in one call."""
        self._in[:] = values
        if rates is not None:
            self._du[:] = rates
        self.step_inputs(t, h, rates is not None)
        return self._out[:]

    def output_jacobian(self, rows, columns) -> list:
        """d outputs[rows] / d inputs[columns] at the present inputs (nested lists [rows][columns],
        bind positions): the FMU's directional derivatives, or central differences where it has
        none (the inputs are left as they were)."""
        J = [[0.0] * len(columns) for _ in rows]
        n = len(self._out)
        fast = self._fast
        if self.directional and fast is not None:
            dd, out, args = self._dd, fast.derivative, fast.jacobian_args
            for j, c in enumerate(columns):
                if out(*args[c]) > 1:
                    self._check(2, "the directional derivative")
                for i, r in enumerate(rows):
                    J[i][j] = dd[r]
            return J
        if self.directional:
            for j, c in enumerate(columns):
                if self.version == 2:
                    status = self._dll.fmi2GetDirectionalDerivative(self._c, self._out_vr, n, self._known[c], 1,
                                                                    self._seed, self._dd)
                else:
                    status = self._dll.fmi3GetDirectionalDerivative(self._c, self._out_vr, n, self._known[c], 1,
                                                                    self._seed, 1, self._dd, n)
                self._check(status, "the directional derivative")
                for i, r in enumerate(rows):
                    J[i][j] = self._dd[r]
            return J
        base = self._in[:]
        for j, c in enumerate(columns):
            d = FD_STEP * max(1.0, abs(base[c]))
            values = list(base)
            values[c] = base[c] + d
            self.set_inputs(values)
            hi = self.outputs()
            values[c] = base[c] - d
            self.set_inputs(values)
            lo = self.outputs()
            for i, r in enumerate(rows):
                J[i][j] = (hi[r] - lo[r]) / (2.0 * d)
        self.set_inputs(base)
        return J

    def block(self, rows, columns) -> tuple:
        """output_jacobian(rows, columns) of two rows and two columns, flat row by row: (d r0 / d c0,
        d r0 / d c1, d r1 / d c0, d r1 / d c1)."""
        fast = self._fast
        if not (self.directional and fast is not None):
            (a, b), (c, d) = self.output_jacobian(rows, columns)
            return a, b, c, d
        dd, out, args = self._dd, fast.derivative, fast.jacobian_args
        r0, r1 = rows
        c0, c1 = columns
        if out(*args[c0]) > 1:
            self._check(2, "the directional derivative")
        a, c = dd[r0], dd[r1]
        if out(*args[c1]) > 1:
            self._check(2, "the directional derivative")
        return a, dd[r0], c, dd[r1]

    def do_step(self, t: float, h: float) -> None:
        """One communication step from t [s] by h [s] (the inputs as they were set)."""
        fast = self._fast if self.version == 2 else None
        if fast is not None:
            fast.t.value, fast.h.value = t, h
            if fast.do_step(*fast.step_args) > 1:
                self._check(2, f"the step at t = {t:.6g} s")
            return
        if self.version == 2:
            status = self._dll.fmi2DoStep(self._c, self._Real(t), self._Real(h), 1)
        else:
            status = self._dll.fmi3DoStep(self._c, self._Real(t), self._Real(h), False, *self._flag_refs)
        self._check(status, f"the step at t = {t:.6g} s")

    def save(self):
        """The FMU state now, for restore()."""
        if self.version == 2:
            from fmpy.fmi2 import fmi2FMUstate as State
        else:
            from fmpy.fmi3 import fmi3FMUState as State
        state = State()
        fn = self._dll.fmi2GetFMUstate if self.version == 2 else self._dll.fmi3GetFMUState
        self._check(fn(self._c, ctypes.byref(state)), "getting the FMU state")
        return state

    def restore(self, state) -> None:
        """Sets the FMU state save() returned (it stays valid)."""
        fn = self._dll.fmi2SetFMUstate if self.version == 2 else self._dll.fmi3SetFMUState
        self._check(fn(self._c, state), "setting the FMU state")

    def free(self, state) -> None:
        fn = self._dll.fmi2FreeFMUstate if self.version == 2 else self._dll.fmi3FreeFMUState
        fn(self._c, ctypes.byref(state))

    def checkpoint(self) -> None:
        """The FMU state now kept in the instance's one checkpoint (for rollback()); the checkpoint's
        memory is the FMU's, reused from one checkpoint to the next (fmi2GetFMUstate into a state it
        handed out before) and freed on close."""
        if self._checkpoint is None:
            self._checkpoint = self.save()
            self._checkpoint_ref = ctypes.byref(self._checkpoint)
            return
        fast = self._fast if self.version == 2 else None
        if fast is not None:
            status = fast.get_state(fast.component, self._checkpoint_ref)
        else:
            fn = self._dll.fmi2GetFMUstate if self.version == 2 else self._dll.fmi3GetFMUState
            status = fn(self._c, self._checkpoint_ref)
        if status > 1:
            self._check(status, "getting the FMU state")

    def rollback(self) -> None:
        """Back to the state checkpoint() kept (it stays kept)."""
        if self._checkpoint is None:
            raise CouplingError(f"{self.name} ({self.model_name}): no checkpoint to roll back to")
        fast = self._fast if self.version == 2 else None
        if fast is not None:
            if fast.set_state(fast.component, self._checkpoint) > 1:
                self._check(2, "setting the FMU state")
            return
        self.restore(self._checkpoint)

    def rewind(self) -> None:
        """Back to the state right after initialisation (a new run of the same instance)."""
        if self._initial is None:
            raise CouplingError(f"{self.name} ({self.model_name}): cannot rewind an FMU that cannot set its state")
        self.restore(self._initial)
        self.messages.clear()
        self.t = 0.0

    def close(self) -> None:
        """Frees the instance and the folder it was extracted into (idempotent)."""
        if self.fmu is not None:
            try:
                if self._initial is not None:
                    self.free(self._initial)
                    self._initial = None
                if self._checkpoint is not None:
                    self.free(self._checkpoint)
                    self._checkpoint = None
                self.fmu.terminate()
            except Exception:
                pass
            try:
                self.fmu.freeInstance()
            except Exception:
                pass
            self.fmu = None
        if self._log_key is not None:
            from cosim import fmi2_logging

            fmi2_logging.release(self._log_key)
            self._log_key = None
        if self._directory is not None:
            self._cleanup()
            self._directory = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class _Calls:
    """An FMI 2.0 instance's every-step functions as plain C function pointers (no argtypes: their
    arguments are built once, as ctypes objects, at bind; fmpy's prototypes convert every argument
    on every call) and their argument tuples."""

    def __init__(self, fmu: FMU):
        def plain(name):
            return ctypes.CFUNCTYPE(ctypes.c_int)(ctypes.cast(getattr(fmu._dll, name), ctypes.c_void_p).value)

        self.component = c = ctypes.c_void_p(fmu._c)
        n_in, n_out = ctypes.c_size_t(len(fmu._in)), ctypes.c_size_t(len(fmu._out))
        self.set_real, self.get_real = plain("fmi2SetReal"), plain("fmi2GetReal")
        self.set_args = (c, fmu._in_vr, n_in, fmu._in)
        self.get_args = (c, fmu._out_vr, n_out, fmu._out)
        self.do_step = plain("fmi2DoStep")
        self.t, self.h = ctypes.c_double(), ctypes.c_double()
        self.step_args = (c, self.t, self.h, ctypes.c_int(1))
        self.set_derivatives = plain("fmi2SetRealInputDerivatives")
        self.derivative_args = (c, fmu._in_vr, n_in, fmu._order, fmu._du)
        self.curvature_args = (c, fmu._in_vr, n_in, fmu._order2, fmu._d2u)
        self.derivative = plain("fmi2GetDirectionalDerivative")
        one = ctypes.c_size_t(1)
        self.jacobian_args = [(c, fmu._out_vr, n_out, known, one, fmu._seed, fmu._dd) for known in fmu._known]
        self.get_state = plain("fmi2GetFMUstate") if fmu.rolls_back else None
        self.set_state = plain("fmi2SetFMUstate") if fmu.rolls_back else None


def _input_order(directory) -> int:
    """The highest order of input derivatives an FMU that interpolates its inputs takes: 2 where its
    own sources' config.h defines OPFMU_INPUT_ORDER 2 (an opfmu native reference FMU), else 1."""
    try:
        text = (Path(directory) / "sources" / "config.h").read_text(errors="replace")
    except OSError:
        return 1
    return 2 if "#define OPFMU_INPUT_ORDER 2" in text else 1
