"""An fmpy FMU2Slave of a component's FMU, driven step by step, recording what the FMU logs; and the
step mirror (fmu_export.step_mirror) evaluated on a surrogate FMU's own compiled kernel.

Value references come from the FMU's model description, by name; the component says which
variables are its inputs and states (default SM4).
"""
import ctypes

import numpy as np
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

from reference_models.sm4 import SM4


class Slave:
    """An FMU instance (initialized unless init=False) that records log messages.

    start: values set in initialization mode, by variable name (parameters such as delta0 or
    rest_radius). vr: value reference by name; inputs/states: the component's names.
    """

    def __init__(self, unzipped, name="a", init=True, logging_on=False, component=SM4, **start):
        directory, md = unzipped
        self.md = md
        self.messages = []
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.starts = {v.name: float(v.start) for v in md.modelVariables if v.type == "Real" and v.start is not None}
        self.inputs, self.states = component.input_names, component.state_names
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=directory, modelIdentifier=md.coSimulation.modelIdentifier,
                             instanceName=name)
        self.fmu.instantiate(callbacks=self.callbacks, loggingOn=logging_on)
        self.t = 0.0
        if init:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
            self.set(**start)
            self.fmu.exitInitializationMode()

    def _log(self, env, instance, status, category, message):
        self.messages.append((status, message.decode()))

    def set(self, **values) -> None:
        """fmi2SetReal of the named variables."""
        if values:
            self.fmu.setReal([self.vr[n] for n in values], [float(v) for v in values.values()])

    def get(self, *names) -> np.ndarray:
        """fmi2GetReal of the named variables."""
        return np.array(self.fmu.getReal([self.vr[n] for n in names]))

    def get_boolean(self, name) -> bool:
        return bool(self.fmu.getBoolean([self.vr[name]])[0])

    def state(self) -> np.ndarray:
        """The states [n_x] now."""
        return self.get(*self.states)

    def step(self, h, *values, **named):
        """Sets the inputs, positional in the component's order or by name (an input not given is set
        to its start value), steps by h and returns the states [n_x] at the end of the step."""
        if len(values) > len(self.inputs):
            raise TypeError(f"at most {len(self.inputs)} input values ({', '.join(self.inputs)})")
        inputs = {n: self.starts[n] for n in self.inputs}
        inputs.update(zip(self.inputs, values))
        unknown = set(named) - set(self.inputs)
        if unknown:
            raise TypeError(f"not an input: {', '.join(sorted(unknown))}")
        inputs.update(named)
        self.set(**inputs)
        self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=h)
        self.t += h
        return self.state()

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def on_the_fmus_kernel(mirror, unzipped):
    """The StepMirror `mirror` of the FMU unzipped = (directory, model description), with its network evaluated by the FMU's own compiled kernel (opfmu_operator, in
    double) instead of onnxruntime (float32): what is left between it and the FMU is round-off."""
    library = ctypes.CDLL(f"{unzipped[0]}/binaries/linux64/{unzipped[1].coSimulation.modelIdentifier}.so")
    double_p = ctypes.POINTER(ctypes.c_double)
    library.opfmu_operator.argtypes = [double_p, double_p, ctypes.c_double, double_p]

    def network(x0_f, sensors_f, tau):
        x0, u, out = np.array(x0_f, np.float64), np.ascontiguousarray(sensors_f, np.float64), np.zeros(len(x0_f))
        library.opfmu_operator(x0.ctypes.data_as(double_p), u.ctypes.data_as(double_p), float(tau),
                               out.ctypes.data_as(double_p))
        return out

    mirror.network = network
    return mirror
