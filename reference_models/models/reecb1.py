"""REECB1: the renewable energy electrical controller model B for PV plants (PSS/E REECB1, WECC
REEC_B, ANDES 2.0), REECA1 (models/reeca1.py) without its voltage-dependent current limits, hold
logic, speed dependency and Vref1.

States  x = (s0_y [pu] filtered voltage; S1_y [pu] filtered active power; PIQ_xi [pu] reactive power
        PI's integrator; PIV_xi [pu] the second PI's integrator; s4_y [pu] filtered reactive current
        demand; pfilt_y [pu] filtered power reference; s5_y [pu] active power order Pord (non-windup
        within [PMIN, PMAX]); dIpcmd [pu] the converter's active current command at the start less
        p0 / V0, held)
Inputs  u = (V [pu] bus voltage; Pe, Qe [pu] the converter's active and reactive power; Pref, Qref
        [pu] active and reactive power references; Vref [pu] the reference of the reactive current
        injection (ANDES' Vref0r: Vref0, or the initial bus voltage where Vref0 = 0); pfaref [rad]
        power factor angle reference): REECA1's inputs and ports
Outputs y = (Ipcmd, Iqcmd [pu]: the converter's current commands, ANDES' sign: Iqcmd = -IqHL_y)

Equations (ANDES 2.0 model reference, RenExciter: REECB1), all on the system base; as REECA1:

    dip = 1 where V < Vdip or V > Vup, else 0 (ANDES' Volt_dip); "frozen": the rate is 0 during a dip
    Trv ds0_y/dt = V - s0_y,  Tp dS1_y/dt = Pe - S1_y  (T = 0: held, the input used)
    vp = max(V, 0.01)
    PFsel = Qref (PFFLAG = 0) or S1_y tan(pfaref) (PFFLAG = 1),  Qerr = PFsel clipped to [QMin, QMax] - Qe
    PIQ: PI kp = Kqp, ki = Kqi with tracking anti-windup (ks = kqs) on VFLAG Qerr, output PIQ_y within
        [VMIN, VMAX]; its integrator frozen
    Tiq ds4_y/dt = PFsel / vp - s4_y, frozen
    tpfilt dpfilt_y/dt = Pref - pfilt_y clipped to [dPmin, dPmax] (a rate limit on tpfilt dpfilt_y/dt)
    Tpord ds5_y/dt = pfilt_y - s5_y, frozen, non-windup within [PMIN, PMAX]; s5_y is Pord
    Qsel = PIV_y (QFLAG = 1) or s4_y (QFLAG = 0)
    IqHL_y = Qsel + Iqinj clipped to [-Iqmax, Iqmax],  IpHL_y = s5_y / vp clipped to [0, Ipmax]
    Ipcmd = IpHL_y + dIpcmd,  Iqcmd = -IqHL_y
and unlike REECA1:
    Vsel = VFLAG PIQ_y clipped to [VMIN, VMAX] (no Vref1)
    PIV: PI kp = Kvp, ki = Kvi with tracking anti-windup (ks = kvs) on QFLAG Vsel (no voltage
        feedback), output within [-Iqmax, Iqmax]; its integrator frozen
    Iqinj = Kqv db(Vref - s0_y) clipped to [Iql1, Iqh1] (dead band [dbd1, dbd2]), at all times
        (no state machine, no hold after a dip)
    Q priority (PQFLAG = 0): Iqmax = Imax, Ipmax = sqrt(max(Imax^2 - IqHL_y^2, 0))
    P priority (PQFLAG = 1): Ipmax = Imax, Iqmax = sqrt(max(Imax^2 - IpHL_y^2, 0))

Deviation from ANDES, as REECA1's: during a dip ANDES also holds the two PI controllers' outputs at
their last values; here their integrators are frozen and the outputs follow kp u + xi.

Bases: the parameters ANDES converts by Sn / Sb (QMax, QMin, dPmax, dPmin, PMAX, PMIN: powers; Imax:
a current) are given on the converter's base Sn and converted; the rest (Iqh1, Iql1 included)
unconverted, as in ANDES. kqs, kvs, tpfilt are ANDES' configuration (defaults 2, 2, 0.02 s).

Start (ANDES' initialisation), from the bus voltage V, the converter's Pe = p0, Qe = q0 and the
command Ipcmd the converter needs: Pref = p0, Qref = q0, pfaref = atan2(q0, p0), Vref = Vref0 (or V
where Vref0 = 0); s0_y = V, S1_y = pfilt_y = s5_y = p0, s4_y = q0 / vp, PIQ_xi = 0,
PIV_xi = QFLAG q0 / V, dIpcmd = Ipcmd - p0 / V. Where the injection Iqinj or a limit moves the
reactive current command off the converter's, there is no rest (ValueError).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import clip, dead_band, lag_rate, non_windup, non_windup_reset
from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import Ports
from .common import check_limits, check_ranges, finite_inputs
from .reeca1 import INPUTS, LOWEST_VOLTAGE, REECA1, _during_dip, _pi_rest, current_limits, reactive_power_control

FLAGS = ("PFFLAG", "VFLAG", "QFLAG", "PQFLAG")

PARAMETER_RANGES = {
    "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA"), "Vdip": (0.0, 2.0, "pu"), "Vup": (0.0, 5.0, "pu"),
    "Trv": (0.0, 100.0, "s"), "dbd1": (-1.0, 0.0, "pu"), "dbd2": (0.0, 1.0, "pu"), "Kqv": (0.0, 100.0, "pu"),
    "Iqh1": (-1e4, 1e4, "pu"), "Iql1": (-1e4, 1e4, "pu"), "Vref0": (0.0, 2.0, "pu"), "Tp": (0.0, 100.0, "s"),
    "Kqp": (0.0, 1e4, "pu"), "Kqi": (0.0, 1e4, "pu/s"), "Kvp": (0.0, 1e4, "pu"), "Kvi": (0.0, 1e4, "pu/s"),
    "Tiq": (0.001, 100.0, "s"), "Imax": (1e-3, 1e4, "pu"), "Tpord": (0.001, 100.0, "s"),
    "kqs": (1e-3, 1e4, "pu"), "kvs": (1e-3, 1e4, "pu"), "tpfilt": (0.001, 100.0, "s"),
}


@dataclass(frozen=True)
class REECB1Params(Parameters):
    """ANDES/PSS/E REECB1 data: the converter's base Sn [MVA] and the system base Sb [MVA]; the mode
    flags (0 or 1); the dip thresholds Vdip, Vup [pu]; the injection (Kqv, dead band dbd1, dbd2
    [pu], limits Iql1, Iqh1 [pu], Vref0 [pu], 0: the initial voltage); time constants [s]; PI gains;
    limits (QMax, QMin, dPmax, dPmin, PMAX, PMIN [pu, base Sn]; VMAX, VMIN [pu]; Imax [pu, base Sn]);
    ANDES' configuration kqs, kvs, tpfilt."""

    Sn: float = 100.0
    Sb: float = 100.0
    PFFLAG: float = 0.0
    VFLAG: float = 0.0
    QFLAG: float = 0.0
    PQFLAG: float = 0.0
    Vdip: float = 0.8
    Vup: float = 1.2
    Trv: float = 0.02
    dbd1: float = -0.02
    dbd2: float = 0.02
    Kqv: float = 1.0
    Iqh1: float = 999.0
    Iql1: float = -999.0
    Vref0: float = 1.0
    Tp: float = 0.02
    QMax: float = 999.0
    QMin: float = -999.0
    VMAX: float = 999.0
    VMIN: float = -999.0
    Kqp: float = 1.0
    Kqi: float = 0.1
    Kvp: float = 1.0
    Kvi: float = 0.1
    Tiq: float = 0.02
    dPmax: float = 999.0
    dPmin: float = -999.0
    PMAX: float = 999.0
    PMIN: float = 0.0
    Imax: float = 999.0
    Tpord: float = 0.02
    kqs: float = 2.0
    kvs: float = 2.0
    tpfilt: float = 0.02

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        for flag in FLAGS:
            self.require(flag, getattr(self, flag) in (0.0, 1.0), "be 0 or 1")
        for low, high in (("Vdip", "Vup"), ("Iql1", "Iqh1"), ("QMin", "QMax"), ("VMIN", "VMAX"), ("dPmin", "dPmax"),
                          ("PMIN", "PMAX")):
            check_limits(self, low, high)

    @property
    def base_ratio(self) -> float:
        """Sn / Sb: a power or current on the converter's base times this is on the system base."""
        return self.Sn / self.Sb


