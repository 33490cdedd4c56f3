"""The FMUs' variables and value references: the one table, derived from a component.

Real value references, in this order: the component's inputs, its states (outputs at the
communication point), its derived outputs, the initial-state parameters `<state>0`, then the
variables a kind of FMU adds (`SURROGATE_EXTRAS`, `REFERENCE_EXTRAS`) in the order listed, then,
where the FMU offers them (the native reference FMU of a component with a bus port), the bus port's
outputs (`BUS_OUTPUTS`: the Norton equivalent and P, Q at the bus), then, where the native reference
FMU starts itself from the load flow (fmu_export.self_start), its start parameters and calculated
parameters, then, in a native FMU, the
component's parameters in its parameter class's order (fixed parameters, start the built values, min
and max their range where the component checks one: fmu_export.c_parameters). Booleans come after every Real,
so that a value reference names one variable whatever its type (FMI 2.0 allows types to share
them; importers that read by value reference alone do not). For SM4's native reference FMU this is
Vs 0, theta_vs 1, Pm 2, Efd 3, delta..Eq_p 4-7, Id..Q 8-13, rotor_speed 14, delta0..Eq_p0 15-18, rtol 19,
atol 20, I_N_re..Q_bus 21-28, V_lf..Q_lf 29-32, Pm_init 33, Efd_init 34, D..Wb 35-46. The C sources get the same table as generated `#define`s (`vr_header`); tests,
benchmarks and importers read the model description.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, fields, replace

from reference_models.component import Component
from reference_models.ports import Ports

from .c_equations import output_input_dependencies


@dataclass(frozen=True)
class Variable:
    name: str
    vr: int
    causality: str            # input | output | parameter
    description: str
    unit: str = ""
    start: float | None = None
    kind: str = "Real"        # Real | Boolean
    dependencies: tuple = ()  # an output's direct dependencies on inputs within a step (input names)
    derivative: bool = True   # an output the FMU gives directional derivatives of (where it has dependencies)
    minimum: float | None = None  # a parameter's declared range (None: unbounded)
    maximum: float | None = None
    derivative_of: str | None = None  # a state derivative's state (exchange_variables), None for another variable


class VariableTable(list):
    """The variables of one FMU (`Variable`, in value-reference order) with the ports of its
    component (reference_models.ports.Ports), which the model description declares."""

    def __init__(self, variables, ports: Ports):
        super().__init__(variables)
        self.ports = ports


@dataclass(frozen=True)
class Extra:
    """A variable one kind of FMU adds: name, causality, description, unit, Real or Boolean,
    whether it depends directly on every input (an output computed from the current inputs) and
    whether the FMU gives its directional derivatives."""

    name: str
    causality: str
    description: str
    unit: str = ""
    kind: str = "Real"
    feedthrough: bool = False
    derivative: bool = True


SURROGATE_EXTRAS = (
    Extra("residual", "output", "RMS of the operator's physics residual, per state scaled", feedthrough=True,
          derivative=False),
    Extra("rollover_horizon", "parameter", "operator window length (at most the trained horizon)", "s"),
    Extra("in_envelope", "output", "false once an input or window start state left the trained envelope",
          kind="Boolean"),
    Extra("residual_limit", "parameter", "residual above which a warning is logged once per excursion (0: no check)"),
    Extra("restart_jump", "parameter", "an input change larger than this (in the input's unit) starts a new "
          "operator window at once (0: only at the rollover horizon)"),
    Extra("rest_radius", "parameter", "reach of the rest correction, which removes the operator's error at the "
          "equilibrium of the held input (0: off)"),
    Extra("slow_weight", "parameter", "weight in [0, 1] of the slow-mode correction, which integrates the slowest "
          "mode from the physics (0: off)"),
    Extra("swing_weight", "parameter", "weight in [0, 1] of the exact step of the states whose rate is affine in "
          "themselves (SM4: omega, the swing equation) over each step (0: the operator's values)"),
)
REFERENCE_EXTRAS = (
    Extra("rtol", "parameter", "relative tolerance of RK45 over each step"),
    Extra("atol", "parameter", "absolute tolerance of RK45 over each step"),
)
# The bus port's outputs (native reference FMU of a component with a bus port), in this order: the
# Norton equivalent at the port for the step to come, I = I_N + Y_N V to first order in the bus
# voltage V at the current state (exactly where the current is affine in V), and the power into the
# bus. All on the system base, network frame (fmu_export/c/variables.c computes them).
BUS_OUTPUTS = (
    ("I_N_re", "Norton current source at the bus for the step to come (I = I_N + Y_N V), real part, network frame"),
    ("I_N_im", "Norton current source at the bus for the step to come (I = I_N + Y_N V), imaginary part, "
               "network frame"),
    ("Y_N_11", "Norton admittance at the bus for the step to come: d I_re / d V_re"),
    ("Y_N_12", "Norton admittance at the bus for the step to come: d I_re / d V_im"),
    ("Y_N_21", "Norton admittance at the bus for the step to come: d I_im / d V_re"),
    ("Y_N_22", "Norton admittance at the bus for the step to come: d I_im / d V_im"),
    ("P_bus", "active power into the bus, Re(V conj(I)), generator convention"),
    ("Q_bus", "reactive power into the bus, Im(V conj(I)), generator convention"),
)
NORTON_OUTPUTS = tuple(name for name, _ in BUS_OUTPUTS[:6])
POWER_OUTPUTS = tuple(name for name, _ in BUS_OUTPUTS[6:])
SYSTEM_BASE_MVA = 100.0  # the system base an FMU declares unless its builder is told another

# defaults of rtol, atol in both reference FMUs. The tolerance bounds each solver step's error, and
# over 60 s of 10 ms steps an undamped machine (D = 0) accumulates them to 6e-8 rad/s in omega at
# 1e-8, 1e-10 (1e-9 at these), against DOP853 at 1e-11; the default machine stays within 1e-9 at
# either. A 10 ms step of the native reference costs about 1 us at these.
REFERENCE_STARTS = {"rtol": 1e-10, "atol": 1e-12}


def start_inputs(component: Component, operating_point: dict | None = None):
    """The FMU's input start values [n_u]: the component's, with those of `operating_point`
    ({input name: value}, e.g. a machine's Pm and Efd from its load flow) instead."""
    import numpy as np

    point = operating_point or {}
    return np.array([float(point.get(q.name, q.start)) for q in component.inputs])


def start_state(component: Component, params, operating_point: dict | None = None):
    """The default initial state of an FMU [n_x]: the machine's equilibrium at its inputs' start
    values (start_inputs). ValueError (one line) where there is no finite one."""
    import numpy as np

    u = start_inputs(component, operating_point)
    starts = ", ".join(f"{q.name} = {float(v)!r}" for q, v in zip(component.inputs, u))
    try:
        x = np.asarray(component.steady_state(u, params), dtype=float)
    except (ValueError, ArithmeticError) as exc:
        raise ValueError(f"the {component.name} machine has no equilibrium at the start inputs ({starts}) to start "
                         f"from: {' '.join(str(exc).split())[:200]}") from None
    if x.shape != (component.n_states,) or not np.all(np.isfinite(x)):
        raise ValueError(f"the {component.name} machine has no finite equilibrium at the start inputs ({starts})")
    return x


def fmu_ports(component: Component, base_mva: float | None = SYSTEM_BASE_MVA) -> Ports:
    """The ports an FMU with the bus port's outputs (BUS_OUTPUTS) declares: its component's, the bus
    port with those outputs and the system base `base_mva` [MVA] added. A component without a bus
    port: its own ports."""
    ports = component.ports
    if ports.bus is None:
        return ports
    return replace(ports, bus=replace(ports.bus, norton=NORTON_OUTPUTS, power=POWER_OUTPUTS,
                                      base_mva=None if base_mva is None else float(base_mva)))


def fmu_variables(component: Component, params, x_start, extras=(), starts=None,
                  operating_point: dict | None = None, bus_outputs: bool = False,
                  base_mva: float = SYSTEM_BASE_MVA, space=None, self_start=None) -> VariableTable:
    """The variable table of an FMU of `component` with parameters `params`: x_start [n_x] are the
    defaults of the initial-state parameters, `extras` the FMU kind's own variables and `starts`
    their start values by name (parameters need one); the inputs start at start_inputs. bus_outputs:
    a component with a bus port gets its outputs (BUS_OUTPUTS), on the system base `base_mva` [MVA].
    space: the build's fmu_export.c_parameters.ParameterSpace, whose parameters the table then
    declares (parameter_variables). self_start: the variables of the start from the load flow
    (fmu_export.self_start.variables), after the bus outputs.
    The table carries the ports for the model description (fmu_ports where it has the bus outputs).
    ValueError where a bus output's name is one of the component's."""
    starts = starts or {}
    dependencies = output_input_dependencies(component, params)
    u_start = start_inputs(component, operating_point)
    # value references are numbered once the table is complete (below); -1 until then
    out = [Variable(q.name, -1, "input", q.description, q.unit, float(u)) for q, u in zip(component.inputs, u_start)]
    out += [Variable(q.name, -1, "output", f"{q.description} at the communication point", q.unit)
            for q in component.states]
    out += [Variable(q.name, -1, "output", q.description, q.unit, dependencies=deps)
            for q, deps in zip(component.outputs, dependencies)]
    out += [Variable(f"{q.name}0", -1, "parameter", f"initial {q.description}", q.unit, float(x))
            for q, x in zip(component.states, x_start)]
    for extra in extras:
        start = starts.get(extra.name)
        if extra.causality == "parameter" and start is None:
            raise ValueError(f"parameter {extra.name} needs a start value")
        deps = component.input_names if extra.feedthrough else ()
        out.append(Variable(extra.name, -1, extra.causality, extra.description, extra.unit, start, extra.kind, deps,
                            extra.derivative))
    bus = component.ports.bus if bus_outputs else None
    if bus is not None:
        taken = {v.name for v in out}
        clash = [name for name, _ in BUS_OUTPUTS if name in taken]
        if clash:
            raise ValueError(f"{component.name}: the bus port's output {clash[0]!r} is also one of its variables")
        # what the bus outputs are computed from: the bus current and the bus voltage
        by_output = dict(zip(component.output_names, dependencies))
        reads = set(bus.voltage).union(*(by_output.get(name, ()) for name in bus.current))
        deps = tuple(name for name in component.input_names if name in reads)
        base = f", pu on the system base Sb = {float(base_mva):g} MVA"
        # the Norton outputs, themselves derivatives, have none; P_bus and Q_bus have exact ones
        out += [Variable(name, -1, "output", text + base, "pu", dependencies=deps, derivative=name in POWER_OUTPUTS)
                for name, text in BUS_OUTPUTS]
    if self_start:
        taken = {v.name for v in out}
        clash = [v.name for v in self_start if v.name in taken]
        if clash:
            raise ValueError(f"{component.name}: the start variable {clash[0]!r} has the name of one of its variables")
        out += list(self_start)
    if space is not None:
        taken = {v.name for v in out}
        clash = [name for name in space.names if name in taken]
        if clash:
            raise ValueError(f"{component.name}: the parameter {clash[0]!r} has the name of one of its variables")
        out += parameter_variables(space)
    # Real value references in table order, then the Booleans' after the last Real
    n_real = sum(v.kind == "Real" for v in out)
    counters = {"Real": 0, "Boolean": n_real}
    numbered = []
    for v in out:
        numbered.append(replace(v, vr=counters[v.kind]))
        counters[v.kind] += 1
    return VariableTable(numbered, fmu_ports(component, base_mva) if bus is not None else component.ports)


def parameter_variables(space) -> list:
    """The component's parameters as fixed FMU parameters (value references still -1): start the
    built value, min/max the range the component checks (fmu_export.c_parameters.ParameterSpace)."""
    model = space.component.name.upper()
    structural = set(space.structural_names())
    out = []
    for i, (name, value) in enumerate(zip(space.names, space.values)):
        low, high, unit = space.ranges.get(i, (None, None, ""))
        if space.fixed == "trained":
            note = f"; fixed: the operator was trained for {value!r}"
        elif space.fixed:
            note = "; structural: the FMU refuses another value"
        elif name in structural:
            note = "; structural: a value that changes the form of the equations is refused"
        else:
            note = ""
        out.append(Variable(name, -1, "parameter", f"{model} parameter {name}{note}", unit, value,
                            minimum=low, maximum=high))
    return out


TIME = "time"  # the independent variable FMI 3.0 requires


def fmi3_value_references(variables: list[Variable]) -> dict[str, int]:
    """FMI 3.0 value references by name: the variables' own (unique across types in both versions),
    and the independent variable `time` last."""
    refs = {v.name: v.vr for v in variables}
    if TIME in refs:
        raise ValueError(f"a variable may not be named {TIME!r}: FMI 3.0 reserves it for the independent variable")
    refs[TIME] = len(variables)
    return refs


C_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}")
# a calculated parameter is read like an output: nothing may set it
KIND_TOKENS = {"input": "VAR_INPUT", "parameter": "VAR_PARAMETER", "output": "VAR_OUTPUT",
               "calculatedParameter": "VAR_OUTPUT", "local": "VAR_LOCAL"}


