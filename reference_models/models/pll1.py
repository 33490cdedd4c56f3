"""PLL1: a phase-locked loop with one PI controller and input and output filters (ANDES 2.0 PLL1), a
control device of the converter that takes its measured angle (REGCP1).

States  x = (af_y [rad] filtered bus angle; PI_xi [pu] the PI controller's integrator; ae [rad] the
        estimated angle before the output filter; am [rad] the measured angle)
Inputs  u = (theta_vs [rad]: the bus voltage angle, network frame; ANDES' a)
Outputs y = (PI_y [pu]: the PI controller's output, the estimated frequency deviation in pu of fn)

Equations (ANDES 2.0 model reference, PLL: PLL1):

    Tf daf_y/dt = theta_vs - af_y  (Tf = 0: af_y held, theta_vs used)
    dPI_xi/dt = Ki (af_y - am),  PI_y = Kp (af_y - am) + PI_xi
    dae/dt = 2 pi fn PI_y
    Tp dam/dt = ae - am

The measured angle am is the output (`pll_angle`) the converter takes. fn [Hz] is the nominal
frequency; the gains have no base.

Start (ANDES' initialisation): at rest from the bus angle, af_y = ae = am = theta_vs, PI_xi = 0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import lag
from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_ranges, finite_inputs

PARAMETER_RANGES = {"fn": (1.0, 1000.0, "Hz"), "Kp": (0.0, 1e4, "pu"), "Ki": (0.0, 1e4, "pu/s"),
                    "Tf": (0.0, 100.0, "s"), "Tp": (0.001, 100.0, "s")}


@dataclass(frozen=True)
class PLL1Params(Parameters):
    """ANDES PLL1 data: the nominal frequency fn [Hz]; the PI gains Kp, Ki; the input filter's time
    constant Tf [s] (0: none) and the output filter's Tp [s]."""

    fn: float = 60.0
    Kp: float = 0.1
    Ki: float = 0.1
    Tf: float = 0.05
    Tp: float = 0.05

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)


def angle_speed(PI_y, fn: float):
    """The estimated angle's speed [rad/s] for the PI output PI_y [pu of fn]: 2 pi fn PI_y."""
    return 2.0 * math.pi * fn * PI_y


def start_angle(given, name: str) -> float:
    """The bus angle given["theta_vs"] [rad] a PLL starts at rest on; ValueError where the converter
    it feeds solved another measured angle (given["am"])."""
    theta = float(given["theta_vs"])
    if "am" in given and abs(float(given["am"]) - theta) > 1e-12 * max(1.0, abs(theta)):
        raise ValueError(f"{name}: its converter needs the measured angle {float(given['am']):.12g} rad at the "
                         f"start, not the bus angle {theta:.12g} rad")
    return theta


def derivatives(x, u, p: PLL1Params, m):
    """(daf_y, dPI_xi, dae, dam)/dt for x = (af_y, PI_xi, ae, am), u = (theta_vs,)."""
    af_y, PI_xi, ae, am = x
    d_af, filtered = lag(m, u[0], af_y, 1.0, p.Tf)
    error = filtered - am
    return d_af, p.Ki * error, angle_speed(p.Kp * error + PI_xi, p.fn), (ae - am) / p.Tp


def outputs(x, u, p: PLL1Params, m):
    """(PI_y,) [pu]."""
    _, filtered = lag(m, u[0], x[0], 1.0, p.Tf)
    return (p.Kp * (filtered - x[3]) + x[1],)


def _start(given, p: PLL1Params) -> tuple:
    return equilibrium(np.array([start_angle(given, "PLL1")]), p), {}


def equilibrium(u, p: PLL1Params) -> np.ndarray:
    """The steady state [4] at a constant bus angle: every angle on it, the integrator at 0."""
    theta = finite_inputs(u, "PLL1")[0]
    return np.array([theta, 0.0, theta, theta])


PLL1 = Component(
    name="pll1",
    description="PLL1 phase-locked loop with a PI controller and input and output filters (ANDES)",
    states=(Quantity("af_y", "rad", "filtered bus voltage angle"),
            Quantity("PI_xi", "pu", "PI controller integrator"),
            Quantity("ae", "rad", "estimated angle before the output filter"),
            Quantity("am", "rad", "measured angle (network frame)")),
    inputs=(Quantity("theta_vs", "rad", "bus voltage angle", start=0.0, operating_range=(-0.5, 0.5)),),
    outputs=(Quantity("PI_y", "pu", "estimated frequency deviation (pu of fn)"),),
    params_type=PLL1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.1, 0.01, 0.1, 0.1),
    ports=Ports(inputs=(Link("terminal_voltage_angle", "theta_vs"),), outputs=(Link("pll_angle", "am"),)),
    initialisation=Initialisation((), _start),
)
