"""IEEEX1: the IEEE Type 1 DC exciter as ANDES models it: EXDC2's equations (exdc2.py) with the
regulator's non-windup limits proportional to the terminal voltage, VRMIN Vt <= LA_y <= VRMAX Vt
(with ANDES' reset: LA_y is placed on a limit it is at or beyond while its rate pushes outward, so
it follows VRMAX Vt down when the voltage drops), and no speed term (Efd = vp; the saturation's switch compares vp with A).

States  x = (LS_y, LL_x, LA_y, vp, W_x) [pu] as EXDC2
Inputs  u = (Vt [pu], Vref [pu], Vss [pu])
Outputs y = (Efd [pu] field voltage = vp)

Source: ANDES 2.0 model reference, Exciter: IEEEX1 (derived from EXDC2).
"""
from __future__ import annotations

import numpy as np

from ..component import Component, Quantity
from ..ports import Link, Ports
from .common import finite_inputs
from .exdc2 import DC_INPUTS, DC_STATES, EXDC2Params, dc_derivatives, dc_equilibrium, dc_initialise, dc_reset

IEEEX1Params = EXDC2Params


def derivatives(x, u, p: EXDC2Params, m):
    """(dLS_y, dLL_x, dLA_y, dvp, dW_x)/dt for x = (LS_y, LL_x, LA_y, vp, W_x), u = (Vt, Vref, Vss)."""
    Vt, Vref, Vss = u
    return dc_derivatives(x, Vt, Vref, Vss, None, p, m, True)


def reset(x, u, p: EXDC2Params, m):
    """x after the reset of the regulator's moving limits: LA_y at or beyond VRMAX Vt while its
    unlimited rate KA LL_y - LA_y >= 0 is placed on VRMAX Vt, at or below VRMIN Vt while the rate
    <= 0 on VRMIN Vt (ANDES' AntiWindup), so LA_y follows a limit that moves inward with Vt."""
    Vt, Vref, Vss = u
    return dc_reset(x, Vt, Vref, Vss, p, m, True)


def outputs(x, u, p: EXDC2Params, m):
    """(Efd,) = vp."""
    return (x[3],)


def initialise(Efd: float, u, p: EXDC2Params) -> tuple:
    """(x [5], Vref [pu]): the state at rest giving field voltage Efd [pu] at inputs u (its Vref
    ignored) and the set point that holds it."""
    Vt, _, Vss = (float(v) for v in u)
    return dc_initialise(Efd, Vt, Vss, 1.0, p)


def equilibrium(u, p: EXDC2Params) -> np.ndarray:
    """The steady state [5] at constant (Vt, Vref, Vss); ValueError where there is none within the
    regulator limits."""
    Vt, Vref, Vss = finite_inputs(u, "IEEEX1")
    return dc_equilibrium(lambda e: initialise(e, u, p), Vref, (p.VRMIN * Vt, p.VRMAX * Vt), "IEEEX1")


IEEEX1 = Component(
    name="ieeex1",
    description="IEEEX1 IEEE Type 1 DC exciter (ANDES)",
    states=DC_STATES,
    inputs=DC_INPUTS,
    outputs=(Quantity("Efd", "pu", "field voltage"),),
    params_type=EXDC2Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.05, 1.0, 0.5, 0.5),
    reset=reset,
    ports=Ports(inputs=(Link("terminal_voltage", "Vt"), Link("voltage_reference", "Vref"),
                        Link("stabiliser_signal", "Vss")),
                outputs=(Link("field_voltage", "Efd"),)),
)
