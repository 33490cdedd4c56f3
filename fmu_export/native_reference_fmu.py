"""Builds the native reference FMU of a component for any machine: its ODE in C, integrated over each
communication step by Dormand-Prince 5(4).

From the component and its parameters, generated at build time: config.h (sizes, defaults, the
solver's default tolerances, GUID), variables.h (the value references of the model description,
fmu_export.variables: the same table as the surrogate's, less its own variables, plus rtol and atol),
equations.c (the component's right-hand side and derived outputs, fmu_export.c_equations: the same
C the surrogate FMU runs; with its switching functions and, where the component declares one, its
reset: model_reset) and derivatives.c (their exact partial derivatives, fmu_export.c_derivatives).
With the static sources in c/ (cosimulation.c: the FMI plumbing both versions share, with fmi2_cs.c
or fmi3_cs.c: the FMI 2.0 or 3.0 API over it; variables.c: the component's variables; reference_model.c and reference_state.h: the step and
the state; dopri5.c: the integrator, which locates the instants the right-hand side's conditions change:
docs/fmu.md, "limit crossings") they compile into one binary per platform (binaries.py: gcc for
linux64, MinGW-w64 for win64, ...), which needs the C runtime only.
The C sources go into sources/ and the machine's parameters into resources/machine.json (a record of
the defaults built in).

Parameters (fmu_export.c_parameters): the component's parameters are fixed FMU parameters, start the
values built for, which the equations read from the instance, so one FMU serves every device of its
model: an importer sets them before initialisation (fmi2SetReal / fmi3SetFloat64 in instantiated or
initialisation mode), and the parameters derived from them follow. A value outside the range the
component checks, or one that would change the form of the equations (a structural parameter: a time
constant of 0 making a lag algebraic, saturation data that Python turns into coefficients), is
refused with fmi2Error and a logged reason; relations between parameters (VMIN < VMAX) are checked
when initialisation ends. The GUID (and the grid's cache key) depends on the component and its
structure only (`structure_of`), not on the values of the other parameters nor on the defaults of
the inputs and the initial state.

What the FMU does (docs/design.md, "The FMUs (FMI 2.0 and 3.0 co-simulation)"): inputs set before
fmi2DoStep(t, h) hold over [t, t + h], or are linear over it where the master set their first
derivatives (canInterpolateInputs); the states after the call are the ODE's solution at t + h to the
parameters rtol and atol (defaults 1e-10, 1e-12: SOLVER_STARTS), and the derived outputs are
computed from them and the inputs whenever they are read. The solver's step size carries over from
step to step. A component with a reset (Component.reset: a state at or beyond a non-windup limit
while its rate pushes outward is placed on the limit, ANDES' anti-windup) has it applied where the
solver (re)locks the branches of the right-hand side: at the start of each step, at the step's
inputs, and at each located switching. A step the solver cannot complete within the tolerance is
refused with fmi2Error and a logged reason. fmi2GetDirectionalDerivative gives the outputs' exact
derivatives with respect to the inputs. The default initial state is the machine's equilibrium at the inputs' start values.
A component with a bus port also gives the port's outputs (variables.BUS_OUTPUTS, computed in
c/variables.c from the exact derivatives of its bus current): its Norton equivalent for the step to
come and P, Q at the bus, on the system base it is built for (`system_base_mva`, declared in the
model description's ports).

Model Exchange (docs/fmu.md, "Model Exchange"): the same FMU also offers it (c/fmi2_me.c or
c/fmi3_me.c over c/model_exchange.c), with the states' derivatives and the switching functions as event
indicators (variables.exchange_variables), integrated by the importer with the branches locked and
relocked, the resets applied, at events as the co-simulation step does (c/switching.c, which both share).

The pythonfmu reference FMU (python_reference_fmu.py) has the same variables and value references, less
Model Exchange's.
"""
from __future__ import annotations

import hashlib
import json
import math
import shutil
import tempfile
from pathlib import Path