def _signals(x, u, p: REECB1Params, m) -> dict:
    """The controller's rates (before freezing) and algebraic signals (ANDES' names) at x, u."""
    s0, S1, PIQ_xi, PIV_xi, s4_y, pfilt_y, s5_y, dIpcmd = x
    V, Pe, Qe, Pref, Qref, Vref, pfaref = u
    k = p.base_ratio
    q = reactive_power_control(m, V, Pe, Qe, Qref, pfaref, s0, S1, PIQ_xi, p)
    Vsel = clip(m, q["PIQ_y"] if p.VFLAG else 0.0 * q["PIQ_y"], p.VMIN, p.VMAX)
    PIV_u = Vsel if p.QFLAG else 0.0 * Vsel
    Iqinj = clip(m, p.Kqv * dead_band(m, Vref - q["s0_y"], p.dbd1, p.dbd2), p.Iql1, p.Iqh1)
    c = current_limits(m, p, p.Imax * k + 0.0 * V, lambda Ipmax: Ipmax, PIV_u, PIV_xi, s4_y, Iqinj, s5_y, q["vp"])
    return dict(q, d_s4=(q["PFsel"] / q["vp"] - s4_y) / p.Tiq,
                d_pfilt=lag_rate(m, Pref, pfilt_y, 1.0, p.tpfilt, p.dPmin * k, p.dPmax * k)[0],
                d_s5=(pfilt_y - s5_y) / p.Tpord, Vsel=Vsel, PIV_u=PIV_u, Iqinj=Iqinj, **c,
                Ipcmd=c["IpHL_y"] + dIpcmd, Iqcmd=-c["IqHL_y"])


