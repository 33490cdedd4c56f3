"""The WSCC 9-bus system as one DAE, the network solved inside the right-hand side: the monolithic
reference of the grid co-simulation.

States, 21: the three machines' SM4 states (delta, omega, Ed_p, Eq_p) in GENERATOR_BUSES order, then
the three exciters' IEEE1 states (Efd, RF, VR). Couplings: a machine's Vs, theta_vs is its generator
bus voltage, its Pm is held at the load-flow value, its Efd input is its exciter's Efd state
(`exciters=False`: held at the initial value); the exciter's Vt is the machine's Vs, its Vref the
initial one. Loads are constant impedances drawing their load-flow power at the load-flow voltages.

The network. With the machines' states given, each machine's bus current (SM4's outputs I_re, I_im,
the current into the bus in the network frame) is affine in its bus voltage (V_re, V_im): the stator
equations are linear in Vs sin(delta - theta_vs) = V_re sin(delta) - V_im cos(delta) and
Vs cos(delta - theta_vs). Its map I = c + A v (2-vector c, 2x2 A) is read off SM4's own output
equations at v = 0, (1, 0), (0, 1), so the component's equations are used as they are. The network,
Kron-reduced to the generator buses for each topology (pre-fault, fault-on, post-clearing), gives
I = Y_red V there; so every right-hand side is one 6x6 real linear solve (Y_red - A) v = c, exact.
The other buses' voltages follow from the generator buses' (V_other = R V_gen).

Events: a fault (a shunt of impedance `fault_impedance`, default 1e-6 pu: bolted) at a bus from
`fault_start` to `clear_s` (absolute times in s), optionally a branch opened at clearing; scipy's
solve_ivp (DOP853 at rtol 1e-10 by default) is restarted at every event. A run is stable when no
rotor-angle difference between two machines exceeds pi before `stop` (located by solve_ivp events).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..ieee1 import IEEE1
from ..sm4 import SM4
from . import wscc9
from .contingency import BOLTED_FAULT_IMPEDANCE, Contingency

N_GEN = len(wscc9.GENERATOR_BUSES)
N_MACHINE_STATES = SM4.n_states
N_EXCITER_STATES = IEEE1.n_states
N_STATES = N_GEN * (N_MACHINE_STATES + N_EXCITER_STATES)
_I_RE, _I_IM = SM4.output_names.index("I_re"), SM4.output_names.index("I_im")
_GEN_ROWS = [wscc9.bus_index(b) for b in wscc9.GENERATOR_BUSES]
_OTHER_ROWS = [i for i in range(len(wscc9.BUSES)) if i not in _GEN_ROWS]


@dataclass(frozen=True)
class Network:
    """One topology: the full admittance matrix with loads and any fault shunt, and its reduction to
    the generator buses (real 6x6 form on v = (V_re, V_im) per generator) with the recovery of all bus
    voltages from the generator ones (V_bus = recovery @ V_gen, complex [9, 3])."""

    Y: np.ndarray
    Y_real: np.ndarray
    recovery: np.ndarray
    description: str


@dataclass(frozen=True)
class GridResult:
    """A simulation, one row per output time (rows at an event time: the state after it, and with
    `event_rows` also the one before it, left limit first). Arrays [n, 3] per generator in
    GENERATOR_BUSES order, [n, 9] per bus in bus order 1..9; angles in rad, speeds rad/s deviation.

    theta_vs is exact and continuous (delta + the angle of V e^{-j delta}); theta_bus is unwrapped
    along the rows (np.unwrap), with the generator buses' columns equal to theta_vs."""

    time: np.ndarray
    delta: np.ndarray
    omega: np.ndarray
    Ed_p: np.ndarray
    Eq_p: np.ndarray
    Efd: np.ndarray
    RF: np.ndarray
    VR: np.ndarray
    Vs: np.ndarray
    theta_vs: np.ndarray
    P: np.ndarray
    Q: np.ndarray
    V_bus: np.ndarray
    theta_bus: np.ndarray
    Pm: np.ndarray
    Vref: np.ndarray
    stable: bool
    loss_of_synchronism_s: float | None
    events: tuple
    exciters: bool
    gen_buses: tuple = wscc9.GENERATOR_BUSES
    buses: tuple = wscc9.BUSES
    n_rhs: int = 0

    def angle_difference(self, bus: int, reference_bus: int = 1) -> np.ndarray:
        """delta at `bus` minus delta at `reference_bus` [n] (rad)."""
        g = self.gen_buses
        return self.delta[:, g.index(bus)] - self.delta[:, g.index(reference_bus)]

    def columns(self) -> dict:
        """The result as named columns (the grid CSV's names): time, delta_<gen bus>, omega_<gen bus>,
        Efd_<gen bus>, V_<bus>, then theta_<bus>, Vs_<gen bus>, theta_vs_<gen bus>, P_<gen bus>, Q_<gen bus>."""
        out = {"time": self.time}
        for name in ("delta", "omega", "Efd"):
            for k, bus in enumerate(self.gen_buses):
                out[f"{name}_{bus}"] = getattr(self, name)[:, k]
        for i, bus in enumerate(self.buses):
            out[f"V_{bus}"] = self.V_bus[:, i]
        for i, bus in enumerate(self.buses):
            out[f"theta_{bus}"] = self.theta_bus[:, i]
        for name in ("Vs", "theta_vs", "P", "Q"):
            for k, bus in enumerate(self.gen_buses):
                out[f"{name}_{bus}"] = getattr(self, name)[:, k]
        return out


