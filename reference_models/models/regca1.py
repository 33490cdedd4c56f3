"""REGCA1: the renewable energy generator/converter model A (PSS/E REGCA1, WECC REGC_A, ANDES), on a bus.

States  x = (S0_y [pu] active current, held under the LVPL limit; S1_y [pu] reactive current;
        S2_y [pu] filtered bus voltage (LVPL's input); q0 [pu] the reactive power at the start,
        held: it decides which rate limit of the reactive current acts, as ANDES' q0)
Inputs  u = (Vs [pu], theta_vs [rad]: the bus voltage; Ipcmd, Iqcmd [pu]: the active and reactive
        current commands, ANDES' sign: Iqcmd < 0 delivers reactive power)
Outputs y = (I_re, I_im [pu]: the current into the bus, network frame; P, Q [pu]: the power into
        the bus; Ipout, Iqout [pu]: the active and reactive currents (ANDES' Ipout, Iqout_y);
        Pe, Qe [pu]: ANDES' names of P and Q, the signals its electrical controller measures)

Equations (ANDES 2.0 model reference, RenGen: REGCA1), all on the system base:

    LVG(V) = 0 for V <= Lvpnt0, (V - Lvpnt0) / (Lvpnt1 - Lvpnt0) up to Lvpnt1, 1 above
    Tfltr dS2_y/dt = V - S2_y  (Tfltr = 0: S2_y held, V used)
    LVPL(S2_y) = F for S2_y <= Zerox, (S2_y - Zerox) Lvplsw Lvpl1 / (Brkpt - Zerox) + F up to Brkpt,
        9999 above, with F = 9999 (1 - Lvplsw)
    Tg dS0_y/dt = r = min(Ipcmd - S0_y, Rrpwr), non-windup above LVPL(S2_y): where S0_y >= LVPL - 1e-9 and
        r > Tg dLVPL/dt, S0_y follows the limit (dS0_y/dt = dLVPL/dt, which is 0 where LVPL rests,
        as ANDES holds it; Tfltr = 0: 0, the limit moving with the input)
        (reset: S0_y at or above LVPL while its rate is >= 0 is placed on LVPL)
    Tg dS1_y/dt = e, e = -Iqcmd - S1_y, clipped above at Iqrmax where q0 > 0, below at Iqrmin where q0 < 0
    dq0/dt = 0
    Ipout = S0_y LVG(V),  HVG = max(Khv (V - Volim), 0),  Iqout = max(S1_y - HVG, Iolim)
    P = Pe = Ipout V,  Q = Qe = Iqout V,  I = (Ipout - j Iqout) exp(j theta_vs)

The rate limits bound Tg dS/dt, as ANDES' RateLimiter does (it clips the equation before the time
constant divides it): a rate of Rrpwr / Tg pu/s.

Bases: the currents, powers and the current commands are on the system base Sb, as ANDES computes
them. The parameters are as the case data give them: Iolim, Iqrmax, Iqrmin on the converter's base
Sn, converted by Sn / Sb as ANDES converts them (its `current` parameters); the others unconverted,
as in ANDES. ANDES' Accel (unused by its equations) is not a parameter.

Start (ANDES' initialisation): from the load-flow point V0, P0, Q0 (its share of the static
generator's power): Iqcmd = -Q0 / V0, Ipcmd = P0 / (V0 LVG(V0)), S0_y = Ipcmd, S1_y = Q0 / V0,
S2_y = V0, q0 = Q0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import clip, lag, non_windup_reset
from ..component import Component, Initialisation, Parameters, Quantity
from ..piecewise import where
from ..ports import BusPort, Link, Ports
from .common import check_limits, check_ranges, finite_inputs

PARAMETER_RANGES = {
    "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA"), "Tg": (0.001, 100.0, "s"), "Rrpwr": (1e-3, 1e4, "pu"),
    "Brkpt": (0.0, 2.0, "pu"), "Zerox": (0.0, 2.0, "pu"), "Lvplsw": (0.0, 1.0, ""), "Lvpl1": (0.0, 100.0, "pu"),
    "Volim": (0.5, 5.0, "pu"), "Lvpnt1": (0.0, 2.0, "pu"), "Lvpnt0": (0.0, 2.0, "pu"), "Iolim": (-100.0, 0.0, "pu"),
    "Tfltr": (0.0, 100.0, "s"), "Khv": (0.0, 100.0, "pu"), "Iqrmax": (1e-3, 1e4, "pu"), "Iqrmin": (-1e4, -1e-3, "pu"),
}
NO_LVPL = 9999.0  # pu: ANDES' LVPL output where the limit is off
# pu: S0_y within this below LVPL counts as on it, so that a state sliding along a falling limit stays held
# through the round-off of its steps (the switching function S0_y - LVPL + HOLD_BAND keeps its sign)
HOLD_BAND = 1e-9


@dataclass(frozen=True)
class REGCA1Params(Parameters):
    """ANDES/PSS/E REGCA1 data: the converter's base Sn [MVA] and the system base Sb [MVA]; time
    constants [s]; LVPL (Zerox, Brkpt [pu] voltages, Lvpl1 [pu] current at Brkpt, Lvplsw 1: on, 0: off),
    Rrpwr [pu] its ramp limit; low-voltage active current gain (Lvpnt0, Lvpnt1 [pu]); high-voltage
    reactive current management (Volim [pu], Khv, Iolim [pu, base Sn]); reactive current rate limits
    Iqrmax, Iqrmin [pu, base Sn]."""

    Sn: float = 100.0
    Sb: float = 100.0
    Tg: float = 0.1
    Rrpwr: float = 10.0
    Brkpt: float = 1.0
    Zerox: float = 0.5
    Lvplsw: float = 1.0
    Lvpl1: float = 1.0
    Volim: float = 1.2
    Lvpnt1: float = 0.8
    Lvpnt0: float = 0.4
    Iolim: float = -1.5
    Tfltr: float = 0.1
    Khv: float = 0.7
    Iqrmax: float = 1.0
    Iqrmin: float = -1.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "Zerox", "Brkpt")
        check_limits(self, "Lvpnt0", "Lvpnt1")

    @property
    def base_ratio(self) -> float:
        """Sn / Sb: a current on the converter's base times this is on the system base."""
        return self.Sn / self.Sb


