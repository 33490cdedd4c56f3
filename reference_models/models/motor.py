"""Motor5 and Motor3: the induction motors of ANDES (F. Milano's fifth- and third-order models), on a bus.

States  Motor3: x = (slip [pu], e1d, e1q [pu]: the first cage's voltage behind x1)
        Motor5: x = (slip, e1d, e1q, e2d, e2q [pu]: the second cage's voltage behind x2)
Inputs  u = (Vs [pu], theta_vs [rad]: the bus voltage, network frame)
Outputs y = (I_re, I_im [pu, system base]: the current injected into the bus, network frame; P, Q
        [pu, system base]: the power injected into the bus, generator convention, so a motor's P is
        negative; te [pu, motor base]: the electrical torque)

Equations (ANDES 2.0 model reference, Motor: Motor3, Motor5), on the motor's own base:

    r = Vb / Vn (bus nominal voltage over the motor's),  vd = -r Vs sin(theta_vs),  vq = r Vs cos(theta_vs)
    x0 = xs + xm,  x1 = xs + xr1 xm / (xr1 + xm),  T10 = (xr1 + xm) / (wb rr1),  wb = 2 pi fn
    Motor5:  x2 = xs + xr1 xr2 xm / (xr1 xr2 + xr1 xm + xr2 xm),  T20 = (xr2 + xr1 xm / (xr1 + xm)) / (wb rr2)
    stator (ed, eq, x) = (e1d, e1q, x1) for Motor3, (e2d, e2q, x2) for Motor5:
        rs Id - x Iq = vd - ed,   x Id + rs Iq = vq - eq,   te = ed Id + eq Iq
    2 Hm d slip/dt = tm - te,   tm = (Sb / Sn) (c1 + c2 + c3 - (c2 + 2 c3) slip + c2 slip^2)
    de1d/dt = wb slip e1q - (e1d + (x0 - x1) Iq) / T10
    de1q/dt = -wb slip e1d - (e1q - (x0 - x1) Id) / T10
    Motor5:
    de2d/dt = -wb slip (e1q - e2q) + de1d/dt + (e1d - e2d - (x1 - x2) Iq) / T20
    de2q/dt = wb slip (e1d - e2d) + de1q/dt + (e1q - e2q + (x1 - x2) Id) / T20
    drawn current (network frame) Iq - j Id, so I_re + j I_im = -(Iq - j Id) (Sn / Sb) r

The load torque is ANDES' as written, c2 slip^2 (not c3 slip^2 of c1 + c2 (1 - slip) + c3 (1 - slip)^2),
and ANDES applies c1, c2, c3 unconverted to its system-base torque: on the motor base they are
scaled by Sb / Sn. ANDES' zb ("allow working as brake") enters no equation and is not a parameter.

Bases: rs, xs, rr1, xr1, rr2, xr2, xm [pu] and Hm [s] on the motor's rating Sn [MVA] at its rated
voltage Vn [kV], as the case files give them; Vb [kV] the nominal voltage of its bus, Sb [MVA] the
system base. ANDES converts the impedances by (Vn^2 / Sn) / (Vb^2 / Sb) and Hm by Sn / Sb and works
on the system base: its e1d ... e2q are ours divided by r, its Id, Iq ours times (Sn / Sb) r.

Initialisation: ANDES solves the motor in its power flow (its states are power-flow unknowns, the
load torque fixed by c1, c2, c3), so the load flow's voltage alone fixes the motor's rest: at V0,
theta0 the slip is the stable root of tm(slip) = te(slip) nearest 0 (the first where 2 Hm d slip/dt
turns from positive to negative), the cage voltages the rest of the rotor equations at that slip. P0,
Q0 must be what the motor then draws (a load flow that solved the motor, as ANDES'); the start
refuses others.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import BusPort, Ports
from .common import check_ranges, finite_inputs

PARAMETER_RANGES = {
    "fn": (16.0, 400.0, "Hz"), "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA"),
    "Vn": (1e-3, 1e4, "kV"), "Vb": (1e-3, 1e4, "kV"),
    "rs": (1e-6, 1.0, "pu"), "xs": (1e-4, 10.0, "pu"), "rr1": (1e-6, 1.0, "pu"), "xr1": (1e-4, 10.0, "pu"),
    "xm": (1e-2, 100.0, "pu"), "Hm": (1e-3, 100.0, "s"),
    "c1": (-10.0, 10.0, "pu"), "c2": (-10.0, 10.0, "pu"), "c3": (-10.0, 10.0, "pu"),
}
SECOND_CAGE_RANGES = {"rr2": (1e-6, 1.0, "pu"), "xr2": (1e-4, 10.0, "pu")}
SLIP_GRID = np.linspace(-1.0, 1.0, 20001)  # where the rest's slip is searched
POWER_TOLERANCE = 1e-6  # pu, system base: how far the load flow's P0, Q0 may lie from what the motor draws


@dataclass(frozen=True)
class Motor3Params(Parameters):
    """ANDES Motor3 data: resistances, reactances [pu] and the inertia constant Hm [s] on the
    motor's rating Sn [MVA] and voltage Vn [kV]; load-torque coefficients c1, c2, c3 [pu, as ANDES
    applies them: system base]; fn [Hz]; Vb [kV] its bus's nominal voltage; Sb [MVA] the system base."""

    fn: float = 60.0
    Sn: float = 100.0
    Sb: float = 100.0
    Vn: float = 110.0
    Vb: float = 110.0
    rs: float = 0.01
    xs: float = 0.15
    rr1: float = 0.05
    xr1: float = 0.15
    xm: float = 5.0
    Hm: float = 3.0
    c1: float = 0.1
    c2: float = 0.02
    c3: float = 0.02

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)


