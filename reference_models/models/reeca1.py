"""REECA1: the renewable energy electrical controller model A (PSS/E REECA1, WECC REEC_A, ANDES).

States  x = (s0_y [pu] filtered voltage; S1_y [pu] filtered active power; PIQ_xi [pu] reactive power
        PI's integrator; s4_y [pu] filtered reactive current demand; pfilt_y [pu] filtered power
        reference; s5_y [pu] active power order Pord (non-windup within [PMIN, PMAX]); PIV_xi [pu]
        voltage PI's integrator; tdip [s] time since the last voltage dip ended (capped at the
        longer hold time); Ipmaxh [pu] the active current limit held after a dip; dIpcmd [pu] the
        converter's active current command at the start less p0 / V0, held)
Inputs  u = (V [pu] bus voltage; Pe, Qe [pu] the converter's active and reactive power; Pref, Qref
        [pu] active and reactive power references (ANDES' Pref, Qref: what a plant controller
        drives); Vref [pu] the reference of the voltage-dip current injection (ANDES' Vref0r:
        Vref0, or the initial bus voltage where Vref0 = 0); pfaref [rad] power factor angle
        reference (ANDES' pfaref))
Outputs y = (Ipcmd, Iqcmd [pu]: the converter's current commands, ANDES' sign: Iqcmd = -IqHL_y)

Equations (ANDES 2.0 model reference, RenExciter: REECA1), all on the system base:

    dip = 1 where V < Vdip or V > Vup, else 0 (ANDES' Volt_dip); "frozen": the rate is 0 during a dip
    Trv ds0_y/dt = V - s0_y,  Tp dS1_y/dt = Pe - S1_y  (T = 0: held, the input used)
    vp = max(V, 0.01)
    PFsel = Qref (PFFLAG = 0) or S1_y tan(pfaref) (PFFLAG = 1),  Qerr = PFsel clipped to [QMin, QMax] - Qe
    PIQ: PI kp = Kqp, ki = Kqi with tracking anti-windup (ks = kqs) on VFLAG Qerr, output PIQ_y within
        [VMIN, VMAX]; its integrator frozen
    Vsel = (PIQ_y (VFLAG = 1) or Vref1 + PFsel (VFLAG = 0)) clipped to [VMIN, VMAX]
    Tiq ds4_y/dt = PFsel / vp - s4_y, frozen
    Iqv = Kqv db(Vref - s0_y) (dead band [dbd1, dbd2]);  Iqinj = Iqv during a dip; for |Thld| after
        it Iqv (Thld < 0) or Iqfrz (Thld > 0); else 0
    tpfilt dpfilt_y/dt = Pref - pfilt_y clipped to [dPmin, dPmax] (a rate limit on tpfilt dpfilt_y/dt)
    Tpord ds5_y/dt = pfilt_y - s5_y, frozen, non-windup within [PMIN, PMAX] (Psel = pfilt_y: ANDES'
        Psel = wg pfilt_y for PFLAG = 1 is not modelled; its wg is 1 without a wind turbine, and with a
        drive train and torque controller 1 + wg - fPe (models/wttqa1.py), 1 at the start)
    s5_y is the active power order Pord a wind turbine's pitch controller takes (WTPTA1)
    VDL1(s0_y), VDL2(s0_y): piecewise-linear (Vq, Iq), (Vp, Ip) tables; a table in service (both
        columns non-decreasing) caps a limit at min(VDL, Imax), else the limit is 1e8
    Q priority (PQFLAG = 0): Iqmax = VDL1 cap, Ipmax = sqrt(max(Imax^2 - IqHL_y^2, 0))
    P priority (PQFLAG = 1): Ipmax = VDL2 cap, Iqmax = sqrt(max(Imax^2 - IpHL_y^2, 0))
    for Thld2 after a dip, Ipmax = Ipmaxh, the value it had when the dip ended
    PIV: PI kp = Kvp, ki = Kvi with tracking anti-windup (ks = kvs) on QFLAG (Vsel - (1 - VFLAG) s0_y),
        output within [-Iqmax, Iqmax]; its integrator frozen
    Qsel = PIV_y (QFLAG = 1) or s4_y (QFLAG = 0)
    IqHL_y = Qsel + Iqinj clipped to [-Iqmax, Iqmax],  IpHL_y = s5_y / vp clipped to [0, Ipmax]
    Ipcmd = IpHL_y + dIpcmd,  Iqcmd = -IqHL_y

The hold timers (ANDES' ExtendedEvent fThld, fThld2) are the state tdip: 0 during a dip (its reset
places it there, its rate is 0), then counting seconds up to max(|Thld|, Thld2). Ipmaxh is a
sample: where Thld2 > 0 the reset places it on the present Ipmax during a dip, at each restart of
an integrator (each communication step's start, each located switching: the dip's start is one), so
after a dip it holds the value of the dip's last restart (ANDES: of its last Newton iterate, one
step later). dIpcmd carries ANDES' offset: the converter's command equation is
Ipcmd = Ipcmd0_LVG + IpHL_y - p0 / V0, so where the converter's low-voltage gain is below 1 at the
start its command exceeds IpHL_y by a constant.

Deviations from ANDES: during a dip ANDES also holds the two PI controllers' outputs (their
algebraic ys, y) at their last values; here their integrators are frozen and the outputs follow
kp u + xi (no effect with VFLAG = QFLAG = 0, and none on QFLAG = 0's commands). ANDES' Iqh1, Iql1
limit nothing in its equations and are not parameters. ANDES' extend-only flag fThld2 keeps the
value 1 it took at the end of a first dip through every later dip (its ExtendedEvent keeps v_event);
here Ipmax is the live limit during every dip.

Bases: the parameters ANDES converts by Sn / Sb (QMax, QMin, dPmax, dPmin, PMAX, PMIN: powers;
Imax, Iq1..Iq4, Ip1..Ip4: currents) are given on the converter's base Sn and converted; the rest
unconverted, as in ANDES. kqs, kvs, tpfilt are ANDES' configuration (defaults 2, 2, 0.02 s).

Start (ANDES' initialisation), from the bus voltage V, the converter's Pe = p0, Qe = q0 and the
command Ipcmd the converter needs: Pref = p0; pfaref = atan2(q0, p0); Qref = -qref0 with
qref0 = V - Vref1 (QFLAG = 1) or -q0 / V vp (QFLAG = 0); Vref = Vref0 (or V where Vref0 = 0);
s0_y = V, S1_y = pfilt_y = s5_y = p0, s4_y = PFsel / vp, PIQ_xi = 0, PIV_xi = QFLAG q0 / V,
tdip = its cap, Ipmaxh = Ipmax, dIpcmd = Ipcmd - p0 / V.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import clip, clip_between, dead_band, lag, lag_rate, non_windup, non_windup_reset
from ..blocks import pi_tracking, piecewise_linear
from ..component import Component, Initialisation, Parameters, Quantity
from ..piecewise import where
from ..ports import Link, Ports
from .common import check_limits, check_ranges, finite_inputs

FLAGS = ("PFFLAG", "VFLAG", "QFLAG", "PFLAG", "PQFLAG")
NO_CURRENT_LIMIT = 1e8  # pu: ANDES' limit where a VDL table is out of service
LOWEST_VOLTAGE = 0.01  # pu: vp = max(V, this)

PARAMETER_RANGES = {
    "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA"), "Vdip": (0.0, 2.0, "pu"), "Vup": (0.0, 5.0, "pu"),
    "Trv": (0.0, 100.0, "s"), "dbd1": (-1.0, 0.0, "pu"), "dbd2": (0.0, 1.0, "pu"), "Kqv": (0.0, 100.0, "pu"),
    "Vref0": (0.0, 2.0, "pu"), "Iqfrz": (-100.0, 100.0, "pu"), "Thld": (-100.0, 100.0, "s"),
    "Thld2": (0.0, 100.0, "s"), "Tp": (0.0, 100.0, "s"), "Kqp": (0.0, 1e4, "pu"), "Kqi": (0.0, 1e4, "pu/s"),
    "Kvp": (0.0, 1e4, "pu"), "Kvi": (0.0, 1e4, "pu/s"), "Vref1": (0.01, 2.0, "pu"), "Tiq": (0.001, 100.0, "s"),
    "Imax": (1e-3, 1e4, "pu"), "Tpord": (0.001, 100.0, "s"), "kqs": (1e-3, 1e4, "pu"), "kvs": (1e-3, 1e4, "pu"),
    "tpfilt": (0.001, 100.0, "s"),
}


@dataclass(frozen=True)
class REECA1Params(Parameters):
    """ANDES/PSS/E REECA1 data: the converter's base Sn [MVA] and the system base Sb [MVA]; the mode
    flags (0 or 1); the dip logic (Vdip, Vup [pu], Thld, Thld2 [s], Iqfrz, Kqv, dead band dbd1, dbd2
    [pu], Vref0 [pu], 0: the initial voltage); time constants [s]; PI gains; limits (QMax, QMin,
    dPmax, dPmin, PMAX, PMIN [pu, base Sn]; VMAX, VMIN [pu]; Imax [pu, base Sn]); the VDL tables
    (Vq*, Vp* [pu]; Iq*, Ip* [pu, base Sn]); ANDES' configuration kqs, kvs, tpfilt."""

    Sn: float = 100.0
    Sb: float = 100.0
    PFFLAG: float = 0.0
    VFLAG: float = 0.0
    QFLAG: float = 0.0
    PFLAG: float = 0.0
    PQFLAG: float = 0.0
    Vdip: float = 0.8
    Vup: float = 1.2
    Trv: float = 0.02
    dbd1: float = -0.02
    dbd2: float = 0.02
    Kqv: float = 1.0
    Vref0: float = 1.0
    Iqfrz: float = 0.0
    Thld: float = 0.0
    Thld2: float = 0.0
    Tp: float = 0.02
    QMax: float = 999.0
    QMin: float = -999.0
    VMAX: float = 999.0
    VMIN: float = -999.0
    Kqp: float = 1.0
    Kqi: float = 0.1
    Kvp: float = 1.0
    Kvi: float = 0.1
    Vref1: float = 1.0
    Tiq: float = 0.02
    dPmax: float = 999.0
    dPmin: float = -999.0
    PMAX: float = 999.0
    PMIN: float = 0.0
    Imax: float = 999.0
    Tpord: float = 0.02
    Vq1: float = 0.2
    Iq1: float = 2.0
    Vq2: float = 0.4
    Iq2: float = 4.0
    Vq3: float = 0.8
    Iq3: float = 8.0
    Vq4: float = 1.0
    Iq4: float = 10.0
    Vp1: float = 0.2
    Ip1: float = 2.0
    Vp2: float = 0.4
    Ip2: float = 4.0
    Vp3: float = 0.8
    Ip3: float = 8.0
    Vp4: float = 1.0
    Ip4: float = 12.0
    kqs: float = 2.0
    kvs: float = 2.0
    tpfilt: float = 0.02

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        for flag in FLAGS:
            self.require(flag, getattr(self, flag) in (0.0, 1.0), "be 0 or 1")
        for low, high in (("Vdip", "Vup"), ("QMin", "QMax"), ("VMIN", "VMAX"), ("dPmin", "dPmax"), ("PMIN", "PMAX")):
            check_limits(self, low, high)

    @property
    def base_ratio(self) -> float:
        """Sn / Sb: a power or current on the converter's base times this is on the system base."""
        return self.Sn / self.Sb

    def current_cap(self, table: str):
        """The cap of a current limit from VDL table "q" or "p" as a function of (m, s0_y) [pu, system
        base]: min(VDL(s0_y), Imax) where the table is in service (its voltages and currents
        non-decreasing), else None (the limit is 1e8)."""
        k = self.base_ratio
        points = tuple(getattr(self, f"V{table}{i}") for i in range(1, 5))
        values = tuple(getattr(self, f"I{table}{i}") * k for i in range(1, 5))
        if any(b < a for a, b in zip(points, points[1:])) or any(b < a for a, b in zip(values, values[1:])):
            return None
        Imax = self.Imax * k

        def cap(m, s0_y):
            VDL = piecewise_linear(m, s0_y, points, values)
            return where(m, VDL < Imax, VDL, Imax + 0.0 * VDL)

        return cap

    @property
    def timer_cap(self) -> float:
        """The longest hold after a dip, max(|Thld|, Thld2) [s]: where tdip rests."""
        return max(abs(self.Thld), self.Thld2)


