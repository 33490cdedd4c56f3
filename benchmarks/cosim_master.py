"""A co-simulation master for a machine FMU (SM4: the surrogate or the native reference) with an
IEEE Type I exciter FMU (IEEE1) in the loop, over fmpy's FMU2Slave, and the monolithic solve of the
same pair it is checked against.

The coupling, every communication step [t_k, t_k + h] (Gauss-Seidel, the exciter first):

1. set the machine's bus inputs Vs, theta_vs, Pm to their values at t_k (held over the step);
2. read the machine's bus current I_re + j I_im (its outputs depend on Vs, theta_vs directly; the
   FMUs recompute them after fmi2SetReal) and compute the terminal voltage behind the machine's own
   external impedance, Vt = |Vs e^{j theta_vs} + (Re + j Xep) I| (= Vs for Re = Xep = 0);
3. set the exciter's Vt (Vref is a constant set point), step the exciter over [t_k, t_k + h];
4. set the machine's Efd input to the exciter's Efd output at t_k + h, step the machine.

So the exciter holds Vt(t_k) over the step and the machine holds Efd(t_k + h): a coupling error of
first order in h, the same for any machine FMU the master drives (`monolithic` solves the same
equations without it, under the same zero-order-held bus inputs).

Every FMU's parameters are read from the FMU itself (the native reference's resources/machine.json,
the surrogate's resources/model.onnx metadata), so the master knows the Re, Xep it needs for Vt and
refuses FMUs that are not what their role needs (a machine FMU without the inputs Vs, theta_vs, Pm,
Efd or the outputs I_re, I_im; an exciter FMU without Vt, Vref, Efd) and pairs of different machines
(`same_parameters`), with one-line `CouplingError`s.

Used by benchmarks/cosim_controls.py and tests/test_machine_with_exciter.py.
"""
from __future__ import annotations

import json
import math
import shutil
import tempfile
import time
import weakref
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from reference_models.component import Component, ParameterError
from reference_models.ieee1 import IEEE1, IEEE1Params
from reference_models.initialisation import exciter_start
from reference_models.sm4 import SM4, SM4Params

BUS_INPUTS = ("Vs", "theta_vs", "Pm")  # the machine's inputs the scenario gives; Efd comes from the exciter
# what each role needs of an FMU: (inputs, outputs, parameters)
NEEDS = {
    "sm4": (SM4.input_names, SM4.state_names + ("I_re", "I_im"), tuple(f"{s}0" for s in SM4.state_names)),
    "ieee1": (IEEE1.input_names, IEEE1.state_names, tuple(f"{s}0" for s in IEEE1.state_names)),
}
ROLE = {"sm4": "a machine (SM4)", "ieee1": "an exciter (IEEE1)"}


class CouplingError(ValueError):
    """FMUs the master cannot couple (not what their role needs, different machines, bad inputs) or a
    failed FMI call; a one-line message."""


def terminal_voltage(Vs: float, theta_vs: float, I_re: float, I_im: float, p: SM4Params) -> float:
    """|V + (Re + j Xep) I| [pu]: the voltage at the machine's terminals, behind its own external
    impedance from the bus V = Vs e^{j theta_vs}, with I the current it injects into the bus."""
    V = complex(Vs * math.cos(theta_vs), Vs * math.sin(theta_vs))
    return abs(V + complex(p.Re, p.Xep) * complex(I_re, I_im))


def fmu_parameters(directory, component: Component):
    """The parameters of `component` an extracted FMU was built with: resources/machine.json (the
    native and pythonfmu reference FMUs) or the operator's metadata (resources/model.onnx, surrogate
    FMUs). CouplingError where the FMU carries neither or they are not the component's."""
    directory = Path(directory)
    record, operator = directory / "resources" / "machine.json", directory / "resources" / "model.onnx"
    if record.is_file():
        try:
            return component.params(json.loads(record.read_text(encoding="utf-8")))
        except (OSError, ValueError, ParameterError) as exc:
            raise CouplingError(f"{directory.name}: resources/machine.json holds no {component.name} parameters "
                                f"({' '.join(str(exc).split())[:160]})") from None
    if operator.is_file() and component is SM4:
        from opfmu.compare import CompareError, operator_machine

        try:
            return operator_machine(operator)
        except CompareError as exc:
            raise CouplingError(str(exc)) from None
    raise CouplingError(f"{directory.name}: the FMU records no {component.name} parameters (no resources/machine.json "
                        "or resources/model.onnx); give them to the master")