def derivatives(x, u, p: REECB1Params, m):
    """dx/dt for x = (s0_y, S1_y, PIQ_xi, PIV_xi, s4_y, pfilt_y, s5_y, dIpcmd),
    u = (V, Pe, Qe, Pref, Qref, Vref, pfaref)."""
    V = u[0]
    s = _signals(x, u, p, m)
    k = p.base_ratio

    def frozen(rate):
        return _during_dip(m, V, p, 0.0 * rate, rate)

    return (s["d_s0"], s["d_S1"], frozen(s["d_PIQ"]), frozen(s["d_PIV"]), frozen(s["d_s4"]), s["d_pfilt"],
            non_windup(m, frozen(s["d_s5"]), x[6], p.PMIN * k, p.PMAX * k), 0.0 * x[7])


def reset(x, u, p: REECB1Params, m):
    """x after the reset of s5_y's non-windup limits (at its frozen rate)."""
    s = _signals(x, u, p, m)
    k = p.base_ratio
    s5_y = non_windup_reset(m, _during_dip(m, u[0], p, 0.0 * s["d_s5"], s["d_s5"]), x[6], p.PMIN * k, p.PMAX * k)
    return x[0], x[1], x[2], x[3], x[4], x[5], s5_y, x[7]


def outputs(x, u, p: REECB1Params, m):
    """(Ipcmd, Iqcmd) [pu, system base]."""
    s = _signals(x, u, p, m)
    return s["Ipcmd"], s["Iqcmd"]


