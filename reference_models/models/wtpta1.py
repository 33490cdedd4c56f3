"""WTPTA1: the pitch controller of a type-3 wind turbine (PSS/E WTPTA1, WECC WTGPT_A, ANDES).

States  x = (PIc_xi [deg] integrator of the power compensation PI; PIw_xi [deg] integrator of the
        speed PI; LG_y [deg] the pitch angle, the output lag's state)
Inputs  u = (wt [pu] turbine speed (its drive train's); Pord [pu] the electrical controller's active
        power order; Pref [pu] the electrical controller's active power reference (its torque
        controller's output); wref [pu] the speed reference (its drive train's set point w0))
Outputs y = (theta [deg]: the pitch angle LG_y, the aerodynamics' input)

Equations (ANDES 2.0 model reference, RenPitch: WTPTA1):

    ec = Pord - Pref,  ew = Kcc ec + wt - wref
    dPIc_xi/dt = Kic ec, non-windup within [thmin, thmax];  PIc_y = Kpc ec + PIc_xi clipped to [thmin, thmax]
    dPIw_xi/dt = Kiw ew, non-windup within [thmin, thmax];  PIw_y = Kpw ew + PIw_xi clipped to [thmin, thmax]
    Tp dLG_y/dt = PIw_y + PIc_y - LG_y clipped to [dthmin, dthmax], non-windup within [thmin, thmax]
    theta = LG_y

(ANDES' PIAWHardLimit twice and its LagAntiWindupRate: the rate limits bound Tp dLG_y/dt, as its
RateLimiter clips the equation before the time constant divides it.) The powers are on the system
base, as ANDES computes them; the angles and their limits in degrees, as the case data give them.

The speed reference: ANDES sets its wref to the turbine speed when the pitch controller starts,
which is before the torque controller moves the drive train's speeds to its power-speed
characteristic: the drive train's set point w0. The drive train gives it here
(`turbine_speed_reference`), so below w0 the speed PI holds its integrator on thmin as ANDES does.

Start (ANDES' initialisation): both integrators at 0, LG_y at PIw_y + PIc_y; refused where 0 lies
outside [thmin, thmax] or the point is not at rest (the turbine faster than the reference, with
Kiw > 0, or a power order apart from the reference: the pitch would move).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import clip, integrator_non_windup, integrator_non_windup_reset, non_windup, non_windup_reset
from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_limits, check_ranges, finite_inputs

PARAMETER_RANGES = {
    "Kiw": (0.0, 1e4, "deg/(pu s)"), "Kpw": (0.0, 1e4, "deg/pu"), "Kic": (0.0, 1e4, "deg/(pu s)"),
    "Kpc": (0.0, 1e4, "deg/pu"), "Kcc": (0.0, 1e4, "pu"), "Tp": (1e-3, 100.0, "s"), "thmax": (-90.0, 90.0, "deg"),
    "thmin": (-90.0, 90.0, "deg"), "dthmax": (0.0, 1e3, "deg"), "dthmin": (-1e3, 0.0, "deg"),
}
REST_RATE = 1e-10  # deg/s: the largest rate at a start taken as rest (rounding of the power order)


@dataclass(frozen=True)
class WTPTA1Params(Parameters):
    """ANDES/PSS/E WTPTA1 data: the speed PI (Kpw, Kiw) and the power compensation PI (Kpc, Kic)
    gains, the power difference gain Kcc, the blade response time Tp [s], the pitch limits thmin,
    thmax [deg] and the limits dthmin, dthmax [deg] of Tp times its rate."""

    Kiw: float = 0.1
    Kpw: float = 0.0
    Kic: float = 0.1
    Kpc: float = 0.0
    Kcc: float = 0.0
    Tp: float = 0.3
    thmax: float = 30.0
    thmin: float = 0.0
    dthmax: float = 5.0
    dthmin: float = -5.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "thmin", "thmax")
        check_limits(self, "dthmin", "dthmax")


def _signals(x, u, p: WTPTA1Params, m) -> tuple:
    """(ec, ew, PIc_y + PIw_y: the output lag's input) at x, u."""
    PIc_xi, PIw_xi = x[0], x[1]
    wt, Pord, Pref, wref = u
    ec = Pord - Pref
    ew = p.Kcc * ec + wt - wref
    PIc_y = clip(m, p.Kpc * ec + PIc_xi, p.thmin, p.thmax)
    PIw_y = clip(m, p.Kpw * ew + PIw_xi, p.thmin, p.thmax)
    return ec, ew, PIc_y + PIw_y


def _lag_rate(x, demand, p: WTPTA1Params, m):
    """Tp dLG_y/dt before its non-windup limit: demand - LG_y clipped to [dthmin, dthmax]."""
    return clip(m, demand - x[2], p.dthmin, p.dthmax)


def derivatives(x, u, p: WTPTA1Params, m):
    """(dPIc_xi, dPIw_xi, dLG_y)/dt for x = (PIc_xi, PIw_xi, LG_y), u = (wt, Pord, Pref, wref)."""
    ec, ew, demand = _signals(x, u, p, m)
    lag_rate = _lag_rate(x, demand, p, m)
    return (integrator_non_windup(m, ec, x[0], p.Kic, 1.0, p.thmin, p.thmax)[0],
            integrator_non_windup(m, ew, x[1], p.Kiw, 1.0, p.thmin, p.thmax)[0],
            non_windup(m, lag_rate, x[2], p.thmin, p.thmax) / p.Tp)


def reset(x, u, p: WTPTA1Params, m):
    """x after the resets of its three non-windup limits [thmin, thmax] (blocks.non_windup_reset)."""
    ec, ew, demand = _signals(x, u, p, m)
    lag_rate = _lag_rate(x, demand, p, m)
    return (integrator_non_windup_reset(m, ec, x[0], p.Kic, 1.0, p.thmin, p.thmax),
            integrator_non_windup_reset(m, ew, x[1], p.Kiw, 1.0, p.thmin, p.thmax),
            non_windup_reset(m, lag_rate, x[2], p.thmin, p.thmax))


def outputs(x, u, p: WTPTA1Params, m):
    """(theta,) [deg]."""
    return (x[2] + 0.0 * u[0],)


def _lag_rest(PIc_xi: float, PIw_xi: float, u, p: WTPTA1Params) -> np.ndarray:
    """The state with the given integrators and LG_y at rest: the PI outputs' sum within [thmin, thmax]."""
    x = np.array([PIc_xi, PIw_xi, 0.0])
    x[2] = clip(math, _signals(x, u, p, math)[2], p.thmin, p.thmax)
    return x


def _start(given, p: WTPTA1Params) -> tuple:
    if not p.thmin <= 0.0 <= p.thmax:
        raise ValueError(f"WTPTA1: its integrators start at 0, outside [thmin, thmax] = [{p.thmin}, {p.thmax}] deg")
    u = np.array([float(given[n]) for n in ("wt", "Pord", "Pref", "wref")])
    x = _lag_rest(0.0, 0.0, u, p)
    rates = np.array(derivatives(x, u, p, math), dtype=float)
    if np.abs(rates).max() > REST_RATE:
        raise ValueError(f"WTPTA1: no rest at the start (turbine speed {u[0]:.6g} pu, reference {u[3]:.6g} pu, "
                         f"power order {u[1]:.6g} pu, reference {u[2]:.6g} pu): the pitch would move")
    return x, {}


def equilibrium(u, p: WTPTA1Params) -> np.ndarray:
    """The steady state [3] at constant inputs: an integrator whose input is not 0 on the limit it
    drives it to; one with input 0 rests anywhere: ours, where both do, share the mid-range pitch
    (each at (thmin + thmax) / 4 within the limits); LG_y at the PI outputs' sum within the limits."""
    wt, Pord, Pref, wref = finite_inputs(u, "WTPTA1")
    ec = Pord - Pref
    ew = p.Kcc * ec + wt - wref
    share = min(max(0.25 * (p.thmin + p.thmax), p.thmin), p.thmax)

    def rest(rate):
        return p.thmax if rate > 0 else p.thmin if rate < 0 else share

    return _lag_rest(rest(p.Kic * ec), rest(p.Kiw * ew), np.array([wt, Pord, Pref, wref]), p)


WTPTA1 = Component(
    name="wtpta1",
    description="WTPTA1 pitch controller of a type-3 wind turbine (PSS/E, WECC WTGPT_A, ANDES)",
    states=(Quantity("PIc_xi", "deg", "power compensation PI integrator (non-windup)"),
            Quantity("PIw_xi", "deg", "speed PI integrator (non-windup)"),
            Quantity("LG_y", "deg", "pitch angle (rate limited, non-windup)")),
    inputs=(Quantity("wt", "pu", "turbine speed", start=1.0, operating_range=(0.6, 1.2)),
            Quantity("Pord", "pu", "active power order of the electrical controller (system base)", start=0.5,
                     operating_range=(0.0, 1.0)),
            Quantity("Pref", "pu", "active power reference of the electrical controller (system base)", start=0.5,
                     operating_range=(0.0, 1.0)),
            Quantity("wref", "pu", "speed reference", start=1.0, operating_range=(0.9, 1.1))),
    outputs=(Quantity("theta", "deg", "pitch angle"),),
    params_type=WTPTA1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(1.0, 1.0, 1.0),
    reset=reset,
    ports=Ports(inputs=(Link("turbine_speed", "wt"), Link("active_power_order", "Pord"),
                        Link("active_power_reference", "Pref"), Link("turbine_speed_reference", "wref")),
                outputs=(Link("pitch_angle", "theta"),)),
    initialisation=Initialisation((), _start),
)