def vr_header(variables: list[Variable], component: Component | None = None, guard: str = "OPFMU_VARIABLES_H",
              self_start=None) -> str:
    """C header of the value-reference table: `#define VR_<NAME> <vr>` per variable (Booleans as
    VR_BOOL_<NAME>; not the component's parameters, whose names may differ in case alone, AC8B's kD
    and KD: the C reads them by VR_FIRST_PARAM, nor the start's variables, read by their groups'), the counts VR_REAL_COUNT and VR_BOOLEAN_COUNT, VR_REAL_KINDS (the initializer of
    each Real's VarKind by value reference, model.h's tokens) and, given the component, the first
    value reference of each of its groups (VR_FIRST_INPUT, VR_FIRST_STATE, VR_FIRST_OUTPUT,
    VR_FIRST_START: inputs, states, derived outputs, initial-state parameters, each contiguous in the
    component's order; VR_FIRST_PARAM where the table declares the component's parameters; an empty group, as a component without states has two, starts at 0, where
    IN_GROUP over its no values finds none). Where the table has the bus port's outputs (BUS_OUTPUTS,
    contiguous in that order): VR_FIRST_BUS, BUS_N_OUTPUTS, the bus voltage's inputs by index
    (BUS_VOLTAGE_MAGNITUDE, BUS_VOLTAGE_ANGLE) and the bus current's value references
    (VR_BUS_CURRENT_REAL, VR_BUS_CURRENT_IMAGINARY). Given the table's self_start
    (fmu_export.self_start.SelfStart): the first value reference of its load flow (VR_FIRST_FLOW),
    delivered values (VR_FIRST_DELIVERED) and solved inputs (VR_FIRST_SOLVED). ValueError for a name
    that is not a C identifier or that collides in upper case."""
    lines = ["/* Generated by opfmu: value references of the model description. */",
             f"#ifndef {guard}", f"#define {guard}"]
    seen = {}
    params = [f.name for f in fields(component.params_type)] if component is not None else []
    start_names = set()
    if self_start is not None:
        start_names = {"V_lf", "theta_lf", "P_lf", "Q_lf"} if self_start.load_flow else set()
        start_names |= {f"{n}_init" for n in self_start.delivers + self_start.solves}
    for v in variables:
        if v.causality == "local":  # Model Exchange's (exchange_variables): read by their groups below
            continue
        if not C_NAME.fullmatch(v.name):
            raise ValueError(f"variable name {v.name!r} is not a C identifier")
        if (v.causality == "parameter" and v.name in params) or v.name in start_names:
            continue  # read by the first value reference of their group
        macro = ("VR_" if v.kind == "Real" else "VR_BOOL_") + v.name.upper()
        if macro in seen:
            raise ValueError(f"variables {seen[macro]!r} and {v.name!r} both give {macro}")
        seen[macro] = v.name
        lines.append(f"#define {macro} {v.vr}u")
    reals = sorted((v for v in variables if v.kind == "Real"), key=lambda v: v.vr)
    if [v.vr for v in reals] != list(range(len(reals))):
        raise ValueError("Real value references must be 0, 1, ... without gaps")
    booleans = [v for v in variables if v.kind == "Boolean"]
    if [v.vr for v in booleans] != list(range(len(reals), len(reals) + len(booleans))):
        raise ValueError("Boolean value references must follow the last Real's without gaps")
    fmi3 = fmi3_value_references(variables)
    lines += [f"#define VR_REAL_COUNT {len(reals)}u", f"#define VR_BOOLEAN_COUNT {len(booleans)}u",
              f"#define FMI3_VR_TIME {fmi3[TIME]}u /* FMI 3.0: the independent variable */",
              "#define VR_REAL_KINDS {" + ", ".join(KIND_TOKENS[v.causality] for v in reals) + "}"]
    if component is not None:
        by_name = {v.name: v.vr for v in reals}
        groups = (("INPUT", component.input_names), ("STATE", component.state_names),
                  ("OUTPUT", component.output_names), ("START", [f"{n}0" for n in component.state_names]))
        if params and params[0] in by_name:
            groups += (("PARAM", params),)
        for group, names in groups:
            refs = [by_name[n] for n in names] or [0]
            if refs != list(range(refs[0], refs[0] + len(refs))):
                raise ValueError(f"the {group.lower()} value references of {component.name} are not contiguous")
            lines.append(f"#define VR_FIRST_{group} {refs[0]}u")
        if BUS_OUTPUTS[0][0] in by_name:
            refs = [by_name[name] for name, _ in BUS_OUTPUTS]
            if refs != list(range(refs[0], refs[0] + len(refs))):
                raise ValueError(f"the bus port's value references of {component.name} are not contiguous")
            bus = component.ports.bus
            lines += [f"#define VR_FIRST_BUS {refs[0]}u", f"#define BUS_N_OUTPUTS {len(refs)}",
                      f"#define BUS_VOLTAGE_MAGNITUDE {component.input_names.index(bus.voltage[0])}",
                      f"#define BUS_VOLTAGE_ANGLE {component.input_names.index(bus.voltage[1])}",
                      f"#define VR_BUS_CURRENT_REAL {by_name[bus.current[0]]}u",
                      f"#define VR_BUS_CURRENT_IMAGINARY {by_name[bus.current[1]]}u"]
    if self_start is not None:
        groups = (("FLOW", ["V_lf", "theta_lf", "P_lf", "Q_lf"] if self_start.load_flow else []),
                  ("DELIVERED", [f"{n}_init" for n in self_start.delivers]),
                  ("SOLVED", [f"{n}_init" for n in self_start.solves]))
        for group, names in groups:
            refs = [by_name[n] for n in names] or [0]
            if refs != list(range(refs[0], refs[0] + len(refs))):
                raise ValueError(f"the start's {group.lower()} value references of {component.name} are not contiguous")
            lines.append(f"#define VR_FIRST_{group} {refs[0]}u")
    derivatives = [v.vr for v in reals if v.derivative_of is not None]
    indicators = [v.vr for v in reals if v.causality == "local" and v.derivative_of is None]
    if derivatives or indicators:
        for group, refs in (("DERIVATIVE", derivatives), ("INDICATOR", indicators)):
            refs = refs or [0]
            if refs != list(range(refs[0], refs[0] + len(refs))):
                raise ValueError(f"the {group.lower()} value references are not contiguous")
            lines.append(f"#define VR_FIRST_{group} {refs[0]}u")
    lines += ["#endif", ""]
    return "\n".join(lines)


