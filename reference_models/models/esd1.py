"""ESD1: the distributed energy storage model of ANDES 2.0.0, PVD1 (models/pvd1.py) with a state of
charge that limits its active current, and its bus-frequency measurement as its own states, on a bus.

States  x = (theta_f, theta_w [rad]: the measurement; Ipout_y, Iqout_y [pu, system base]: the
        currents, as PVD1; SOC: the state of charge [pu of En], ANDES' pIG_y)
Inputs  u = (Vs [pu], theta_vs [rad], pref0, qref0 [pu, system base]), as PVD1 (pref0 < 0 charges)
Outputs y = (I_re, I_im, P, Q, Ipout, Iqout [pu, system base], f [pu]), as PVD1

Equations (ANDES 2.0 model reference, DG: ESD1): PVD1's, with
    Psum's lower limit -pmx (not 0); as ANDES computes Ipul, Psum <= -pmx gives Ipul = 0
    the active current's limits [-(1 - zu) Imax, (1 - zl) Imax], Imax = ialim (P priority) or
        sqrt(max(ialim^2 - Iqcmd^2, 0)) (Q priority), zl = (SOC <= SOCmin), zu = (SOC >= SOCmax):
        an empty store delivers no active current, a full one takes none
    Tf dSOC/dt = Sb / (3600 En) (-P EtaC where Ipout_y < 0 (charging), -P / EtaD otherwise),
        P = Vs Ipout_y [pu, system base], En [MWh]

Bases as PVD1; Tf [s], SOCmin, SOCmax, SOCinit [pu], En [MWh], EtaC, EtaD as the case data give them.

Start (ANDES' initialisation): PVD1's, and SOC = SOCinit. SOC is not at rest there unless P0 = 0 (it
integrates the power delivered; ANDES does not check its start either). Its rest under constant
inputs (`equilibrium`) is at SOCinit where the active current is 0, else at the limit it runs to
(SOCmin discharging, SOCmax charging), where the active current is cut to 0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..component import Component, Initialisation, Quantity
from ..piecewise import where
from .common import check_limits, check_ranges
from .pvd1 import (BUS_PORT, OUTPUTS, STATES, PVD1Params, current_rates, inputs, load_flow_start, outputs,
                   rest_currents)

PARAMETER_RANGES = {
    "Tf": (1e-3, 1e4, "s"), "SOCmin": (0.0, 1.0, ""), "SOCmax": (0.0, 1.0, ""), "SOCinit": (0.0, 1.0, ""),
    "En": (1e-3, 1e7, "MWh"), "EtaC": (1e-3, 1.0, ""), "EtaD": (1e-3, 1.0, ""),
}
SECONDS_PER_HOUR = 3600.0


@dataclass(frozen=True)
class ESD1Params(PVD1Params):
    """PVD1's data and the store's: the SOC integrator's time constant Tf [s], its limits SOCmin <
    SOCmax and start SOCinit [pu], the rated energy En [MWh], the charging and discharging
    efficiencies EtaC, EtaD."""

    Tf: float = 1.0
    SOCmin: float = 0.0
    SOCmax: float = 1.0
    SOCinit: float = 0.5
    En: float = 100.0
    EtaC: float = 1.0
    EtaD: float = 1.0

    def check(self) -> None:
        super().check()
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "SOCmin", "SOCmax")


def storage_limits(m, SOC, p: ESD1Params):
    """The active current's limits(Imax) -> (low, high) at state of charge SOC: none to deliver from
    an empty store (SOC <= SOCmin), none to take into a full one (SOC >= SOCmax)."""

    def limits(Imax):
        return (-where(m, SOC >= p.SOCmax, 0.0 * Imax, Imax), where(m, SOC <= p.SOCmin, 0.0 * Imax, Imax))

    return limits


def derivatives(x, u, p: ESD1Params, m):
    """(dtheta_f, dtheta_w, dIpout_y, dIqout_y, dSOC)/dt for u = (Vs, theta_vs, pref0, qref0)."""
    Ipout, SOC, Vs = x[2], x[4], u[0]
    P = Vs * Ipout
    stored = where(m, Ipout < 0.0, -P * p.EtaC, -P / p.EtaD)
    return (*current_rates(x, u, p, m, storage_limits(m, SOC, p), -p.pmx * p.power_ratio),
            p.Sb / (SECONDS_PER_HOUR * p.En) * stored / p.Tf)


def equilibrium(u, p: ESD1Params) -> np.ndarray:
    """The rest [5] at constant (Vs, theta_vs, pref0, qref0): PVD1's at SOC = SOCinit where its
    active current is 0 there, else at SOCmin (delivering) or SOCmax (charging), where it is cut."""
    SOC = p.SOCinit
    for _ in range(2):
        Ip, Iq = rest_currents(u, p, storage_limits(math, SOC, p), -p.pmx * p.power_ratio, "ESD1")
        if Ip == 0.0:
            theta = float(u[1])
            return np.array([theta, theta, Ip, Iq, SOC])
        SOC = p.SOCmin if Ip > 0.0 else p.SOCmax
    raise ValueError("ESD1: no steady state at these inputs (its active current is not cut at its SOC limit)")


def _start(given, p: ESD1Params) -> tuple:
    x, u = load_flow_start(given, p, lambda x, u: derivatives([*x, p.SOCinit], u, p, math), "ESD1")
    return np.array([*x, p.SOCinit]), {"pref0": u[2], "qref0": u[3]}


ESD1 = Component(
    name="esd1",
    description="ESD1 distributed energy storage (ANDES: PVD1 with a state of charge) with its bus-frequency "
                "measurement, on a bus",
    states=STATES + (Quantity("SOC", "pu", "state of charge (of En; ANDES' pIG_y)"),),
    inputs=inputs((-1.0, 1.0)),
    outputs=OUTPUTS,
    params_type=ESD1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.1, 0.2, 0.2, 0.1),
    # the measurement's lag and washout; dSOC/dt does not depend on SOC
    affine_states=(0, 1, 4),
    ports=BUS_PORT,
    initialisation=Initialisation(("pref0", "qref0"), _start),
)
