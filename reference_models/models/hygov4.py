"""HYGOV4: the hydro turbine-governor with a dashpot (PSS/E HYGOV4, ANDES), as ANDES 2.0.0 computes
it (without PSS/E's input dead band DB1, valve dead band DB2 and gate-power table, which ANDES 2.0.0
leaves out: its GV/PGV points are commented out of its data).

States  x = (LAG_y [pu] pilot servo output, GATE_y [pu] gate opening held within [PMIN, PMAX],
        WO_x [pu] dashpot (washout) state, q_y [pu] turbine flow)
Inputs  u = (omega [pu] rotor speed, Pref [pu] reference: ANDES' pref, in the units of Rperm times
        gate opening (at rest at omega = wref0: Pref = Rperm q0 / sqrt(Hdam) with
        q0 = Pm / (At Hdam) + qNL on ANDES' system base, below))
Outputs y = (Pm [pu] mechanical power)

Equations (ANDES 2.0 model reference, TurbineGov: HYGOV4), with c = Sn / Sb:

    wd = omega - wref0
    washout (dashpot) s Rtemp Tr / (1 + s Tr) of GATE_y -> WO_y = Rtemp (GATE_y - WO_x),
        Tr dWO_x/dt = GATE_y - WO_x
    Psum = Pref - Rperm GATE_y - WO_y - wd
    lag 1 / (1 + s Tp):  Tp dLAG_y/dt = Psum - LAG_y (Tp = 0: LAG_y = Psum, the state held)
    gate velocity SV = LAG_y / (c Tg) clipped to [UC, UO] (windup limiter)
    non-windup integrator: dGATE_y/dt = SV,  PMIN <= GATE_y <= PMAX
        (reset: GATE_y at or beyond a limit while SV pushes outward is placed on it)
    h = q_y^2 / GATE_y^2 (turbine head);  dq_y/dt = (c Hdam - h) / (c Tw)
    Pm = At h (q_y - qNL) - c Dturb wd GATE_y

Bases: Rperm, Rtemp, UO, UC, PMAX, PMIN, Dturb, Hdam, qNL and Pm on the turbine's base, which the
integration takes as the machine's base Sn (ANDES' default when Tn is not given). ANDES converts
them to the system base Sb (Hdam and qNL as powers), where its equations mix bases: the base-free
servo output drives the gate against the power-based UO, UC, the head is compared with the
power-based Hdam, and the damping multiplies two powers; on the turbine base that is the factor
c = Sn / Sb above (parameters Sn, Sb [MVA]; Sn = Sb: PSS/E's equations).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import clip, integrator_non_windup, integrator_non_windup_reset, lag, washout
from ..component import Parameters, Quantity
from .common import check_limits, check_ranges, finite_inputs
from .tgov1 import turbine_governor

PARAMETER_RANGES = {"Rperm": (0.001, 10.0, "pu"), "Rtemp": (0.0, 10.0, "pu"), "UO": (0.0, 100.0, "pu/s"),
                    "UC": (-100.0, 0.0, "pu/s"), "Tp": (0.0, 100.0, "s"), "Tg": (0.001, 100.0, "s"),
                    "Tr": (0.001, 100.0, "s"), "Tw": (0.001, 100.0, "s"), "At": (0.001, 100.0, "pu"),
                    "Dturb": (0.0, 100.0, "pu"), "Hdam": (0.001, 10.0, "pu"), "qNL": (0.0, 10.0, "pu"),
                    "wref0": (0.5, 1.5, "pu"), "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA")}


@dataclass(frozen=True)
class HYGOV4Params(Parameters):
    """ANDES/PSS/E HYGOV4 data: permanent and temporary droops Rperm, Rtemp [pu], gate velocity
    limits UO (opening), UC (closing) [pu/s], gate limits PMAX, PMIN [pu], time constants Tp
    (pilot servo), Tg (gate servo), Tr (dashpot), Tw (water inertia) [s], turbine gain At, damping
    Dturb [pu], head at the dam Hdam [pu], no-load flow qNL [pu], speed reference wref0 [pu], the
    turbine's base Sn and the system base Sb [MVA] (ANDES' bases, above)."""

    Rperm: float = 0.5
    Rtemp: float = 1.0
    UO: float = 1.0
    UC: float = 0.0
    PMAX: float = 1.0
    PMIN: float = 0.0
    Tp: float = 0.05
    Tg: float = 0.05
    Tr: float = 0.05
    Tw: float = 1.0
    At: float = 1.0
    Dturb: float = 0.0
    Hdam: float = 1.0
    qNL: float = 0.1
    wref0: float = 1.0
    Sn: float = 100.0
    Sb: float = 100.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "PMIN", "PMAX")


def _servo(x, u, p: HYGOV4Params, m):
    """(dLAG_y, SV, dWO_x): the pilot servo's derivative, the gate velocity, the dashpot's derivative."""
    LAG_y, GATE_y, WO_x, _ = x
    omega, Pref = u
    d_WO, WO_y = washout(m, GATE_y, WO_x, p.Rtemp * p.Tr, p.Tr)
    d_LAG, servo = lag(m, Pref - p.Rperm * GATE_y - WO_y - (omega - p.wref0), LAG_y, 1.0, p.Tp)
    return d_LAG, clip(m, servo / (p.Sn / p.Sb * p.Tg), p.UC, p.UO), d_WO


def _head(x):
    return x[3] * x[3] / (x[1] * x[1])


def derivatives(x, u, p: HYGOV4Params, m):
    """(dLAG_y, dGATE_y, dWO_x, dq_y)/dt for x = (LAG_y, GATE_y, WO_x, q_y), u = (omega, Pref)."""
    d_LAG, SV, d_WO = _servo(x, u, p, m)
    c = p.Sn / p.Sb
    d_GATE, _ = integrator_non_windup(m, SV, x[1], 1.0, 1.0, p.PMIN, p.PMAX)
    return d_LAG, d_GATE, d_WO, (c * p.Hdam - _head(x)) / (c * p.Tw)


def reset(x, u, p: HYGOV4Params, m):
    """x after the reset of the gate's non-windup limit (blocks.integrator_non_windup_reset)."""
    SV = _servo(x, u, p, m)[1]
    return x[0], integrator_non_windup_reset(m, SV, x[1], 1.0, 1.0, p.PMIN, p.PMAX), x[2], x[3]