def rate_unit(unit: str) -> str:
    """The unit of the time derivative of a quantity in `unit`: 1/s of a dimensionless one, 1 of a
    time [s], rad/s2 of a speed [rad/s], <unit>/s of any other."""
    return {"": "1/s", "-": "1/s", "1": "1/s", "s": "1", "rad/s": "rad/s2"}.get(unit, f"{unit}/s")


def exchange_variables(variables: VariableTable, component: Component, n_switching: int) -> VariableTable:
    """`variables` (a native reference FMU's table) with what Model Exchange adds after its last Real:
    each state's derivative `der(<state>)` (local, continuous; the model description's `derivative`
    attribute names the state), then the event indicators `event_indicator_<k>`, the right-hand
    side's n_switching switching functions g_k = a - b of its conditions a op b (local; FMI 3.0
    declares them in ModelStructure). The Booleans' value references move up behind them."""
    units = {q.name: q.unit for q in component.states}
    added = [Variable(f"der({name})", -1, "local", f"time derivative of {name} on the branches locked at the last "
                      "event", rate_unit(units[name]), derivative_of=name)
             for name in component.state_names]
    added += [Variable(f"event_indicator_{k}", -1, "local", f"switching function {k} of the right-hand side: a - b "
                       "of its condition a op b, whose sign change is an event") for k in range(n_switching)]
    reals = [v for v in variables if v.kind == "Real"]
    booleans = [v for v in variables if v.kind != "Real"]
    added = [replace(v, vr=len(reals) + i) for i, v in enumerate(added)]
    n_real = len(reals) + len(added)
    booleans = [replace(v, vr=n_real + i) for i, v in enumerate(booleans)]
    return VariableTable(reals + added + booleans, variables.ports)
