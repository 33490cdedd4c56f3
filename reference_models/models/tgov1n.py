"""TGOV1N: TGOV1 with the reference added after the droop (ANDES): pd = Pref - (omega - wref0) / R,
so Pref is a power (at rest Pref = Pm at omega = wref0). Otherwise TGOV1's equations (tgov1.py).

States  x = (LAG_y, LL_x) [pu];  Inputs u = (omega [pu], Pref [pu]);  Outputs y = (Pm [pu])

Source: ANDES 2.0 model reference, TurbineGov: TGOV1N.
"""
from __future__ import annotations

import numpy as np

from ..component import Component, Quantity
from .common import controller_initialisation, finite_inputs
from .tgov1 import (OUTPUTS, PORTS, STATES, TGOV1Params, governor_derivatives, governor_power, governor_reset,
                    rest_valve)

TGOV1NParams = TGOV1Params


def _demand(u, p: TGOV1Params):
    """pd = Pref - (omega - wref0) / R [pu]."""
    omega, Pref = u
    return Pref - (omega - p.wref0) / p.R


def derivatives(x, u, p: TGOV1Params, m):
    """(dLAG_y, dLL_x)/dt for x = (LAG_y, LL_x), u = (omega, Pref)."""
    return governor_derivatives(x, u[0], _demand(u, p), p, m)


def reset(x, u, p: TGOV1Params, m):
    """x after the reset of the valve's non-windup limit (tgov1.governor_reset)."""
    return governor_reset(x, _demand(u, p), p, m)


def outputs(x, u, p: TGOV1Params, m):
    """(Pm,)."""
    return (governor_power(x, u[0], p, m),)


def initialise(Pm: float, u, p: TGOV1Params) -> tuple:
    """(x [2], Pref [pu]): the state at rest giving Pm [pu] at speed u[0] and the reference that
    holds it (ANDES: Pref = Pm at omega = wref0)."""
    wd = float(u[0]) - p.wref0
    valve = Pm + p.Dt * wd
    return np.array([valve, valve]), valve + wd / p.R


def equilibrium(u, p: TGOV1Params) -> np.ndarray:
    """The steady state [2] at constant (omega, Pref); ValueError outside the valve limits."""
    omega, Pref = finite_inputs(u, "TGOV1N")
    return rest_valve(Pref - (omega - p.wref0) / p.R, p, "TGOV1N")


INPUTS = (Quantity("omega", "pu", "rotor speed", start=1.0, operating_range=(0.95, 1.05), minimum=0.0),
          Quantity("Pref", "pu", "power reference", start=0.7, operating_range=(0.0, 1.2)))

TGOV1N = Component(
    name="tgov1n",
    description="TGOV1N steam turbine-governor, reference after the droop (ANDES)",
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
