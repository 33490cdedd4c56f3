"""PVD1: the WECC distributed PV model as ANDES 2.0.0 computes it, with the bus-frequency measurement
it reads (ANDES' BusFreq) as its own states, on a bus.

States  x = (theta_f [rad]: the bus angle through the measurement's filter, theta_w [rad]: the
        measurement's washout state, both network-frame angles; Ipout_y, Iqout_y [pu, system base]:
        the active and reactive currents, ANDES' output lags)
Inputs  u = (Vs [pu], theta_vs [rad]: the bus voltage; pref0, qref0 [pu, system base]: the active and
        reactive power set points, ANDES' pref0, qref0, which the start gives)
Outputs y = (I_re, I_im [pu, system base]: the current injected into the bus, network frame; P, Q
        [pu, system base]: the power injected, generator convention; Ipout, Iqout [pu, system
        base]: the active and reactive currents (ANDES' Ipout_y, Iqout_y); f [pu]: the measured bus
        frequency)

Equations (ANDES 2.0 model reference, DG: PVD1; FreqMeasurement: BusFreq), on the system base:

    measurement (blocks.bus_frequency, the BusFreq's busf_Tf, busf_Tw, busf_fn):
        busf_Tf dtheta_f/dt = theta_vs - theta_f,  busf_Tw dtheta_w/dt = theta_f - theta_w,
        f = 1 + (theta_f - theta_w) / (2 pi busf_fn busf_Tw),   fHz = fn f
    trip factors (ANDES' Limiter flags, no latching): Ffl = 0 below ft0, linear to 1 at ft1, 1
        above; Ffh = 1 below ft2, linear to 0 at ft3, 0 above (of fHz); Fvl, Fvh the same of Vs
        with vt0, vt1 and vt2, vt3;  R = recflag Fvl Fvh Ffl Ffh + 1 - recflag
    frequency droop: Pdrp = ddn db(fn - fHz), db the dead band [fdbd, 999] Hz (DeadBand1: the
        excess beyond its edges): only over-frequency (fHz > fn - fdbd) lowers the power
    vp = max(Vs, 0.01);  Psum = pref0 + Pdrp;  Ipul = pmx / vp where Psum >= pmx, 0 where
        Psum <= Pfloor (0; ESD1: -pmx), else Psum / vp
    voltage droop on Vcomp = |Vs e^{j theta_vs} + j xc (Ipout_y + j Iqout_y)| (ANDES adds the
        current without rotating it into the network frame), with
        Vql = v0 + (qmx - qref0) / dqdv, Vqu = v1 - (qref0 - qmn) / dqdv:
        Qdrp = qmx where Vcomp <= Vql, else 0 where Vcomp >= v0, else qmx + dqdv (Vqu - Vcomp)
             + qmn where Vcomp >= Vqu, else 0 where Vcomp <= v1, else dqdv (v1 - Vcomp)
        (ANDES' two comparers VQ1, VQ2 as it writes them: the first piece is not continuous at v0
        and Vql, and where Vqu < v1 the second gives qmn between Vqu and v1)
    Iqul = (qref0 + Qdrp) / vp
    current limits, pqflag = 1 (P priority): Ipcmd = R clip(Ipul, 0, ialim),
        Iqmax = sqrt(max(ialim^2 - Ipcmd^2, 0)), Iqcmd = R clip(Iqul, -Iqmax, Iqmax);
        pqflag = 0 (Q priority): Iqcmd = R clip(Iqul, -ialim, ialim),
        Ipmax = sqrt(max(ialim^2 - Iqcmd^2, 0)), Ipcmd = R clip(Ipul, 0, Ipmax)
    tip dIpout_y/dt = Ipcmd - Ipout_y,   tiq dIqout_y/dt = Iqcmd - Iqout_y
    P = Ipout_y Vs, Q = Iqout_y Vs,  I = (Ipout_y - j Iqout_y) e^{j theta_vs}

ANDES computes Vcomp, Iqmax and Ipmax as services from its previous iterate; at a converged step
they are the functions above. Its Vql and Vqu are constants of the start (of pref0, qref0 there);
ours follow the input qref0. The latching flags vrflag, frflag enter no equation in ANDES 2.0.0 and
are not parameters here; ANDES' power limit check (config plim) is on, as by default.

Bases: the parameters are as the case data give them, on the device's base Sn: qmx, qmn, pmx,
dqdv, ddn (powers) and ialim (a current) times Sn / Sb, xc (an impedance) times Sb / Sn, as ANDES
converts them. busf_Tf, busf_Tw, busf_fn are those of the BusFreq at the device's bus (ANDES' own,
or the one it adds with defaults 0.02 s, 0.1 s, 60 Hz); fn is the device's own.

What the case conversion decides: ANDES' PVD1 replaces its static generator `gen` (switched off in
the time domain) and delivers the share P0 = gammap p, Q0 = gammaq q of its load-flow power; its
droop bus igreg (a remote bus) is not modelled.

Start (ANDES' initialisation): pref0 = P0, qref0 = Q0, theta_f = theta_w = theta0, Ipout_y = P0 / V0,
Iqout_y = Q0 / V0; ValueError where the commands there differ (a current limit, a droop or a trip
factor acts at the load flow, so ANDES too starts off it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import bus_frequency, clip, clip_between, dead_band, lag, piecewise_linear
from ..component import Component, Initialisation, Parameters, Quantity
from ..piecewise import where
from ..ports import BusPort, Ports
from .common import check_limits, check_ranges, finite_inputs
from .reeca1 import _headroom as headroom

PARAMETER_RANGES = {
    "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA"), "fn": (16.0, 400.0, "Hz"), "xc": (0.0, 10.0, "pu"),
    "pqflag": (0.0, 1.0, ""), "qmx": (-100.0, 100.0, "pu"), "qmn": (-100.0, 100.0, "pu"), "pmx": (0.0, 1e5, "pu"),
    "v0": (0.01, 2.0, "pu"), "v1": (0.01, 2.0, "pu"), "dqdv": (-1e3, -1e-6, "pu"), "fdbd": (-10.0, 0.0, "Hz"),
    "ddn": (0.0, 1e3, "pu/Hz"), "ialim": (1e-3, 100.0, "pu"),
    "vt0": (0.01, 3.0, "pu"), "vt1": (0.01, 3.0, "pu"), "vt2": (0.01, 3.0, "pu"), "vt3": (0.01, 3.0, "pu"),
    "ft0": (10.0, 500.0, "Hz"), "ft1": (10.0, 500.0, "Hz"), "ft2": (10.0, 500.0, "Hz"), "ft3": (10.0, 500.0, "Hz"),
    "tip": (1e-3, 10.0, "s"), "tiq": (1e-3, 10.0, "s"), "recflag": (0.0, 1.0, ""),
    "busf_Tf": (0.0, 10.0, "s"), "busf_Tw": (1e-3, 10.0, "s"), "busf_fn": (16.0, 400.0, "Hz"),
}
DEAD_BAND_TOP = 999.0  # Hz: the upper edge of ANDES' frequency dead band (under-frequency never raises the power)
MIN_VOLTAGE = 0.01  # pu: the voltage the currents are computed with at most down to (ANDES' VLo)
REST_ITERATIONS = 100  # fixed-point iterations of the currents at rest (the voltage droop through xc)


@dataclass(frozen=True)
class PVD1Params(Parameters):
    """ANDES' PVD1 data: the device's base Sn and the system base Sb [MVA], its nominal frequency fn
    [Hz]; coupling reactance xc [pu, base Sn]; pqflag (1: P priority, 0: Q priority); reactive power
    limits qmx, qmn and power limit pmx [pu, base Sn]; the voltage droop's band v0, v1 [pu] and slope
    dqdv [pu/pu, base Sn]; the frequency droop's dead band fdbd [Hz] and gain ddn [pu/Hz, base Sn];
    the current limit ialim [pu, base Sn]; the voltage and frequency trip curves vt0 < vt1 < vt2 <
    vt3 [pu], ft0 < ft1 < ft2 < ft3 [Hz] and their switch recflag (1: on, 0: off); the current lags
    tip, tiq [s]; the BusFreq measuring the bus: busf_Tf, busf_Tw [s], busf_fn [Hz]."""

    Sn: float = 100.0
    Sb: float = 100.0
    fn: float = 60.0
    xc: float = 0.0
    pqflag: float = 1.0
    qmx: float = 0.33
    qmn: float = -0.33
    pmx: float = 9999.0
    v0: float = 0.8
    v1: float = 1.1
    dqdv: float = -1.0
    fdbd: float = -0.017
    ddn: float = 0.0
    ialim: float = 1.3
    vt0: float = 0.88
    vt1: float = 0.90
    vt2: float = 1.1
    vt3: float = 1.2
    ft0: float = 59.5
    ft1: float = 59.7
    ft2: float = 60.3
    ft3: float = 60.5
    tip: float = 0.02
    tiq: float = 0.02
    recflag: float = 1.0
    busf_Tf: float = 0.02
    busf_Tw: float = 0.1
    busf_fn: float = 60.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        self.require("pqflag", self.pqflag in (0.0, 1.0), "be 0 (Q priority) or 1 (P priority)")
        for low, high in (("qmn", "qmx"), ("v0", "v1"), ("vt0", "vt1"), ("vt1", "vt2"), ("vt2", "vt3"),
                          ("ft0", "ft1"), ("ft1", "ft2"), ("ft2", "ft3")):
            check_limits(self, low, high)

    @property
    def power_ratio(self) -> float:
        """Sn / Sb: a power or current on the device's base times this is on the system base."""
        return self.Sn / self.Sb