def _during_dip(m, V, p: REECA1Params, during, otherwise):
    """`during` where V < Vdip or V > Vup (a voltage dip, ANDES' Volt_dip), else `otherwise`."""
    return where(m, V < p.Vdip, during, where(m, V > p.Vup, during, otherwise))


def _limit(m, s0_y, cap):
    """A current limit from its VDL cap (None: 1e8)."""
    return NO_CURRENT_LIMIT + 0.0 * s0_y if cap is None else cap(m, s0_y)


def _headroom(m, Imax: float, current):
    """sqrt(max(Imax^2 - current^2, 0)): what the current limit leaves the other axis."""
    rest = Imax * Imax - current * current
    return m.sqrt(where(m, rest <= 0.0, 0.0 * rest, rest))


def reactive_power_control(m, V, Pe, Qe, Qref, pfaref, s0, S1, PIQ_xi, p) -> dict:
    """The voltage and power filters, vp, PFsel and the reactive power PI (ANDES' names: rates d_s0,
    d_S1, d_PIQ before freezing; s0_y, vp, PFsel, PIQ_u, PIQ_y) of REECA1 and REECB1 (parameters p
    with their names)."""
    k = p.base_ratio
    d_s0, s0_y = lag(m, V, s0, 1.0, p.Trv)
    d_S1, S1_y = lag(m, Pe, S1, 1.0, p.Tp)
    vp = clip(m, V, LOWEST_VOLTAGE, math.inf)
    PFsel = S1_y * m.sin(pfaref) / m.cos(pfaref) if p.PFFLAG else Qref
    Qerr = clip(m, PFsel, p.QMin * k, p.QMax * k) - Qe
    PIQ_u = Qerr if p.VFLAG else 0.0 * Qerr
    d_PIQ, PIQ_y = pi_tracking(m, PIQ_u, PIQ_xi, p.Kqp, p.Kqi, p.kqs, p.VMIN, p.VMAX)
    return dict(d_s0=d_s0, d_S1=d_S1, d_PIQ=d_PIQ, s0_y=s0_y, vp=vp, PFsel=PFsel, PIQ_u=PIQ_u, PIQ_y=PIQ_y)


