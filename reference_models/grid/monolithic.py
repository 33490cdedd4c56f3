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

The network. With the machines' states given, each machine's bus current (its bus-port current
outputs, network frame) is affine in its bus voltage (V_re, V_im) for the machines modelled here
(SM4, GENCLS, GENROU: the stator equations are linear in Vs sin(delta - theta_vs) and
Vs cos(delta - theta_vs), GENROU's saturation a function of its states only), read at the machine's
other inputs: their start values, or the state of the device of its unit that gives them (GENCLS'
Efd enters its current: held, or an exciter state). Its map I = c + A v is read off the
component's own output equations at v = 0, (1, 0), (0, 1), so the equations are used as they are.
The network, Kron-reduced to the generator buses for each topology (Case.reduced; units at one bus
inject into it together), gives I = Y_red V there; so every right-hand side is one linear solve
(Y_red - A) v = c, exact. The other buses' voltages follow from the generator buses'.

Events: a fault (a shunt of impedance `fault_impedance`, default 1e-6 pu: bolted) at a bus from
`fault_start` to `clear_s` (absolute times in s), optionally a branch opened at clearing; scipy's
solve_ivp (DOP853 at rtol 1e-10 by default) is restarted at every event. A run is stable when no
rotor-angle difference between two machines exceeds pi before `stop` (located by solve_ivp events).
"""
from __future__ import annotations

import math

import numpy as np

from .case import Case, Reduced, external_impedance, held_inputs, unit_wiring
from .contingency import BOLTED_FAULT_IMPEDANCE, Contingency
from .result import ROTOR_ANGLE, GridResult


def _current_map(component, x, p, m, u0=None):
    """(c [2], A [2][2]) with the machine's bus current (I_re, I_im) = c + A (V_re, V_im), read off the
    component's output equations at three voltages (x: its states, scalars or arrays; u0: its
    other inputs, component order, the bus-port entries ignored; None: zeros)."""
    bus = component.ports.bus
    names = component.input_names
    i_v, i_a = names.index(bus.voltage[0]), names.index(bus.voltage[1])
    i_re, i_im = (component.output_names.index(n) for n in bus.current)

    def current(Vs, theta):
        u = [0.0] * len(names) if u0 is None else list(u0)
        u[i_v], u[i_a] = Vs, theta
        y = component.output_equations(x, tuple(u), p, m)
        return y[i_re], y[i_im]

    c_re, c_im = current(0.0, 0.0)
    r_re, r_im = current(1.0, 0.0)
    i_re_, i_im_ = current(1.0, 0.5 * math.pi)
    return (c_re, c_im), ((r_re - c_re, i_re_ - c_re), (r_im - c_im, i_im_ - c_im))


def unit_inputs(devices, wiring, starts, impedance: complex, state, V_re, V_im, controls: bool = True, m=math,
                held=None) -> list:
    """The inputs of every device of a unit (tuples in component order), wired by `wiring`
    (case.unit_wiring): the bus voltage V_re + j V_im (scalars, m = math; arrays, m = numpy), the
    devices' states `state(j)` (lists in component order), the terminal voltage behind `impedance`,
    set points at their start values in `starts` (or `held` {variable: value} of the machine where
    given). controls=False: the machine's links from other devices held at their start values."""
    if m is math:
        Vs, theta = math.hypot(V_re, V_im), math.atan2(V_im, V_re)
    else:
        Vs, theta = np.hypot(V_re, V_im), np.arctan2(V_im, V_re)
    held = held or {}
    inputs = [None] * len(devices)

    def value(j, variable):
        d = devices[j]
        if variable in d.component.state_names:
            return state(j)[d.component.state_names.index(variable)]
        return d.component.output_equations(state(j), inputs_of(j), d.params, m)[d.component.output_names.index(variable)]

    def terminal(index):
        if impedance == 0:
            return Vs if index == 0 else theta
        bus = devices[0].component.ports.bus
        I_re, I_im = (value(0, n) for n in bus.current)
        if m is math:
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
                else:
                    values.append(value(source.device, source.variable))
            inputs[j] = tuple(values)
        return inputs[j]

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
        self.case = case
        self.units = case.units
        self.wiring = tuple(unit_wiring([d.component.ports for d in u.devices], f"generator at bus {u.bus}")
                            for u in case.units)
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
        self.rotor_angles = [self.slices[k][0].start + u.machine.component.state_names.index(ROTOR_ANGLE)
                             for k, u in enumerate(case.units)]
        # the machine inputs its bus current is read at: start values, or the state of the device giving them
        self.machine_links = tuple(
            tuple((i, self.slices[k][w[name].device].start
                   + u.devices[w[name].device].component.state_names.index(w[name].variable))
                  for i, name in enumerate(u.machine.component.input_names)
                  if name in w and w[name].kind == "device"
                  and w[name].variable in u.devices[w[name].device].component.state_names)
            for k, (u, w) in enumerate(zip(case.units, (wi[0] for wi in self.wiring))))
        buses = list(dict.fromkeys(u.bus for u in case.units))  # the reduced network's buses, in Case.reduced's order
        self.bus_slot = tuple(buses.index(u.bus) for u in case.units)
        self.first_unit = tuple(self.bus_slot.index(b) for b in range(len(buses)))
        self._networks = {}

    def network(self, fault_bus: int | None = None, fault_impedance: complex = BOLTED_FAULT_IMPEDANCE,
                out_of_service=()) -> Reduced:
        """Case.reduced, kept per topology."""
        key = (fault_bus, complex(fault_impedance) if fault_bus is not None else None, tuple(out_of_service))
        if key not in self._networks:
            self._networks[key] = self.case.reduced(fault_bus, fault_impedance, out_of_service)
        return self._networks[key]

    def generator_voltages(self, y, network: Reduced, m=math):
        """(V_re [g], V_im [g]) at every unit's bus for the state y (m = math), or for states
        y [n, n_states] (m = numpy: arrays [n, g]); units at one bus inject into it together."""
        b = len(self.first_unit)
        if m is math:
            M = np.array(network.Y_real)
            c = np.zeros(2 * b)
            for k, u in enumerate(self.units):
                d, i = u.machine, 2 * self.bus_slot[k]
                ck, A = _current_map(d.component, list(y[self.slices[k][0]]), d.params, math, self._machine_u(k, y))
                c[i: i + 2] += ck
                M[i: i + 2, i: i + 2] -= A
            v = np.linalg.solve(M, c)
            return v[0::2][list(self.bus_slot)], v[1::2][list(self.bus_slot)]
        y = np.asarray(y)
        M = np.broadcast_to(network.Y_real, (y.shape[0], 2 * b, 2 * b)).copy()
        c = np.zeros((y.shape[0], 2 * b))
        for k, u in enumerate(self.units):
            d, s, i = u.machine, self.slices[k][0], 2 * self.bus_slot[k]
            ck, A = _current_map(d.component, [y[:, j] for j in range(s.start, s.stop)], d.params, np,
                                 self._machine_u(k, y, np))
            c[:, i] += ck[0]
            c[:, i + 1] += ck[1]
            for r in range(2):
                for q in range(2):
                    M[:, i + r, i + q] -= A[r][q]
        v = np.linalg.solve(M, c[..., None])[..., 0]
        return v[:, 0::2][:, list(self.bus_slot)], v[:, 1::2][:, list(self.bus_slot)]

    def _machine_u(self, k: int, y, m=math) -> list:
        """The inputs of unit k's machine (component order) that its bus current is read at: each
        held at its start value, or the state of the device of its unit that gives it (y [n_states],
        m = math; y [n, n_states], m = numpy)."""
        start = self.case.starts[k][0].inputs
        u = [start[name] for name in self.units[k].machine.component.input_names]
        for i, at in self.machine_links[k]:
            u[i] = y[at] if m is math else y[:, at]
        return u

    def unit_inputs(self, k: int, y, V_re, V_im, controls: bool = True, m=math) -> list:
        """The inputs of every device of unit k (tuples in component order) at state y (scalars, m =
        math; or arrays over rows, m = numpy) and bus voltage V_re + j V_im."""
        slices = self.slices[k]
        if m is math:
            def state(j):
                return [y[i] for i in range(slices[j].start, slices[j].stop)]
        else:
            def state(j):
                return [y[:, i] for i in range(slices[j].start, slices[j].stop)]
        return unit_inputs(self.units[k].devices, self.wiring[k], self.case.starts[k], self.impedance[k], state,
                           V_re, V_im, controls, m)

    def rhs(self, t, y, network: Reduced, controls: bool = True) -> np.ndarray:
        """dy/dt [n_states] with the network voltages solved for the state y."""
        V_re, V_im = self.generator_voltages(y, network)
        out = np.zeros(self.n_states)
        for k, unit in enumerate(self.units):
            inputs = self.unit_inputs(k, y, V_re[k], V_im[k], controls)
            for j, d in enumerate(unit.devices):
                if j > 0 and not controls:
                    continue
                s = self.slices[k][j]
                out[s] = d.component.derivatives(list(y[s]), inputs[j], d.params, math)
        return out

    def observe(self, t, y, network: Reduced, controls: bool = True) -> dict:
        """The result rows for states y [n, n_states] at times t [n] in one topology: time, V_gen,
        V_bus, Vs, theta_vs, P, Q [n, g] / [n, buses], states {name: [n, g]} and machine_inputs."""
        y = np.atleast_2d(y)
        n, g = len(y), len(self.units)
        V_re, V_im = self.generator_voltages(y, network, np)
        V_gen = V_re + 1j * V_im
        delta = y[:, self.rotor_angles]
        theta_vs = delta + np.angle(V_gen * np.exp(-1j * delta))
        I = np.empty((n, g), dtype=complex)
        states, machine_inputs = {}, {}
        for k, unit in enumerate(self.units):
            inputs = self.unit_inputs(k, y, V_re[:, k], V_im[:, k], controls, np)
            machine = unit.machine
            bus = machine.component.ports.bus
            u = np.stack([np.broadcast_to(np.asarray(v, dtype=float), (n,)) for v in inputs[0]], -1)
            u[:, machine.component.input_names.index(bus.voltage[1])] = theta_vs[:, k]
            outputs = machine.component.output_values(y[:, self.slices[k][0]], u, machine.params)
            I[:, k] = (outputs[:, machine.component.output_names.index(bus.current[0])]
                       + 1j * outputs[:, machine.component.output_names.index(bus.current[1])])
            for name, column in zip(machine.component.input_names, u.T):
                machine_inputs.setdefault(name, np.full((n, g), np.nan))[:, k] = column
            for j, d in enumerate(unit.devices):
                for i, name in enumerate(d.component.state_names):
                    states.setdefault(name, np.full((n, g), np.nan))[:, k] = y[:, self.slices[k][j].start + i]
        if "Efd" not in states and "Efd" in machine_inputs:  # the field voltage where no device has it as a state
            states["Efd"] = machine_inputs["Efd"]
        S = V_gen * np.conj(I)
        return {"time": np.asarray(t, dtype=float), "V_gen": V_gen, "V_bus": V_gen[:, list(self.first_unit)] @ network.recovery.T,
                "Vs": np.abs(V_gen), "theta_vs": theta_vs, "P": S.real, "Q": S.imag, "states": states,
                "machine_inputs": machine_inputs}