def trip_factor(m, Vs, fHz, p: PVD1Params):
    """R = recflag Fvl Fvh Ffl Ffh + 1 - recflag: the under/over voltage and frequency factors."""
    F = (piecewise_linear(m, Vs, (p.vt0, p.vt1), (0.0, 1.0)) * piecewise_linear(m, Vs, (p.vt2, p.vt3), (1.0, 0.0))
         * piecewise_linear(m, fHz, (p.ft0, p.ft1), (0.0, 1.0)) * piecewise_linear(m, fHz, (p.ft2, p.ft3), (1.0, 0.0)))
    return p.recflag * F + (1.0 - p.recflag)


def reactive_droop(m, Vcomp, qref0, p: PVD1Params):
    """Qdrp [pu, system base]: ANDES' voltage droop of Vcomp (module docstring)."""
    qmx, qmn, dqdv = (p.qmx * p.power_ratio, p.qmn * p.power_ratio, p.dqdv * p.power_ratio)
    Vql, Vqu = p.v0 + (qmx - qref0) / dqdv, p.v1 - (qref0 - qmn) / dqdv
    under = where(m, Vcomp <= Vql, qmx + 0.0 * Vcomp, where(m, Vcomp >= p.v0, 0.0 * Vcomp, qmx + dqdv * (Vqu - Vcomp)))
    over = where(m, Vcomp >= Vqu, qmn + 0.0 * Vcomp, where(m, Vcomp <= p.v1, 0.0 * Vcomp, dqdv * (p.v1 - Vcomp)))
    return under + over


