"""AC8B: the IEEE 421.5 AC8B exciter (PID voltage regulator, PSS/E AC8B) as ANDES 2.0.0 computes it.

States  x = (LG_y [pu] sensed voltage, PID_xi [pu] PID integrator, PID_WO_x [pu] PID derivative
        washout state, LA_y [pu] regulator output VR held within [VRMIN, VRMAX], INT_y [pu] exciter
        voltage VE)
Inputs  u = (Vt [pu] input voltage (terminal, or compensated by IEEEVC), Vref [pu] set point,
        Vss [pu] stabiliser signal, XadIfd [pu] the machine's field current)
Outputs y = (Efd [pu] field voltage = FEX(IN) INT_y)

Equations (ANDES 2.0.0, andes/models/exciter/ac8b.py, excbase.ExcACSat; andes/core/block.py
PIDTrackAW):

    sensing lag 1 / (1 + s TR):  TR dLG_y/dt = Vt - LG_y  (TR = 0: LG_y held, Vt used)
    vi = Vref - LG_y + Vss  (ANDES' UEL = OEL = 0)
    PID with tracking anti-windup (blocks.pid_tracking), ks ANDES' tracking gain (its config, 2):
        Td dPID_WO_x/dt = vi - PID_WO_x,  ys = kP vi + PID_xi + kD (vi - PID_WO_x) / Td,
        PID_y = ys clipped to [VPMIN, VPMAX] (windup),  dPID_xi/dt = kI (vi - ks (ys - PID_y))
    non-windup lag KA / (1 + s TA) of PID_y:  TA dLA_y/dt = KA PID_y - LA_y,  VRMIN <= LA_y <= VRMAX
        (reset: LA_y at or beyond a limit while its unlimited rate pushes outward is placed on it);
        its output VR = LA_y; TA = 0: LA_y held, VR = KA PID_y clipped to [VRMIN, VRMAX] (ANDES:
        the lag's equation algebraic, pegged by its limiter)
    VFE = KE INT_y + Se + KD XadIfd,  Se = B (INT_y - A)^2 where INT_y >= A, else 0 (quadratic
        saturation through (E1, SE1), (E2, SE2), ANDES' ExcQuadSat)
    TE dINT_y/dt = VR - VFE
    IN = KC XadIfd / INT_y,  Efd = FEX(IN) INT_y  (blocks.rectifier_loading)

At rest (ANDES' initialisation): INT_y solves INT_y FEX(KC XadIfd / INT_y) = Efd, LA_y = VFE,
PID_xi = VFE / KA, PID_WO_x = 0, LG_y = Vt, Vref = Vt - Vss (vi = 0).

ANDES 2.0.0 declares VFEMAX and VEMIN but uses neither (no field current limit, no lower limit on
INT_y): they are not parameters here. ks is ANDES' AC8B config value, a parameter here.

Equilibrium at given inputs: the integral action rests only with vi = 0 or with the PID output at a
limit. With vi = Vref - Vt + Vss = 0 every field voltage is at rest (the integrator holds what it
has integrated): the one returned gives Efd = 1 pu. With vi > 0 (< 0) the integrator winds until
ys - VPMAX = vi / ks (ys - VPMIN), and LA_y rests at KA VPMAX (KA VPMIN) clipped to its limits.

Bases: pu of the exciter's base (the machine's field voltage and field current); no powers.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import (lag, lag_non_windup, lag_non_windup_reset, pid_tracking, quadratic_saturation_coefficients,
                      quadratic_saturation_product, rectifier_loading)
from ..component import Component, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_limits, check_ranges, controller_initialisation, finite_inputs, set_point

PARAMETER_RANGES = {"TR": (0.0, 10.0, "s"), "kP": (0.0, 1000.0, "pu"), "kI": (0.001, 1000.0, "pu/s"),
                    "kD": (0.0, 1000.0, "pu s"), "Td": (0.001, 10.0, "s"), "TA": (0.0, 10.0, "s"),
                    "KA": (0.01, 5000.0, "pu"), "TE": (0.001, 10.0, "s"), "E1": (0.0, 20.0, "pu"),
                    "SE1": (0.0, 10.0, "pu"), "E2": (0.0, 20.0, "pu"), "SE2": (0.0, 10.0, "pu"),
                    "KE": (-1.0, 10.0, "pu"), "KD": (0.0, 10.0, "pu"), "KC": (0.0, 10.0, "pu"),
                    "ks": (0.001, 1000.0, "pu")}
REST_FIELD_VOLTAGE = 1.0  # pu: the field voltage of the equilibrium returned where every one is at rest (vi = 0)


@dataclass(frozen=True)
class AC8BParams(Parameters):
    """ANDES/PSS/E AC8B data: PID gains kP [pu], kI [pu/s], kD [pu s] and Td [s], its limits VPMIN,
    VPMAX [pu]; regulator KA [pu], TA [s], VRMIN, VRMAX [pu]; exciter TE [s], KE, KD, KC [pu],
    saturation points E1, E2 [pu] with SE1, SE2 [pu]; ks [pu] the PID's tracking gain (ANDES' config)."""

    TR: float = 0.01
    kP: float = 10.0
    kI: float = 10.0
    kD: float = 10.0
    Td: float = 0.2
    VPMAX: float = 999.0
    VPMIN: float = -999.0
    VRMAX: float = 7.3
    VRMIN: float = 1.0
    TA: float = 0.04
    KA: float = 40.0
    TE: float = 0.8
    E1: float = 0.0
    SE1: float = 0.0
    E2: float = 1.0
    SE2: float = 1.0
    KE: float = 1.0
    KD: float = 0.0
    KC: float = 0.1
    ks: float = 2.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "VPMIN", "VPMAX")
        check_limits(self, "VRMIN", "VRMAX")
        self.require("E2", self.E2 != self.E1 or self.SE1 == 0, f"differ from E1 = {self.E1!r}")

    @property
    def saturation(self) -> tuple:
        """(A, B) of Se = B (INT_y - A)^2 (ANDES: ExcQuadSat(E1, SE1, E2, SE2))."""
        return quadratic_saturation_coefficients(self.E1, self.SE1, self.E2, self.SE2)


def _feedback(INT_y, XadIfd, p: AC8BParams, m):
    """VFE = KE INT_y + Se + KD XadIfd [pu]."""
    A, B = p.saturation
    return p.KE * INT_y + quadratic_saturation_product(m, INT_y, A, B) + p.KD * XadIfd


def field_voltage(INT_y, XadIfd, p: AC8BParams, m):
    """Efd = FEX(KC XadIfd / INT_y) INT_y [pu]."""
    return rectifier_loading(m, p.KC * XadIfd / INT_y) * INT_y


def _regulator(x, u, p: AC8BParams, m):
    """(dLG_y/dt, dPID_xi/dt, dPID_WO_x/dt, PID_y)."""
    LG_y, PID_xi, PID_WO_x = x[:3]
    Vt, Vref, Vss, _ = u
    d_LG, sensed = lag(m, Vt, LG_y, 1.0, p.TR)
    d_xi, d_WO, PID_y = pid_tracking(m, Vref - sensed + Vss, PID_xi, PID_WO_x, p.kP, p.kI, p.kD, p.Td, p.ks,
                                     p.VPMIN, p.VPMAX)
    return d_LG, d_xi, d_WO, PID_y


def derivatives(x, u, p: AC8BParams, m):
    """(dLG_y, dPID_xi, dPID_WO_x, dLA_y, dINT_y)/dt for x = (LG_y, PID_xi, PID_WO_x, LA_y, INT_y),
    u = (Vt, Vref, Vss, XadIfd)."""
    d_LG, d_xi, d_WO, PID_y = _regulator(x, u, p, m)
    LA_y, INT_y = x[3], x[4]
    d_LA, VR = lag_non_windup(m, PID_y, LA_y, p.KA, p.TA, p.VRMIN, p.VRMAX)
    return d_LG, d_xi, d_WO, d_LA, (VR - _feedback(INT_y, u[3], p, m)) / p.TE


def reset(x, u, p: AC8BParams, m):
    """x after the reset of LA_y's limits VRMIN, VRMAX (blocks.lag_non_windup_reset)."""
    LA_y = lag_non_windup_reset(m, _regulator(x, u, p, m)[3], x[3], p.KA, p.TA, p.VRMIN, p.VRMAX)
    return x[0], x[1], x[2], LA_y, x[4]


