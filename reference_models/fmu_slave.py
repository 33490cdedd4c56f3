"""The reference SM4 FMU's model: a pythonfmu slave that integrates the ODE with scipy's RK45.

This file runs inside the FMU, not in the repository: the builder (reference_fmu.py) copies it
into the FMU's resources as `sm4_reference/slave.py`, next to a copy of sm4.py as
`sm4_reference/sm4.py`, so the FMU carries every line of model code it runs (it needs numpy and
scipy in the Python that loads it, and nothing from opfmu). pythonfmu passes log messages to the
importer only while logging is on (fmi2Instantiate's loggingOn, or fmi2SetDebugLogging): a refused
step then comes with its reason under logStatusError.

Step semantics (DESIGN section 5): the inputs set before do_step(t, h) hold over [t, t + h]; after
it the states are those at t + h. The derived outputs (currents, powers) are computed when read,
from the states and the inputs as they are then, which is the direct feedthrough the model
description declares. Value references are the registration order and must match
reference_fmu.reference_variables().
"""
import math
import sys

import numpy as np
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Initial, Fmi2Status
from scipy.integrate import solve_ivp

from .sm4 import INPUT_NAMES, OUTPUT_NAMES, STATE_NAMES, SM4Params, outputs, rhs, steady_state

SOLVER_PARAMETERS = (("rtol", 1e-8), ("atol", 1e-10))
# pythonfmu 0.7's binary, when it instantiates, looks the slave class up in the FMU's script module
# and then releases a reference to that module's namespace that it never took. Left alone, the
# namespace is freed after a few instantiations in one process and the next one fails ("module has
# no attribute ...") or crashes the importer. Every instance therefore keeps one reference here,
# which the next instantiation's release takes back; the script module pins a few more at import.
_NAMESPACE_REFERENCES = []


class SM4ReferenceSlave(Fmi2Slave):
    """SM4 on a bus of time-varying voltage, integrated by RK45 over each communication step."""

    author = "opfmu"
    description = "SM4 synchronous machine: reference RK45 integration of the two-axis model"
    log_categories = {"logStatusWarning": "warnings", "logStatusError": "errors: invalid calls and values",
                      "logAll": "everything"}

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        _NAMESPACE_REFERENCES.append(vars(sys.modules[type(self).__module__]))
        self.params = SM4Params()
        start = steady_state(1.0, 0.0, self.params)
        self.Vs, self.theta_vs = 1.0, 0.0
        for name, value in zip(STATE_NAMES, start):
            setattr(self, name, float(value))
            setattr(self, f"{name}0", float(value))
        self.rtol, self.atol = (value for _, value in SOLVER_PARAMETERS)
        for name in INPUT_NAMES:
            self.register_variable(Real(name, causality=Fmi2Causality.input, variability=Fmi2Variability.continuous))
        for name in STATE_NAMES:
            self.register_variable(Real(name, causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                                        initial=Fmi2Initial.calculated))
        for i, name in enumerate(OUTPUT_NAMES):
            self.register_variable(Real(name, causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                                        initial=Fmi2Initial.calculated, getter=self._derived_getter(i)))
        for name in [f"{n}0" for n in STATE_NAMES] + [n for n, _ in SOLVER_PARAMETERS]:
            self.register_variable(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))

    def _derived_getter(self, i: int):
        return lambda: float(self._derived()[i])

    def _derived(self) -> np.ndarray:
        """Id, Iq, I_re, I_im, P, Q [6] from the current states and inputs."""
        return outputs(self._state(), np.array([self.Vs, self.theta_vs]), self.params)

    def _state(self) -> np.ndarray:
        return np.array([getattr(self, n) for n in STATE_NAMES])

    def exit_initialization_mode(self):
        """The states start at the initial-state parameters."""
        for name in STATE_NAMES:
            setattr(self, name, float(getattr(self, f"{name}0")))

    def do_step(self, current_time: float, step_size: float) -> bool:
        problem = self._invalid_step(step_size)
        if problem:
            self.log(problem, Fmi2Status.error)
            return False
        u = np.array([self.Vs, self.theta_vs])
        solution = solve_ivp(lambda _t, x: rhs(x, u, self.params), (current_time, current_time + step_size),
                             self._state(), method="RK45", rtol=self.rtol, atol=self.atol)
        if not solution.success or not np.all(np.isfinite(solution.y[:, -1])):
            self.log(f"RK45 failed over [{current_time}, {current_time + step_size}]: {solution.message}",
                     Fmi2Status.error)
            return False
        for name, value in zip(STATE_NAMES, solution.y[:, -1]):
            setattr(self, name, float(value))
        return True

    def _invalid_step(self, step_size: float) -> str:
        """Why this step cannot be taken, or "" when it can."""
        if not (math.isfinite(step_size) and step_size > 0):
            return f"communication step size must be positive and finite, got {step_size}"
        values = {n: getattr(self, n) for n in INPUT_NAMES + tuple(f"{s}0" for s in STATE_NAMES)}
        bad = [f"{n} = {v}" for n, v in values.items() if not math.isfinite(v)]
        if bad:
            return f"non-finite value: {', '.join(bad)}"
        if not (self.rtol > 0 and self.atol > 0):
            return f"rtol and atol must be positive, got rtol = {self.rtol}, atol = {self.atol}"
        return ""
