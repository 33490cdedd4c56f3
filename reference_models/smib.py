"""What a machine's bus sees in a network: windows recorded from a machine in a closed loop.

In a network the bus voltage is not an open-loop signal: it moves with the machine's own swing (the
machine's current flows through the network impedance) while the rest of the network swings and
accelerates. A window of the `network` input family (families.py) is recorded from the smallest
such loop: the machine (SM4, with the dataset's parameters) with an IEEE Type I exciter, on an
infinite bus of voltage E behind a reactance Xe, whose angle accelerates at `accel` during a fault
(the rest of the network speeding up, as every machine of the WSCC 9-bus system does in a fault
with no governors) and keeps the speed gained. The fault is a shunt reactance Xf at the machine's
bus from t_fault for `duration`; clearing it opens part of the line (Xe grows by the factor
1 + trip). The loop starts at rest at a load-flow point (the machine delivers P0 at terminal
voltage Vt0, initialisation.py) and the window is taken from t0 on: its initial state is the
machine's state at t0, and its inputs are the bus voltage (Vs, theta_vs), Pm = P0 and the
exciter's Efd from t0 on, tabulated every 5 ms (with both sides of each jump). Where the machine
slips a pole, the window is moved to end just after the slip begins (a window of a lost machine
teaches nothing a grid study uses beyond its first swing).

The loop is wired by the components' ports (reference_models.ports): the machine's bus port takes
the bus voltage and gives the current into the bus, its `mechanical_power` link holds P0, its
`field_voltage` link takes the exciter's `field_voltage` output, the exciter's `terminal_voltage`
link takes the bus voltage magnitude and its `voltage_reference` link holds the set point; the
recorded channels are the machine's inputs by those names (SM4: Vs, theta_vs, Pm, Efd).

All quantities in pu on the machine's base, angles in rad, times in s.
"""
from __future__ import annotations

import cmath
import math

import numpy as np
from scipy.integrate import solve_ivp

from .ieee1 import IEEE1Params
from .initialisation import EXCITER, MACHINE, exciter_start, machine_start
from .ports import machine_inputs
from .signals import Signal, Table
from .sm4 import SM4Params

MACHINE_INPUTS = machine_inputs(MACHINE)
SAMPLE_S = 0.005  # s: the tabulation step of the recorded inputs
BOLTED = 1e-4  # pu: the smallest fault reactance (a bolted fault)
# the machine's bus current outputs, the exciter's field state and its inputs, by the ports
_CURRENT = tuple(MACHINE.output_names.index(name) for name in MACHINE.ports.bus.current)
_FIELD = EXCITER.state_names.index(EXCITER.ports.output("field_voltage"))
_EXCITER_INPUTS = tuple(dict((link.variable, link.signal) for link in EXCITER.ports.inputs)[name]
                        for name in EXCITER.input_names)


def _machine_u(Vs: float, theta: float, Pm: float, Efd: float) -> tuple:
    """The machine's inputs in its order from bus voltage, mechanical power and field voltage (a
    further input at its start value)."""
    given = {MACHINE_INPUTS.magnitude: Vs, MACHINE_INPUTS.angle: theta, MACHINE_INPUTS.power: Pm,
             MACHINE_INPUTS.field: Efd}
    return tuple(given.get(q.name, q.start) for q in MACHINE.inputs)


def _exciter_u(Vt: float, Vref: float) -> tuple:
    """The exciter's inputs in its order: terminal voltage and voltage reference by their links."""
    given = {"terminal_voltage": Vt, "voltage_reference": Vref}
    return tuple(given[signal] for signal in _EXCITER_INPUTS)


def _current_map(x, p: SM4Params):
    """(c [2], A [2, 2]): the machine's bus current (I_re, I_im) = c + A (V_re, V_im), read off its
    output equations at three voltages (it is affine in the bus voltage)."""
    def current(Vs, theta):
        y = MACHINE.output_equations(x, _machine_u(Vs, theta, 0.0, 0.0), p, math)
        return np.array([y[_CURRENT[0]], y[_CURRENT[1]]])

    c = current(0.0, 0.0)
    return c, np.column_stack([current(1.0, 0.0) - c, current(1.0, 0.5 * math.pi) - c])


def bus_voltage(x, E: complex, Xe: float, Xf: float | None, p: SM4Params) -> complex:
    """The machine's bus voltage [pu] with the infinite bus E behind jXe and a fault jXf at the bus
    (None: no fault): the machine's current c + A V leaves through the line and the fault,
    c + A V = (V - E)/(jXe) + V/(jXf), solved for V."""
    c, A = _current_map(x, p)
    turn = np.array([[0.0, 1.0], [-1.0, 0.0]])  # z/(jX) = -j z/X: (re, im) -> (im, -re) / X
    G = A - turn / Xe
    rhs = -c - turn @ np.array([E.real, E.imag]) / Xe
    if Xf is not None:
        G = G - turn / Xf
    v = np.linalg.solve(G, rhs)
    return complex(v[0], v[1])


