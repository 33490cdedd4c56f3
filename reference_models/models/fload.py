"""FLoad: the voltage- and frequency-dependent load of ANDES, with the bus-frequency measurement it
reads (ANDES' BusFreq) as its own states, on a bus.

States  x = (theta_f [rad]: the bus angle through the measurement's filter, theta_w [rad]: the
        washout's state), both network-frame angles
Inputs  u = (Vs [pu], theta_vs [rad]: the bus voltage; pv0, qv0 [pu, system base]: the active and
        reactive power drawn at V = 1 pu and f = 1 pu, ANDES' pv0, qv0, set points the start gives)
Outputs y = (I_re, I_im [pu, system base]: the current injected into the bus, network frame; P, Q
        [pu, system base]: the power injected into the bus, generator convention (negative: drawn);
        f [pu]: the measured bus frequency)

Equations (ANDES 2.0 model reference, DynLoad: FLoad; FreqMeasurement: BusFreq):

    lag 1 / (1 + s Tf) of the bus angle:  Tf dtheta_f/dt = theta_vs - theta_f   (Tf = 0: theta_f held, the
        filter passes theta_vs)
    washout s K / (1 + s Tw) of the filtered angle, K = 1 / (2 pi fn):
        Tw dtheta_w/dt = theta_f - theta_w,   f = 1 + K (theta_f - theta_w) / Tw
    drawn:  Pd = pv0 Vs^ap f^bp,   Qd = qv0 Vs^aq f^bq;   injected P + j Q = -(Pd + j Qd) = Vs e^{j theta_vs} conj(I)

ANDES' BusFreq filters theta_vs - theta0 (theta0: the load flow's angle); ours filters theta_vs
itself, the same dynamics with both states shifted by theta0: ANDES' L_y = theta_f - theta0, WO_x =
theta_w - theta0. Tf, Tw and fn are those of the BusFreq at the load's bus (ANDES' own, or the one it
adds with defaults Tf = 0.02 s, Tw = 0.1 s, fn = 60 Hz); FLoad's own Tf enters no equation in ANDES
2.0.0.

Its share of the load: ANDES switches the PQ load an FLoad replaces off (u = 0) and the FLoad
draws kp / 100 of the PQ's load-flow power Ppf and kq / 100 of its Qpf (the rest is dropped); P0 + j Q0
of the start is that share, injected (-(kp Ppf + j kq Qpf) / 100). The start: theta_f = theta_w =
theta0, pv0 = -P0 / V0^ap, qv0 = -Q0 / V0^aq (ANDES' pv0 = kp / 100 p0 / v0^ap).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import lag, power, washout
from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import BusPort, Ports
from .common import check_ranges, finite_inputs

PARAMETER_RANGES = {
    "Tf": (0.0, 10.0, "s"), "Tw": (1e-3, 10.0, "s"), "fn": (16.0, 400.0, "Hz"),
    "ap": (-5.0, 5.0, ""), "aq": (-5.0, 5.0, ""), "bp": (-10.0, 10.0, ""), "bq": (-10.0, 10.0, ""),
}


@dataclass(frozen=True)
class FLoadParams(Parameters):
    """The measurement's filter Tf and washout Tw time constants [s] and nominal frequency fn [Hz]
    (the BusFreq at the bus); the voltage exponents ap, aq and the frequency exponents bp, bq."""

    Tf: float = 0.02
    Tw: float = 0.1
    fn: float = 60.0
    ap: float = 1.0
    aq: float = 0.0
    bp: float = 0.0
    bq: float = 0.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)


def _measurement(x, u, p: FLoadParams, m) -> tuple:
    """(d theta_f/dt, d theta_w/dt, f)."""
    d_f, filtered = lag(m, u[1], x[0], 1.0, p.Tf)
    d_w, deviation = washout(m, filtered, x[1], 1.0 / (2.0 * math.pi * p.fn), p.Tw)
    return d_f, d_w, 1.0 + deviation


def derivatives(x, u, p: FLoadParams, m):
    """(d theta_f, d theta_w)/dt for u = (Vs, theta_vs, pv0, qv0)."""
    return _measurement(x, u, p, m)[:2]


def outputs(x, u, p: FLoadParams, m):
    """(I_re, I_im, P, Q) [pu, system base, injected into the bus], f [pu]."""
    Vs, theta = u[0], u[1]
    f = _measurement(x, u, p, m)[2]
    P = -u[2] * power(m, Vs, p.ap) * power(m, f, p.bp)
    Q = -u[3] * power(m, Vs, p.aq) * power(m, f, p.bq)
    c, s = m.cos(theta), m.sin(theta)
    return (P * c + Q * s) / Vs, (P * s - Q * c) / Vs, P, Q, f


def equilibrium(u, p: FLoadParams) -> np.ndarray:
    """The rest [2] at constant (Vs, theta_vs, pv0, qv0): both states at theta_vs (f = 1)."""
    theta_vs = finite_inputs(u, "FLoad")[1]
    return np.array([theta_vs, theta_vs])


def _start(given, p: FLoadParams) -> tuple:
    """(x0, {pv0, qv0}) at the load flow's V0, theta0, drawing -(P0 + j Q0) there."""
    V0 = float(given["V0"])
    return equilibrium((V0, given["theta0"], 0.0, 0.0), p), {"pv0": -given["P0"] / V0 ** p.ap,
                                                             "qv0": -given["Q0"] / V0 ** p.aq}


FLoad = Component(
    name="fload",
    description="FLoad voltage- and frequency-dependent load (ANDES) with its bus-frequency measurement, on a bus",
    states=(Quantity("theta_f", "rad", "bus angle through the measurement's filter (ANDES' BusFreq L_y + theta0)"),
            Quantity("theta_w", "rad", "washout state of the measurement (ANDES' BusFreq WO_x + theta0)")),
    inputs=(Quantity("Vs", "pu", "bus voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
            Quantity("theta_vs", "rad", "bus voltage angle", start=0.0, operating_range=(-0.5, 0.5)),
            Quantity("pv0", "pu", "active power drawn at V = 1 pu, f = 1 pu (system base; set point)", start=0.5,
                     operating_range=(0.0, 1.0)),
            Quantity("qv0", "pu", "reactive power drawn at V = 1 pu, f = 1 pu (system base; set point)", start=0.2,
                     operating_range=(-0.5, 0.5))),
    outputs=(Quantity("I_re", "pu", "current injected into the bus, real part (network frame, system base)"),
             Quantity("I_im", "pu", "current injected into the bus, imaginary part (network frame, system base)"),
             Quantity("P", "pu", "active power injected into the bus (system base; negative: drawn)"),
             Quantity("Q", "pu", "reactive power injected into the bus (system base)"),
             Quantity("f", "pu", "measured bus frequency (1: nominal)")),
    params_type=FLoadParams,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.1),
    # Tf dtheta_f/dt = theta_vs - theta_f, Tw dtheta_w/dt = theta_f - theta_w (Tf = 0: held, decay 0)
    affine_states=(0, 1),
    ports=Ports(bus=BusPort(voltage=("Vs", "theta_vs"), current=("I_re", "I_im"))),
    initialisation=Initialisation(("pv0", "qv0"), _start),
)