class Unit:
    """One FMU in the loop: an fmpy FMU2Slave of an extracted FMU (or a .fmu file, extracted beside
    into a temporary directory removed with the unit) checked for its role (component SM4 or IEEE1), with its parameters (`params`, read from the
    FMU unless given), the time spent inside fmi2DoStep (`do_step_s`) and what it logged."""

    def __init__(self, path, component: Component, params=None, name: str | None = None):
        from fmpy import extract, read_model_description

        path = Path(path)
        try:
            if path.is_file():
                directory = Path(tempfile.mkdtemp(prefix="opfmu_unit_"))
                weakref.finalize(self, shutil.rmtree, directory, True)
                extract(str(path), unzipdir=str(directory))
            else:
                directory = path
            md = read_model_description(str(directory))
        except Exception as exc:  # fmpy raises plain Exceptions for unreadable files
            raise CouplingError(f"{path.name} is not a readable FMU: {' '.join(str(exc).split())[:160]}") from None
        self.path, self.directory, self.md, self.component = path, directory, md, component
        self.name = name or md.modelName
        variables = {v.name: v for v in md.modelVariables}
        inputs, outputs, parameters = NEEDS[component.name]
        lacks = [f"input {n}" for n in inputs if getattr(variables.get(n), "causality", None) != "input"]
        lacks += [f"output {n}" for n in outputs if getattr(variables.get(n), "causality", None) != "output"]
        lacks += [f"parameter {n}" for n in parameters if getattr(variables.get(n), "causality", None) != "parameter"]
        if lacks:
            has = [v.name for v in md.modelVariables if v.causality == "input"]
            raise CouplingError(f"{md.modelName} ({path.name}) is not {ROLE[component.name]} FMU: it lacks the "
                                f"{', '.join(lacks[:6])}{', ...' if len(lacks) > 6 else ''} (its inputs: "
                                f"{', '.join(has) or 'none'})")
        if md.coSimulation is None:
            raise CouplingError(f"{md.modelName} ({path.name}) has no co-simulation interface")
        self.params = params if params is not None else fmu_parameters(directory, component)
        if not isinstance(self.params, component.params_type):
            raise CouplingError(f"{md.modelName}: {component.name} parameters needed, got {type(self.params).__name__}")
        self.vr = {n: v.valueReference for n, v in variables.items()}
        self.boolean = {n for n, v in variables.items() if v.type == "Boolean"}
        self.fmu, self.do_step_s, self.messages, self.t = None, 0.0, [], 0.0

    def start(self, parameters: dict, inputs: dict, instance: str = "a") -> Unit:
        """Instantiate and initialise: `parameters` (start values, e.g. delta0) and `inputs` set in
        initialization mode (the surrogate takes the inputs there as the first window's frame)."""
        from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

        self.callbacks = fmi2CallbackFunctions()  # kept: ctypes must not free the logger
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=str(self.directory),
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=instance)
        self.do_step_s, self.messages, self.t = 0.0, [], 0.0
        try:
            self.fmu.instantiate(callbacks=self.callbacks, loggingOn=False)
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
            self.set(**parameters, **inputs)
            self.fmu.exitInitializationMode()
        except Exception as exc:
            self.close()
            raise CouplingError(f"{self.name} did not initialise: {self._said(exc)}") from None
        return self

    def _log(self, _env, _instance, status, category, message):
        self.messages.append(f"{category.decode(errors='replace')}: {message.decode(errors='replace')}")

    def _said(self, exc) -> str:
        return f"{exc}" + (f" ({self.messages[-1]})" if self.messages else "")

    def set(self, **values) -> None:
        if values:
            self.fmu.setReal([self.vr[n] for n in values], [float(v) for v in values.values()])

    def get(self, *names) -> list:
        return self.fmu.getReal([self.vr[n] for n in names])

    def flag(self, name: str) -> bool:
        return bool(self.fmu.getBoolean([self.vr[name]])[0])

    def step(self, h: float) -> None:
        begin = time.perf_counter()
        try:
            self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=h)
        except Exception as exc:  # fmpy's FMICallException
            raise CouplingError(f"{self.name} failed at t = {self.t:.4f} s: {self._said(exc)}") from None
        finally:
            self.do_step_s += time.perf_counter() - begin
        self.t += h

    def close(self) -> None:
        if self.fmu is not None:
            try:
                self.fmu.terminate()
            except Exception:
                pass
            self.fmu.freeInstance()
            self.fmu.freeLibrary()
            self.fmu = None