def current_limits(m, p, priority_cap, held, PIV_u, PIV_xi, s4_y, Iqinj, s5_y, vp) -> dict:
    """The voltage PI and the current commands within Imax, the priority axis (P: PQFLAG = 1, else Q)
    capped at priority_cap [pu, system base], the other at the rest of Imax; held(Ipmax) the active
    current limit in use (REECA1's hold after a dip). ANDES' names: d_PIV, Iqmax, Ipmax, Ipmax_now
    (before held), IqHL_y, IpHL_y. REECA1's and REECB1's (parameters p with their names)."""
    Imax = p.Imax * p.base_ratio
    if p.PQFLAG:  # P priority: the active current first
        Ipmax_now = priority_cap
        Ipmax = held(Ipmax_now)
        IpHL_y = clip_between(m, s5_y / vp, 0.0 * Ipmax, Ipmax)
        Iqmax = _headroom(m, Imax, IpHL_y)
        d_PIV, PIV_y = pi_tracking(m, PIV_u, PIV_xi, p.Kvp, p.Kvi, p.kvs, -Iqmax, Iqmax)
        IqHL_y = clip_between(m, (PIV_y if p.QFLAG else s4_y) + Iqinj, -Iqmax, Iqmax)
    else:  # Q priority: the reactive current first
        Iqmax = priority_cap
        d_PIV, PIV_y = pi_tracking(m, PIV_u, PIV_xi, p.Kvp, p.Kvi, p.kvs, -Iqmax, Iqmax)
        IqHL_y = clip_between(m, (PIV_y if p.QFLAG else s4_y) + Iqinj, -Iqmax, Iqmax)
        Ipmax_now = _headroom(m, Imax, IqHL_y)
        Ipmax = held(Ipmax_now)
        IpHL_y = clip_between(m, s5_y / vp, 0.0 * Ipmax, Ipmax)
    return dict(d_PIV=d_PIV, Iqmax=Iqmax, Ipmax=Ipmax, Ipmax_now=Ipmax_now, IqHL_y=IqHL_y, IpHL_y=IpHL_y)