def _pair_events(system: System, terminal: bool = False):
    """solve_ivp event functions (delta_i - delta_j)^2 - pi^2 for every pair of machines (terminal:
    the solve stops at the first)."""
    events = []
    angles = system.rotor_angles
    for i in range(len(angles)):
        for j in range(i + 1, len(angles)):
            events.append(_pair_event(angles[i], angles[j], terminal))
    return events


def _pair_event(a: int, b: int, terminal: bool):
    def event(t, y, *args):
        return (y[a] - y[b]) ** 2 - math.pi ** 2

    event.direction = 1.0
    event.terminal = terminal
    return event


# A healthy solve of a shipped case takes 2,000-6,000 evaluations of the right-hand side for 5 s with
# a fault; one whose step collapses (a limiter switching back and forth) is stopped at this budget.
RHS_BUDGET_BASE, RHS_BUDGET_PER_SECOND = 10_000, 4_000


class _Stalled(Exception):
    """The right-hand side was evaluated more often than the budget allows (at time `t` [s])."""

    def __init__(self, t: float):
        super().__init__(t)
        self.t = t


def simulate(system: System, contingency: Contingency, stop: float = 5.0, t_eval=None, *, step: float = 0.01,
             controls: bool = True, method: str = "DOP853", rtol: float = 1e-10, atol: float = 1e-12,
             event_rows: bool = False, stop_at_loss: bool = False) -> GridResult:
    """The case from its load-flow equilibrium through `contingency` until `stop` [s].

    Rows at t_eval (default: every `step` s from 0 to stop); `event_rows`: the state just before
    each event too. `controls=False`: every control signal a machine takes held at its start value.
    `stop_at_loss`: the solve ends where two rotor angles get pi apart (the rows stop there)."""
    from scipy.integrate import solve_ivp

    if not (math.isfinite(stop) and stop > 0):
        raise ValueError(f"stop must be a positive time, got {stop!r}")
    if t_eval is None:
        t_eval = np.linspace(0.0, stop, int(round(stop / step)) + 1)
    t_eval = np.asarray(t_eval, dtype=float)
    if t_eval.ndim != 1 or np.any(np.diff(t_eval) < 0) or t_eval[0] < 0 or t_eval[-1] > stop:
        raise ValueError("t_eval must be increasing times within [0, stop]")
    c = contingency
    intact = system.network()
    trip = (c.trip,) if c.trip else ()
    # segments (start, end, network, what happens at start)
    if c.fault_bus is None:
        segments = [(0.0, stop, intact, "start")]
        if c.trip and c.clear_s < stop:
            segments = [(0.0, c.clear_s, intact, "start"),
                        (c.clear_s, stop, system.network(out_of_service=trip), f"open {c.trip}")]
    else:
        fault = system.network(c.fault_bus, c.fault_impedance)
        after = system.network(out_of_service=trip)
        t_f, t_c = min(c.fault_start, stop), min(c.clear_s, stop)
        clearing = f"fault at bus {c.fault_bus} cleared" + (f", {c.trip} opened" if c.trip else "")
        segments = [(0.0, t_f, intact, "start"), (t_f, t_c, fault, f"fault at bus {c.fault_bus}"),
                    (t_c, stop, after, clearing)]
        segments = [s for s in segments if s[0] < stop or s is segments[0]]

    events = _pair_events(system, stop_at_loss)
    budget = RHS_BUDGET_BASE + RHS_BUDGET_PER_SECOND * stop
    calls = [0]

    def rhs(t, y, network, controls):
        calls[0] += 1
        if calls[0] > budget:
            raise _Stalled(t)
        return system.rhs(t, y, network, controls)

    y = np.array(system.x0)
    pieces, event_log, lost, n_rhs = [], [], None, 0
    for n, (a, b, network, what) in enumerate(segments):
        last = n == len(segments) - 1
        if n > 0:
            event_log.append((a, what))
        inside = (t_eval >= a) & ((t_eval <= b) if last else (t_eval < b))
        times = list(t_eval[inside])
        if event_rows and n > 0 and (not times or times[0] != a):
            times.insert(0, a)
        if event_rows and not last:
            times.append(b)
        sol = None
        if b > a:
            try:
                sol = solve_ivp(rhs, (a, b), y, method=method, rtol=rtol, atol=atol, dense_output=True,
                                events=events, args=(network, controls))
            except _Stalled as stalled:
                raise RuntimeError(f"the monolithic solve stalled at t = {stalled.t:.4f} s ({network.description}): "
                                   f"{budget:.0f} evaluations of its right-hand side without reaching {b:g} s (its "
                                   "step collapses at a limiter switching it does not locate)") from None
            if sol.status < 0:
                raise RuntimeError(f"solve_ivp failed on [{a}, {b}] s ({network.description}): {sol.message}")
            n_rhs += sol.nfev
            crossings = [float(te[0]) for te in sol.t_events if len(te)]
            if crossings and lost is None:
                lost = min(crossings)
            if sol.status == 1:  # stopped at the loss of synchronism
                times = [t for t in times if t <= sol.t[-1]]
            states = sol.sol(np.array(times)).T if times else np.empty((0, system.n_states))
            if times and times[0] == a:
                states[0] = y
            y = sol.y[:, -1]
        else:
            states = np.tile(y, (len(times), 1))
        if times:
            pieces.append(system.observe(np.array(times), states, network, controls))
        if sol is not None and sol.status == 1:
            break
    rows = {key: np.concatenate([p[key] for p in pieces]) for key in pieces[0] if key not in ("states", "machine_inputs")}
    states = {name: np.concatenate([p["states"][name] for p in pieces]) for name in pieces[0]["states"]}
    inputs = {name: np.concatenate([p["machine_inputs"][name] for p in pieces]) for name in pieces[0]["machine_inputs"]}
    theta_bus = np.unwrap(np.angle(rows["V_bus"]), axis=0)
    gen_rows = [system.case.network.bus_index(b) for b in system.case.generator_buses]
    theta_bus[:, gen_rows] = rows["theta_vs"]
    return GridResult(time=rows["time"], states=states, Vs=rows["Vs"], theta_vs=rows["theta_vs"], P=rows["P"],
                      Q=rows["Q"], V_bus=np.abs(rows["V_bus"]), theta_bus=theta_bus, stable=lost is None,
                      loss_of_synchronism_s=lost, events=tuple(event_log), gen_buses=system.case.generator_buses,
                      buses=system.case.buses, controls=controls, n_rhs=n_rhs, machine_inputs=inputs)
