"""REGF2: the grid-forming inverter with a virtual synchronous machine as its primary control
(ANDES 2.0 REGF2), on a bus: REGF1's equations (models/regf1.py) with the droop replaced by a
virtual inertia and damping on the frequency its phase-locked loop measures.

States  x = REGF1's with, after delta, INTw_y [pu] the virtual rotor speed and the phase-locked
        loop's PLL_PI_xi [pu] and PLL_am [rad] (ANDES' PLL2 PI_xi, am)
Inputs, outputs: REGF1's

Primary control (ANDES 2.0 model reference, RenGen: REGF2):

    Tint dINTw_y/dt = plldw dd wdrp + wref + wdrp (PIplim_y - Psen) - INTw_y,  Tint = mf wdrp,  wref = 1
    dw = w0 (INTw_y - wref) clipped to [dwmin, dwmax],  vref2 = (PIqlim_y - Qsen) Qdrp + vref (REGF1's)
    plldw = PI_y of the bus's phase-locked loop (models/pll2.py, a type-2 SRF PLL on the bus voltage):
        dPLL_PI_xi/dt = Ki Vs sin(theta_vs - PLL_am),  PI_y = Kp Vs sin(theta_vs - PLL_am) + PLL_PI_xi,
        dPLL_am/dt = 2 pi fn PI_y

The phase-locked loop: ANDES' REGF2 reads PI_y of the PLL its `pll` names, and where it names none
(as usual) adds a PLL2 at its bus with PLL2's defaults (Kp = Ki = 0.1, fn = 60 Hz). Here that PLL2 is
part of the inverter, with its gains Kp, Ki as parameters (PLL2's names and defaults) and the
inverter's fn. Bases: REGF1's; mf [s], dd have no base.

Start (ANDES' initialisation): REGF1's, with INTw_y = wref = 1, PLL_PI_xi = 0, PLL_am = theta0.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blocks import clip
from ..component import Quantity
from . import pll2
from .common import check_ranges
from .regf1 import REGF1Params, equations, grid_forming, rest, start

PARAMETER_RANGES = {"mf": (1e-4, 1e4, "s"), "dd": (0.0, 1e4, "pu"), "Kp": (0.0, 1e4, "pu"), "Ki": (0.0, 1e4, "pu/s")}


@dataclass(frozen=True)
class REGF2Params(REGF1Params):
    """ANDES REGF2 data: REGF1's, the virtual inertia constant mf [s] and damping dd, and the gains Kp,
    Ki of its phase-locked loop (ANDES' PLL2 at its bus)."""

    mf: float = 0.15
    dd: float = 0.11
    Kp: float = 0.1
    Ki: float = 0.1

    def check(self) -> None:
        super().check()
        check_ranges(self, PARAMETER_RANGES)
        self.require("wdrp", self.wdrp > 0, "be > 0 (the virtual rotor's time constant is mf wdrp)")

    @property
    def pll(self) -> pll2.PLL2Params:
        """The phase-locked loop's parameters (PLL2)."""
        return pll2.PLL2Params(fn=self.fn, Kp=self.Kp, Ki=self.Ki)


WREF = 1.0  # pu: ANDES' speed reference wref


def virtual_machine(x_primary, powers, u, p: REGF2Params, m) -> tuple:
    """REGF2's primary control: ((dINTw_y, dPLL_PI_xi, dPLL_am)/dt, dw [rad/s], vref2 [pu])."""
    Psen, Qsen, PIplim_y, PIqlim_y = powers
    INTw_y, pll_states, bus = x_primary[0], x_primary[1:], (u[0], u[1])
    plldw = pll2.outputs(pll_states, bus, p.pll, m)[0]
    d_INTw = (plldw * p.dd * p.wdrp + WREF + p.wdrp * (PIplim_y - Psen) - INTw_y) / (p.mf * p.wdrp)
    dw = clip(m, p.w0 * (INTw_y - WREF), p.dwmin, p.dwmax)
    return (d_INTw, *pll2.derivatives(pll_states, bus, p.pll, m)), dw, (PIqlim_y - Qsen) * p.Qdrp + u[2]


def derivatives(x, u, p: REGF2Params, m):
    """dx/dt [16] of REGF2 for u = (Vs, theta_vs, vref, Paux, Qaux)."""
    return equations(x, u, p, m, virtual_machine, 3)[0]


def outputs(x, u, p: REGF2Params, m):
    """REGF1's outputs."""
    return equations(x, u, p, m, virtual_machine, 3)[1]


def _primary_start(V0: float, theta0: float, p: REGF2Params) -> np.ndarray:
    return np.array([WREF, 0.0, theta0])


def _start(given, p: REGF2Params) -> tuple:
    return start(given, p, _primary_start, "REGF2")


def equilibrium(u, p: REGF2Params) -> np.ndarray:
    """The steady state [16] at constant inputs (regf1.rest)."""
    return rest(u, p, _primary_start, "REGF2")


REGF2 = grid_forming("regf2", "REGF2 grid-forming inverter with a virtual synchronous machine (ANDES) on a bus",
                     REGF2Params, (derivatives, outputs, equilibrium, _start),
                     (Quantity("INTw_y", "pu", "virtual rotor speed"),
                      Quantity("PLL_PI_xi", "pu", "phase-locked loop's PI integrator"),
                      Quantity("PLL_am", "rad", "phase-locked loop's measured angle (network frame)")),
                     (0.01, 0.01, 0.1))