def _signals(x, u, p: REECA1Params, m) -> dict:
    """The controller's rates (before freezing) and algebraic signals (ANDES' names) at x, u."""
    s0, S1, PIQ_xi, s4_y, pfilt_y, s5_y, PIV_xi, tdip, Ipmaxh, dIpcmd = x
    V, Pe, Qe, Pref, Qref, Vref, pfaref = u
    k = p.base_ratio
    q = reactive_power_control(m, V, Pe, Qe, Qref, pfaref, s0, S1, PIQ_xi, p)
    s0_y, vp, PFsel, PIQ_y = q["s0_y"], q["vp"], q["PFsel"], q["PIQ_y"]
    Vsel = clip(m, PIQ_y if p.VFLAG else p.Vref1 + PFsel, p.VMIN, p.VMAX)
    Iqv = p.Kqv * dead_band(m, Vref - s0_y, p.dbd1, p.dbd2)
    after = 0.0 * Iqv
    if p.Thld != 0:
        after = where(m, tdip < abs(p.Thld), Iqv if p.Thld < 0 else p.Iqfrz + 0.0 * Iqv, after)
    Iqinj = _during_dip(m, V, p, Iqv, after)

    def held(Ipmax_now):  # Ipmax after a dip: Ipmaxh for Thld2
        if p.Thld2 == 0:
            return Ipmax_now
        return _during_dip(m, V, p, Ipmax_now, where(m, tdip < p.Thld2, Ipmaxh, Ipmax_now))

    PIV_u = (Vsel - s0_y if not p.VFLAG else Vsel) if p.QFLAG else 0.0 * Vsel
    c = current_limits(m, p, _limit(m, s0_y, p.current_cap("p" if p.PQFLAG else "q")), held, PIV_u, PIV_xi, s4_y,
                       Iqinj, s5_y, vp)
    return dict(q, d_s4=(PFsel / vp - s4_y) / p.Tiq,
                d_pfilt=lag_rate(m, Pref, pfilt_y, 1.0, p.tpfilt, p.dPmin * k, p.dPmax * k)[0],
                d_s5=(pfilt_y - s5_y) / p.Tpord, Vsel=Vsel, PIV_u=PIV_u, Iqinj=Iqinj, **c,
                Ipcmd=c["IpHL_y"] + dIpcmd, Iqcmd=-c["IqHL_y"])


