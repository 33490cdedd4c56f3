"""SEXS: the simplified excitation system (PSS/E, ANDES).

States  x = (LL_x [pu] lead-lag state, LAW_y [pu] exciter output, held within [EMIN, EMAX])
Inputs  u = (Vt [pu] terminal voltage, Vref [pu] voltage set point, Vss [pu] stabiliser signal)
Outputs y = (Efd [pu] field voltage)

Equations (ANDES 2.0 model reference, Exciter: SEXS):

    vi = Vref - Vt + Vss
    lead-lag (1 + s TA) / (1 + s TB), TA = TATB TB:  TB dLL_x/dt = vi - LL_x,
        LL_y = TATB (vi - LL_x) + LL_x  (TB = 0: LL_y = vi)
    non-windup lag K / (1 + s TE):  TE dLAW_y/dt = K LL_y - LAW_y,  EMIN <= LAW_y <= EMAX
        (reset: LAW_y at or beyond a limit while K LL_y - LAW_y pushes outward is placed on it)
    Efd = LAW_y
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blocks import lag_non_windup, lag_non_windup_reset, lead_lag
from ..component import Component, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_limits, check_ranges, controller_initialisation, finite_inputs

PARAMETER_RANGES = {"TATB": (0.0, 10.0, "pu"), "TB": (0.0, 100.0, "s"), "K": (0.01, 1000.0, "pu"),
                    "TE": (0.001, 10.0, "s")}


@dataclass(frozen=True)
class SEXSParams(Parameters):
    """TATB = TA / TB [pu], TB [s], K [pu], TE [s], EMIN, EMAX [pu] (ANDES/PSS/E names)."""

    TATB: float = 0.4
    TB: float = 5.0
    K: float = 20.0
    TE: float = 0.1
    EMIN: float = -99.0
    EMAX: float = 99.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "EMIN", "EMAX")


def _lead_lag(x, u, p: SEXSParams, m):
    """(dLL_x/dt, LL_y)."""
    Vt, Vref, Vss = u
    return lead_lag(m, Vref - Vt + Vss, x[0], 1.0, p.TATB * p.TB, p.TB)


def derivatives(x, u, p: SEXSParams, m):
    """(dLL_x, dLAW_y)/dt for x = (LL_x, LAW_y), u = (Vt, Vref, Vss)."""
    d_LL, LL_y = _lead_lag(x, u, p, m)
    d_LAW, _ = lag_non_windup(m, LL_y, x[1], p.K, p.TE, p.EMIN, p.EMAX)
    return d_LL, d_LAW


def reset(x, u, p: SEXSParams, m):
    """x after the reset of LAW_y's non-windup limit (blocks.lag_non_windup_reset)."""
    return x[0], lag_non_windup_reset(m, _lead_lag(x, u, p, m)[1], x[1], p.K, p.TE, p.EMIN, p.EMAX)


def outputs(x, u, p: SEXSParams, m):
    """(Efd,)."""
    return (x[1],)


def initialise(Efd: float, u, p: SEXSParams) -> tuple:
    """(x [2], Vref [pu]): the state at rest giving field voltage Efd [pu] at inputs u (its Vref
    ignored) and the voltage set point that holds it (ANDES' initialisation)."""
    Vt, _, Vss = (float(v) for v in u)
    vi = Efd / p.K
    return np.array([vi, Efd]), Vt + vi - Vss


def equilibrium(u, p: SEXSParams) -> np.ndarray:
    """The steady state [2] at constant (Vt, Vref, Vss); ValueError where the output would rest
    beyond its limits."""
    Vt, Vref, Vss = finite_inputs(u, "SEXS")
    Efd = p.K * (Vref - Vt + Vss)
    if not p.EMIN <= Efd <= p.EMAX:
        raise ValueError(f"SEXS: the field voltage {Efd:.6g} pu at rest lies outside [EMIN, EMAX]")
    return initialise(Efd, u, p)[0]


INPUTS = (Quantity("Vt", "pu", "terminal voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
          Quantity("Vref", "pu", "voltage set point", start=1.1, operating_range=(0.9, 1.2)),
          Quantity("Vss", "pu", "stabiliser signal", start=0.0, operating_range=(-0.1, 0.1)))

SEXS = Component(
    name="sexs",
    description="SEXS simplified excitation system (PSS/E, ANDES)",
    states=(Quantity("LL_x", "pu", "lead-lag state"),
            Quantity("LAW_y", "pu", "exciter output (non-windup limited)")),
    inputs=INPUTS,
    outputs=(Quantity("Efd", "pu", "field voltage"),),
    params_type=SEXSParams,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.05, 0.5),
    reset=reset,
    ports=Ports(inputs=(Link("terminal_voltage", "Vt"), Link("voltage_reference", "Vref"),
                        Link("stabiliser_signal", "Vss")),
                outputs=(Link("field_voltage", "Efd"),)),
    initialisation=controller_initialisation(INPUTS, "Efd", "Vref", initialise),
)