def _current_map(x, p, m):
    """(c [2], A [2][2]) with the machine's bus current (I_re, I_im) = c + A (V_re, V_im), read off
    SM4's output equations at three voltages (x: the machine's states, scalars or arrays)."""
    def current(Vs, theta):
        y = SM4.output_equations(x, (Vs, theta, 0.0, 0.0), p, m)
        return y[_I_RE], y[_I_IM]

    c_re, c_im = current(0.0, 0.0)
    r_re, r_im = current(1.0, 0.0)
    i_re, i_im = current(1.0, 0.5 * math.pi)
    return (c_re, c_im), ((r_re - c_re, i_re - c_re), (r_im - c_im, i_im - c_im))


class WSCC9:
    """The system with every machine and exciter started from the load flow.

    x0 [21]: the equilibrium; Pm, Efd0, Vref [3]: the held mechanical powers, the initial field
    voltages, the exciters' set points. `network(...)` builds a topology, `rhs(t, y, network)` is
    the DAE's right-hand side with the network solved inside."""

    def __init__(self, dynamics=None, flow=None):
        from ..initialisation import exciter_start, machine_start

        self.dynamics = tuple(dynamics) if dynamics is not None else wscc9.dynamic_data()
        self.flow = flow if flow is not None else wscc9.load_flow()
        self.machines = tuple(g.machine for g in self.dynamics)
        self.exciter_params = tuple(g.exciter for g in self.dynamics)
        self.load_admittances = self.flow.load_admittances()
        x0 = np.zeros(N_STATES)
        Pm, Efd0, Vref = [], [], []
        for k, g in enumerate(self.dynamics):
            op = self.flow.generator(g.bus)
            ms = machine_start(op["V"], op["theta"], op["P"], op["Q"], g.machine)
            es = exciter_start(ms.Efd, ms.Vt, g.exciter)
            x0[self.machine_slice(k)] = np.asarray(ms.x0, dtype=float)
            x0[self.exciter_slice(k)] = np.asarray(es.x0, dtype=float)
            Pm.append(float(ms.Pm))
            Efd0.append(float(ms.Efd))
            Vref.append(float(es.Vref))
        self.x0 = x0
        self.Pm, self.Efd0, self.Vref = np.array(Pm), np.array(Efd0), np.array(Vref)
        for a in (self.x0, self.Pm, self.Efd0, self.Vref):
            a.setflags(write=False)

    @staticmethod
    def machine_slice(k: int) -> slice:
        return slice(N_MACHINE_STATES * k, N_MACHINE_STATES * (k + 1))

    @staticmethod
    def exciter_slice(k: int) -> slice:
        start = N_GEN * N_MACHINE_STATES + N_EXCITER_STATES * k
        return slice(start, start + N_EXCITER_STATES)

    def network(self, fault_bus: int | None = None, fault_impedance: complex = BOLTED_FAULT_IMPEDANCE,
                out_of_service=()) -> Network:
        """The topology with the loads, a fault shunt at `fault_bus` (None: none) and the named
        branches open, reduced to the generator buses."""
        opened = tuple(wscc9.openable(b) for b in out_of_service)
        Y = wscc9.assemble_ybus(opened) if opened else np.array(self.flow.Ybus)
        Y = Y + np.diag(self.load_admittances)
        parts = []
        if fault_bus is not None:
            if fault_impedance == 0 or not np.isfinite(fault_impedance):
                raise ValueError(f"fault impedance must be finite and nonzero (a bolted fault: "
                                 f"{BOLTED_FAULT_IMPEDANCE} pu), got {fault_impedance!r}")
            i = wscc9.bus_index(fault_bus)
            Y[i, i] += 1.0 / complex(fault_impedance)
            parts.append(f"fault at bus {fault_bus}")
        if opened:
            parts.append("open " + ", ".join(br.name for br in opened))
        g, o = _GEN_ROWS, _OTHER_ROWS
        Y_oo_inv_Y_og = np.linalg.solve(Y[np.ix_(o, o)], Y[np.ix_(o, g)])
        Y_red = Y[np.ix_(g, g)] - Y[np.ix_(g, o)] @ Y_oo_inv_Y_og
        recovery = np.zeros((len(wscc9.BUSES), N_GEN), dtype=complex)
        recovery[g, :] = np.eye(N_GEN)
        recovery[o, :] = -Y_oo_inv_Y_og
        Y_real = np.zeros((2 * N_GEN, 2 * N_GEN))
        Y_real[0::2, 0::2] = Y_red.real
        Y_real[0::2, 1::2] = -Y_red.imag
        Y_real[1::2, 0::2] = Y_red.imag
        Y_real[1::2, 1::2] = Y_red.real
        for a in (Y, Y_real, recovery):
            a.setflags(write=False)
        return Network(Y=Y, Y_real=Y_real, recovery=recovery, description="; ".join(parts) or "intact")

    def generator_voltages(self, y, network: Network, m=math):
        """(V_re [3], V_im [3]) at the generator buses for the state y [21] (m = math), or for states
        y [n, 21] (m = numpy: arrays [n, 3])."""
        if m is math:
            M = np.array(network.Y_real)
            c = np.empty(2 * N_GEN)
            for k, p in enumerate(self.machines):
                ck, A = _current_map(list(y[self.machine_slice(k)]), p, math)
                c[2 * k: 2 * k + 2] = ck
                M[2 * k: 2 * k + 2, 2 * k: 2 * k + 2] -= A
            v = np.linalg.solve(M, c)
            return v[0::2], v[1::2]
        y = np.asarray(y)
        M = np.broadcast_to(network.Y_real, (y.shape[0], 2 * N_GEN, 2 * N_GEN)).copy()
        c = np.empty((y.shape[0], 2 * N_GEN))
        for k, p in enumerate(self.machines):
            xk = [y[:, j] for j in range(self.machine_slice(k).start, self.machine_slice(k).stop)]
            ck, A = _current_map(xk, p, np)
            c[:, 2 * k], c[:, 2 * k + 1] = ck
            for r in range(2):
                for s in range(2):
                    M[:, 2 * k + r, 2 * k + s] -= A[r][s]
        v = np.linalg.solve(M, c[..., None])[..., 0]
        return v[:, 0::2], v[:, 1::2]

    def rhs(self, t, y, network: Network, exciters: bool = True) -> np.ndarray:
        """dy/dt [21] with the network voltages solved for the state y."""
        V_re, V_im = self.generator_voltages(y, network)
        out = np.zeros(N_STATES)
        for k, (p, pe) in enumerate(zip(self.machines, self.exciter_params)):
            Vs = math.hypot(V_re[k], V_im[k])
            theta = math.atan2(V_im[k], V_re[k])
            ms, es = self.machine_slice(k), self.exciter_slice(k)
            e = y[es]
            Efd = e[0] if exciters else self.Efd0[k]
            out[ms] = SM4.derivatives(list(y[ms]), (Vs, theta, self.Pm[k], Efd), p, math)
            if exciters:
                out[es] = IEEE1.derivatives(list(e), (Vs, self.Vref[k]), pe, math)
        return out

    def observe(self, t, y, network: Network, exciters: bool = True) -> dict:
        """The result rows (see GridResult) for states y [n, 21] at times t [n] in one topology."""
        y = np.atleast_2d(y)
        V_re, V_im = self.generator_voltages(y, network, np)
        V_gen = V_re + 1j * V_im
        delta = y[:, [self.machine_slice(k).start for k in range(N_GEN)]]
        theta_vs = delta + np.angle(V_gen * np.exp(-1j * delta))
        Vs = np.abs(V_gen)
        P, Q = np.empty_like(Vs), np.empty_like(Vs)
        for k, p in enumerate(self.machines):
            u = np.stack([Vs[:, k], theta_vs[:, k], np.full(len(y), self.Pm[k]), y[:, self.exciter_slice(k).start]], -1)
            outputs = SM4.output_values(y[:, self.machine_slice(k)], u, p)
            P[:, k] = outputs[:, SM4.output_names.index("P")]
            Q[:, k] = outputs[:, SM4.output_names.index("Q")]
        rows = {"time": np.asarray(t, dtype=float), "V_gen": V_gen, "V_bus": V_gen @ network.recovery.T,
                "Vs": Vs, "theta_vs": theta_vs, "P": P, "Q": Q}
        for j, name in enumerate(SM4.state_names):
            rows[name] = y[:, [self.machine_slice(k).start + j for k in range(N_GEN)]]
        for j, name in enumerate(IEEE1.state_names):
            rows[name] = y[:, [self.exciter_slice(k).start + j for k in range(N_GEN)]]
        return rows


