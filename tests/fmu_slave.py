"""An fmpy FMU2Slave of an SM4 FMU, driven step by step, recording what the FMU logs."""
import numpy as np
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

STATES = [2, 3, 4, 5]  # value references of delta, omega, Ed_p, Eq_p in both SM4 FMUs


class Slave:
    """An initialized FMU instance that records log messages."""

    def __init__(self, unzipped, name="a", init=True, logging_on=False, **start):
        directory, md = unzipped
        self.messages = []
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=directory, modelIdentifier=md.coSimulation.modelIdentifier,
                             instanceName=name)
        self.fmu.instantiate(callbacks=self.callbacks, loggingOn=logging_on)
        self.t = 0.0
        if init:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
            for name_, value in start.items():
                self.fmu.setReal([self.vr[name_]], [value])
            self.fmu.exitInitializationMode()

    def _log(self, env, instance, status, category, message):
        self.messages.append((status, message.decode()))

    def step(self, h, Vs=1.0, theta=0.0):
        self.fmu.setReal([0, 1], [Vs, theta])
        self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=h)
        self.t += h
        return np.array(self.fmu.getReal(STATES))

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()