def low_voltage_gain(m, V, p: REGCA1Params):
    """LVG(V): the active current's gain at low voltage, 0 up to Lvpnt0, linear to 1 at Lvpnt1."""
    return where(m, V <= p.Lvpnt0, 0.0 * V,
                 where(m, V <= p.Lvpnt1, (V - p.Lvpnt0) / (p.Lvpnt1 - p.Lvpnt0), 1.0 + 0.0 * V))


def low_voltage_power_limit(m, S2_y, p: REGCA1Params):
    """LVPL(S2_y) [pu]: the upper limit of the active current (9999: none) at filtered voltage S2_y."""
    off = NO_LVPL * (1.0 - p.Lvplsw)
    slope = p.Lvplsw * p.Lvpl1 / (p.Brkpt - p.Zerox)
    return where(m, S2_y <= p.Zerox, off + 0.0 * S2_y,
                 where(m, S2_y <= p.Brkpt, (S2_y - p.Zerox) * slope + off, NO_LVPL + 0.0 * S2_y))


def _active_rate(x, u, p: REGCA1Params, m):
    """(Tg dS0_y/dt before the LVPL limit: Ipcmd - S0_y capped at Rrpwr, LVPL at the filtered
    voltage: S2_y, or V where Tfltr = 0)."""
    _, filtered = lag(m, u[0], x[2], 1.0, p.Tfltr)
    return clip(m, u[2] - x[0], -math.inf, p.Rrpwr), low_voltage_power_limit(m, filtered, p)


def _limit_rate(x, u, p: REGCA1Params, m):
    """dLVPL/dt [pu/s]: LVPL's slope times dS2_y/dt between Zerox and Brkpt, else 0 (0 where
    Tfltr = 0: the limit then moves with the input, whose rate the equations do not see)."""
    d_S2, filtered = lag(m, u[0], x[2], 1.0, p.Tfltr)
    slope = p.Lvplsw * p.Lvpl1 / (p.Brkpt - p.Zerox)
    return where(m, filtered <= p.Zerox, 0.0 * d_S2, where(m, filtered <= p.Brkpt, slope * d_S2, 0.0 * d_S2))


def derivatives(x, u, p: REGCA1Params, m):
    """(dS0_y, dS1_y, dS2_y, dq0)/dt for x = (S0_y, S1_y, S2_y, q0), u = (Vs, theta_vs, Ipcmd, Iqcmd)."""
    S0_y, S1_y, S2_y, q0 = x
    Vs, _, _, Iqcmd = u
    rate, LVPL = _active_rate(x, u, p, m)
    held = p.Tg * _limit_rate(x, u, p, m)  # on the limit, S0_y moves with it (a rate at most the free one)
    rate = where(m, S0_y >= LVPL - HOLD_BAND, where(m, rate > held, held, rate), rate)
    e = -Iqcmd - S1_y
    e = where(m, q0 < 0.0, clip(m, e, p.Iqrmin * p.base_ratio, math.inf), e)
    e = where(m, q0 > 0.0, clip(m, e, -math.inf, p.Iqrmax * p.base_ratio), e)
    d_S2, _ = lag(m, Vs, S2_y, 1.0, p.Tfltr)
    return rate / p.Tg, e / p.Tg, d_S2, 0.0 * q0


def reset(x, u, p: REGCA1Params, m):
    """x after the reset of S0_y's non-windup limit LVPL (blocks.non_windup_reset)."""
    rate, LVPL = _active_rate(x, u, p, m)
    return non_windup_reset(m, rate, x[0], -math.inf, LVPL), x[1], x[2], x[3]