def outputs(x, u, p: HYGOV4Params, m):
    """(Pm,) = At h (q_y - qNL) - c Dturb wd GATE_y."""
    return (p.At * _head(x) * (x[3] - p.qNL) - p.Sn / p.Sb * p.Dturb * (u[0] - p.wref0) * x[1],)


def _rest(gate: float, p: HYGOV4Params) -> np.ndarray:
    if not (p.PMIN <= gate <= p.PMAX and gate > 0):
        raise ValueError(f"HYGOV4: the gate opening {gate:.6g} pu at rest lies outside [PMIN, PMAX] "
                         "or is not positive")
    return np.array([0.0, gate, gate, gate * math.sqrt(p.Sn / p.Sb * p.Hdam)])


def equilibrium(u, p: HYGOV4Params) -> np.ndarray:
    """The steady state [4] at constant (omega, Pref): the pilot servo at 0, the gate at
    (Pref - wd) / Rperm, the flow at the head c Hdam; ValueError outside [PMIN, PMAX]."""
    omega, Pref = finite_inputs(u, "HYGOV4")
    return _rest((Pref - (omega - p.wref0)) / p.Rperm, p)


def start(given, p: HYGOV4Params) -> tuple:
    """(x0 [4], {"Pref": ...}): at rest at speed given["omega"] giving Pm = given["Pm"] (ANDES:
    the gate at q0 / sqrt(Hdam), pref = Rperm q0 / sqrt(Hdam) at omega = wref0)."""
    c = p.Sn / p.Sb
    wd = float(given["omega"]) - p.wref0
    slope = p.At * c * p.Hdam * math.sqrt(c * p.Hdam) - c * p.Dturb * wd
    if slope <= 0:
        raise ValueError("HYGOV4: no gate opening at rest gives the power at this speed")
    x0 = _rest((float(given["Pm"]) + p.At * c * p.Hdam * p.qNL) / slope, p)
    return x0, {"Pref": wd + p.Rperm * x0[1]}


HYGOV4 = turbine_governor(
    "hygov4", "HYGOV4 hydro turbine-governor with a dashpot (PSS/E, ANDES 2.0.0)",
    states=(Quantity("LAG_y", "pu", "pilot servo output"),
            Quantity("GATE_y", "pu", "gate opening (non-windup limited)"),
            Quantity("WO_x", "pu", "dashpot (washout) state"),
            Quantity("q_y", "pu", "turbine flow")),
    reference=Quantity("Pref", "pu", "reference (Rperm times gate opening at rest)", start=0.4,
                       operating_range=(0.0, 0.5)),
    params_type=HYGOV4Params, state_scales=(0.01, 0.2, 0.2, 0.2),
    derivatives=derivatives, outputs=outputs, equilibrium=equilibrium, reset=reset, start=start)
