"""A grid case as one DAE, the network solved inside the right-hand side: the monolithic reference
of the grid co-simulation, built from the case's units and their components' definitions, wired
by their ports (case.unit_wiring) exactly as the co-simulation master wires their FMUs.

States: every device's states, device slot by device slot (the machines of all units in generator
order, then the units' second devices, ...), each in its component's order. Couplings: a machine's
bus-port voltage inputs are its generator bus voltage; an input link takes the output link of the
same signal within the unit (a state, or an output of that device evaluated at its inputs); the
terminal voltage is the bus voltage magnitude behind the machine's external impedance; set points
are held at their start values (`controls=False`: every control signal a machine takes is held at
its start value too, and the control devices stand still). Within a cycle of links (an exciter
taking the machine's bus current, the machine its field voltage) the inputs of the device first
reached are read at their start values except its bus voltage: exact where the links read back do
not depend on them (the machines' bus currents do not depend on Pm or Efd). Loads are constant
impedances drawing their load-flow power at the load-flow voltages. A machine's quantities are on
its own base Sn, its bus port on the system base (the components convert).

The network. With the bus devices' states given, each one's bus current (its bus-port current
outputs, network frame) is a function of its bus voltage (V_re, V_im), read at its other inputs:
their start values, or the state of the device of its unit that gives them (GENCLS' Efd enters its
current: held, or an exciter state). A component that declares its current affine in the voltage
(`affine_current`: the machines, whose stator equations are linear in Vs sin(delta - theta_vs) and
Vs cos(delta - theta_vs)) gives its map I = c + A v read off its own output equations at v = 0,
(1, 0), (0, 1) - the declaration is checked when the System is built, at the start state and two
more voltages. The network, Kron-reduced to the units' buses for each topology (Case.reduced; units
at one bus inject into it together), gives I = Y_red V there; with affine currents only, every
right-hand side is one linear solve (Y_red - A) v = c, exact. Any other current (an inverter's
limits, a constant-power load) is linearised at the voltage reached (I(v), and its differences over
NEWTON_STEP in V_re and V_im) and the network solved by Newton from the voltages of the last solve to
NEWTON_TOLERANCE; the last linearisation, at the solution, is evaluated on the namespace whose
conditions the solve locks (so the branches a right-hand side records are those of one linear
solve). The other buses' voltages follow from the units' buses'.

Events: the topologies of the contingency (Contingency.topologies: a fault, a shunt of impedance
`fault_impedance`, default 1e-6 pu: bolted, at a bus from `fault_start` to `clear_s`, absolute
times in s; branches opened; units tripped: they inject no current, their devices stand still and
their rotor angles leave the stability check); scipy's DOP853 (rtol 1e-10 by default), or Radau
where the case is stiff (STIFF_RATE), restarts at every topology change. Limiters, switches and
saturations (reference_models.piecewise.where) run on locked branches, their switchings located and
the solve restarted there with the components' limit resets applied (`simulate`). A run is stable
when no rotor-angle difference between two units in service exceeds pi before `stop` (located on
the solver's dense output).
"""
from __future__ import annotations

import math

import numpy as np

from .case import Case, Reduced, external_impedance, held_inputs, measured_values, remote_wiring, unit_wiring
from .contingency import BOLTED_FAULT_IMPEDANCE, Contingency, Topology
from .result import GridResult, device_labels, rotor_angle_state


class _Branches:
    """A math namespace for the equations' scalars (the `math` module's functions) whose `where`
    (reference_models.piecewise) either records the branch each condition takes (`locked` None:
    `modes`, in call order) or returns the branch locked for that call (`locked`: the modes of a
    recording pass, taken in the same call order; the order of the calls is fixed by the case and the
    topology, as both branches are always evaluated). `owner` (unit, device) is set by the caller
    before each device's equations; a recording pass keeps it per condition (`owners`)."""

    __slots__ = ("modes", "locked", "at", "owner", "owners")

    def __init__(self, locked=None):
        self.modes, self.locked, self.at, self.owner, self.owners = [], locked, 0, None, []

    def where(self, condition, a, b):
        if self.locked is None:
            taken = bool(condition)
            self.modes.append(taken)
            self.owners.append(self.owner)
        else:
            taken = self.locked[self.at]
            self.at += 1
        return a if taken else b


for _name, _value in vars(math).items():  # the math module's functions and constants
    if not _name.startswith("_"):
        setattr(_Branches, _name, staticmethod(_value) if callable(_value) else _value)


def _scalar(m) -> bool:
    """True for the namespaces of scalar equations (math, _Branches), False for numpy's arrays."""
    return m is math or isinstance(m, _Branches)


NEWTON_STEP = 1e-7  # pu: the voltage difference a non-affine current is linearised over
NEWTON_TOLERANCE = 1e-14  # pu: the voltage change that ends the network's Newton iteration (converged to rounding:
# a right-hand side that depends on where its iteration stopped is noise to a tight integrator)
NEWTON_ITERATIONS = 30


def _bus_current(component, x, p, m, u0, V_re, V_im):
    """(I_re, I_im): the bus current of a device in states x at bus voltage V_re + j V_im (scalars, or
    arrays with m = numpy), its other inputs u0 (component order, the bus-port entries ignored;
    None: zeros)."""
    magnitude, angle, real, imaginary = component.bus_port_at
    u = [0.0] * len(component.inputs) if u0 is None else list(u0)
    if _scalar(m):
        u[magnitude], u[angle] = math.hypot(V_re, V_im), math.atan2(V_im, V_re)
    else:
        u[magnitude], u[angle] = np.hypot(V_re, V_im), np.arctan2(V_im, V_re)
    y = component.output_equations(x, tuple(u), p, m)
    return y[real], y[imaginary]