def current_commands(x, u, f, p: PVD1Params, m, active_limits, power_floor: float) -> tuple:
    """(Ipcmd, Iqcmd) [pu, system base] at states x, inputs u and measured frequency f [pu];
    active_limits(headroom) -> (low, high): the active current's limits given the current the
    priority leaves it (PVD1: [0, headroom]); power_floor: Psum's lower limit (PVD1: 0)."""
    Ipout, Iqout = x[2], x[3]
    Vs, theta, pref0, qref0 = u[0], u[1], u[2], u[3]
    fHz = p.fn * f
    R = trip_factor(m, Vs, fHz, p)
    vp = clip(m, Vs, MIN_VOLTAGE, math.inf)
    pmx = p.pmx * p.power_ratio
    Psum = pref0 + p.ddn * p.power_ratio * dead_band(m, p.fn - fHz, p.fdbd, DEAD_BAND_TOP)
    Ipul = where(m, Psum >= pmx, pmx + 0.0 * Psum, where(m, Psum <= power_floor, 0.0 * Psum, Psum)) / vp
    xc = p.xc / p.power_ratio
    re, im = Vs * m.cos(theta) - xc * Iqout, Vs * m.sin(theta) + xc * Ipout
    Vcomp = m.sqrt(re * re + im * im)
    Iqul = (qref0 + reactive_droop(m, Vcomp, qref0, p)) / vp
    ialim = p.ialim * p.power_ratio
    if p.pqflag == 1.0:
        low, high = active_limits(ialim + 0.0 * Ipul)
        Ipcmd = R * clip_between(m, Ipul, low, high)
        Iqmax = headroom(m, ialim, Ipcmd)
        return Ipcmd, R * clip_between(m, Iqul, -Iqmax, Iqmax)
    Iqcmd = R * clip(m, Iqul, -ialim, ialim)
    low, high = active_limits(headroom(m, ialim, Iqcmd))
    return R * clip_between(m, Ipul, low, high), Iqcmd


