"""What a component is: its variables, parameters, equations and steady state, declared once.

Every layer derives from a `Component`: dataset generation (channels, sizes), the networks (input
and output sizes), the physics losses (the right-hand side), the ONNX metadata, the generated C, the
model descriptions and value references, and the reference FMUs. The equations are plain Python
functions of sequences of scalars written against a math namespace `m` (anything with `sin`, `cos`,
`exp`, `sqrt`: the `math` module, numpy, torch, or the C tracer of fmu_export), so one definition
serves scipy, autograd and code generation.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, fields
from functools import cached_property
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from .drift import Drift
from .messages import one_line
from .ports import Ports

MAX_PARAMETER_FILE_BYTES = 64 * 1024


class ParameterError(ValueError):
    """A parameter set that a component refuses: unknown key, not a number, out of range."""


#: The load-flow point a device with a bus port starts from (keys of its initialisation's `given`):
#: bus voltage magnitude V0 [pu] and angle theta0 [rad] (network frame), and its share P0 + jQ0 of
#: the power injected at its bus [pu, system base, generator convention: a load's is negative].
LOAD_FLOW = ("V0", "theta0", "P0", "Q0")


@dataclass(frozen=True)
class Initialisation:
    """How a component starts at rest from what its surroundings fix (ANDES: each variable's initial
    equation, declared with the model).

    solves: the inputs its start sets itself, by name: set points (an exciter's Vref, a governor's
        Pref) and inputs linked from a device of its unit, which then has to give that value (a
        machine's Pm and Efd, an inverter's current commands).
    start(given, p) -> (x0 [n_x], {input: value} for every name in `solves`), where `given` holds
        by name the value of every other input (a bus device's voltage inputs, a governor's speed),
        the value each output that a device it drives has solved for must take (an exciter's Efd),
        and for a component with a bus port the load-flow point LOAD_FLOW. Raises ValueError,
        naming the component, where there is no such rest (a limit, no solution).

    A component without one starts at `equilibrium(u)` with every input given (a stabiliser).
    """

    solves: tuple
    start: Callable


@dataclass(frozen=True)
class Quantity:
    """One state, input or output: name, unit, what it is, and for an input its start value, the
    operating range [low, high] the built-in input families draw levels from and the lowest value it
    may take (None: unbounded; an FMU refuses a value below it)."""

    name: str
    unit: str
    description: str
    start: float | None = None
    operating_range: tuple | None = None
    minimum: float | None = None


@dataclass(frozen=True)
class Parameters:
    """Base of a component's parameter dataclass: every field a finite real number; subclasses add
    their own checks in `check` (raise ParameterError naming the field)."""

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not _finite(value):
                raise ParameterError(f"parameter {f.name} = {str(value)[:40]} must be a finite number")
            object.__setattr__(self, f.name, float(value))
        self.check()

    def check(self) -> None:
        """Range checks of a subclass (none here)."""

    def to_dict(self) -> dict:
        return asdict(self)

    def require(self, name: str, condition: bool, rule: str) -> None:
        """Raise ParameterError "parameter NAME = VALUE must RULE" unless condition."""
        if not condition:
            raise ParameterError(f"parameter {name} = {getattr(self, name)!r} must {rule}")


@dataclass(frozen=True)
class Component:
    """A dynamic component x' = f(x, u; p) with derived outputs y = g(x, u; p). It may have no
    states (n_x = 0: a bus device whose current is a function of its bus voltage and inputs alone,
    ZIP): then f is empty, y = g(u; p), and it has no operator to learn (`require_states`).

    derivatives(x, u, p, m) and output_equations(x, u, p, m) take sequences of scalars (or arrays
    broadcast together) and return tuples of len(states) and len(outputs). equilibrium(u [n_u], p)
    returns the stable steady state [n_x] under constant inputs u, or raises ValueError.
    rest(u, p): the state at rest nearest to constant inputs u where equilibrium has none (SM4: the
        equilibrium at the lowest voltage that has one); None: equilibrium's answer or its error.
    state_scales: a typical excursion of each state in its units (how far "near rest" reaches).
    affine_states: indices of states whose own derivative is affine in that state alone,
        dx_i/dt = g(other states, u) - k x_i with k >= 0 constant, or constant on pieces (a PI with
        anti-windup, a hold): integrated exactly over a step, with k and g where the state is.
    drift: the component's angles and speed, when its equations are invariant under a common
        rotation and a constant extra speed of its frame (reference_models.drift); operators of
        it then work in the frame of each window. None: no such symmetry.
    ports: how it connects (reference_models.ports): its bus port and its control links.
    affine_current: for a component with a bus port, whether its bus current is affine in the bus
        voltage (V_re, V_im) at given states and other inputs (a machine's stator equations): the
        monolithic DAE then solves the network in one linear step (checked there); otherwise it
        solves the network by Newton (an inverter's current limits, a constant-power load).
    initialisation: how it starts at rest from the load flow and from what the devices it drives
        need (`Initialisation`); None: at `equilibrium` with every input given.
    learned_states: indices of states whose rate no equation gives (a sub-system's devices seen
        through its boundary: reference_models.models.subsystem): `derivatives` gives 0 for them,
        an operator learns them from data alone (the physics losses and the FMU's residual leave
        them out), and nothing integrates the component (`require_known_rates`).
    started_states: the learned states whose start `start_equations` fixes (a learned measurement
        that starts at its rest); the others' start the load flow fixes (their rows are unread).
    start_equations(x, u, p, m): where a start from the load flow needs other equations than the
        rates, its residuals (a tuple of len(states), 0 at the start): a state constant through a
        study (dx/dt = 0) that the load flow fixes (the sub-system's tap n = V0 / V_own). The rows
        of learned states are not read (the load flow's P and Q fix them). None: the rates.
    window_features(p, sensor_times [S]): known linear functionals of an operator's inputs that its
        branch reads besides them, A [n_f, n_x + n_u S] over x0 and the sensors flattened time-major
        (the sub-system's measured frequency at each sensor time, exact for inputs linear between
        sensors: what its units' droops act on, which the raw angles give only through the filter run
        over all of them). None: none.
    reset(x, u, p, m): the states after the resets of its non-windup limits (ANDES'
        AntiWindup: a state at or beyond a limit while its unlimited derivative pushes outward is
        placed on the limit), a tuple of len(states); integrators apply it where they (re)start,
        after inputs change and at located switchings. None: the component has no such reset.
    """

    name: str
    description: str
    states: tuple
    inputs: tuple
    outputs: tuple
    params_type: type
    derivatives: Callable
    output_equations: Callable
    equilibrium: Callable
    state_scales: tuple
    affine_states: tuple = ()
    rest: Callable | None = None
    drift: Drift | None = None
    ports: Ports = Ports()
    reset: Callable | None = None
    initialisation: Initialisation | None = None
    affine_current: bool = False
    learned_states: tuple = ()
    started_states: tuple = ()
    start_equations: Callable | None = None
    window_features: Callable | None = None

    def __post_init__(self):
        names = [q.name for q in self.states + self.inputs + self.outputs]
        if not (self.inputs and self.outputs):
            raise ValueError(f"component {self.name!r} needs at least one input and one derived output")
        if len(set(names)) != len(names) or not all(n.isidentifier() for n in names):
            raise ValueError(f"component {self.name!r}: variable names must be distinct identifiers, got {names}")
        if len(self.state_scales) != len(self.states) or not all(s > 0 for s in self.state_scales):
            raise ValueError(f"component {self.name!r}: one positive state scale per state")
        if not all(0 <= i < len(self.states) for i in self.affine_states):
            raise ValueError(f"component {self.name!r}: affine_states must index its states")
        if not all(0 <= i < len(self.states) for i in self.learned_states) or \
                set(self.learned_states) & set(self.affine_states):
            raise ValueError(f"component {self.name!r}: learned_states must index states that are not affine")
        if not set(self.started_states) <= set(self.learned_states):
            raise ValueError(f"component {self.name!r}: started_states must be learned states")
        if self.drift is not None:
            self.drift.check(len(self.states), len(self.inputs))
        self.ports.check(self.input_names, self.state_names + self.output_names, f"component {self.name!r}")
        if self.initialisation is not None and not set(self.initialisation.solves) <= set(self.input_names):
            raise ValueError(f"component {self.name!r}: its initialisation solves {self.initialisation.solves}, "
                             f"which are not all inputs ({', '.join(self.input_names)})")

    @cached_property  # read in every right-hand side of a grid's DAE
    def state_names(self) -> tuple:
        return tuple(q.name for q in self.states)

    @cached_property  # read in every right-hand side of a grid's DAE
    def input_names(self) -> tuple:
        return tuple(q.name for q in self.inputs)

    @cached_property  # read in every right-hand side of a grid's DAE
    def output_names(self) -> tuple:
        return tuple(q.name for q in self.outputs)

    @cached_property
    def bus_port_at(self) -> tuple:
        """(magnitude, angle, I_re, I_im): where the bus port's voltage is among the inputs and its
        current among the outputs (a device on a bus)."""
        bus = self.ports.bus
        return (self.input_names.index(bus.voltage[0]), self.input_names.index(bus.voltage[1]),
                self.output_names.index(bus.current[0]), self.output_names.index(bus.current[1]))

    @property
    def n_states(self) -> int:
        return len(self.states)

    @property
    def n_inputs(self) -> int:
        return len(self.inputs)

    def require_states(self) -> None:
        """ValueError where the component has no states (a dataset, an operator, a surrogate ask for
        some)."""
        if not self.states:
            raise ValueError(f"the {self.name} component has no states: a component without states has no "
                             "operator to learn")

    def require_known_rates(self, purpose: str) -> None:
        """ValueError where some of the component's rates are learned, not known: `purpose` (a
        reference FMU, a monolithic solve) needs every rate from an equation."""
        if self.learned_states:
            names = ", ".join(self.state_names[i] for i in self.learned_states)
            raise ValueError(f"the {self.name} component's rates of {names} are learned from data, not equations: "
                             f"it has no {purpose}; its operator's surrogate FMU stands for it")

    def physics_mask(self) -> np.ndarray:
        """[n_x]: 1 for a state whose rate an equation gives, 0 for a learned one."""
        mask = np.ones(self.n_states)
        mask[list(self.learned_states)] = 0.0
        return mask

    @property
    def start_inputs(self) -> np.ndarray:
        """The inputs' start values [n_u]: where the default initial state is the equilibrium."""
        return np.array([q.start for q in self.inputs], dtype=float)

    def rhs(self, x, u, p):
        """dx/dt [..., n_x] for states x [..., n_x] and inputs u [..., n_u] (numpy or torch, broadcast)."""
        m, stack = _namespace(x)
        columns = _columns(x, self.n_states), _columns(u, self.n_inputs)
        if not self.states:  # nothing to stack: an empty last axis on the leading axes broadcast
            return _broadcast(m, x[..., :0], x, u, 0)
        return stack(self.derivatives(*columns, p, m))

    def start_residual(self, x, u, p):
        """[..., n_x]: the start equations' residuals (`start_equations`), the rates where it has none."""
        if self.start_equations is None:
            return self.rhs(x, u, p)
        m, stack = _namespace(x)
        return stack(self.start_equations(_columns(x, self.n_states), _columns(u, self.n_inputs), p, m))

    def output_values(self, x, u, p):
        """Derived outputs [..., n_y] for x [..., n_x], u [..., n_u] (numpy or torch, broadcast)."""
        m, stack = _namespace(x)
        y = stack(self.output_equations(_columns(x, self.n_states), _columns(u, self.n_inputs), p, m))
        return _broadcast(m, y, x, u, len(self.outputs))

    def reset_states(self, x, u, p):
        """The states [..., n_x] after the component's limit resets (`reset`) at inputs u [..., n_u]
        (numpy or torch); x itself where it declares none."""
        if self.reset is None:
            return x
        m, stack = _namespace(x)
        return stack(self.reset(_columns(x, self.n_states), _columns(u, self.n_inputs), p, m))

    def steady_state(self, u=None, p=None) -> np.ndarray:
        """The stable equilibrium [n_x] at constant inputs u [n_u] (default: the start inputs)."""
        u = self.start_inputs if u is None else np.asarray(u, dtype=float)
        return np.asarray(self.equilibrium(u, p if p is not None else self.params_type()), dtype=float)

    def rest_state(self, u, p=None) -> np.ndarray:
        """The state [n_x] at rest under constant inputs u [n_u]: the equilibrium, or where there is
        none the nearest state at rest the component declares (`rest`)."""
        p = p if p is not None else self.params_type()
        if self.rest is None:
            return self.steady_state(u, p)
        return np.asarray(self.rest(np.asarray(u, dtype=float), p), dtype=float)

    def start(self, given: Mapping, p=None) -> tuple:
        """(x0 [n_x], inputs {name: value} for every input) of the component at rest, from `given`
        (see Initialisation: the inputs it does not solve, the outputs demanded of it, and for a
        bus device the load-flow point). ValueError where there is no rest or an input is missing."""
        p = p if p is not None else self.params_type()
        init = self.initialisation
        solves = init.solves if init is not None else ()
        missing = [n for n in self.input_names if n not in solves and n not in given]
        if missing:
            raise ValueError(f"{self.name}: no start without the input(s) {', '.join(missing)}")
        inputs = {n: float(given[n]) for n in self.input_names if n not in solves}
        if init is None:
            x0 = self.steady_state(np.array([inputs[n] for n in self.input_names]), p)
            return x0, inputs
        x0, solved = init.start(dict(given), p)
        inputs.update({n: float(solved[n]) for n in solves})
        return np.asarray(x0, dtype=float), {n: inputs[n] for n in self.input_names}

    def params(self, values: Mapping | None = None):
        """The component's parameters from a mapping of some of them (the rest default), checked:
        unknown names, non-numbers and out-of-range values raise ParameterError naming the field."""
        values = {} if values is None else values
        if not isinstance(values, Mapping):
            raise ParameterError(f"{self.name} parameters must be a JSON object of name: number, "
                                 f"got {type(values).__name__}")
        known = [f.name for f in fields(self.params_type)]
        unknown = [str(k) for k in values if k not in known]
        if unknown:
            raise ParameterError(f"unknown {self.name} parameter(s) {', '.join(repr(k)[:40] for k in unknown[:5])} "
                                 f"(known: {', '.join(known)})")
        return self.params_type(**values)

    def load_params(self, path) -> object:
        """Parameters from a JSON file of name: number (any subset; the rest default)."""
        path = Path(path)
        try:
            if path.stat().st_size > MAX_PARAMETER_FILE_BYTES:
                raise ParameterError(f"machine file {path} is larger than {MAX_PARAMETER_FILE_BYTES} bytes")
            values = json.loads(path.read_text(encoding="utf-8"), parse_constant=_refuse_constant)
        except IsADirectoryError:
            raise ParameterError(f"machine file {path} is a folder, not a file") from None
        except FileNotFoundError:
            raise ParameterError(f"cannot read machine file {path}: there is no such file") from None
        except OSError as exc:
            raise ParameterError(f"cannot read machine file {path}: {exc.strerror or one_line(exc)}") from None
        except (UnicodeDecodeError, ValueError, RecursionError) as exc:
            if isinstance(exc, ParameterError):
                raise
            raise ParameterError(f"cannot read machine file {path}: {one_line(exc)}") from None
        try:
            return self.params(values)
        except ParameterError as exc:
            raise ParameterError(f"{path}: {exc}") from None


def _finite(value) -> bool:
    """True for a number that is finite as a float (a huge int is not)."""
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def _refuse_constant(name: str):
    raise ValueError(f"{name} is not a number this file may hold")


def _columns(a, n: int) -> list:
    """The n entries of a's last axis as a list."""
    if a.shape[-1] != n:
        raise ValueError(f"expected {n} values on the last axis, got shape {tuple(a.shape)}")
    return [a[..., i] for i in range(n)]


def _broadcast(m, a, x, u, n: int):
    """a on the leading axes of x and u broadcast together, with a last axis of n (a component's
    outputs that read only the inputs follow a batch of states; one without states has none)."""
    shape = (*m.broadcast_shapes(tuple(x.shape[:-1]), tuple(u.shape[:-1])), n)
    return a if tuple(a.shape) == shape else m.broadcast_to(a, shape)


def _namespace(x):
    """(math namespace, stack on a new last axis) for numpy arrays or torch tensors."""
    if type(x).__module__.startswith("torch"):
        import torch

        return torch, lambda parts: torch.stack(list(parts), dim=-1)
    return np, lambda parts: np.stack(list(parts), axis=-1)
