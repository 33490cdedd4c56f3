"""REGF3: the grid-forming inverter with a dispatchable virtual oscillator (dVOC) as its primary
control (ANDES 2.0 REGF3), on a bus: REGF1's equations (models/regf1.py) with the droop replaced by
the oscillator's frequency and voltage laws.

States  x = REGF1's with, after delta, vref2 [pu] the oscillator's voltage (the outer voltage PI's
        reference)
Inputs, outputs: REGF1's (the output vdref is the state vref2)

Primary control (ANDES 2.0 model reference, RenGen: REGF3):

    dw = w0 wdrp (PIplim_y - Psen) / vref2^2 clipped to [dwmin, dwmax]
    dvref2/dt = w0 derv,  derv = wdrp / vref2 (PIqlim_y - Qsen) + Kdvoc vref2 (vref + vref2) (vref - vref2)
    Kdvoc = wdrp 4e8 / (1e8 - 2 (100 - 100 Qdrp)^2 - 1e4)^2  (ANDES' constant, as it computes it)

Bases and parameters: REGF1's (the data are the same).

Start (ANDES' initialisation): REGF1's, with vref2 = V0 (derv = 0 at vref = V0).
"""
from __future__ import annotations

import numpy as np

from ..blocks import clip
from ..component import Quantity
from .regf1 import REGF1Params, equations, grid_forming, rest, start


def oscillator_gain(p: REGF1Params) -> float:
    """ANDES' Kdvoc of the droops wdrp, Qdrp."""
    return p.wdrp * 4e8 / (1e8 - 2.0 * (100.0 - 100.0 * p.Qdrp) ** 2 - 1e4) ** 2


def virtual_oscillator(x_primary, powers, u, p: REGF1Params, m) -> tuple:
    """REGF3's primary control: ((dvref2/dt,), dw [rad/s], vref2 [pu])."""
    Psen, Qsen, PIplim_y, PIqlim_y = powers
    vref2, vref = x_primary[0], u[2]
    dw = clip(m, p.w0 * (PIplim_y - Psen) * p.wdrp / vref2 / vref2, p.dwmin, p.dwmax)
    derv = p.wdrp / vref2 * (PIqlim_y - Qsen) + vref2 * oscillator_gain(p) * (vref + vref2) * (vref - vref2)
    return (p.w0 * derv,), dw, vref2


def derivatives(x, u, p: REGF1Params, m):
    """dx/dt [14] of REGF3 for u = (Vs, theta_vs, vref, Paux, Qaux)."""
    return equations(x, u, p, m, virtual_oscillator, 1)[0]


def outputs(x, u, p: REGF1Params, m):
    """REGF1's outputs."""
    return equations(x, u, p, m, virtual_oscillator, 1)[1]


def _primary_start(V0: float, theta0: float, p: REGF1Params) -> np.ndarray:
    return np.array([V0])


def _start(given, p: REGF1Params) -> tuple:
    return start(given, p, _primary_start, "REGF3")


def equilibrium(u, p: REGF1Params) -> np.ndarray:
    """The steady state [14] at constant inputs (regf1.rest)."""
    return rest(u, p, _primary_start, "REGF3")


REGF3 = grid_forming("regf3", "REGF3 grid-forming inverter with a dispatchable virtual oscillator (ANDES) on a bus",
                     REGF1Params, (derivatives, outputs, equilibrium, _start),
                     (Quantity("vref2", "pu", "oscillator voltage (outer voltage PI's reference)"),), (0.05,))