def _pv_limits(headroom_p):
    """A PV's active current limits: [0, what the priority leaves]."""
    return 0.0 * headroom_p, headroom_p


def current_rates(x, u, p: PVD1Params, m, active_limits, power_floor: float) -> tuple:
    """(dtheta_f, dtheta_w, dIpout_y, dIqout_y)/dt (see current_commands)."""
    d_f, d_w, f = bus_frequency(m, u[1], x[0], x[1], p.busf_Tf, p.busf_Tw, p.busf_fn)
    Ipcmd, Iqcmd = current_commands(x, u, f, p, m, active_limits, power_floor)
    return d_f, d_w, lag(m, Ipcmd, x[2], 1.0, p.tip)[0], lag(m, Iqcmd, x[3], 1.0, p.tiq)[0]


def derivatives(x, u, p: PVD1Params, m):
    """(dtheta_f, dtheta_w, dIpout_y, dIqout_y)/dt for u = (Vs, theta_vs, pref0, qref0)."""
    return current_rates(x, u, p, m, _pv_limits, 0.0)


def outputs(x, u, p: PVD1Params, m):
    """(I_re, I_im, P, Q, Ipout, Iqout) [pu, system base], f [pu]."""
    Ipout, Iqout = x[2], x[3]
    Vs, theta = u[0], u[1]
    f = bus_frequency(m, theta, x[0], x[1], p.busf_Tf, p.busf_Tw, p.busf_fn)[2]
    c, s = m.cos(theta), m.sin(theta)
    return Ipout * c + Iqout * s, Ipout * s - Iqout * c, Ipout * Vs, Iqout * Vs, Ipout, Iqout, f


def rest_currents(u, p: PVD1Params, active_limits, power_floor: float, name: str) -> tuple:
    """(Ipout_y, Iqout_y) at rest under constant inputs u (f = 1): the currents equal to their
    commands, found by fixed-point iteration (they depend on themselves only through xc's voltage
    droop); ValueError naming the device where that finds none."""
    theta = finite_inputs(u, name)[1]
    x = [theta, theta, 0.0, 0.0]
    for _ in range(REST_ITERATIONS):
        commands = [float(c) for c in current_commands(x, u, 1.0, p, math, active_limits, power_floor)]
        settled = max(abs(c - i) for c, i in zip(commands, x[2:])) <= 1e-15 * (1.0 + max(map(abs, commands)))
        x[2:] = commands
        if settled:
            return tuple(commands)
    raise ValueError(f"{name}: no steady state at these inputs (its currents do not settle on their commands)")