@dataclass(frozen=True)
class Motor5Params(Motor3Params):
    """ANDES Motor5 data: Motor3's and the second cage's rr2, xr2 [pu, motor base]."""

    rr2: float = 0.001
    xr2: float = 0.04

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_ranges(self, SECOND_CAGE_RANGES)


def _first_cage(p: Motor3Params) -> tuple:
    """(wb [rad/s], x0, x1 [pu], T10 [s])."""
    wb = 2.0 * math.pi * p.fn
    return wb, p.xs + p.xm, p.xs + p.xr1 * p.xm / (p.xr1 + p.xm), (p.xr1 + p.xm) / (wb * p.rr1)


def _second_cage(p: Motor5Params, wb: float) -> tuple:
    """(x2 [pu], T20 [s])."""
    x2 = p.xs + p.xr1 * p.xr2 * p.xm / (p.xr1 * p.xr2 + p.xr1 * p.xm + p.xr2 * p.xm)
    return x2, (p.xr2 + p.xr1 * p.xm / (p.xr1 + p.xm)) / (wb * p.rr2)


def _stator(u, ed, eq, x: float, p: Motor3Params, m) -> tuple:
    """(vd, vq, Id, Iq) [pu, motor base] behind (ed, eq) and reactance x:
    rs Id - x Iq = vd - ed, x Id + rs Iq = vq - eq."""
    r = p.Vb / p.Vn
    vd, vq = -r * u[0] * m.sin(u[1]), r * u[0] * m.cos(u[1])
    a, b, det = vd - ed, vq - eq, p.rs * p.rs + x * x
    return vd, vq, (p.rs * a + x * b) / det, (p.rs * b - x * a) / det


def load_torque(slip, p: Motor3Params):
    """tm [pu, motor base]: ANDES' (c1 + c2 + c3) - (c2 + 2 c3) slip + c2 slip^2 (system base)."""
    return (p.Sb / p.Sn) * (p.c1 + p.c2 + p.c3 - (p.c2 + 2.0 * p.c3) * slip + p.c2 * slip * slip)


def _electrical(x, u, p: Motor3Params, m, second: bool) -> tuple:
    """(vd, vq, Id, Iq, te, rates): the stator and the states' derivatives; second: Motor5 (its
    second cage), else Motor3."""
    slip, e1d, e1q = x[0], x[1], x[2]
    wb, x0, x1, T10 = _first_cage(p)
    if second:
        x2, T20 = _second_cage(p, wb)
        vd, vq, Id, Iq = _stator(u, x[3], x[4], x2, p, m)
        te = x[3] * Id + x[4] * Iq
    else:
        vd, vq, Id, Iq = _stator(u, e1d, e1q, x1, p, m)
        te = e1d * Id + e1q * Iq
    d_e1d = wb * slip * e1q - (e1d + (x0 - x1) * Iq) / T10
    d_e1q = -wb * slip * e1d - (e1q - (x0 - x1) * Id) / T10
    rates = ((load_torque(slip, p) - te) / (2.0 * p.Hm), d_e1d, d_e1q)
    if second:
        e2d, e2q = x[3], x[4]
        rates += (-wb * slip * (e1q - e2q) + d_e1d + (e1d - e2d - (x1 - x2) * Iq) / T20,
                  wb * slip * (e1d - e2d) + d_e1q + (e1q - e2q + (x1 - x2) * Id) / T20)
    return vd, vq, Id, Iq, te, rates


def _derivatives(x, u, p: Motor3Params, m, second: bool):
    """d(slip, e1d, e1q[, e2d, e2q])/dt for u = (Vs, theta_vs)."""
    return _electrical(x, u, p, m, second)[5]


def _outputs(x, u, p: Motor3Params, m, second: bool):
    """(I_re, I_im, P, Q) [pu, system base, injected into the bus], te [pu, motor base]."""
    vd, vq, Id, Iq, te, _ = _electrical(x, u, p, m, second)
    k, s = (p.Sn / p.Sb) * (p.Vb / p.Vn), p.Sn / p.Sb
    return -Iq * k, Id * k, -(vd * Id + vq * Iq) * s, -(vq * Id - vd * Iq) * s, te