def record(p: SM4Params, E: float, Vt0: float, Xe: float, P0: float, t_fault: float, duration: float, Xf: float,
           trip: float, accel: float, t0: float, horizon: float, exciter: IEEE1Params = IEEE1Params()):
    """(x0 [4], Signal) of one window [t0, t0 + horizon] of the loop (see the module docstring)."""
    # load flow of the loop: P0 = Vt0 E sin(angle) / Xe, the machine's bus at angle `angle`
    reach = P0 * Xe / (Vt0 * E)
    if abs(reach) >= 0.95:  # no (stable enough) load flow: shorten the line
        Xe = 0.95 * Vt0 * E / max(abs(P0), 1e-9)
        reach = math.copysign(0.95, reach)
    angle = math.asin(reach)
    V = cmath.rect(Vt0, angle)
    I = (V - E) / (1j * Xe)  # current into the network from the machine's bus
    S = V * I.conjugate()
    start = machine_start(Vt0, angle, S.real, S.imag, p)
    field = exciter_start(start.Efd, start.Vt, exciter)
    t_clear = t_fault + duration
    stop = t0 + horizon

    def phase(t):
        """The infinite bus angle: accelerating at `accel` during the fault, then turning at the speed gained."""
        during = min(max(t - t_fault, 0.0), duration)
        return 0.5 * accel * during**2 + accel * duration * max(t - t_clear, 0.0)

    def network(t, y, faulted):
        x = y[:MACHINE.n_states]
        return bus_voltage(x, cmath.rect(E, phase(t)), Xe * (1.0 + trip) if t >= t_clear else Xe,
                           max(Xf, BOLTED) if faulted else None, p)

    n = MACHINE.n_states

    def rhs(t, y, faulted):
        x, z = y[:n], y[n:]
        V = network(t, y, faulted)
        dx = MACHINE.derivatives(x, _machine_u(abs(V), cmath.phase(V), start.Pm, z[_FIELD]), p, math)
        dz = EXCITER.derivatives(z, _exciter_u(abs(V), field.Vref), exciter, math)
        return [*dx, *dz]

    y = np.concatenate([start.x0, field.x0])
    times, states, faults = [], [], []
    edges = sorted({0.0, min(t_fault, stop), min(t_clear, stop), stop})
    for a, b in zip(edges[:-1], edges[1:]):
        if b <= a:
            continue
        faulted = t_fault <= a < t_clear
        grid = np.unique(np.concatenate([np.arange(math.ceil(a / SAMPLE_S), math.floor(b / SAMPLE_S) + 1) * SAMPLE_S,
                                         [a, b, min(max(t0, a), b)]]))
        sol = solve_ivp(rhs, (a, b), y, t_eval=grid, args=(faulted,), method="RK45", rtol=1e-8, atol=1e-10)
        if sol.status != 0:
            raise RuntimeError(f"network window: the loop's solve failed ({sol.message})")
        times.append(sol.t)
        states.append(sol.y.T)
        faults += [faulted] * len(sol.t)
        y = sol.y[:, -1]
    t = np.concatenate(times)
    Y = np.concatenate(states)
    faults = np.asarray(faults)
    volts = np.array([network(ti, yi, f) for ti, yi, f in zip(t, Y, faults)])
    theta = np.unwrap(np.angle(volts))  # continuous over the whole run, as the rotor angle is
    # slipping a pole against the network: the rotor angle more than pi from the infinite bus angle
    slipped = np.nonzero(np.abs(Y[:, MACHINE.drift.angle_states[0]] - np.array([phase(ti) for ti in t])) > math.pi)[0]
    if slipped.size:  # the machine slips a pole: the window ends with the start of the slip
        t0 = min(t0, max(float(t[slipped[0]]) - 0.6 * horizon, 0.0))
    keep = (t >= t0 - 1e-12) & (t <= t0 + horizon + 1e-12)
    t, Y, volts, theta = t[keep], Y[keep], volts[keep], theta[keep]
    rel = tuple(float(v) for v in t - t0)
    x0 = Y[0, :n]
    recorded = {MACHINE_INPUTS.magnitude: Table(rel, tuple(float(abs(v)) for v in volts)),
                MACHINE_INPUTS.angle: Table(rel, tuple(float(a) for a in theta)),
                MACHINE_INPUTS.power: Table((0.0,), (float(start.Pm),)),
                MACHINE_INPUTS.field: Table(rel, tuple(float(e) for e in Y[:, n + _FIELD]))}
    signal = Signal({q.name: recorded.get(q.name, Table((0.0,), (q.start,))) for q in MACHINE.inputs},
                    x0=tuple(float(v) for v in x0))
    return x0, signal