def equilibrium(u, p: PVD1Params) -> np.ndarray:
    """The rest [4] at constant (Vs, theta_vs, pref0, qref0): the measurement at theta_vs (f = 1),
    the currents at their commands."""
    theta = float(u[1])
    return np.array([theta, theta, *rest_currents(u, p, _pv_limits, 0.0, "PVD1")])


def load_flow_start(given, p: PVD1Params, rates, name: str) -> tuple:
    """(x [4], u [4]) of ANDES' start at the load flow's V0, theta0, P0, Q0: pref0 = P0, qref0 = Q0,
    the currents P0 / V0, Q0 / V0; rates(x, u) -> the device's derivatives there, which must leave
    the currents at rest (ValueError naming the device otherwise)."""
    V0, theta0, P0, Q0 = (float(given[k]) for k in ("V0", "theta0", "P0", "Q0"))
    x, u = [theta0, theta0, P0 / V0, Q0 / V0], [V0, theta0, P0, Q0]
    d_Ip, d_Iq = (float(r) for r in rates(x, u)[2:4])
    if abs(d_Ip * p.tip) + abs(d_Iq * p.tiq) > 1e-12 * (abs(x[2]) + abs(x[3]) + p.ialim * p.power_ratio):
        raise ValueError(f"{name}: no rest at the load flow (V0 = {V0:.6g} pu, P0 = {P0:.6g}, Q0 = {Q0:.6g} pu): "
                         "its current limits, a droop or a trip factor change its currents there")
    return x, u


def _start(given, p: PVD1Params) -> tuple:
    x, u = load_flow_start(given, p, lambda x, u: derivatives(x, u, p, math), "PVD1")
    return np.array(x), {"pref0": u[2], "qref0": u[3]}


STATES = (Quantity("theta_f", "rad", "bus angle through the measurement's filter (ANDES' BusFreq L_y + theta0)"),
          Quantity("theta_w", "rad", "washout state of the measurement (ANDES' BusFreq WO_x + theta0)"),
          Quantity("Ipout_y", "pu", "active current (system base)"),
          Quantity("Iqout_y", "pu", "reactive current (system base; > 0 delivers reactive power)"))
OUTPUTS = (Quantity("I_re", "pu", "current injected into the bus, real part (network frame, system base)"),
           Quantity("I_im", "pu", "current injected into the bus, imaginary part (network frame, system base)"),
           Quantity("P", "pu", "active power injected into the bus (system base)"),
           Quantity("Q", "pu", "reactive power injected into the bus (system base)"),
           Quantity("Ipout", "pu", "active current (system base; ANDES' Ipout_y)"),
           Quantity("Iqout", "pu", "reactive current (system base; ANDES' Iqout_y)"),
           Quantity("f", "pu", "measured bus frequency (1: nominal)"))
BUS_PORT = Ports(bus=BusPort(voltage=("Vs", "theta_vs"), current=("I_re", "I_im")))


def inputs(power_range: tuple) -> tuple:
    """The inputs (Vs, theta_vs, pref0, qref0), pref0 drawn from power_range [pu]."""
    return (Quantity("Vs", "pu", "bus voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
            Quantity("theta_vs", "rad", "bus voltage angle", start=0.0, operating_range=(-0.5, 0.5)),
            Quantity("pref0", "pu", "active power set point (system base)", start=0.5, operating_range=power_range),
            Quantity("qref0", "pu", "reactive power set point (system base)", start=0.1,
                     operating_range=(-0.3, 0.3)))


PVD1 = Component(
    name="pvd1",
    description="PVD1 WECC distributed PV (ANDES) with its bus-frequency measurement, on a bus",
    states=STATES,
    inputs=inputs((0.0, 1.0)),
    outputs=OUTPUTS,
    params_type=PVD1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.1, 0.2, 0.2),
    # busf_Tf dtheta_f/dt = theta_vs - theta_f, busf_Tw dtheta_w/dt = theta_f - theta_w
    affine_states=(0, 1),
    ports=BUS_PORT,
    initialisation=Initialisation(("pref0", "qref0"), _start),
)
