"""Self-initialisation of a native FMU (reference or surrogate) from the load flow: what the FMU solves
for at its start.

A component's initialisation (reference_models.component.Initialisation) starts it at rest from what
its surroundings fix. Its native FMUs solve the same rest themselves, in C (c/self_start.c), as
one square system in its states x and the inputs it solves (`solves`: a machine's Pm and Efd, an
exciter's Vref, a governor's Pref):

    dx/dt (x, u) = 0                                    the component's right-hand side
    P_bus (x, u) = P_lf,  Q_bus (x, u) = Q_lf           a bus device that solves inputs: its load-flow power
    y_k (x, u) = y_k_init                               each output it delivers to a device that solved for it
                                                        (an exciter's Efd, a governor's Pm)

with the bus voltage inputs at the load flow's V_lf, theta_lf and every other input at the value the
host set. What the component delivers and whether it reads the load flow are what its initialisation reads
from `given` at its default rest (`describe`), so the FMU and reference_models.grid.case start from the
same equations. The FMU's variables for this (`variables`): parameters V_lf, theta_lf, P_lf, Q_lf (the
load flow; system base, generator convention; named apart from the `<state>0` initial-state parameters), `<y>_init` for each delivered output, and calculated parameters `<u>_init`, the
value each solved input takes at the start, which stays its set point while the host leaves the input
unconnected. A component whose system is not square gets no self-initialisation (`describe` says why):
an inverter's electrical controller solves more inputs than it has such equations (its references
follow relations of their own), and a load reads the load flow into its parameters rather than
solving anything from it.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from reference_models.component import LOAD_FLOW, Component

from .variables import Variable, start_inputs

LOAD_FLOW_VARIABLES = (
    ("V_lf", "pu", "bus voltage magnitude at the load flow"),
    ("theta_lf", "rad", "bus voltage angle at the load flow, network frame"),
    ("P_lf", "pu", "active power into the bus at the load flow, generator convention (system base)"),
    ("Q_lf", "pu", "reactive power into the bus at the load flow, generator convention (system base)"),
)
INIT_SUFFIX = "_init"


@dataclass(frozen=True)
class Anchor:
    """A solved start the C continues from (lambda = 0) at the built parameters: states x [n_x],
    inputs u [n_u] (the solved ones solved), load flow (V_lf, theta_lf, P_lf, Q_lf) and delivered values;
    `inert`: the states the equations hold and read nowhere (a lag with T = 0), which keep their
    anchor value."""

    x: tuple
    u: tuple
    flow: tuple
    delivered: tuple
    inert: tuple


@dataclass(frozen=True)
class SelfStart:
    """What a component's FMU solves at its start: `load_flow` (its bus power P_lf, Q_lf is an equation),
    `delivers` (names of its outputs or states whose start values the devices it drives fixed),
    `solves` (inputs it solves, in its input order), the defaults [len] of the load flow (V_lf,
    theta_lf, P_lf, Q_lf at its default rest) and of the delivered values, and the anchor."""

    load_flow: bool
    delivers: tuple
    solves: tuple
    flow_defaults: tuple
    deliver_defaults: tuple
    anchor: Anchor


class _Reads(dict):
    """A dict that records the keys read from it."""

    def __init__(self, values):
        super().__init__(values)
        self.read = set()

    def __getitem__(self, key):
        self.read.add(key)
        return super().__getitem__(key)

    def get(self, key, default=None):
        self.read.add(key)
        return super().get(key, default)


def describe(component: Component, params, x_rest, u_rest) -> tuple:
    """(SelfStart, None) for a component the FMU can start from the load flow, or (None, why) where
    it cannot. x_rest [n_x], u_rest [n_u]: its default rest (the FMU's default initial state and
    inputs), where its initialisation is asked what it reads."""
    init = component.initialisation
    x_rest, u_rest = np.asarray(x_rest, dtype=float), np.asarray(u_rest, dtype=float)
    y = np.asarray(component.output_values(x_rest, u_rest, params), dtype=float)
    values = {**dict(zip(component.input_names, u_rest)), **dict(zip(component.state_names, x_rest)),
              **dict(zip(component.output_names, y))}
    bus = component.ports.bus
    flow = (0.0, 0.0, 0.0, 0.0)
    if bus is not None:
        V, theta = (values[name] for name in bus.voltage)
        current = complex(values[bus.current[0]], values[bus.current[1]])
        power = V * np.exp(1j * theta) * current.conjugate()
        flow = (V, theta, float(power.real), float(power.imag))
        values.update(zip(LOAD_FLOW, flow))
    solves = init.solves if init is not None else ()
    given = _Reads(values)
    if init is not None:
        try:
            init.start(given, params)
        except (ValueError, ArithmeticError) as exc:
            return None, f"its initialisation has no start at its default rest ({' '.join(str(exc).split())[:120]})"
    deliverable = set(component.output_names) | set(component.state_names)
    delivers = tuple(n for n in component.output_names + component.state_names
                     if n in given.read and n in deliverable and n not in component.input_names)
    load_flow = bus is not None and any(k in given.read for k in LOAD_FLOW)
    conditions = (["P_lf", "Q_lf"] if load_flow else []) + [f"{n}{INIT_SUFFIX}" for n in delivers]
    learned = [component.state_names[i] for i in component.learned_states if i not in component.started_states]
    if len(solves) + len(learned) != len(conditions):
        return None, (f"its start fixes {', '.join(conditions) or 'nothing'} but solves "
                      f"{', '.join(list(solves) + learned) or 'no input'}: not one solved input or learned state "
                      "per condition")
    solves = tuple(n for n in component.input_names if n in solves)
    spec = SelfStart(load_flow, delivers, solves, tuple(float(v) for v in flow),
                     tuple(float(values[n]) for n in delivers), None)
    for delivered in [spec.deliver_defaults] + [(v,) * len(delivers) for v in ANCHOR_LEVELS if delivers]:
        point = _anchor(component, params, spec, values, delivered)
        if point is not None:
            return replace(spec, anchor=point), None
    return None, ("its start equations are singular at each start tried (a limit active there, or a state no rest "
                  "fixes: a storage's state of charge, an integrator of gain 0 that its output reads)")


def self_start_of(component: Component, params, x_start, operating_point: dict | None = None):
    """The start from the load flow a native FMU (reference or surrogate) of `component` solves itself
    (fmu_export.self_start.SelfStart), at its default rest x_start [n_x] under the start inputs;
    None where it has none (its system is not square, or it fixes nothing to start from)."""
    spec, _ = describe(component, params, x_start, start_inputs(component, operating_point))
    if spec is None or not (spec.load_flow or spec.delivers or spec.solves):
        return None
    return spec


# the delivered values tried as the anchor where the default rest's Jacobian is singular (a limit is active there)
ANCHOR_LEVELS = (1.0, 1.5, 2.0, 0.5, 3.0)
SINGULAR = 1e-9  # smallest singular value of the row-scaled Jacobian, relative to its largest, taken as singular


def _residual(component: Component, params, spec: SelfStart, z, u, flow, delivered) -> np.ndarray:
    """The start's residual (self_start.c's) at unknowns z = (x, solved inputs), numpy."""
    n_x = component.n_states
    x, u = np.asarray(z[:n_x], dtype=float), np.array(u, dtype=float)
    index = [component.input_names.index(n) for n in spec.solves]
    u[index] = z[n_x:]
    rates = np.asarray(component.start_residual(x, u, params), dtype=float).reshape(-1)[:n_x]
    out = [rates[i] for i in rate_rows(component)]
    y = dict(zip(component.output_names, np.asarray(component.output_values(x, u, params), dtype=float)))
    y.update(zip(component.state_names, x))
    if spec.load_flow:
        bus = component.ports.bus
        V = flow[0] * np.exp(1j * flow[1])
        power = V * complex(y[bus.current[0]], y[bus.current[1]]).conjugate()
        out += [power.real - flow[2], power.imag - flow[3]]
    out += [y[n] - d for n, d in zip(spec.delivers, delivered)]
    return np.array(out)


def rate_rows(component: Component) -> list:
    """The states whose start equations (their rates, or `start_equations`) are the start's first
    rows, in order: all but the learned ones whose start the load flow's P and Q fix (those not in
    Component.started_states)."""
    return [i for i in range(component.n_states)
            if i not in component.learned_states or i in component.started_states]


def _anchor(component: Component, params, spec: SelfStart, values: dict, delivered) -> Anchor | None:
    """The anchor at the delivered values `delivered` (the default rest's inputs and load flow),
    from the component's own initialisation; None where there is none or its Jacobian (by central
    differences, inert states aside) is singular."""
    given = {**values, **dict(zip(spec.delivers, delivered))}
    try:
        x, inputs = component.start(given, params)
    except (ValueError, ArithmeticError):
        return None
    u = np.array([inputs[n] for n in component.input_names], dtype=float)
    flow = spec.flow_defaults
    z = np.concatenate([np.asarray(x, dtype=float), u[[component.input_names.index(n) for n in spec.solves]]])
    if not np.all(np.isfinite(z)) or z.size == 0:
        return None
    columns = []
    for j in range(z.size):
        h = 1e-6 * max(1.0, abs(z[j]))
        e = np.zeros(z.size)
        e[j] = h
        columns.append((_residual(component, params, spec, z + e, u, flow, delivered)
                        - _residual(component, params, spec, z - e, u, flow, delivered)) / (2 * h))
    J = np.array(columns).T
    rows = rate_rows(component)  # the state whose start equation each first row is
    inert = tuple(i for k, i in enumerate(rows) if not np.any(J[k]) and not np.any(J[:, i]))
    for i in inert:
        J[rows.index(i), i] = 1.0
    scale = np.max(np.abs(J), axis=1)
    if not np.all(scale > 0):
        return None
    sv = np.linalg.svd(J / scale[:, None], compute_uv=False)
    if not sv[-1] > SINGULAR * sv[0]:
        return None
    return Anchor(tuple(map(float, x)), tuple(map(float, u)), tuple(map(float, flow)), tuple(map(float, delivered)),
                  inert)


def variables(spec: SelfStart, component: Component) -> list:
    """The FMU variables of a self-start (value references -1): V_lf, theta_lf, P_lf, Q_lf where it reads the
    load flow, `<y>_init` parameters of the delivered values, `<u>_init` calculated parameters of the
    solved inputs (which depend on every input: the ones it does not solve are given)."""
    units = {q.name: q.unit for q in component.inputs + component.states + component.outputs}
    out = []
    if spec.load_flow:
        out += [Variable(name, -1, "parameter", f"{text}: the start solves the states and {', '.join(spec.solves)} "
                         "from it", unit, value) for (name, unit, text), value in zip(LOAD_FLOW_VARIABLES,
                                                                                     spec.flow_defaults)]
    out += [Variable(f"{name}{INIT_SUFFIX}", -1, "parameter", f"{name} at the start, as the device it drives "
                     "solved for it (that device's calculated parameter of its linked input)", units[name], value)
            for name, value in zip(spec.delivers, spec.deliver_defaults)]
    out += [Variable(f"{name}{INIT_SUFFIX}", -1, "calculatedParameter", f"{name} at the start, solved from the "
                     "load flow and the values delivered; the input's set point while it is left unconnected",
                     units[name], dependencies=component.input_names, derivative=False) for name in spec.solves]
    return out


def config_lines(component: Component, spec: SelfStart) -> list:
    """config.h lines of a self-start (c/self_start.c): OPFMU_SELF_START and its tables."""
    index = {n: i for i, n in enumerate(component.input_names)}
    columns = []
    for name in spec.delivers:  # an output's row of the outputs' Jacobian, or (negative) a state's
        columns.append(component.output_names.index(name) if name in component.output_names
                       else -1 - component.state_names.index(name))
    solved = [index[n] for n in spec.solves]
    anchor = spec.anchor
    rows = rate_rows(component)
    own = ["#define OPFMU_HAS_START_EQUATIONS 1 /* model_start_equations replaces the rates */"] \
        if component.start_equations is not None else []
    return own + [
        "#define OPFMU_SELF_START 1 /* the FMU solves its start from the load flow (c/self_start.c) */",
        f"#define SELF_START_N_RATE_ROWS {len(rows)} /* all but the learned states P_lf, Q_lf fix */",
        f"static const int SELF_START_RATE_ROWS[{max(len(rows), 1)}] = {{{', '.join(map(str, rows or [0]))}}}; "
        "/* the state each first row is of */",
        f"#define SELF_START_LOAD_FLOW {int(spec.load_flow)} /* P_bus = P_lf and Q_bus = Q_lf are start equations */",
        f"#define SELF_START_N_DELIVERS {len(spec.delivers)}",
        f"#define SELF_START_N_SOLVES {len(spec.solves)}",
        f"static const int SELF_START_DELIVERS[{max(len(columns), 1)}] = {{{', '.join(map(str, columns or [0]))}}}; "
        "/* output index, or -1 - state index */",
        f"static const int SELF_START_SOLVES[{max(len(solved), 1)}] = {{{', '.join(map(str, solved or [0]))}}}; "
        "/* input index */",
        f"static const double SELF_START_FLOW_DEFAULT[4] = {_array(spec.flow_defaults)}; "
        "/* V_lf, theta_lf, P_lf, Q_lf at the default rest */",
        f"static const double SELF_START_DELIVER_DEFAULT[{max(len(spec.delivers), 1)}] = "
        f"{_array(spec.deliver_defaults)}; /* the delivered values at the default rest */",
        "/* the anchor the start is continued from (lambda = 0), at the built parameters */",
        f"static const double SELF_START_ANCHOR_X[{max(component.n_states, 1)}] = {_array(anchor.x)};",
        f"static const double SELF_START_ANCHOR_U[{component.n_inputs}] = {_array(anchor.u)};",
        f"static const double SELF_START_ANCHOR_FLOW[4] = {_array(anchor.flow)};",
        f"static const double SELF_START_ANCHOR_DELIVERED[{max(len(spec.delivers), 1)}] = {_array(anchor.delivered)};",
        f"static const int SELF_START_INERT[{max(component.n_states, 1)}] = "
        f"{{{', '.join(str(int(i in anchor.inert)) for i in range(max(component.n_states, 1)))}}}; "
        "/* 1: a state held and read nowhere, kept at its anchor value */",
        f"static const char *const SELF_START_DELIVER_NAMES[{max(len(spec.delivers), 1)}] = "
        "{" + ", ".join(f'"{n}"' for n in (spec.delivers or ("",))) + "};",
    ]


def _array(values) -> str:
    """A C initializer of finite doubles (one 0 for none), each as repr prints it: exact."""
    return "{" + ", ".join(repr(float(v)) for v in (tuple(values) or (0.0,))) + "}"
