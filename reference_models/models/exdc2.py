"""EXDC2: the IEEE DC2 exciter (PSS/E EXDC2, ANDES); its equations also serve IEEEX1 (ieeex1.py).

States  x = (LS_y [pu] sensed voltage, LL_x [pu] lead-lag state, LA_y [pu] regulator output held
        within [VRMIN, VRMAX], vp [pu] exciter voltage before the speed term, W_x [pu] feedback
        washout state)
Inputs  u = (Vt [pu] terminal voltage, Vref [pu] set point, Vss [pu] stabiliser signal,
        omega [pu] rotor speed)
Outputs y = (Efd [pu] field voltage = omega vp)

Equations (ANDES 2.0 model reference, Exciter: EXDC2):

    sensing lag 1 / (1 + s TR):  TR dLS_y/dt = Vt - LS_y  (TR = 0: LS_y held, Vt used)
    washout s KF1 / (1 + s TF1) of vp:  TF1 dW_x/dt = vp - W_x,  W_y = KF1 (vp - W_x) / TF1
    vi = Vref - LS_y - W_y + Vss
    lead-lag (1 + s TC) / (1 + s TB) of vi (TB = 0: a gain of 1)
    non-windup lag KA / (1 + s TA):  TA dLA_y/dt = KA LL_y - LA_y,  VRMIN <= LA_y <= VRMAX
        (reset: LA_y at or beyond a limit while KA LL_y - LA_y pushes outward is placed on it);
        its output VR = LA_y; TA = 0: LA_y held, VR = KA LL_y clipped to [VRMIN, VRMAX] (ANDES
        makes the lag's equation algebraic, 0 = KA LL_y - LA_y, its limiter then pegs LA_y)
    TE dvp/dt = VR - KE vp - Se vp,  Se vp = B (vp - A)^2 where Efd >= A, else 0
        (quadratic saturation through (E1, SE1), (E2, SE2), ANDES' ExcQuadSat)
    Efd = omega vp
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blocks import lag, lag_non_windup, lag_non_windup_reset, lead_lag, quadratic_saturation_coefficients, washout
from ..component import Component, Parameters, Quantity
from ..piecewise import where
from ..ports import Link, Ports
from .common import check_limits, check_ranges, controller_initialisation, finite_inputs, set_point

PARAMETER_RANGES = {"TR": (0.0, 10.0, "s"), "TA": (0.0, 10.0, "s"), "TC": (0.0, 100.0, "s"),
                    "TB": (0.0, 100.0, "s"), "TE": (0.001, 10.0, "s"), "TF1": (0.001, 100.0, "s"),
                    "KF1": (0.0, 10.0, "pu"), "KA": (0.01, 5000.0, "pu"), "KE": (-1.0, 10.0, "pu"),
                    "E1": (0.0, 20.0, "pu"), "SE1": (0.0, 10.0, "pu"), "E2": (0.0, 20.0, "pu"),
                    "SE2": (0.0, 10.0, "pu")}


@dataclass(frozen=True)
class EXDC2Params(Parameters):
    """ANDES/PSS/E EXDC2 (and IEEEX1) data: time constants [s], gains [pu], regulator limits [pu]
    (IEEEX1 alike), saturation points E1, E2 [pu] with SE1, SE2 [pu]."""

    TR: float = 0.01
    TA: float = 0.04
    TC: float = 1.0
    TB: float = 1.0
    TE: float = 0.8
    TF1: float = 1.0
    KF1: float = 0.03
    KA: float = 40.0
    KE: float = 1.0
    VRMAX: float = 7.3
    VRMIN: float = -7.3
    E1: float = 0.0
    SE1: float = 0.0
    E2: float = 1.0
    SE2: float = 1.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "VRMIN", "VRMAX")
        self.require("E2", self.E2 != self.E1 or self.SE1 == 0, f"differ from E1 = {self.E1!r}")

    @property
    def saturation(self) -> tuple:
        """(A, B) of Se vp = B (vp - A)^2 (ANDES: ExcQuadSat(E1, SE1, E2, SE2))."""
        return quadratic_saturation_coefficients(self.E1, self.SE1, self.E2, self.SE2)


def _regulator_input(x, Vt, Vref, Vss, p: EXDC2Params, m):
    """(dLS_y, dLL_x, dW_x, LL_y): the sensing lag's, lead-lag's and washout's derivatives and the
    regulator's input LL_y."""
    LS_y, LL_x, LA_y, vp, W_x = x
    d_LS, sensed = lag(m, Vt, LS_y, 1.0, p.TR)
    d_W, W_y = washout(m, vp, W_x, p.KF1, p.TF1)
    d_LL, LL_y = lead_lag(m, Vref - sensed - W_y + Vss, LL_x, 1.0, p.TC, p.TB)
    return d_LS, d_LL, d_W, LL_y


def dc_derivatives(x, Vt, Vref, Vss, omega, p: EXDC2Params, m):
    """The DC exciter's derivatives; omega None: no speed term (IEEEX1)."""
    LS_y, LL_x, LA_y, vp, W_x = x
    A, B = p.saturation
    d_LS, d_LL, d_W, LL_y = _regulator_input(x, Vt, Vref, Vss, p, m)
    d_LA, VR = lag_non_windup(m, LL_y, LA_y, p.KA, p.TA, p.VRMIN, p.VRMAX)
    out = vp if omega is None else omega * vp
    saturation = where(m, out >= A, B * (vp - A) * (vp - A), 0.0 * vp) if B != 0 else 0.0 * vp
    d_vp = (VR - p.KE * vp - saturation) / p.TE
    return d_LS, d_LL, d_LA, d_vp, d_W