import numpy as np

from reference_models.component import Component, ParameterError
from reference_models.sm4 import SM4

from .binaries import PLUMBING, check_fmi_version, compile_binaries, targets
from .surrogate_fmu import BuildError, _c_double, check_model_name, component_config, derivatives_source
from .c_equations import equations_c_source, parameter_space, reset_c_source, switching_c_source
from .c_parameters import parameters_c_source
from .cross_check import cross_check
from .fmu_archive import write_fmu
from .model_description import model_description
from .python_reference_fmu import machine_params
from .self_start import config_lines as self_start_config, self_start_of
from .self_start import variables as self_start_variables
from .variables import (REFERENCE_EXTRAS, REFERENCE_STARTS, SYSTEM_BASE_MVA, exchange_variables, fmu_variables,
                        start_inputs, start_state, vr_header)

C_DIR = Path(__file__).parent / "c"
MODEL_SOURCES = ("cosimulation.c", "variables.c", "reference_model.c", "dopri5.c", "switching.c", "model_exchange.c",
                 "self_start.c", "linalg.c", "cosimulation.h", "model.h", "reference_state.h", "dopri5.h",
                 "switching.h", "model_exchange.h", "linalg.h")
EXCHANGE_PLUMBING = {2: "fmi2_me.c", 3: "fmi3_me.c"}  # the Model Exchange API of each version (c/)
# beside the version's plumbing (binaries.PLUMBING) and its Model Exchange API (EXCHANGE_PLUMBING)
C_FILES = ("cosimulation.c", "variables.c", "reference_model.c", "dopri5.c", "switching.c", "model_exchange.c",
           "equations.c", "derivatives.c")
START_C_FILES = ("self_start.c", "linalg.c")  # where the FMU starts itself from the load flow
RTOL_MIN = 1e-14  # the smallest rtol the FMU accepts (the integrator needs at least 10 machine epsilons)
SOLVER_STARTS = REFERENCE_STARTS  # defaults of the parameters rtol, atol (variables.py says why)


class NativeReferenceError(BuildError):
    """The native reference FMU cannot be built as asked (refused parameters, no equilibrium to start
    from, a bad model name, compiler failure, an FMU that does not validate); one-line message."""


def native_reference_variables(component: Component = SM4, params=None):
    """The native reference FMU's variables for that machine (the pythonfmu reference FMU's table)."""
    params = machine_params(component, params)
    x_start = _start_state(component, params)
    spec = self_start_of(component, params, x_start)
    space = parameter_space(component, params)
    return exchange_variables(fmu_variables(component, params, x_start, REFERENCE_EXTRAS, SOLVER_STARTS,
                                            bus_outputs=True, space=space,
                                            self_start=spec and self_start_variables(spec, component)),
                              component, switching_c_source(component, space)[0])


def structure_of(component: Component, params=None) -> dict:
    """The structure a native reference FMU of `component` with parameters `params` (as
    build_native_reference_fmu takes them) is built for: {"component", "predicates"} (the
    structural predicates with their outcomes, fmu_export.c_parameters), JSON-able. FMUs of equal
    structure differ only in their defaults: one serves the parameters of the other.
    NativeReferenceError for refused parameters."""
    try:
        params = machine_params(component, params)
    except ParameterError as exc:
        raise NativeReferenceError(str(exc)) from None
    return {"component": component.name, "predicates": parameter_space(component, params).structure()}