def _current_map(component, x, p, m, u0=None, at=None):
    """(c [2], A [2][2]) with the device's bus current (I_re, I_im) = c + A (V_re, V_im): read off
    the component's output equations at v = 0, (1, 0), (0, 1) (at None: exact for an affine
    current), or its linearisation at the voltage `at` = (V_re, V_im) (differences over
    NEWTON_STEP). x: its states, scalars or arrays; u0: its other inputs, component order, the
    bus-port entries ignored (None: zeros)."""
    if at is None:
        c = _bus_current(component, x, p, m, u0, 0.0, 0.0)
        r = _bus_current(component, x, p, m, u0, 1.0, 0.0)
        i = _bus_current(component, x, p, m, u0, 0.0, 1.0)
        return c, ((r[0] - c[0], i[0] - c[0]), (r[1] - c[1], i[1] - c[1]))
    v_re, v_im = at
    f = _bus_current(component, x, p, m, u0, v_re, v_im)
    r = _bus_current(component, x, p, m, u0, v_re + NEWTON_STEP, v_im)
    i = _bus_current(component, x, p, m, u0, v_re, v_im + NEWTON_STEP)
    A = (((r[0] - f[0]) / NEWTON_STEP, (i[0] - f[0]) / NEWTON_STEP),
         ((r[1] - f[1]) / NEWTON_STEP, (i[1] - f[1]) / NEWTON_STEP))
    return (f[0] - A[0][0] * v_re - A[0][1] * v_im, f[1] - A[1][0] * v_re - A[1][1] * v_im), A


def unit_inputs(devices, wiring, starts, impedance: complex, state, V_re, V_im, controls: bool = True, m=math,
                held=None, measured=None, remote=None) -> list:
    """The inputs of every device of a unit (tuples in component order), wired by `wiring`
    (case.unit_wiring): the bus voltage V_re + j V_im (scalars, m = math; arrays, m = numpy), the
    devices' states `state(j)` (lists in component order), the terminal voltage behind `impedance`,
    set points at their start values in `starts` (or `held` {variable: value} of the machine where
    given), network measurements from `measured` {device index: its MEASURED values}, a signal from
    another unit by `remote(source)`.
    controls=False: the machine's links from other devices held at their start values."""
    if _scalar(m):
        Vs, theta = math.hypot(V_re, V_im), math.atan2(V_im, V_re)
    else:
        Vs, theta = np.hypot(V_re, V_im), np.arctan2(V_im, V_re)
    held = held or {}
    inputs = [None] * len(devices)
    outputs = [None] * len(devices)  # each device's outputs, once its inputs are final

    def value(j, variable):
        d = devices[j]
        if variable in d.component.state_names:
            return state(j)[d.component.state_names.index(variable)]
        found = outputs[j]
        if found is None:
            found = d.component.output_equations(state(j), inputs_of(j), d.params, m)
            if j in final:  # not while a cycle reads j's provisional inputs
                outputs[j] = found
        return found[d.component.output_names.index(variable)]

    def terminal(index):
        if impedance == 0:
            return Vs if index == 0 else theta
        bus = devices[0].component.ports.bus
        I_re, I_im = (value(0, n) for n in bus.current)
        if _scalar(m):
            Vt = complex(V_re, V_im) + impedance * complex(I_re, I_im)
            return abs(Vt) if index == 0 else theta + math.remainder(math.atan2(Vt.imag, Vt.real) - theta, 2 * math.pi)
        Vt = (V_re + 1j * V_im) + impedance * (I_re + 1j * I_im)
        return np.abs(Vt) if index == 0 else theta + np.remainder(np.angle(Vt) - theta + np.pi, 2 * np.pi) - np.pi

    def inputs_of(j):
        if inputs[j] is None:
            d, wires = devices[j], wiring[j]
            # within a cycle (an exciter taking the machine's current, the machine its field voltage)
            # the device's inputs read their bus values and, for the rest, their start values
            inputs[j] = tuple((Vs if wires[name].index == 0 else theta)
                              if name in wires and wires[name].kind == "bus" else starts[j].inputs[name]
                              for name in d.component.input_names)
            values = []
            for name in d.component.input_names:
                source = wires.get(name)
                start = held.get(name, starts[j].inputs[name]) if j == 0 else starts[j].inputs[name]
                if source is None or source.kind == "held" or (source.kind != "bus" and not controls and j == 0):
                    values.append(start)
                elif source.kind == "bus":
                    values.append(Vs if source.index == 0 else theta)
                elif source.kind == "terminal":
                    values.append(terminal(source.index))
                elif source.kind == "measured":
                    values.append(measured[j][source.index])
                elif source.unit is not None:
                    values.append(remote(source))
                else:
                    values.append(value(source.device, source.variable))
            inputs[j] = tuple(values)
            final.add(j)
        return inputs[j]

    final = set()  # the devices whose inputs are final
    return [inputs_of(j) for j in range(len(devices))]


def simulate_unit(devices, starts, times, bus, rtol: float = 1e-10, atol: float = 1e-12):
    """The states of every device of a unit on a bus whose voltage is prescribed, solved as one ODE
    (scipy DOP853): bus [T, 2 + k] holds over [times[i], times[i + 1]] the bus voltage magnitude [pu]
    and angle [rad] and the k machine inputs nothing in the unit gives (its held links, in its
    ports' order); each stretch of equal rows in one solve. Returns a list per device of its states
    [T, n_j]. devices: case.Device (the machine first); starts: case.DeviceStart per device."""
    from scipy.integrate import solve_ivp

    wiring = unit_wiring([d.component.ports for d in devices], "the unit")
    impedance = external_impedance(devices[0])
    held_names = held_inputs(devices[0].component.ports, wiring[0])
    sizes = [d.component.n_states for d in devices]
    bounds = np.cumsum([0] + sizes)

    def f(y, row):
        def state(j):
            return list(y[bounds[j]:bounds[j + 1]])

        Vs, theta = row[0], row[1]
        inputs = unit_inputs(devices, wiring, starts, impedance, state, Vs * math.cos(theta), Vs * math.sin(theta),
                             held=dict(zip(held_names, row[2:])))
        out = []
        for j, d in enumerate(devices):
            out += list(d.component.derivatives(state(j), inputs[j], d.params, math))
        return out

    times, bus = np.asarray(times, dtype=float), np.asarray(bus, dtype=float)
    y = np.concatenate([np.asarray(s.states, dtype=float) for s in starts])
    out = np.empty((len(times), len(y)))
    out[0] = y
    k = 0
    while k < len(times) - 1:
        end = k + 1
        while end < len(times) - 1 and np.array_equal(bus[end], bus[k]):
            end += 1  # bus[k] holds over [times[k], times[end]]
        row = tuple(bus[k])
        sol = solve_ivp(lambda _t, s, row=row: f(s, row), (times[k], times[end]), y, method="DOP853", rtol=rtol,
                        atol=atol, t_eval=times[k + 1:end + 1])
        if not sol.success:
            raise RuntimeError(f"the monolithic solve failed at t = {times[k]:.4f} s: {sol.message}")
        out[k + 1:end + 1] = sol.y.T
        y = sol.y[:, -1]
        k = end
    return [out[:, bounds[j]:bounds[j + 1]] for j in range(len(devices))]