_SYSTEM: WSCC9 | None = None


def system() -> WSCC9:
    """The shipped WSCC 9-bus system (built once per process)."""
    global _SYSTEM
    if _SYSTEM is None:
        _SYSTEM = WSCC9()
    return _SYSTEM


def _pair_events(terminal: bool = False):
    """solve_ivp event functions (delta_i - delta_j)^2 - pi^2 for every pair of machines (terminal:
    the solve stops at the first)."""
    events = []
    for i in range(N_GEN):
        for j in range(i + 1, N_GEN):
            a, b = WSCC9.machine_slice(i).start, WSCC9.machine_slice(j).start
            events.append(_pair_event(a, b, terminal))
    return events


def _pair_event(a: int, b: int, terminal: bool):
    def event(t, y, *args):
        return (y[a] - y[b]) ** 2 - math.pi ** 2

    event.direction = 1.0
    event.terminal = terminal
    return event


def simulate_contingency(contingency: Contingency, stop: float = 5.0, **options) -> GridResult:
    """simulate_wscc9 of a contingency.Contingency (options: those of simulate_wscc9)."""
    c = contingency
    return simulate_wscc9(c.fault_bus, c.clear_s, c.trip, c.fault_start, stop,
                          fault_impedance=c.fault_impedance, **options)