def _start(given, p: REECB1Params) -> tuple:
    V, p0, q0, Ipcmd = (float(given[n]) for n in ("V", "Pe", "Qe", "Ipcmd"))
    if V <= 0:
        raise ValueError(f"REECB1: no start at bus voltage {V} pu")
    if p.PFFLAG and p0 == 0:
        raise ValueError("REECB1: power factor control (PFFLAG = 1) at zero active power has no power factor angle")
    k = p.base_ratio
    if not p.PMIN * k <= p0 <= p.PMAX * k:
        raise ValueError(f"REECB1: the active power {p0:.6g} pu at the start lies outside [PMIN, PMAX]")
    vp = max(V, LOWEST_VOLTAGE)
    x = np.array([V, p0, 0.0, p.QFLAG * q0 / V, q0 / vp, p0, p0, Ipcmd - p0 / V])
    u = np.array([V, p0, q0, p0, q0, p.Vref0 if p.Vref0 != 0 else V, math.atan2(q0, p0)])
    Iqcmd = _signals(x, u, p, math)["Iqcmd"]
    if "Iqcmd" in given and abs(Iqcmd - float(given["Iqcmd"])) > 1e-9 * max(1.0, abs(Iqcmd)):
        raise ValueError(f"REECB1: its reactive current command {Iqcmd:.9g} pu at the start differs from the "
                         f"converter's {float(given['Iqcmd']):.9g} pu (the injection Kqv db(Vref0 - V) or a limit)")
    return x, {"Pref": u[3], "Qref": u[4], "Vref": u[5], "pfaref": u[6]}


def equilibrium(u, p: REECB1Params) -> np.ndarray:
    """The steady state [8] at constant inputs: the filters at their inputs, s5_y at Pref (on a
    power limit beyond it), each PI's integrator at rest (on the limit its input drives it to where
    that input is not 0), dIpcmd 0."""
    V, Pe, _, Pref, _, _, _ = finite_inputs(u, "REECB1")
    k = p.base_ratio
    vp = max(V, LOWEST_VOLTAGE)
    x = np.array([V, Pe, 0.0, 0.0, 0.0, Pref, min(max(Pref, p.PMIN * k), p.PMAX * k), 0.0])
    s = _signals(x, u, p, math)
    x[4] = s["PFsel"] / vp
    x[2] = _pi_rest(s["PIQ_u"], p.Kqp, p.kqs, p.VMIN, p.VMAX, 0.0)
    s = _signals(x, u, p, math)
    x[3] = _pi_rest(s["PIV_u"], p.Kvp, p.kvs, -s["Iqmax"], s["Iqmax"], 0.0)
    return x


REECB1 = Component(
    name="reecb1",
    description="REECB1 renewable energy electrical controller model B (PSS/E, WECC REEC_B, ANDES)",
    states=(Quantity("s0_y", "pu", "filtered bus voltage"),
            Quantity("S1_y", "pu", "filtered active power"),
            Quantity("PIQ_xi", "pu", "reactive power PI integrator"),
            Quantity("PIV_xi", "pu", "second PI integrator (reactive current)"),
            Quantity("s4_y", "pu", "filtered reactive current demand"),
            Quantity("pfilt_y", "pu", "filtered active power reference"),
            Quantity("s5_y", "pu", "active power order Pord (non-windup limited)"),
            Quantity("dIpcmd", "pu", "active current command offset from the start (held)")),
    inputs=INPUTS,
    outputs=REECA1.outputs,
    params_type=REECB1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.2, 0.1, 0.1, 0.1, 0.2, 0.2, 0.1),
    reset=reset,
    ports=Ports(inputs=REECA1.ports.inputs, outputs=REECA1.ports.outputs),
    initialisation=Initialisation(("Pref", "Qref", "Vref", "pfaref"), _start),
)