class System:
    """The DAE of a Case: every device started from the case's start values.

    x0 [n_states]: the equilibrium; `slices[k][j]`: the states of device j of unit k;
    `rhs(t, y, network)` is the right-hand side with the network (Case.reduced) solved inside."""

    def __init__(self, case: Case):
        for unit in case.units:
            for device in unit.devices:
                device.component.require_known_rates("monolithic solve")
        self.case = case
        self.units = case.units
        self.wiring = tuple(unit_wiring([d.component.ports for d in u.devices], f"generator at bus {u.bus}", remote)
                            for u, remote in zip(case.units, remote_wiring(case.units)))
        self.impedance = tuple(external_impedance(u.machine) for u in case.units)
        slots = max(len(u.devices) for u in case.units)
        slices = [[None] * len(u.devices) for u in case.units]
        at = 0
        for j in range(slots):
            for k, u in enumerate(case.units):
                if j < len(u.devices):
                    n = u.devices[j].component.n_states
                    slices[k][j] = slice(at, at + n)
                    at += n
        self.slices = tuple(tuple(s) for s in slices)
        self.n_states = at
        x0 = np.zeros(at)
        for k, u in enumerate(case.units):
            for j, start in enumerate(case.starts[k]):
                x0[self.slices[k][j]] = start.states
        x0.setflags(write=False)
        self.x0 = x0
        # per unit the position of its bus device's rotor angle in the state (None: no rotor angle)
        self.rotor_angles = [None if rotor_angle_state(u.machine.component) is None else
                             self.slices[k][0].start + u.machine.component.state_names.index(
                                 rotor_angle_state(u.machine.component))
                             for k, u in enumerate(case.units)]
        # the machine inputs its bus current is read at: start values, or the state of the device giving them
        self.machine_links = tuple(
            tuple((i, self.slices[giver][w[name].device].start
                   + self.units[giver].devices[w[name].device].component.state_names.index(w[name].variable))
                  for i, name in enumerate(u.machine.component.input_names)
                  for giver in [k if w.get(name) is None or w[name].unit is None else w[name].unit]
                  if name in w and w[name].kind == "device"
                  and w[name].variable in self.units[giver].devices[w[name].device].component.state_names)
            for k, (u, w) in enumerate(zip(case.units, (wi[0] for wi in self.wiring))))
        buses = list(dict.fromkeys(u.bus for u in case.units))  # the reduced network's buses, in Case.reduced's order
        self.bus_slot = tuple(buses.index(u.bus) for u in case.units)
        self.first_unit = tuple(self.bus_slot.index(b) for b in range(len(buses)))
        self._networks = {}
        self._voltages = {}  # id(Reduced) -> the reduced buses' voltages of the last scalar solve there
        # unit -> [(device, Measurement)] of the devices that measure the network
        self.measuring = {k: [(j, d.measures) for j, d in enumerate(u.devices)
                              if any(s.kind == "measured" for s in self.wiring[k][j].values())]
                          for k, u in enumerate(case.units)}
        self.measuring = {k: v for k, v in self.measuring.items() if v}
        self._rates = {}  # controls -> largest_rate(controls)
        self._check_affine_currents()

    def largest_rate(self, controls: bool = True) -> float:
        """The largest |eigenvalue| [1/s] of the right-hand side's Jacobian at the start, intact network,
        branches and limits as they hold there (_largest_rate); kept per `controls`."""
        if controls not in self._rates:
            f = _Locked(self, self.network(), controls, (), lambda t: None)
            y = f.reset(self.x0, 0.0, 0.0)[0]
            f.lock(0.0, y)
            self._rates[controls] = _largest_rate(f, 0.0, y)
        return self._rates[controls]

    def _check_affine_currents(self) -> None:
        """ValueError where a bus device declares its current affine in its bus voltage
        (Component.affine_current) and it is not, at its start state: the map read at 0, 1 and j
        must give the current at the load-flow voltage and at two voltages around it."""
        for k, unit in enumerate(self.units):
            d = unit.machine
            if not d.component.affine_current:
                continue
            x, u0 = list(self.case.starts[k][0].states), self._machine_u(k, self.x0)
            (c_re, c_im), ((a, b), (e, f)) = _current_map(d.component, x, d.params, math, u0)
            V = complex(self.case.flow.V_complex[self.case.network.bus_index(unit.bus)])
            for probe in (V, 1.1 * V, V * complex(math.cos(0.3), math.sin(0.3))):
                I = complex(*_bus_current(d.component, x, d.params, math, u0, probe.real, probe.imag))
                mapped = complex(c_re + a * probe.real + b * probe.imag, c_im + e * probe.real + f * probe.imag)
                if abs(I - mapped) > 1e-9 * max(1.0, abs(I)):
                    raise ValueError(f"{d.component.name} at bus {unit.bus} declares its bus current affine in the "
                                     f"bus voltage, but it is not (off by {abs(I - mapped):.3g} pu at {abs(probe):.3g} pu)")

    def network(self, fault_bus: int | None = None, fault_impedance: complex = BOLTED_FAULT_IMPEDANCE,
                out_of_service=(), loads_off=()) -> Reduced:
        """Case.reduced, kept per topology."""
        key = (fault_bus, complex(fault_impedance) if fault_bus is not None else None, tuple(out_of_service),
               tuple(loads_off))
        if key not in self._networks:
            self._networks[key] = self.case.reduced(fault_bus, fault_impedance, out_of_service, loads_off)
        return self._networks[key]

    def generator_voltages(self, y, network: Reduced, m=math, tripped=()):
        """(V_re [g], V_im [g]) at every unit's bus for the state y (m = math or a _Branches namespace),
        or for states y [n, n_states] (m = numpy: arrays [n, g]); units at one bus inject into it
        together; the units `tripped` (indices) inject nothing. Affine currents in one linear solve,
        any other by Newton (module docstring)."""
        active = [k for k in range(len(self.units)) if k not in tripped]
        scalar = _scalar(m)
        y = y if scalar else np.asarray(y)
        states = {k: (list(y[self.slices[k][0]]) if scalar else
                      [y[:, j] for j in range(self.slices[k][0].start, self.slices[k][0].stop)]) for k in active}
        others = {k: self._machine_u(k, y, math if scalar else np) for k in active}
        newton = [k for k in active if not self.units[k].machine.component.affine_current]
        at = None
        if newton:
            at = self._last_voltages(network, None if scalar else y.shape[0])
            plain = math if scalar else np
            for _ in range(NEWTON_ITERATIONS):
                v = self._linear_solve(network, states, others, active, newton, plain, at, scalar)
                change = np.max(np.abs(v - at))
                at = v
                if change < NEWTON_TOLERANCE:
                    break
        if scalar and m is not math:
            v = self._linear_solve(network, states, others, active, newton, m, at, scalar)
        elif not newton:
            v = self._linear_solve(network, states, others, active, newton, m, at, scalar)
        else:
            v = at
        if scalar:
            self._voltages[id(network)] = v
        slots = list(self.bus_slot)
        return (v[0::2][slots], v[1::2][slots]) if scalar else (v[:, 0::2][:, slots], v[:, 1::2][:, slots])

    def _last_voltages(self, network: Reduced, rows: int | None) -> np.ndarray:
        """v [2b] (or [rows, 2b]): the reduced buses' voltages of the last scalar solve in this
        topology, else the load flow's."""
        v = self._voltages.get(id(network))
        if v is None:
            V = self.case.flow.V_complex[[self.case.network.bus_index(u.bus) for u in self.units]][list(self.first_unit)]
            v = np.empty(2 * len(V))
            v[0::2], v[1::2] = V.real, V.imag
        return v.copy() if rows is None else np.tile(v, (rows, 1))

    def _linear_solve(self, network: Reduced, states, others, active, newton, m, at, scalar) -> np.ndarray:
        """v [2b] (or [n, 2b]): the network solved with every active unit's current map (exact for an
        affine one, linearised at `at` for those in `newton`) evaluated on m."""
        b = len(self.first_unit)
        if scalar:
            M, c = np.array(network.Y_real), np.zeros(2 * b)
        else:
            n = len(at) if at is not None else len(next(iter(states.values()))[0])
            M = np.broadcast_to(network.Y_real, (n, 2 * b, 2 * b)).copy()
            c = np.zeros((n, 2 * b))
        slots, maps = [], []  # scalar: per active unit its bus's first row in M and its (c, A) flattened
        for k in active:
            if isinstance(m, _Branches):
                m.owner = (k, 0)
            d, i = self.units[k].machine, 2 * self.bus_slot[k]
            point = None if k not in newton else ((at[i], at[i + 1]) if scalar else (at[:, i], at[:, i + 1]))
            ck, A = _current_map(d.component, states[k], d.params, m, others[k], point)
            if scalar:
                slots.append(i)
                maps.append((ck[0], ck[1], A[0][0], A[0][1], A[1][0], A[1][1]))
                continue
            for r in range(2):
                c[..., i + r] += ck[r]
                for q in range(2):
                    M[..., i + r, i + q] -= A[r][q]
        if slots:  # in one numpy call each; units on one bus add up in unit order (ufunc.at is unbuffered)
            rows, values = np.array(slots), np.array(maps, dtype=float)
            np.add.at(c, rows, values[:, 0])
            np.add.at(c, rows + 1, values[:, 1])
            for e, (r, q) in enumerate(((0, 0), (0, 1), (1, 0), (1, 1))):
                np.subtract.at(M, (rows + r, rows + q), values[:, 2 + e])
        return np.linalg.solve(M, c) if scalar else np.linalg.solve(M, c[..., None])[..., 0]

    def _machine_u(self, k: int, y, m=math) -> list:
        """The inputs of unit k's machine (component order) that its bus current is read at: each
        held at its start value, or the state of the device of its unit that gives it (y [n_states],
        m = math; y [n, n_states], m = numpy)."""
        start = self.case.starts[k][0].inputs
        u = [start[name] for name in self.units[k].machine.component.input_names]
        for i, at in self.machine_links[k]:
            u[i] = y[at] if _scalar(m) else y[:, at]
        return u

    def unit_inputs(self, k: int, y, V_re, V_im, controls: bool = True, m=math, measured=None, _through=()) -> list:
        """The inputs of every device of unit k (tuples in component order) at state y (scalars, m =
        math; or arrays over rows, m = numpy) and the units' bus voltages V_re + j V_im ([g], or
        [n, g]); `measured`: the network's measurements of every unit (System.measured). A signal
        from another unit is that unit's device's state, or its output at that unit's inputs."""
        scalar = _scalar(m)

        def state_of(unit, j):
            at = self.slices[unit][j]
            return [y[i] for i in range(at.start, at.stop)] if scalar else [y[:, i] for i in range(at.start, at.stop)]

        def remote(source):
            if source.unit in _through + (k,):
                raise ValueError(f"the units at buses {self.units[k].bus} and {self.units[source.unit].bus} take "
                                 "signals from each other through their outputs")
            d = self.units[source.unit].devices[source.device]
            x = state_of(source.unit, source.device)
            if source.variable in d.component.state_names:
                return x[d.component.state_names.index(source.variable)]
            inputs = self.unit_inputs(source.unit, y, V_re, V_im, controls, m, measured, _through + (k,))
            return d.component.output_equations(x, inputs[source.device], d.params, m)[
                d.component.output_names.index(source.variable)]

        own = (V_re[k], V_im[k]) if scalar else (V_re[:, k], V_im[:, k])
        return unit_inputs(self.units[k].devices, self.wiring[k], self.case.starts[k], self.impedance[k],
                           lambda j: state_of(k, j), *own, controls, m,
                           measured=None if measured is None else measured.get(k), remote=remote)

    def measured(self, V_re, V_im, network: Reduced) -> dict | None:
        """{unit: {device: its MEASURED values}} at the unit-bus voltages V_re + j V_im ([g], or [n, g]),
        the other buses' by the network's recovery, each measured angle continuous with its unit's bus
        angle; None where no device measures."""
        if not self.measuring:
            return None
        V = np.asarray(V_re) + 1j * np.asarray(V_im)
        V_bus = V[..., list(self.first_unit)] @ network.recovery.T
        out = {}
        for k, devices in self.measuring.items():
            theta = np.angle(V[..., k])
            out[k] = {}
            for j, measures in devices:
                values = list(measured_values(self.case.network, V_bus, measures, network.open))
                values[1] = theta + np.remainder(values[1] - theta + np.pi, 2 * np.pi) - np.pi
                out[k][j] = values
        return out

    def rhs(self, t, y, network: Reduced, controls: bool = True, m=math, tripped=()) -> np.ndarray:
        """dy/dt [n_states] with the network voltages solved for the state y; m: the math namespace
        the equations run on (math: their conditions as they hold at y; a _Branches namespace: its
        locked branches); the devices of the units `tripped` (indices) stand still."""
        V_re, V_im = self.generator_voltages(y, network, m, tripped)
        measured = self.measured(V_re, V_im, network)
        out = np.zeros(self.n_states)
        for k, unit in enumerate(self.units):
            if k in tripped:
                continue
            if m is not math:
                m.owner = (k, None)
            inputs = self.unit_inputs(k, y, V_re, V_im, controls, m, measured)
            for j, d in enumerate(unit.devices):
                if j > 0 and not controls:
                    continue
                if m is not math:
                    m.owner = (k, j)
                s = self.slices[k][j]
                out[s] = d.component.derivatives(list(y[s]), inputs[j], d.params, m)
        return out

    def reset(self, y, network: Reduced, controls: bool = True, tripped=()) -> np.ndarray:
        """The state [n_states] after every device's limit resets (Component.reset_states) at its
        inputs at y; the devices that stand still (tripped units, controls=False) are left as they are."""
        y = np.array(y, dtype=float)
        V_re, V_im = self.generator_voltages(y, network, math, tripped)
        measured = self.measured(V_re, V_im, network)
        for k, unit in enumerate(self.units):
            if k in tripped:
                continue
            inputs = self.unit_inputs(k, y, V_re, V_im, controls, measured=measured)
            for j, d in enumerate(unit.devices):
                if j > 0 and not controls:
                    continue
                s = self.slices[k][j]
                y[s] = d.component.reset_states(np.array(y[s]), np.array(inputs[j], dtype=float), d.params)
        return y

    def observe(self, t, y, network: Reduced, controls: bool = True, tripped=()) -> dict:
        """The result rows for states y [n, n_states] at times t [n] in one topology: time, V_gen,
        V_bus, Vs, theta_vs, P, Q [n, g] / [n, buses], states {name: [n, g]} and machine_inputs
        (the units `tripped` inject no current: P = Q = 0)."""
        y = np.atleast_2d(y)
        n, g = len(y), len(self.units)
        V_re, V_im = self.generator_voltages(y, network, np, tripped)
        measured = self.measured(V_re, V_im, network)
        V_gen = V_re + 1j * V_im
        # the bus angles continuous: near the rotor angle of a machine, unwrapped along the rows elsewhere
        delta = np.full((n, g), np.nan)
        theta_vs = np.unwrap(np.angle(V_gen), axis=0)
        for k, at in enumerate(self.rotor_angles):
            if at is not None:
                delta[:, k] = y[:, at]
                theta_vs[:, k] = delta[:, k] + np.angle(V_gen[:, k] * np.exp(-1j * delta[:, k]))
        I = np.empty((n, g), dtype=complex)
        states, machine_inputs, device_states = {}, {}, {}
        labels = device_labels(self.units)
        for k, unit in enumerate(self.units):
            inputs = self.unit_inputs(k, y, V_re, V_im, controls, np, measured)
            machine = unit.machine
            bus = machine.component.ports.bus
            u = np.stack([np.broadcast_to(np.asarray(v, dtype=float), (n,)) for v in inputs[0]], -1)
            u[:, machine.component.input_names.index(bus.voltage[1])] = theta_vs[:, k]
            outputs = machine.component.output_values(y[:, self.slices[k][0]], u, machine.params)
            I[:, k] = 0.0 if k in tripped else (outputs[:, machine.component.output_names.index(bus.current[0])]
                                                + 1j * outputs[:, machine.component.output_names.index(bus.current[1])])
            for name, column in zip(machine.component.input_names, u.T):
                machine_inputs.setdefault(name, np.full((n, g), np.nan))[:, k] = column
            for j, d in enumerate(unit.devices):
                for i, name in enumerate(d.component.state_names):
                    column = y[:, self.slices[k][j].start + i]
                    device_states[f"{labels[k][j]}_{name}"] = column
                    if j == 0:
                        states.setdefault(name, np.full((n, g), np.nan))[:, k] = column
        S = V_gen * np.conj(I)
        for k in range(g):
            device_states[f"{labels[k][0]}_P"], device_states[f"{labels[k][0]}_Q"] = S.real[:, k], S.imag[:, k]
            device_states[f"{labels[k][0]}_I_re"], device_states[f"{labels[k][0]}_I_im"] = I.real[:, k], I.imag[:, k]
        return {"time": np.asarray(t, dtype=float), "V_gen": V_gen, "V_bus": V_gen[:, list(self.first_unit)] @ network.recovery.T,
                "Vs": np.abs(V_gen), "theta_vs": theta_vs, "P": S.real, "Q": S.imag, "states": states,
                "machine_inputs": machine_inputs, "device_states": device_states, "rotor_angle": delta}