def outputs(x, u, p: AC8BParams, m):
    """(Efd,) = FEX(IN) INT_y."""
    return (field_voltage(x[4], u[3], p, m),)


def initialise(Efd: float, u, p: AC8BParams) -> tuple:
    """(x [5], Vref [pu]): the state at rest giving field voltage Efd [pu] at inputs u (its Vref
    ignored) and the set point that holds it (ANDES' initialisation; INT_y by a 1-D root of
    INT_y FEX(KC XadIfd / INT_y) = Efd, increasing in INT_y > 0)."""
    Vt, _, Vss, XadIfd = (float(v) for v in u)
    INT_y = set_point(lambda e: field_voltage(e, XadIfd, p, math), Efd, Efd + 0.577 * p.KC * XadIfd, "AC8B",
                      scale=0.1, accept=lambda e: e > 0)
    VFE = _feedback(INT_y, XadIfd, p, math)
    return np.array([Vt, VFE / p.KA, 0.0, VFE, INT_y]), Vt - Vss


def equilibrium(u, p: AC8BParams) -> np.ndarray:
    """The steady state [5] at constant (Vt, Vref, Vss, XadIfd) (module docstring); ValueError where
    there is none within the regulator's limits."""
    Vt, Vref, Vss, XadIfd = finite_inputs(u, "AC8B")
    vi = Vref - Vt + Vss
    if vi == 0:
        x = initialise(REST_FIELD_VOLTAGE, u, p)[0]
        if not p.VRMIN <= x[3] <= p.VRMAX:
            raise ValueError(f"AC8B: the regulator output {x[3]:.6g} pu at rest lies outside its limits")
        return x
    limit = p.VPMAX if vi > 0 else p.VPMIN
    LA_y = min(max(p.KA * limit, p.VRMIN), p.VRMAX)
    INT_y = set_point(lambda e: _feedback(e, XadIfd, p, math), LA_y, 1.0, "AC8B")
    return np.array([Vt, limit + vi / p.ks - p.kP * vi, vi, LA_y, INT_y])