def simulate_wscc9(fault_bus: int | None, clear_s: float | None, trip=None, fault_start: float = 0.0,
                   stop: float = 5.0, t_eval=None, *, step: float = 0.01, exciters: bool = True,
                   fault_impedance: complex = BOLTED_FAULT_IMPEDANCE, method: str = "DOP853",
                   rtol: float = 1e-10, atol: float = 1e-12, event_rows: bool = False,
                   grid: WSCC9 | None = None, stop_at_loss: bool = False) -> GridResult:
    """The system from its load-flow equilibrium, with a fault at `fault_bus` (None: no fault) from
    `fault_start` to `clear_s` [s, absolute], at clearing branch `trip` ("a-b" or (a, b); None: none)
    opened, until `stop` [s].

    Rows at t_eval (default: every `step` s from 0 to stop); `event_rows`: the state just before
    each event too. `exciters=False`: every Efd held at its initial value. `stop_at_loss`: the
    solve ends where two rotor angles get pi apart (the rows stop there). Raises ValueError for an
    unknown bus or branch, a trip that disconnects a generator, or clearing before the fault."""
    from scipy.integrate import solve_ivp

    grid = grid if grid is not None else system()
    if not (math.isfinite(stop) and stop > 0):
        raise ValueError(f"stop must be a positive time, got {stop!r}")
    if t_eval is None:
        t_eval = np.linspace(0.0, stop, int(round(stop / step)) + 1)
    t_eval = np.asarray(t_eval, dtype=float)
    if t_eval.ndim != 1 or np.any(np.diff(t_eval) < 0) or t_eval[0] < 0 or t_eval[-1] > stop:
        raise ValueError("t_eval must be increasing times within [0, stop]")
    trip_branch = wscc9.branch(trip) if trip is not None else None
    if fault_bus is not None:
        wscc9.bus_index(fault_bus)
        if clear_s is None or not (clear_s > fault_start >= 0):
            raise ValueError(f"clearing time must come after the fault start ({fault_start} s), got {clear_s!r}")
    elif trip_branch is not None and (clear_s is None or clear_s < 0):
        raise ValueError("a trip without a fault happens at clear_s, which must be a time >= 0")

    intact = grid.network()
    # segments (start, end, network, what happens at start)
    if fault_bus is None:
        segments = [(0.0, stop, intact, "start")]
        if trip_branch is not None and clear_s < stop:
            segments = [(0.0, clear_s, intact, "start"),
                        (clear_s, stop, grid.network(out_of_service=[trip_branch]), f"open {trip_branch.name}")]
    else:
        fault = grid.network(fault_bus, fault_impedance)
        after = grid.network(out_of_service=[trip_branch] if trip_branch is not None else ())
        t_f, t_c = min(fault_start, stop), min(clear_s, stop)
        clearing = f"fault at bus {fault_bus} cleared" + (f", {trip_branch.name} opened" if trip_branch else "")
        segments = [(0.0, t_f, intact, "start"), (t_f, t_c, fault, f"fault at bus {fault_bus}"),
                    (t_c, stop, after, clearing)]
        segments = [s for s in segments if s[0] < stop or s is segments[0]]

    events = _pair_events(stop_at_loss)
    y = np.array(grid.x0)
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
        if b > a:
            sol = solve_ivp(grid.rhs, (a, b), y, method=method, rtol=rtol, atol=atol, dense_output=True,
                            events=events, args=(network, exciters))
            if sol.status < 0:
                raise RuntimeError(f"solve_ivp failed on [{a}, {b}] s ({network.description}): {sol.message}")
            n_rhs += sol.nfev
            crossings = [float(te[0]) for te in sol.t_events if len(te)]
            if crossings and lost is None:
                lost = min(crossings)
            if sol.status == 1:  # stopped at the loss of synchronism
                times = [t for t in times if t <= sol.t[-1]]
            states = sol.sol(np.array(times)).T if times else np.empty((0, N_STATES))
            if times and times[0] == a:
                states[0] = y
            y = sol.y[:, -1]
        else:
            states = np.tile(y, (len(times), 1))
        if times:
            pieces.append(grid.observe(np.array(times), states, network, exciters))
        if b > a and sol.status == 1:
            break
    rows = {key: np.concatenate([p[key] for p in pieces]) for key in pieces[0]}
    theta_bus = np.unwrap(np.angle(rows["V_bus"]), axis=0)
    theta_bus[:, _GEN_ROWS] = rows["theta_vs"]
    return GridResult(time=rows["time"], delta=rows["delta"], omega=rows["omega"], Ed_p=rows["Ed_p"],
                      Eq_p=rows["Eq_p"], Efd=rows["Efd"], RF=rows["RF"], VR=rows["VR"], Vs=rows["Vs"],
                      theta_vs=rows["theta_vs"], P=rows["P"], Q=rows["Q"], V_bus=np.abs(rows["V_bus"]),
                      theta_bus=theta_bus, Pm=np.array(grid.Pm), Vref=np.array(grid.Vref),
                      stable=lost is None, loss_of_synchronism_s=lost, events=tuple(event_log),
                      exciters=exciters, n_rhs=n_rhs)