def same_parameters(a: Unit, b: Unit) -> None:
    """CouplingError unless the two FMUs were built for the same parameters (two machine FMUs of
    different machines are no comparison)."""
    if a.params != b.params:
        pa, pb = a.params.to_dict(), b.params.to_dict()
        differ = [f"{k} {pa[k]!r} / {pb[k]!r}" for k in pa if pa[k] != pb[k]]
        raise CouplingError(f"{a.name} and {b.name} model different {a.component.name} parameters: "
                            f"{', '.join(differ[:5])}")


@dataclass(frozen=True)
class Start:
    """The pair at rest: the machine's state x0 [4] under the bus inputs u0 = (Vs, theta_vs, Pm) and
    field voltage Efd, the exciter's state xe0 [3] holding that Efd at terminal voltage Vt, and its Vref."""

    x0: np.ndarray
    u0: np.ndarray
    Efd: float
    Vt: float
    xe0: np.ndarray
    Vref: float


def start_at_rest(x0, u0, Efd: float, machine: SM4Params, exciter: IEEE1Params) -> Start:
    """The exciter started where it holds Efd at the terminal voltage of machine state x0 under bus
    inputs u0 = (Vs, theta_vs, Pm) (reference_models.initialisation.exciter_start)."""
    x0, u0 = np.asarray(x0, dtype=float), np.asarray(u0, dtype=float)[:3]
    y = SM4.output_values(x0, np.array([*u0, Efd]), machine)
    names = SM4.output_names
    Vt = terminal_voltage(u0[0], u0[1], y[names.index("I_re")], y[names.index("I_im")], machine)
    field = exciter_start(Efd, Vt, exciter)
    return Start(x0, u0, float(Efd), Vt, np.array(field.x0), field.Vref)


@dataclass
class Run:
    """A coupled run: at the communication points times [T], the machine's states [T, 4], the
    exciter's states [T, 3] (Efd, RF, VR) and the terminal voltage Vt [T] it saw (the last one at
    the final state); seconds inside each FMU's fmi2DoStep and of the whole run (wall_s:
    instantiation to freeing, the master's Python included); the surrogate's in_envelope (all
    points; None for an FMU without it) and largest residual; what the FMUs logged."""

    times: np.ndarray
    machine: np.ndarray
    exciter: np.ndarray
    Vt: np.ndarray
    do_step_s: dict
    wall_s: float
    in_envelope: bool | None = None
    max_residual: float | None = None
    messages: dict = field(default_factory=dict)


def check_inputs(times, bus) -> tuple[np.ndarray, np.ndarray]:
    times, bus = np.asarray(times, dtype=float), np.asarray(bus, dtype=float)
    if times.ndim != 1 or len(times) < 2 or times[0] != 0 or not np.all(np.diff(times) > 0):
        raise CouplingError("the communication points must start at 0 and increase (at least two)")
    if bus.shape != (len(times), 3) or not np.all(np.isfinite(bus)):
        raise CouplingError(f"the bus inputs must be finite (Vs, theta_vs, Pm) at every communication point, "
                            f"[{len(times)}, 3]; got {list(bus.shape)}")
    return times, bus