# A healthy solve of a shipped case takes 2,000-6,000 evaluations of the right-hand side for 5 s with
# a fault; one whose step collapses is stopped at this budget. Each switching condition of the case
# adds RHS_BUDGET_PER_CONDITION: every located switching restarts the solve, and a case of many
# limited devices switches more (ieee14 with a 30-unit PVD1 feeder: 300 conditions, 35,000
# evaluations for 3 s with a fault).
RHS_BUDGET_BASE, RHS_BUDGET_PER_SECOND, RHS_BUDGET_PER_CONDITION = 10_000, 4_000, 100
# the width of the bracket a switching is located to [s], relative to max(1, |t|) (as the native
# reference FMU's DOPRI5_EVENT_RESOLUTION)
SWITCHING_RESOLUTION = 1e-12
# Sliding on a moving limit. A state on a limit that moves away from it while its rate keeps pushing
# on it (IEEEX1's VRMAX Vt rising) switches infinitely often (Zeno): a condition that changed at a
# restart and changes back within ZENO_GAP [s] of it slides. While it is locked to the branch it
# slides on, its switchings are not located; the solve restarts every ZENO_DWELL [s] (resets
# applied, branches re-locked), and from the other branch its return is located as any switching
# (the state catches up with its limit and is placed on it); a sample that leaves its lock unchanged
# ends the sliding. A state beyond a limit that moves towards it (the limit falling under a state
# held on it) is placed back on it by the resets: the solve restarts after any step whose end the
# resets move (by more than the tolerance), and every ZENO_DWELL while they do. So a state follows
# a moving limit sampled every ZENO_DWELL at most, as ANDES' fixed step of that size does (off the
# limit by at most the limit's motion over ZENO_DWELL), instead of stalling.
ZENO_GAP, ZENO_DWELL = 1e-6, 1e-3
# Stiffness. An explicit method's step is bounded by its stability, whatever the accuracy asks for:
# |h lambda| <= about 6 for DOP853 on the negative real axis. A case with a fast inner loop (ESST3A's
# TM dVM/dt = KM (VR - KG VB VM) - VM with KM = 500, TM = 0.1: lambda = -(KM KG VB + 1) / TM, about
# -2.2e4 1/s in kundur_esst3a) takes steps of 0.3 ms at rest and runs out of the budget (4,000
# evaluations per second: DOP853's 12 per step at 3 ms steps, a rate of 2,000 1/s). Where the
# Jacobian's largest |eigenvalue| at the start (System.largest_rate) exceeds STIFF_RATE, `simulate`
# uses the implicit STIFF_METHOD (its steps bounded by accuracy alone). The shipped cases without such
# a loop: 50-160 1/s (kundur_full, ieee14_full, ieee39_full, npcc, EI_33).
STIFF_RATE, STIFF_METHOD = 2000.0, "Radau"