def build_native_reference_fmu(out, model_name: str = "SM4Reference", component: Component = SM4,
                               params=None, operating_point: dict | None = None, platforms=None,
                               fmi_version: int = 2, start_state=None,
                               system_base_mva: float = SYSTEM_BASE_MVA) -> dict:
    """Write the native reference FMU of `component` with parameters `params` (None: its defaults; a
    mapping of some of them; or a parameter object) to `out`, atomically; its inputs start at
    `operating_point` ({input: value}, the rest at the component's start values) and its initial
    state at the equilibrium there, or at `start_state` [n_x] where given (a state at rest known from
    elsewhere, e.g. a grid case's load flow, where the equilibrium search could find another of
    several). platforms: the binaries it carries (platforms.Platform objects or
    names; None: the host's only); fmi_version: the FMI version, 2 or 3 (the same model code, another
    plumbing); system_base_mva: the system base [MVA] the parameters' per-unit values are on, which
    the model description declares for the bus port's currents, powers and admittance. Binaries of other platforms are run here, and compared with the host's, where an
    emulator is installed (cross_check).

    Returns {"path", "size_bytes", "guid", "params", "binaries", "checks"} (params: every parameter
    of the machine built in; binaries: {platform: {"path", "size_bytes"}}; checks: {platform: what
    running it found}). Raises NativeReferenceError (a ValueError, subclass of fmu_export.binaries.BuildError)
    with a one-line message for anything that stops the build."""
    out = Path(out)
    try:
        check_model_name(model_name)
        component.require_known_rates("reference FMU")
        params = machine_params(component, params)
        version, chosen = check_fmi_version(fmi_version), targets(platforms)
        if not (isinstance(system_base_mva, (int, float)) and math.isfinite(system_base_mva) and system_base_mva > 0):
            raise BuildError(f"the system base {system_base_mva!r} MVA is not a positive number")
    except (BuildError, ValueError) as exc:  # ParameterError is a ValueError
        raise NativeReferenceError(str(exc)) from None
    if start_state is None:
        x_start = _start_state(component, params, operating_point)
    else:
        x_start = np.asarray(start_state, dtype=float)
        if x_start.shape != (component.n_states,) or not np.all(np.isfinite(x_start)):
            raise NativeReferenceError(f"the start state must be {component.n_states} finite values")
    space = parameter_space(component, params)
    n_switching, switching = switching_c_source(component, space, linkage="OPFMU_INTERNAL")
    reset = reset_c_source(component, space, linkage="OPFMU_INTERNAL")
    equations = equations_c_source(component, space, linkage="OPFMU_INTERNAL")
    derivatives = derivatives_source(component, space)
    try:
        spec = self_start_of(component, params, x_start, operating_point)
        variables = exchange_variables(fmu_variables(component, params, x_start, REFERENCE_EXTRAS, SOLVER_STARTS,
                                                     operating_point, bus_outputs=True, base_mva=system_base_mva,
                                                     space=space, self_start=spec and self_start_variables(spec, component)),
                                       component, n_switching)
    except ValueError as exc:
        raise NativeReferenceError(str(exc)) from None
    generated = {  # the derived parameters are all known once every function was traced
        "variables.h": vr_header(variables, component, self_start=spec),
        "equations.c": '#include <stdio.h>\n#include "model.h"\n' + equations
                       + ("\n" + switching if switching else "") + ("\n" + reset if reset else "")
                       + "\n" + parameters_c_source(space, linkage="OPFMU_INTERNAL"),
        "derivatives.c": derivatives,
    }
    guid = _guid(model_name, component, generated, version, system_base_mva)
    generated["config.h"] = config_header(model_name, guid, component, x_start, operating_point, n_switching,
                                          bool(reset), space, spec)
    description = f"{component.description}: native reference, Dormand-Prince 5(4) over each communication step"
    xml = model_description(model_name, guid, variables, description, directional_derivatives=True,
                            interpolates_inputs=True, fmi_version=version, model_exchange=True)
    with tempfile.TemporaryDirectory(prefix="opfmu_native_reference_") as tmp:
        src = Path(tmp) / "sources"
        src.mkdir()
        for name in (PLUMBING[version], EXCHANGE_PLUMBING[version], *MODEL_SOURCES):
            shutil.copy(C_DIR / name, src / name)
        for name, text in generated.items():
            (src / name).write_text(text)
        try:
            sources = (EXCHANGE_PLUMBING[version], *C_FILES, *(START_C_FILES if spec else ()))
            binaries = compile_binaries(Path(tmp), model_name, [src / f for f in sources], src, chosen, version,
                                        model_exchange=True)
            checks = cross_check(binaries, variables, guid, version, Path(tmp) / "check", interpolates=version == 2)
            written = write_fmu(out, Path(tmp), xml, model_name, version, {p: binaries[p] for p in chosen},
                                {"machine.json": (json.dumps(params.to_dict(), indent=2) + "\n").encode()}, src)
        except BuildError as exc:
            raise NativeReferenceError(str(exc)) from None
    return {"path": str(out), "size_bytes": written["size_bytes"], "guid": guid, "params": params.to_dict(),
            "binaries": written["binaries"], "checks": checks}


