"""TGOV1: the steam turbine-governor (PSS/E TGOV1, ANDES); TGOV1N (tgov1n.py) shares its equations.

States  x = (LAG_y [pu] valve position held within [VMIN, VMAX], LL_x [pu] lead-lag state)
Inputs  u = (omega [pu] rotor speed, Pref [pu] reference: ANDES' pref, for TGOV1 in the units of
        R times power (at rest Pref = R Pm), for TGOV1N a power)
Outputs y = (Pm [pu] mechanical power)

Equations (ANDES 2.0 model reference, TurbineGov: TGOV1, TGOV1N):

    wd = omega - wref0
    TGOV1: pd = (Pref - wd) / R;   TGOV1N: pd = Pref - wd / R
    non-windup lag 1 / (1 + s T1):  T1 dLAG_y/dt = pd - LAG_y,  VMIN <= LAG_y <= VMAX
        (reset: LAG_y at or beyond a limit while pd - LAG_y pushes outward is placed on it)
    lead-lag (1 + s T2) / (1 + s T3) of LAG_y (T3 = 0: a gain of 1) -> LL_y
    Pm = LL_y - Dt wd

Bases: R, VMAX, VMIN, Dt and Pm on the turbine's base, which the integration takes as the
machine's base Sn (ANDES' default when Tn is not given); ANDES converts them to the system base.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blocks import lag_non_windup, lag_non_windup_reset, lead_lag
from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_limits, check_ranges, controller_initialisation, finite_inputs

PARAMETER_RANGES = {"R": (0.001, 10.0, "pu"), "T1": (0.001, 100.0, "s"), "T2": (0.0, 100.0, "s"),
                    "T3": (0.0, 100.0, "s"), "Dt": (0.0, 100.0, "pu"), "wref0": (0.5, 1.5, "pu")}


@dataclass(frozen=True)
class TGOV1Params(Parameters):
    """ANDES/PSS/E TGOV1 data: droop R [pu], valve limits VMAX, VMIN [pu], time constants [s],
    turbine damping Dt [pu], speed reference wref0 [pu]."""

    R: float = 0.05
    VMAX: float = 1.2
    VMIN: float = 0.0
    T1: float = 0.1
    T2: float = 0.2
    T3: float = 10.0
    Dt: float = 0.0
    wref0: float = 1.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "VMIN", "VMAX")


def governor_derivatives(x, omega, pd, p: TGOV1Params, m):
    """(dLAG_y, dLL_x)/dt at valve demand pd."""
    d_LAG, LAG_y = lag_non_windup(m, pd, x[0], 1.0, p.T1, p.VMIN, p.VMAX)
    d_LL, _ = lead_lag(m, LAG_y, x[1], 1.0, p.T2, p.T3)
    return d_LAG, d_LL


def governor_reset(x, pd, p: TGOV1Params, m) -> tuple:
    """x after the reset of LAG_y's non-windup limit at valve demand pd (blocks.lag_non_windup_reset)."""
    return lag_non_windup_reset(m, pd, x[0], 1.0, p.T1, p.VMIN, p.VMAX), x[1]


def governor_power(x, omega, p: TGOV1Params, m):
    """Pm = LL_y - Dt (omega - wref0) [pu]."""
    LAG_y, LL_x = x
    _, LL_y = lead_lag(m, LAG_y, LL_x, 1.0, p.T2, p.T3)
    return LL_y - p.Dt * (omega - p.wref0)


def _demand(u, p: TGOV1Params):
    """pd = (Pref - (omega - wref0)) / R [pu]."""
    omega, Pref = u
    return (Pref - (omega - p.wref0)) / p.R


def derivatives(x, u, p: TGOV1Params, m):
    """(dLAG_y, dLL_x)/dt for x = (LAG_y, LL_x), u = (omega, Pref)."""
    return governor_derivatives(x, u[0], _demand(u, p), p, m)


def reset(x, u, p: TGOV1Params, m):
    """x after the reset of the valve's non-windup limit (governor_reset)."""
    return governor_reset(x, _demand(u, p), p, m)


def outputs(x, u, p: TGOV1Params, m):
    """(Pm,)."""
    return (governor_power(x, u[0], p, m),)


def initialise(Pm: float, u, p: TGOV1Params) -> tuple:
    """(x [2], Pref [pu]): the state at rest giving mechanical power Pm [pu] at speed u[0] and
    the reference that holds it (ANDES' initialisation: Pref = R Pm at omega = wref0)."""
    wd = float(u[0]) - p.wref0
    valve = Pm + p.Dt * wd
    return np.array([valve, valve]), valve * p.R + wd


def rest_valve(pd: float, p: TGOV1Params, name: str) -> np.ndarray:
    """The state [2] at rest at valve demand pd; ValueError outside [VMIN, VMAX]."""
    if not p.VMIN <= pd <= p.VMAX:
        raise ValueError(f"{name}: the valve demand {pd:.6g} pu at rest lies outside [VMIN, VMAX]")
    return np.array([pd, pd])


def equilibrium(u, p: TGOV1Params) -> np.ndarray:
    """The steady state [2] at constant (omega, Pref); ValueError where the valve would rest
    outside its limits."""
    omega, Pref = finite_inputs(u, "TGOV1")
    return rest_valve((Pref - (omega - p.wref0)) / p.R, p, "TGOV1")


STATES = (Quantity("LAG_y", "pu", "valve position (non-windup limited)"),
          Quantity("LL_x", "pu", "lead-lag state"))
OUTPUTS = (Quantity("Pm", "pu", "mechanical power"),)
PORTS = Ports(inputs=(Link("rotor_speed", "omega"), Link("power_reference", "Pref")),
              outputs=(Link("mechanical_power", "Pm"),))

SPEED = Quantity("omega", "pu", "rotor speed", start=1.0, operating_range=(0.95, 1.05), minimum=0.0)
INPUTS = (SPEED, Quantity("Pref", "pu", "reference (R times power at rest)", start=0.035, operating_range=(0.0, 0.06)))


def turbine_governor(name: str, description: str, states: tuple, reference: Quantity, params_type: type,
                     state_scales: tuple, derivatives, outputs, equilibrium, start, reset=None) -> Component:
    """The Component of a turbine-governor whose module gives its equations: inputs (omega, Pref),
    `reference` the Quantity of its set point Pref; output Pm; the governor's ports; started by
    start(given, p) -> (x0, {"Pref": value}) at rest at speed given["omega"] giving Pm = given["Pm"]."""
    return Component(name=name, description=description, states=states, inputs=(SPEED, reference),
                     outputs=OUTPUTS, params_type=params_type, derivatives=derivatives,
                     output_equations=outputs, equilibrium=equilibrium, state_scales=state_scales,
                     ports=PORTS, reset=reset, initialisation=Initialisation(solves=("Pref",), start=start))

TGOV1 = Component(
    name="tgov1",
    description="TGOV1 steam turbine-governor (PSS/E, ANDES)",
    states=STATES,
    inputs=INPUTS,
    outputs=OUTPUTS,
    params_type=TGOV1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.2, 0.2),
    ports=PORTS,
    reset=reset,
    initialisation=controller_initialisation(INPUTS, "Pm", "Pref", initialise),
)