def _timer_rate(m, tdip, V, p: REECA1Params):
    """dtdip/dt: 1 after a dip until the longest hold has passed, 0 during a dip and after."""
    if p.timer_cap == 0:
        return 0.0 * tdip
    counting = where(m, tdip >= p.timer_cap, 0.0 * tdip, 1.0 + 0.0 * tdip)
    return _during_dip(m, V, p, 0.0 * tdip, counting)


def derivatives(x, u, p: REECA1Params, m):
    """dx/dt for x = (s0_y, S1_y, PIQ_xi, s4_y, pfilt_y, s5_y, PIV_xi, tdip, Ipmaxh, dIpcmd),
    u = (V, Pe, Qe, Pref, Qref, Vref, pfaref)."""
    V = u[0]
    s = _signals(x, u, p, m)
    k = p.base_ratio

    def frozen(rate):
        return _during_dip(m, V, p, 0.0 * rate, rate)

    return (s["d_s0"], s["d_S1"], frozen(s["d_PIQ"]), frozen(s["d_s4"]), s["d_pfilt"],
            non_windup(m, frozen(s["d_s5"]), x[5], p.PMIN * k, p.PMAX * k), frozen(s["d_PIV"]),
            _timer_rate(m, x[7], V, p), 0.0 * x[8], 0.0 * x[9])