def config_header(model_name: str, guid: str, component: Component, x_start, operating_point=None,
                  n_switching: int = 0, reset: bool = False, space=None, self_start=None) -> str:
    """config.h of the native reference FMU: sizes, defaults and component tables, all numbers or
    escaped names; n_switching: the number of switching functions of the right-hand side
    (c_equations.switching_c_source); reset: whether equations.c has the component's model_reset
    (c_equations.reset_c_source; only then is OPFMU_HAS_RESET defined, so the header of a component
    without one is as before); space: the build's ParameterSpace; self_start: the start from the
    load flow it solves (self_start_of), or None."""
    opening, tables = component_config("native reference", model_name, guid, component, "reference_state.h", True,
                                       x_start, operating_point, space, input_order=2)
    lines = opening + [
        f"#define OPFMU_RTOL {_c_double(SOLVER_STARTS['rtol'])} /* default of the parameter rtol */",
        f"#define OPFMU_ATOL {_c_double(SOLVER_STARTS['atol'])} /* default of the parameter atol */",
        f"#define OPFMU_RTOL_MIN {_c_double(RTOL_MIN)} /* the smallest rtol accepted */",
        f"#define OPFMU_N_SWITCHING {int(n_switching)} /* switching functions of the right-hand side */",
        "#define OPFMU_MODEL_EXCHANGE 1 /* Model Exchange beside co-simulation (model_exchange.h) */",
        *(["#define OPFMU_HAS_RESET 1 /* model_reset: states placed on the non-windup limits they are pushed beyond */"]
          if reset else []),
        *tables,
        *(self_start_config(component, self_start) if self_start else []),
        "#endif", "",
    ]
    return "\n".join(lines)


def _start_state(component: Component, params, operating_point=None) -> np.ndarray:
    """The equilibrium at the inputs' start values [n_x]; NativeReferenceError where there is none."""
    try:
        return start_state(component, params, operating_point)
    except ValueError as exc:
        raise NativeReferenceError(str(exc)) from None


def _guid(model_name: str, component: Component, generated: dict, version: int = 2,
          system_base_mva: float = SYSTEM_BASE_MVA) -> str:
    """A GUID (FMI 3.0: instantiation token) that changes with what the binary computes: name,
    component, FMI version, the generated C sources (the structure: structural predicates, derived
    parameters) and system base; not with the defaults of the parameters, inputs and initial state
    (config.h), which any instance may set."""
    digest = hashlib.sha256(b"native reference\0" + model_name.encode() + b"\0" + component.name.encode() + b"\0"
                            + (b"" if version == 2 else b"\0fmi3")
                            + (b"" if system_base_mva == SYSTEM_BASE_MVA else repr(float(system_base_mva)).encode()))
    for name in sorted(generated):
        digest.update(name.encode() + b"\0" + generated[name].encode())
    for name in (PLUMBING[version], EXCHANGE_PLUMBING[version], *MODEL_SOURCES):
        digest.update(name.encode() + b"\0" + (C_DIR / name).read_bytes())
    h = digest.hexdigest()
    return f"{{{h[:8]}-{h[8:12]}-{h[12:16]}-{h[16:20]}-{h[20:32]}}}"
