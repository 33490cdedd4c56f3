"""One FMU instance under the grid master, over fmpy's FMU2Slave, with the few calls the master
makes every step kept cheap (ctypes arrays built once).

A Slave is opened on an FMU file with the names of the inputs it gets and the outputs it is read
for; it records what the FMU logs (status, message) and raises CouplingError (one line) when the FMU
lacks a variable its role needs or a call fails. Its capabilities come from the model description:
`interpolates` (canInterpolateInputs: fmi2SetRealInputDerivatives), `rolls_back`
(canGetAndSetFMUstate), `directional` (providesDirectionalDerivative).
"""
from __future__ import annotations

import ctypes
import shutil
import tempfile

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, fmi2FMUstate, fmi2Integer,
                       fmi2Real, fmi2ValueReference)

LOG_KEPT = 200  # log messages kept per instance
FD_STEP = 1e-6  # relative step of the finite-difference Jacobian for FMUs without directional derivatives


class CouplingError(RuntimeError):
    """An FMU that cannot play its role in the co-simulation, or an FMU call that failed; one line."""


def _array(kind, values):
    return (kind * len(values))(*values)


class Slave:
    """An initialised FMU2Slave of the FMU at `path` (instance `name`).

    inputs, outputs: the variable names set and read every step, in the master's order; start:
    values set in initialisation mode by name (parameters, initial states, the inputs' start values)."""

    def __init__(self, path, name: str, inputs, outputs, start: dict):
        self.name = name
        self.messages = []
        self._directory = tempfile.mkdtemp(prefix="opfmu_grid_")
        try:
            extract(str(path), unzipdir=self._directory)
            md = read_model_description(self._directory)
        except Exception as exc:
            shutil.rmtree(self._directory, ignore_errors=True)
            raise CouplingError(f"{name}: cannot read the FMU {path}: {str(exc)[:200]}") from None
        cs = md.coSimulation
        if cs is None:
            raise CouplingError(f"{name}: {path} is not a co-simulation FMU")
        self.model_name = md.modelName
        variables = {v.name: v for v in md.modelVariables}
        vr = {n: v.valueReference for n, v in variables.items()}
        missing = [n for n in (*inputs, *outputs, *start) if n not in vr]
        if missing:
            raise CouplingError(f"{name}: the FMU {md.modelName} has no variable {', '.join(missing)}")
        not_inputs = [n for n in inputs if variables[n].causality != "input"]
        if not_inputs:
            raise CouplingError(f"{name}: {', '.join(not_inputs)} of {md.modelName} are not inputs")
        self.vr = vr
        self.interpolates = bool(cs.canInterpolateInputs)
        self.rolls_back = bool(cs.canGetAndSetFMUstate)
        self.directional = bool(cs.providesDirectionalDerivative)
        self.input_names, self.output_names = tuple(inputs), tuple(outputs)
        self._in_vr = _array(fmi2ValueReference, [vr[n] for n in inputs])
        self._in = (fmi2Real * len(inputs))()
        self._order = _array(fmi2Integer, [1] * len(inputs))
        self._du = (fmi2Real * len(inputs))()
        self._out_vr = _array(fmi2ValueReference, [vr[n] for n in outputs])
        self._out = (fmi2Real * len(outputs))()
        self._seed = _array(fmi2Real, [1.0])
        self._dd = (fmi2Real * len(outputs))()
        self._known = [_array(fmi2ValueReference, [vr[n]]) for n in inputs]
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        try:
            self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=self._directory, modelIdentifier=cs.modelIdentifier,
                                 instanceName=name)
            self.fmu.instantiate(callbacks=self._callbacks, loggingOn=False)
        except Exception as exc:
            shutil.rmtree(self._directory, ignore_errors=True)
            raise CouplingError(f"{name}: cannot instantiate {md.modelName}: {str(exc)[:200]}") from None
        self._c = self.fmu.component
        self._initial = None
        try:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
            self.fmu.setReal([vr[n] for n in start], [float(v) for v in start.values()])
            self.fmu.exitInitializationMode()
        except Exception:
            self.close()
            raise CouplingError(f"{name}: {md.modelName} refused its start values: {self.last_message()}") from None
        if self.rolls_back:
            self._initial = self.save()

    def _log(self, env, instance, status, category, message):
        entry = (int(status), message.decode(errors="replace"))
        if entry not in self.messages[-4:]:  # a step redone from a saved state logs its message again
            self.messages.append(entry)
            del self.messages[:-LOG_KEPT]

    def last_message(self) -> str:
        return self.messages[-1][1] if self.messages else "(no message logged)"

    def _check(self, status: int, what: str) -> None:
        if status > 1:  # fmi2Discard, fmi2Error, fmi2Fatal
            raise CouplingError(f"{self.name} ({self.model_name}): {what} failed: {self.last_message()}")

    def set_inputs(self, values) -> None:
        """fmi2SetReal of the inputs (master's order)."""
        self._in[:] = values
        self._check(self.fmu.dll.fmi2SetReal(self._c, self._in_vr, len(self._in), self._in), "fmi2SetReal")

    def set_input_derivatives(self, rates) -> None:
        """fmi2SetRealInputDerivatives (first order) of the inputs: their rates over the next step."""
        self._du[:] = rates
        self._check(self.fmu.dll.fmi2SetRealInputDerivatives(self._c, self._in_vr, len(self._du), self._order,
                                                             self._du), "fmi2SetRealInputDerivatives")

    def outputs(self) -> list:
        """fmi2GetReal of the outputs (master's order)."""
        self._check(self.fmu.dll.fmi2GetReal(self._c, self._out_vr, len(self._out), self._out), "fmi2GetReal")
        return self._out[:]

    def output_jacobian(self, rows, columns) -> np.ndarray:
        """d outputs[rows] / d inputs[columns] at the present inputs (nested lists [rows][columns]): the
        FMU's directional derivatives, or central differences where it has none (the inputs are left
        as they were)."""
        if self.directional:
            J = [[0.0] * len(columns) for _ in rows]
            for j, c in enumerate(columns):
                self._check(self.fmu.dll.fmi2GetDirectionalDerivative(self._c, self._out_vr, len(self._out),
                                                                      self._known[c], 1, self._seed, self._dd),
                            "fmi2GetDirectionalDerivative")
                for i, r in enumerate(rows):
                    J[i][j] = self._dd[r]
            return J
        J = [[0.0] * len(columns) for _ in rows]
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

    def step(self, t: float, h: float) -> None:
        """fmi2DoStep(t, h)."""
        self._check(self.fmu.dll.fmi2DoStep(self._c, fmi2Real(t), fmi2Real(h), 1), f"fmi2DoStep at t = {t:.6g} s")

    def save(self):
        """The FMU state now (fmi2GetFMUstate), for restore()."""
        state = fmi2FMUstate()
        self._check(self.fmu.dll.fmi2GetFMUstate(self._c, ctypes.byref(state)), "fmi2GetFMUstate")
        return state

    def restore(self, state) -> None:
        """fmi2SetFMUstate to a state save() returned (it stays valid)."""
        self._check(self.fmu.dll.fmi2SetFMUstate(self._c, state), "fmi2SetFMUstate")

    def free(self, state) -> None:
        self.fmu.dll.fmi2FreeFMUstate(self._c, ctypes.byref(state))

    def rewind(self) -> None:
        """Back to the state right after initialisation (a new run of the same instance)."""
        if self._initial is None:
            raise CouplingError(f"{self.name} ({self.model_name}): cannot rewind an FMU without fmi2SetFMUstate")
        self.restore(self._initial)
        self.messages.clear()

    def close(self) -> None:
        """Frees the instance and its unpacked files (idempotent)."""
        if getattr(self, "fmu", None) is not None:
            try:
                if self._initial is not None:
                    self.free(self._initial)
                self.fmu.terminate()
            except Exception:
                pass
            try:
                self.fmu.freeInstance()
            except Exception:
                pass
            self.fmu = None
        shutil.rmtree(self._directory, ignore_errors=True)