def couple(machine: Unit, exciter: Unit, times, bus, start: Start, machine_parameters: dict | None = None) -> Run:
    """Run the machine FMU with the exciter FMU in the loop (the module docstring's scheme) over the
    communication points `times` [T], the bus inputs bus [T, 3] = (Vs, theta_vs, Pm) at each held
    over the step after it, from `start`. machine_parameters: further start values of the machine
    FMU (e.g. a surrogate's rollover_horizon). The FMUs are instantiated here and freed at the end."""
    times, bus = check_inputs(times, bus)
    if machine.component is not SM4 or exciter.component is not IEEE1:
        raise CouplingError("couple takes a machine (SM4) unit and an exciter (IEEE1) unit, in that order")
    p = machine.params
    n = len(times)
    states, field_states, Vt = np.empty((n, 4)), np.empty((n, 3)), np.empty(n)
    has_envelope = "in_envelope" in machine.vr and "residual" in machine.vr
    envelope, residual = True, 0.0
    began = time.perf_counter()
    machine.start({f"{s}0": v for s, v in zip(SM4.state_names, start.x0)} | dict(machine_parameters or {}),
                  dict(zip(BUS_INPUTS, bus[0])) | {"Efd": start.Efd}, instance="machine")
    try:
        exciter.start({f"{s}0": v for s, v in zip(IEEE1.state_names, start.xe0)}, {"Vt": start.Vt, "Vref": start.Vref},
                      instance="exciter")
        try:
            states[0], field_states[0] = machine.get(*SM4.state_names), exciter.get(*IEEE1.state_names)
            for k in range(n - 1):
                h = times[k + 1] - times[k]
                Vs, theta_vs, Pm = bus[k]
                machine.set(Vs=Vs, theta_vs=theta_vs, Pm=Pm)
                I_re, I_im = machine.get("I_re", "I_im")
                Vt[k] = terminal_voltage(Vs, theta_vs, I_re, I_im, p)
                exciter.set(Vt=Vt[k])
                exciter.step(h)
                field_states[k + 1] = exciter.get(*IEEE1.state_names)
                machine.set(Efd=field_states[k + 1, 0])
                machine.step(h)
                states[k + 1] = machine.get(*SM4.state_names)
                if has_envelope:
                    envelope = envelope and machine.flag("in_envelope")
                    residual = max(residual, machine.get("residual")[0])
            I_re, I_im = machine.get("I_re", "I_im")  # at the last point, under the last bus inputs held
            Vt[-1] = terminal_voltage(*bus[-1, :2], I_re, I_im, p)
        finally:
            exciter.close()
    finally:
        machine.close()
    return Run(times, states, field_states, Vt, {"machine": machine.do_step_s, "exciter": exciter.do_step_s},
               time.perf_counter() - began, envelope if has_envelope else None, residual if has_envelope else None,
               {"machine": machine.messages, "exciter": exciter.messages})


def pair_rhs(machine: SM4Params, exciter: IEEE1Params, Vref: float):
    """The right-hand side f(y, (Vs, theta_vs, Pm)) of the pair without a master, y = (x [4], xe [3]):
    Efd is the exciter's state, Vt the machine's terminal voltage at every instant (scalars, math)."""
    names = SM4.output_names
    i_re, i_im = names.index("I_re"), names.index("I_im")

    def f(y, bus):
        Vs, theta_vs, Pm = bus
        x, xe = y[:4], y[4:]
        u = (Vs, theta_vs, Pm, xe[0])
        out = SM4.output_equations(x, u, machine, math)
        Vt = terminal_voltage(Vs, theta_vs, out[i_re], out[i_im], machine)
        return [*SM4.derivatives(x, u, machine, math), *IEEE1.derivatives(xe, (Vt, Vref), exciter, math)]

    return f


def monolithic(times, bus, start: Start, machine: SM4Params, exciter: IEEE1Params, rtol: float = 1e-10,
               atol: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """(machine states [T, 4], exciter states [T, 3]) of the pair solved as one ODE (scipy DOP853)
    under the same zero-order-held bus inputs: bus[k] over [times[k], times[k + 1]], each stretch of
    equal inputs in one solve."""
    from scipy.integrate import solve_ivp

    times, bus = check_inputs(times, bus)
    f = pair_rhs(machine, exciter, start.Vref)
    y = np.concatenate([start.x0, start.xe0])
    out = np.empty((len(times), 7))
    out[0] = y
    k = 0
    while k < len(times) - 1:
        end = k + 1
        while end < len(times) - 1 and np.array_equal(bus[end], bus[k]):
            end += 1  # bus[k] holds over [times[k], times[end]]
        held = tuple(bus[k])
        sol = solve_ivp(lambda _t, s, held=held: f(s, held), (times[k], times[end]), y, method="DOP853", rtol=rtol, atol=atol,
                        t_eval=times[k + 1:end + 1])
        if not sol.success:
            raise CouplingError(f"the monolithic solve failed at t = {times[k]:.4f} s: {sol.message}")
        out[k + 1:end + 1] = sol.y.T
        y = sol.y[:, -1]
        k = end
    return out[:, :4], out[:, 4:]