def reset(x, u, p: REECA1Params, m):
    """x after the resets: s5_y's non-windup limits (at its frozen rate), tdip to 0 during a dip,
    Ipmaxh on the present Ipmax during a dip (Thld2 > 0; kept otherwise: it is read only for Thld2
    after a dip, and sampling the moving limit outside dips would restart an integrator at every
    sample)."""
    V = u[0]
    s = _signals(x, u, p, m)
    k = p.base_ratio
    s5_y = non_windup_reset(m, _during_dip(m, V, p, 0.0 * s["d_s5"], s["d_s5"]), x[5], p.PMIN * k, p.PMAX * k)
    tdip = _during_dip(m, V, p, 0.0 * x[7], x[7]) if p.timer_cap > 0 else x[7]
    Ipmaxh = x[8]
    if p.Thld2 > 0:
        Ipmaxh = _during_dip(m, V, p, s["Ipmax_now"], x[8])
    return x[0], x[1], x[2], x[3], x[4], s5_y, x[6], tdip, Ipmaxh, x[9]


def outputs(x, u, p: REECA1Params, m):
    """(Ipcmd, Iqcmd) [pu, system base]."""
    s = _signals(x, u, p, m)
    return s["Ipcmd"], s["Iqcmd"]


def _pi_rest(u: float, kp: float, ks: float, low: float, high: float, xi0: float) -> float:
    """The integrator of a tracking anti-windup PI at rest under input u: xi0 where u = 0 (any
    integrator rests), else the one whose clipped excess ks (ys - y) cancels u at the limit u drives to."""
    if u == 0:
        return xi0
    return (high if u > 0 else low) + u / ks - kp * u


def _start(given, p: REECA1Params) -> tuple:
    V, p0, q0, Ipcmd = (float(given[n]) for n in ("V", "Pe", "Qe", "Ipcmd"))
    if V <= 0:
        raise ValueError(f"REECA1: no start at bus voltage {V} pu")
    if p.PFFLAG and p0 == 0:
        raise ValueError("REECA1: power factor control (PFFLAG = 1) at zero active power has no power factor angle")
    k = p.base_ratio
    if not p.PMIN * k <= p0 <= p.PMAX * k:
        raise ValueError(f"REECA1: the active power {p0:.6g} pu at the start lies outside [PMIN, PMAX]")
    vp = max(V, LOWEST_VOLTAGE)
    Qref = p.Vref1 - V if p.QFLAG else q0 / V * vp
    pfaref = math.atan2(q0, p0)
    PFsel = q0 if p.PFFLAG else Qref
    x = np.array([V, p0, 0.0, PFsel / vp, p0, p0, p.QFLAG * q0 / V, p.timer_cap, 0.0, Ipcmd - p0 / V])
    u = np.array([V, p0, q0, p0, Qref, p.Vref0 if p.Vref0 != 0 else V, pfaref])
    x[8] = _signals(x, u, p, math)["Ipmax_now"]
    Iqcmd = _signals(x, u, p, math)["Iqcmd"]
    if "Iqcmd" in given and abs(Iqcmd - float(given["Iqcmd"])) > 1e-9 * max(1.0, abs(Iqcmd)):
        raise ValueError(f"REECA1: its reactive current command {Iqcmd:.9g} pu at the start differs from the "
                         f"converter's {float(given['Iqcmd']):.9g} pu")
    return x, {"Pref": u[3], "Qref": u[4], "Vref": u[5], "pfaref": u[6]}