def dc_reset(x, Vt, Vref, Vss, p: EXDC2Params, m) -> tuple:
    """The DC exciter's states after the reset of the regulator's non-windup limit (LA_y placed on
    a limit it is at or beyond while its unlimited rate pushes outward; blocks.lag_non_windup_reset;
    TA = 0: LA_y held)."""
    LA_y = lag_non_windup_reset(m, _regulator_input(x, Vt, Vref, Vss, p, m)[3], x[2], p.KA, p.TA, p.VRMIN, p.VRMAX)
    return x[0], x[1], LA_y, x[3], x[4]


def dc_initialise(Efd: float, Vt: float, Vss: float, omega: float, p: EXDC2Params) -> tuple:
    """(x [5], Vref): the DC exciter at rest with field voltage Efd (ANDES' initialisation; LA_y
    starts at the regulator output also where TA = 0 holds it)."""
    A, B = p.saturation
    vp = Efd / omega
    Se = B * (vp - A) ** 2 / vp if Efd > A and B != 0 else 0.0
    vr = (p.KE + Se) * vp
    vb = vr / p.KA
    return np.array([Vt, vb, vr, vp, vp]), Vt + vb - Vss


def dc_equilibrium(initialise, Vref: float, limits: tuple, name: str) -> np.ndarray:
    """The state at rest at set point Vref: the field voltage nearest 1 pu whose initialise gives Vref
    with the regulator at rest within `limits` (low, high); ValueError where there is none."""
    Efd = set_point(lambda e: initialise(e)[1], Vref, 1.0, name,
                    accept=lambda e: limits[0] <= initialise(e)[0][2] <= limits[1])
    x = initialise(Efd)[0]
    if not limits[0] <= x[2] <= limits[1]:
        raise ValueError(f"{name}: the regulator output {x[2]:.6g} pu at rest lies outside its limits")
    return x


def derivatives(x, u, p: EXDC2Params, m):
    """(dLS_y, dLL_x, dLA_y, dvp, dW_x)/dt for x = (LS_y, LL_x, LA_y, vp, W_x), u = (Vt, Vref, Vss, omega)."""
    Vt, Vref, Vss, omega = u
    return dc_derivatives(x, Vt, Vref, Vss, omega, p, m)


def reset(x, u, p: EXDC2Params, m):
    """x after the regulator limit's reset (dc_reset), u = (Vt, Vref, Vss, omega)."""
    Vt, Vref, Vss, _ = u
    return dc_reset(x, Vt, Vref, Vss, p, m)


def outputs(x, u, p: EXDC2Params, m):
    """(Efd,) = omega vp."""
    return (u[3] * x[3],)


def initialise(Efd: float, u, p: EXDC2Params) -> tuple:
    """(x [5], Vref [pu]): the state at rest giving field voltage Efd [pu] at inputs u (its Vref
    ignored) and the set point that holds it."""
    Vt, _, Vss, omega = (float(v) for v in u)
    return dc_initialise(Efd, Vt, Vss, omega, p)


def equilibrium(u, p: EXDC2Params) -> np.ndarray:
    """The steady state [5] at constant (Vt, Vref, Vss, omega); ValueError where there is none
    within the regulator limits."""
    Vt, Vref, Vss, omega = finite_inputs(u, "EXDC2")
    return dc_equilibrium(lambda e: initialise(e, u, p), Vref, (p.VRMIN, p.VRMAX), "EXDC2")


DC_STATES = (Quantity("LS_y", "pu", "sensed terminal voltage"),
             Quantity("LL_x", "pu", "lead-lag state"),
             Quantity("LA_y", "pu", "regulator output (non-windup limited)"),
             Quantity("vp", "pu", "exciter voltage before the speed term"),
             Quantity("W_x", "pu", "feedback washout state"))
DC_INPUTS = (Quantity("Vt", "pu", "terminal voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
             Quantity("Vref", "pu", "voltage set point", start=1.05, operating_range=(0.9, 1.2)),
             Quantity("Vss", "pu", "stabiliser signal", start=0.0, operating_range=(-0.1, 0.1)))

INPUTS = DC_INPUTS + (Quantity("omega", "pu", "rotor speed", start=1.0, operating_range=(0.95, 1.05), minimum=0.0),)

EXDC2 = Component(
    name="exdc2",
    description="EXDC2 IEEE DC2 exciter (PSS/E, ANDES)",
    states=DC_STATES,
    inputs=INPUTS,
    outputs=(Quantity("Efd", "pu", "field voltage"),),
    params_type=EXDC2Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.05, 1.0, 0.5, 0.5),
    reset=reset,
    ports=Ports(inputs=(Link("terminal_voltage", "Vt"), Link("voltage_reference", "Vref"),
                        Link("stabiliser_signal", "Vss"), Link("rotor_speed", "omega")),
                outputs=(Link("field_voltage", "Efd"),)),
    initialisation=controller_initialisation(INPUTS, "Efd", "Vref", initialise),
)