def _rest_at_slips(slips: np.ndarray, u, p: Motor3Params, second: bool) -> tuple:
    """(states [n, n_x] with the cage voltages at rest at each slip, the slip's rate there [n]): the
    cage equations are affine in the cage voltages at a given slip, solved exactly."""
    n_x = 5 if second else 3
    u = [np.full_like(slips, float(v)) for v in u]

    def cage_rates(e):
        return np.stack(_derivatives([slips, *e], u, p, np, second)[1:], axis=-1)

    zero = [np.zeros_like(slips)] * (n_x - 1)
    b = cage_rates(zero)
    A = np.stack([cage_rates([np.full_like(slips, float(i == j)) for i in range(n_x - 1)]) - b
                  for j in range(n_x - 1)], axis=-1)
    e = np.linalg.solve(A, -b[..., None])[..., 0]
    x = np.column_stack([slips, e])
    return x, np.asarray(_derivatives(list(x.T), u, p, np, second)[0])


def _equilibrium(u, p: Motor3Params, second: bool) -> np.ndarray:
    """The stable rest [n_x] at constant (Vs, theta_vs): the slip nearest 0 where the slip's rate
    turns from positive to negative with rising slip, the cage voltages at rest there; ValueError
    where there is none (the motor stalls at this voltage)."""
    from scipy.optimize import brentq

    name = "Motor5" if second else "Motor3"
    Vs, theta_vs = finite_inputs(u, name)
    _, rate = _rest_at_slips(SLIP_GRID, (Vs, theta_vs), p, second)
    falling = np.nonzero((rate[:-1] > 0) & (rate[1:] <= 0))[0]
    if Vs <= 0 or falling.size == 0:
        raise ValueError(f"{name}: no stable rest at Vs = {Vs} pu: the load torque exceeds the electrical "
                         "torque at every slip in [-1, 1] (the motor stalls)")
    i = falling[np.argmin(np.abs(SLIP_GRID[falling]))]

    def slip_rate(s):
        return float(_rest_at_slips(np.array([s]), (Vs, theta_vs), p, second)[1][0])

    slip = brentq(slip_rate, SLIP_GRID[i], SLIP_GRID[i + 1], xtol=1e-15, rtol=1e-15)
    return _rest_at_slips(np.array([slip]), (Vs, theta_vs), p, second)[0][0]


def _start(given, p: Motor3Params, second: bool) -> tuple:
    """(x0, {}): the rest at the load flow's V0, theta0; ValueError where P0, Q0 are not what the
    motor injects there."""
    u = (given["V0"], given["theta0"])
    x0 = _equilibrium(u, p, second)
    _, _, P, Q, _ = _outputs(list(x0), u, p, math, second)
    if abs(P - given["P0"]) > POWER_TOLERANCE or abs(Q - given["Q0"]) > POWER_TOLERANCE:
        raise ValueError(f"{'Motor5' if second else 'Motor3'}: at V0 = {given['V0']} pu it injects P = {P:.9g}, "
                         f"Q = {Q:.9g} pu (its load torque c1, c2, c3 fixes it, as ANDES solves the motor in its "
                         f"power flow), not the load flow's P0 = {given['P0']}, Q0 = {given['Q0']} pu")
    return x0, {}


def _component(name: str, params_type: type, cage_states: tuple) -> Component:
    second = len(cage_states) == 4
    return Component(
        name=name.lower(),
        description=f"{name} induction motor (ANDES) on a bus",
        states=(Quantity("slip", "pu", "rotor slip (0: synchronous speed, 1: standstill)"),) + cage_states,
        inputs=(Quantity("Vs", "pu", "bus voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
                Quantity("theta_vs", "rad", "bus voltage angle", start=0.0, operating_range=(-0.5, 0.5))),
        outputs=(Quantity("I_re", "pu", "current injected into the bus, real part (network frame, system base)"),
                 Quantity("I_im", "pu", "current injected into the bus, imaginary part (network frame, system base)"),
                 Quantity("P", "pu", "active power injected into the bus (system base; negative: drawn)"),
                 Quantity("Q", "pu", "reactive power injected into the bus (system base)"),
                 Quantity("te", "pu", "electrical torque (motor base)")),
        params_type=params_type,
        derivatives=lambda x, u, p, m: _derivatives(x, u, p, m, second),
        output_equations=lambda x, u, p, m: _outputs(x, u, p, m, second),
        equilibrium=lambda u, p: _equilibrium(u, p, second),
        state_scales=(0.01,) + (0.1,) * len(cage_states),
        # each cage voltage's rate is affine in itself (the stator currents are linear in it) with a
        # constant decay: 1 / T10 (and 1 / T20) plus the stator's share
        affine_states=tuple(range(1, 1 + len(cage_states))),
        ports=Ports(bus=BusPort(voltage=("Vs", "theta_vs"), current=("I_re", "I_im"))),
        initialisation=Initialisation((), lambda given, p: _start(given, p, second)),
    )


FIRST_CAGE = (Quantity("e1d", "pu", "first cage voltage, d axis (motor base)"),
              Quantity("e1q", "pu", "first cage voltage, q axis (motor base)"))
Motor3 = _component("Motor3", Motor3Params, FIRST_CAGE)
Motor5 = _component("Motor5", Motor5Params, FIRST_CAGE + (
    Quantity("e2d", "pu", "second cage voltage, d axis (motor base)"),
    Quantity("e2q", "pu", "second cage voltage, q axis (motor base)")))