def equilibrium(u, p: REECA1Params) -> np.ndarray:
    """The steady state [10] at constant inputs: the filters at their inputs, s5_y at Pref (on a
    power limit beyond it), each PI's integrator at rest (on the limit its input drives it to where
    that input is not 0), tdip at its cap, Ipmaxh at Ipmax, dIpcmd 0."""
    V, Pe, _, Pref, _, _, _ = finite_inputs(u, "REECA1")
    k = p.base_ratio
    vp = max(V, LOWEST_VOLTAGE)
    x = np.array([V, Pe, 0.0, 0.0, Pref, min(max(Pref, p.PMIN * k), p.PMAX * k), 0.0, p.timer_cap, 0.0, 0.0])
    s = _signals(x, u, p, math)
    x[3] = s["PFsel"] / vp
    x[2] = _pi_rest(s["PIQ_u"], p.Kqp, p.kqs, p.VMIN, p.VMAX, 0.0)
    s = _signals(x, u, p, math)
    x[6] = _pi_rest(s["PIV_u"], p.Kvp, p.kvs, -s["Iqmax"], s["Iqmax"], 0.0)
    x[8] = _signals(x, u, p, math)["Ipmax_now"]
    return x


INPUTS = (Quantity("V", "pu", "bus voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
          Quantity("Pe", "pu", "the converter's active power (system base)", start=0.5, operating_range=(0.0, 1.0)),
          Quantity("Qe", "pu", "the converter's reactive power (system base)", start=0.1,
                   operating_range=(-0.5, 0.5)),
          Quantity("Pref", "pu", "active power reference (system base)", start=0.5, operating_range=(0.0, 1.0)),
          Quantity("Qref", "pu", "reactive power reference (system base)", start=0.1, operating_range=(-0.5, 0.5)),
          Quantity("Vref", "pu", "reference voltage of the dip current injection", start=1.0,
                   operating_range=(0.9, 1.1)),
          Quantity("pfaref", "rad", "power factor angle reference", start=0.2, operating_range=(-0.5, 0.5)))

REECA1 = Component(
    name="reeca1",
    description="REECA1 renewable energy electrical controller model A (PSS/E, WECC REEC_A, ANDES)",
    states=(Quantity("s0_y", "pu", "filtered bus voltage"),
            Quantity("S1_y", "pu", "filtered active power"),
            Quantity("PIQ_xi", "pu", "reactive power PI integrator"),
            Quantity("s4_y", "pu", "filtered reactive current demand"),
            Quantity("pfilt_y", "pu", "filtered active power reference"),
            Quantity("s5_y", "pu", "active power order Pord (non-windup limited)"),
            Quantity("PIV_xi", "pu", "voltage PI integrator"),
            Quantity("tdip", "s", "time since the last voltage dip ended (capped)"),
            Quantity("Ipmaxh", "pu", "active current limit held after a dip"),
            Quantity("dIpcmd", "pu", "active current command offset from the start (held)")),
    inputs=INPUTS,
    outputs=(Quantity("Ipcmd", "pu", "active current command (system base)"),
             Quantity("Iqcmd", "pu", "reactive current command (system base; < 0 delivers reactive power)")),
    params_type=REECA1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.2, 0.1, 0.1, 0.2, 0.2, 0.1, 1.0, 0.5, 0.1),
    reset=reset,
    ports=Ports(inputs=(Link("terminal_voltage", "V"), Link("active_power", "Pe"), Link("reactive_power", "Qe"),
                        Link("active_power_reference", "Pref"), Link("reactive_power_reference", "Qref"),
                        Link("voltage_reference", "Vref"), Link("power_factor_angle_reference", "pfaref")),
                outputs=(Link("active_current_command", "Ipcmd"), Link("reactive_current_command", "Iqcmd"),
                         Link("active_power_order", "s5_y"))),
    initialisation=Initialisation(("Pref", "Qref", "Vref", "pfaref"), _start),
)