def currents(x, Vs, p: REGCA1Params, m) -> tuple:
    """(Ipout, Iqout) [pu]: the active current S0_y LVG(V) and the reactive current
    max(S1_y - HVG, Iolim) with the high-voltage gain HVG = max(Khv (V - Volim), 0)."""
    HVG = clip(m, p.Khv * (Vs - p.Volim), 0.0, math.inf)
    return x[0] * low_voltage_gain(m, Vs, p), clip(m, x[1] - HVG, p.Iolim * p.base_ratio, math.inf)


def outputs(x, u, p: REGCA1Params, m):
    """(I_re, I_im, P, Q, Ipout, Iqout, Pe, Qe) [pu, system base]."""
    Vs, theta_vs = u[0], u[1]
    Ipout, Iqout = currents(x, Vs, p, m)
    c, s = m.cos(theta_vs), m.sin(theta_vs)
    Pe, Qe = Ipout * Vs, Iqout * Vs
    return Ipout * c + Iqout * s, Ipout * s - Iqout * c, Pe, Qe, Ipout, Iqout, Pe, Qe


def operating_point(V0: float, P0: float, Q0: float, p: REGCA1Params) -> tuple:
    """(x [4], Ipcmd, Iqcmd): the state at rest delivering P0 + jQ0 [pu, system base] at bus voltage V0
    and the current commands holding it (ANDES' initialisation); ValueError where a limit forbids it."""
    gain = low_voltage_gain(math, V0, p)
    if V0 <= 0 or gain <= 0:
        raise ValueError(f"REGCA1: no active current at bus voltage {V0:.6g} pu (at or below Lvpnt0 = {p.Lvpnt0})")
    Ipcmd, Iq = P0 / (V0 * gain), Q0 / V0
    if Ipcmd > low_voltage_power_limit(math, V0, p):
        raise ValueError(f"REGCA1: the active current {Ipcmd:.6g} pu at rest exceeds its LVPL limit")
    if currents(np.array([Ipcmd, Iq]), V0, p, math)[1] != Iq:
        raise ValueError(f"REGCA1: the reactive current {Iq:.6g} pu at rest is cut by Iolim or Volim")
    return np.array([Ipcmd, Iq, V0, Q0]), Ipcmd, -Iq


def _start(given, p: REGCA1Params) -> tuple:
    x0, Ipcmd, Iqcmd = operating_point(float(given["V0"]), float(given["P0"]), float(given["Q0"]), p)
    return x0, {"Ipcmd": Ipcmd, "Iqcmd": Iqcmd}


def equilibrium(u, p: REGCA1Params) -> np.ndarray:
    """The steady state [4] at constant (Vs, theta_vs, Ipcmd, Iqcmd): the active current at its
    command or on LVPL, the reactive current at -Iqcmd, q0 the reactive power delivered."""
    Vs, _, Ipcmd, Iqcmd = finite_inputs(u, "REGCA1")
    S0_y = min(Ipcmd, low_voltage_power_limit(math, Vs, p))
    x = np.array([S0_y, -Iqcmd, Vs, 0.0])
    x[3] = currents(x, Vs, p, math)[1] * Vs
    return x


REGCA1 = Component(
    name="regca1",
    description="REGCA1 renewable energy generator/converter model A (PSS/E, WECC REGC_A, ANDES) on a bus",
    states=(Quantity("S0_y", "pu", "active current (non-windup limited by LVPL)"),
            Quantity("S1_y", "pu", "reactive current"),
            Quantity("S2_y", "pu", "filtered bus voltage (LVPL input)"),
            Quantity("q0", "pu", "reactive power at the start (held)")),
    inputs=(Quantity("Vs", "pu", "bus voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
            Quantity("theta_vs", "rad", "bus voltage angle", start=0.0, operating_range=(-0.5, 0.5)),
            Quantity("Ipcmd", "pu", "active current command (system base)", start=0.5, operating_range=(0.0, 0.9)),
            Quantity("Iqcmd", "pu", "reactive current command (system base; < 0 delivers reactive power)",
                     start=-0.1, operating_range=(-0.5, 0.5))),
    outputs=(Quantity("I_re", "pu", "bus current, real part (network frame, system base)"),
             Quantity("I_im", "pu", "bus current, imaginary part (network frame, system base)"),
             Quantity("P", "pu", "active power into the bus (system base)"),
             Quantity("Q", "pu", "reactive power into the bus (system base)"),
             Quantity("Ipout", "pu", "active current (system base)"),
             Quantity("Iqout", "pu", "reactive current (system base)"),
             Quantity("Pe", "pu", "active power output (system base)"),
             Quantity("Qe", "pu", "reactive power output (system base)")),
    params_type=REGCA1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.2, 0.2, 0.1, 0.2),
    reset=reset,
    ports=Ports(bus=BusPort(voltage=("Vs", "theta_vs"), current=("I_re", "I_im")),
                inputs=(Link("active_current_command", "Ipcmd"), Link("reactive_current_command", "Iqcmd")),
                outputs=(Link("active_power", "Pe"), Link("reactive_power", "Qe"))),
    initialisation=Initialisation(("Ipcmd", "Iqcmd"), _start),
)