INPUTS = (Quantity("Vt", "pu", "terminal voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
          Quantity("Vref", "pu", "voltage set point", start=1.0, operating_range=(0.9, 1.2)),
          Quantity("Vss", "pu", "stabiliser signal", start=0.0, operating_range=(-0.1, 0.1)),
          Quantity("XadIfd", "pu", "machine field current", start=1.5, operating_range=(0.5, 3.0)))

AC8B = Component(
    name="ac8b",
    description="AC8B IEEE AC8B exciter with PID regulator (PSS/E, ANDES 2.0.0)",
    states=(Quantity("LG_y", "pu", "sensed voltage"),
            Quantity("PID_xi", "pu", "PID integrator"),
            Quantity("PID_WO_x", "pu", "PID derivative washout state"),
            Quantity("LA_y", "pu", "regulator output (non-windup limited)"),
            Quantity("INT_y", "pu", "exciter voltage VE")),
    inputs=INPUTS,
    outputs=(Quantity("Efd", "pu", "field voltage"),),
    params_type=AC8BParams,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.05, 0.05, 0.5, 0.5),
    reset=reset,
    ports=Ports(inputs=(Link("terminal_voltage", "Vt"), Link("voltage_reference", "Vref"),
                        Link("stabiliser_signal", "Vss"), Link("field_current", "XadIfd")),
                outputs=(Link("field_voltage", "Efd"),)),
    initialisation=controller_initialisation(INPUTS, "Efd", "Vref", initialise),
)