class _Stalled(Exception):
    """The right-hand side was evaluated more often than the budget allows (at time `t` [s])."""

    def __init__(self, t: float):
        super().__init__(t)
        self.t = t


class _Locked:
    """The right-hand side of one topology with its branches locked, and the checks around it.

    `natural(t, y)`: (modes, dy/dt) with every condition as it holds at y; `on(t, y, modes)`: dy/dt
    with the branches `modes`; `rhs(t, y)`: dy/dt on the locked branches `modes`; `differing(t, y,
    held)`: the conditions whose branches at y differ from their locks where that gives another dy/dt
    (the native reference FMU's test); `reset(y)` and `lock(t, y)`: a restart's two parts;
    `spread(y)`: the largest rotor-angle difference of the units in service less pi [rad];
    `owners[i]`: (unit, device or None for the unit's input links) of condition i. Every evaluation
    counts against the budget (`count(t)`); `resets`: whether restarts apply the limit resets."""

    def __init__(self, system: System, network: Reduced, controls: bool, tripped: tuple, count, resets: bool = True):
        self.system, self.network, self.controls, self.tripped, self.count = system, network, controls, tripped, count
        self.resets = resets
        self.modes, self.owners = (), ()
        self.angles = [a for k, a in enumerate(system.rotor_angles) if k not in tripped and a is not None]

    def natural(self, t, y):
        self.count(t)
        m = _Branches()
        dy = self.system.rhs(t, y, self.network, self.controls, m, self.tripped)
        self.owners = m.owners
        return tuple(m.modes), dy

    def on(self, t, y, modes):
        self.count(t)
        return self.system.rhs(t, y, self.network, self.controls, _Branches(modes), self.tripped)

    def rhs(self, t, y):
        """dy/dt on the locked branches. Where a locked branch is evaluated outside its domain (the
        square root of a current headroom gone negative past the switching that ends the branch), with
        every condition as it holds at y instead: the branch's continuation there (the headroom is
        0), and the switching is located after the step as any other."""
        try:
            return self.on(t, y, self.modes)
        except (ArithmeticError, ValueError) as exc:
            if isinstance(exc, ValueError) and str(exc) != "math domain error":
                raise
            self.count(t)
            return self.system.rhs(t, y, self.network, self.controls, _Branches(), self.tripped)

    def differing(self, t, y, held=frozenset()) -> frozenset:
        """The conditions whose branch at y (not one `held`) differs from its lock, where the
        branches at y give another dy/dt than the locked ones (else none)."""
        modes, natural = self.natural(t, y)
        if held:
            modes = tuple(self.modes[i] if i in held else q for i, q in enumerate(modes))
        if modes == self.modes:
            return frozenset()
        if held:
            natural = self.on(t, y, modes)
        if np.array_equal(self.rhs(t, y), natural):
            return frozenset()
        return frozenset(i for i, (p, q) in enumerate(zip(self.modes, modes)) if p != q)

    def reset(self, y, rtol: float, atol: float):
        """(the state after the limit resets at y, whether they moved it by more than the tolerance
        atol + rtol |y|); y itself where `resets` is off."""
        if not self.resets:
            return np.array(y, dtype=float), False
        reset = self.system.reset(y, self.network, self.controls, self.tripped)
        return reset, bool(np.any(np.abs(reset - y) > atol + rtol * np.abs(y)))

    def lock(self, t, y) -> frozenset:
        """Lock the branches holding at y; the conditions whose lock changed."""
        old, self.modes = self.modes, self.natural(t, y)[0]
        return frozenset(i for i, (p, q) in enumerate(zip(old, self.modes)) if p != q)

    def spread(self, y) -> float:
        if len(self.angles) < 2:
            return -math.pi
        angles = y[self.angles]
        return float(np.max(angles) - np.min(angles)) - math.pi


