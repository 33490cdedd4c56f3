"""IEEEX1: the IEEE Type 1 DC exciter as ANDES 2.0.0 computes it: EXDC2's equations (exdc2.py) with
no speed term (Efd = vp; the saturation's switch compares vp with A) and the regulator's
non-windup limits VRMIN <= LA_y <= VRMAX, with their reset (a state at or beyond a limit while its
rate pushes outward is placed on it).

The limits are constant, not VRMIN Vt, VRMAX Vt: ANDES' IEEEX1 declares VRTMAX = VRMAX v and
VRTMIN = VRMIN v and assigns them to its lag's `upper`, `lower` after the lag has built its
AntiWindup limiter from VRMAX, VRMIN, so the limiter (ss.IEEEX1.LA.lim.upper: the parameter
VRMAX) keeps the constant limits. ANDES' own trajectories show it: in ieee39 with a fault at bus
16, its LA_y rises to 4.22 pu at Vt = 0.716 pu with VRMAX = 5.2 (VRMAX Vt = 3.72). With constant
limits our IEEEX1 under ANDES' inputs follows ANDES' states (docs/standard-models.md); with limits
moving with Vt it differed by up to 4.6 pu.

States  x = (LS_y, LL_x, LA_y, vp, W_x) [pu] as EXDC2
Inputs  u = (Vt [pu], Vref [pu], Vss [pu])
Outputs y = (Efd [pu] field voltage = vp)

Source: ANDES 2.0 model reference, Exciter: IEEEX1 (derived from EXDC2), and its code
(andes/models/exciter/ieeex1.py, andes/core/block.py LagAntiWindup) for the limits.
"""
from __future__ import annotations

import numpy as np

from ..component import Component, Quantity
from ..ports import Link, Ports
from .common import controller_initialisation, finite_inputs
from .exdc2 import DC_INPUTS, DC_STATES, EXDC2Params, dc_derivatives, dc_equilibrium, dc_initialise, dc_reset

IEEEX1Params = EXDC2Params


def derivatives(x, u, p: EXDC2Params, m):
    """(dLS_y, dLL_x, dLA_y, dvp, dW_x)/dt for x = (LS_y, LL_x, LA_y, vp, W_x), u = (Vt, Vref, Vss)."""
    Vt, Vref, Vss = u
    return dc_derivatives(x, Vt, Vref, Vss, None, p, m)


def reset(x, u, p: EXDC2Params, m):
    """x after the reset of the regulator's limits: LA_y at or beyond VRMAX while its unlimited
    rate KA LL_y - LA_y >= 0 is placed on VRMAX, at or below VRMIN while the rate <= 0 on VRMIN
    (ANDES' AntiWindup)."""
    Vt, Vref, Vss = u
    return dc_reset(x, Vt, Vref, Vss, p, m)


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
    return dc_equilibrium(lambda e: initialise(e, u, p), Vref, (p.VRMIN, p.VRMAX), "IEEEX1")


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
    initialisation=controller_initialisation(DC_INPUTS, "Efd", "Vref", initialise),
)