def _largest_rate(f: _Locked, t: float, y) -> float:
    """The largest |eigenvalue| [1/s] of the Jacobian of f.rhs (its locked branches) at (t, y), from
    finite-difference products J v: the dense Jacobian for a few states, else ARPACK (about 20
    evaluations of the right-hand side, to 1 %)."""
    from scipy.sparse.linalg import ArpackNoConvergence, LinearOperator, eigs

    y = np.asarray(y, dtype=float)
    if y.size == 0:  # no state (a case of static devices alone)
        return 0.0
    f0, n = f.rhs(t, y), y.size

    def product(v):
        v = np.ravel(v).real
        size = float(np.linalg.norm(v))
        if size == 0:
            return np.zeros(n)
        d = math.sqrt(np.finfo(float).eps) * (1.0 + float(np.linalg.norm(y))) / size
        return (f.rhs(t, y + d * v) - f0) / d

    if n <= 32:
        return float(np.abs(np.linalg.eigvals(np.column_stack([product(e) for e in np.eye(n)]))).max())
    try:
        values = eigs(LinearOperator((n, n), matvec=product, dtype=float), k=1, which="LM", tol=1e-2,
                      return_eigenvectors=False)
    except ArpackNoConvergence as partial:
        values = partial.eigenvalues
    return float(np.abs(values).max()) if len(values) else 0.0


def simulate(system: System, contingency: Contingency, stop: float = 5.0, t_eval=None, *, step: float = 0.01,
             controls: bool = True, method: str | None = None, rtol: float = 1e-10, atol: float = 1e-12,
             event_rows: bool = False, stop_at_loss: bool = False, resets: bool = True) -> GridResult:
    """The case from its load-flow equilibrium through `contingency` until `stop` [s].

    Rows at t_eval (default: every `step` s from 0 to stop); `event_rows`: the state just before
    each event too. `controls=False`: every control signal a machine takes held at its start value.
    `stop_at_loss`: the solve ends where two rotor angles of units in service get pi apart (the rows
    end at the first row past it, or at the end of the step that crossed).

    Each topology of the contingency (Contingency.topologies: fault, clearing, opened branches,
    tripped units, whose devices stand still and inject nothing) is integrated by scipy's `method`
    (None: DOP853, or STIFF_METHOD where System.largest_rate exceeds STIFF_RATE) with the conditions of every device's equations locked to the branches they take at its start
    (the native reference FMU's scheme, fmu_export/c/dopri5.c), so the right-hand side is smooth
    within each step; after each accepted step the branches holding at its end are compared with
    the locked ones, and where they differ (and give another right-hand side) the first instant they
    do is bracketed by bisection on the step's dense output to SWITCHING_RESOLUTION, and the solve
    restarts from the bracket's right end. At every (re)start (t = 0, each topology change, each
    located switching) every device's limit resets (Component.reset_states; `resets=False`: not
    applied) are applied and the branches locked afresh. Chattering: see ZENO_GAP. RuntimeError
    where the right-hand side is evaluated more than RHS_BUDGET_BASE + RHS_BUDGET_PER_SECOND * stop
    + RHS_BUDGET_PER_CONDITION * (the number of switching conditions) times (naming the device whose conditions switched most) or the solver fails."""
    import scipy.integrate
    from scipy.optimize import brentq

    if not (math.isfinite(stop) and stop > 0):
        raise ValueError(f"stop must be a positive time, got {stop!r}")
    if t_eval is None:
        t_eval = np.linspace(0.0, stop, int(round(stop / step)) + 1)
    t_eval = np.asarray(t_eval, dtype=float)
    if t_eval.ndim != 1 or np.any(np.diff(t_eval) < 0) or t_eval[0] < 0 or t_eval[-1] > stop:
        raise ValueError("t_eval must be increasing times within [0, stop]")
    if method is None:
        method = STIFF_METHOD if system.largest_rate(controls) > STIFF_RATE else "DOP853"
    solver_type = getattr(scipy.integrate, method)
    topologies = contingency.topologies(stop)
    if topologies[0].fault_bus is not None or topologies[0].open or topologies[0].tripped:
        # a change at t = 0: the intact network for no time before it (its event and rows at 0)
        topologies = [Topology(0.0, None, (), "intact")] + list(topologies)
    budget = RHS_BUDGET_BASE + RHS_BUDGET_PER_SECOND * stop  # and RHS_BUDGET_PER_CONDITION, once counted
    calls = [0]

    def count(t):
        calls[0] += 1
        if calls[0] > budget:
            raise _Stalled(t)

    y = np.array(system.x0)
    pieces, lost, switched_by = [], None, {}
    for n, tp in enumerate(topologies):
        a = tp.start
        b = topologies[n + 1].start if n + 1 < len(topologies) else stop
        last = n == len(topologies) - 1
        network = system.network(tp.fault_bus, contingency.fault_impedance, tp.open, tp.loads_off)
        inside = (t_eval >= a) & ((t_eval <= b) if last else (t_eval < b))
        times = list(t_eval[inside])
        if event_rows and n > 0 and (not times or times[0] != a):
            times.insert(0, a)
        if event_rows and not last:
            times.append(b)
        rows_t, rows_y = [], []
        f = _Locked(system, network, controls, tuple(tp.tripped), count, resets)
        try:
            y, moved = f.reset(y, rtol, atol)
            changed = f.lock(a, y)
            if n == 0:
                budget += RHS_BUDGET_PER_CONDITION * len(f.modes)
            t, restarted, sliding, held, at, ended, h = a, a, {}, frozenset(), 0, False, None
            sample = a + ZENO_DWELL if moved else math.inf
            while at < len(times) and times[at] <= a:
                rows_t.append(times[at])
                rows_y.append(y)
                at += 1
            spread = f.spread(y)
            while t < b and not ended:
                bound = min(b, sample)
                solver = solver_type(f.rhs, t, y, bound, rtol=rtol, atol=atol,
                                     **({"first_step": min(h, bound - t)} if h else {}))
                while True:
                    message = solver.step()
                    if solver.status == "failed":
                        raise RuntimeError(f"the monolithic solve failed at t = {solver.t:.6g} s "
                                           f"({network.description}): {message}")
                    t0, t1, y1 = solver.t_old, solver.t, solver.y
                    h = getattr(solver, "h_abs", None) or solver.step_size
                    dense = None
                    flips = f.differing(t1, y1, held)
                    if flips:
                        dense = solver.dense_output()
                        lo, hi = t0, t1
                        # a sliding condition's return onto its limit is located to ZENO_GAP (the resets
                        # place the state on the limit there), any other switching to SWITCHING_RESOLUTION
                        resolution = ZENO_GAP if flips <= sliding.keys() else SWITCHING_RESOLUTION * max(1.0, abs(hi))
                        while hi - lo > resolution:
                            mid = lo + 0.5 * (hi - lo)
                            if not lo < mid < hi:
                                break
                            if f.differing(mid, dense(mid), held):
                                hi = mid
                            else:
                                lo = mid
                        if hi < t1:
                            t1, y1 = hi, dense(hi)
                            flips = f.differing(t1, y1, held)
                        back = flips & changed
                        if back and t1 - restarted < ZENO_GAP:
                            # chattering: those conditions slide; the step is taken again from its start
                            # with them held on the branches they were locked to
                            sliding.update((i, f.modes[i]) for i in back)
                            held = frozenset(i for i, v in sliding.items() if f.modes[i] == v)
                            sample = min(sample, restarted + ZENO_DWELL)
                            t, y = t0, dense(t0)
                            break
                    s1 = f.spread(y1)
                    if spread < 0 <= s1 and lost is None:
                        dense = dense if dense is not None else solver.dense_output()
                        lost = brentq(lambda s: f.spread(dense(s)), t0, t1, xtol=1e-12)
                    spread = s1
                    if at < len(times) and times[at] <= t1:
                        dense = dense if dense is not None else solver.dense_output()
                        k = at
                        while k < len(times) and times[k] <= t1:
                            k += 1
                        rows_t.extend(times[at:k])
                        rows_y.extend(np.atleast_2d(dense(np.array(times[at:k])).T))
                        at = k
                    if stop_at_loss and lost is not None:
                        # the rows end with the step that crossed: its end where no row lies past the
                        # loss, so that the last row shows the spread beyond pi (cosim.stability's verdict)
                        if not rows_t or rows_t[-1] < lost:
                            rows_t.append(t1)
                            rows_y.append(np.array(y1))
                        ended = True
                        break
                    t, y = t1, np.array(y1)
                    sampled = sample <= t < b
                    y, moved = f.reset(y, rtol, atol) if t < b else (y, False)
                    if flips or sampled or moved:
                        for i in flips:
                            switched_by[f.owners[i]] = switched_by.get(f.owners[i], 0) + 1
                        changed = f.lock(t, y)
                        restarted = t
                        if sampled:  # a sliding condition whose lock did not change at this sample stops sliding
                            sliding = {i: v for i, v in sliding.items() if i in changed}
                            sample = t + ZENO_DWELL if (sliding or moved) else math.inf
                        elif moved:
                            sample = min(sample, t + ZENO_DWELL)
                        held = frozenset(i for i, v in sliding.items() if f.modes[i] == v)
                        break
                    if solver.status == "finished":
                        break
        except _Stalled as stalled:
            raise RuntimeError(f"the monolithic solve stalled at t = {stalled.t:.4f} s ({network.description}): "
                               f"{budget:.0f} evaluations of its right-hand side without reaching {b:g} s"
                               f"{_switching_summary(system, switched_by)}") from None
        if rows_t:
            pieces.append(system.observe(np.array(rows_t), np.array(rows_y), network, controls, tuple(tp.tripped)))
        if stop_at_loss and lost is not None:
            break
    named = ("states", "machine_inputs", "device_states")
    rows = {key: np.concatenate([p[key] for p in pieces]) for key in pieces[0] if key not in named}
    states, inputs, device_states = ({name: np.concatenate([p[key][name] for p in pieces]) for name in pieces[0][key]}
                                     for key in named)
    theta_bus = np.unwrap(np.angle(rows["V_bus"]), axis=0)
    gen_rows = [system.case.network.bus_index(b) for b in system.case.generator_buses]
    theta_bus[:, gen_rows] = rows["theta_vs"]
    return GridResult(time=rows["time"], states=states, Vs=rows["Vs"], theta_vs=rows["theta_vs"], P=rows["P"],
                      Q=rows["Q"], V_bus=np.abs(rows["V_bus"]), theta_bus=theta_bus, stable=lost is None,
                      loss_of_synchronism_s=lost, events=tuple((tp.start, tp.description) for tp in topologies[1:]),
                      gen_buses=system.case.generator_buses, buses=system.case.buses, controls=controls,
                      n_rhs=calls[0], machine_inputs=inputs, rotor_angle=rows["rotor_angle"],
                      device_states=device_states)


def _switching_summary(system: System, switched_by: dict) -> str:
    """', N switchings located, most by the DEVICE of the unit at bus B (M)' (or ', no switching located')."""
    total = sum(switched_by.values())
    if not total:
        return ", no switching located"
    (k, j), most = max(switched_by.items(), key=lambda item: item[1])
    unit = system.units[k]
    what = "the input links" if j is None else unit.devices[j].component.name.upper()
    return f", {total} switchings located, most by {what} of the unit at bus {unit.bus} ({most})"
