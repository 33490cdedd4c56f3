"""PLL2: a type-2 synchronously rotating reference frame phase-locked loop (ANDES 2.0 PLL2), a control
device of the converter that takes its measured angle (REGCP1).

States  x = (PI_xi [pu] the PI controller's integrator; am [rad] the measured angle)
Inputs  u = (Vt [pu], theta_vs [rad]: the bus voltage magnitude and angle, network frame; ANDES' v, a)
Outputs y = (PI_y [pu]: the PI controller's output, the estimated frequency deviation in pu of fn)

Equations (ANDES 2.0 model reference, PLL: PLL2): the PI controller drives the q-axis voltage
Vt sin(theta_vs - am) of the frame at am to 0:

    dPI_xi/dt = Ki Vt sin(theta_vs - am),  PI_y = Kp Vt sin(theta_vs - am) + PI_xi
    dam/dt = 2 pi fn PI_y

The measured angle am is the output (`pll_angle`) the converter takes. fn [Hz] is the nominal
frequency; the gains have no base.

Start (ANDES' initialisation): at rest from the bus angle, am = theta_vs, PI_xi = 0.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_ranges, finite_inputs
from .pll1 import angle_speed, start_angle

PARAMETER_RANGES = {"fn": (1.0, 1000.0, "Hz"), "Kp": (0.0, 1e4, "pu"), "Ki": (0.0, 1e4, "pu/s")}


@dataclass(frozen=True)
class PLL2Params(Parameters):
    """ANDES PLL2 data: the nominal frequency fn [Hz] and the PI gains Kp, Ki."""

    fn: float = 60.0
    Kp: float = 0.1
    Ki: float = 0.1

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)


def _pi_input(x, u, m):
    """The PI controller's input Vt sin(theta_vs - am): the q-axis voltage in the frame at am."""
    return u[0] * m.sin(u[1] - x[1])


def derivatives(x, u, p: PLL2Params, m):
    """(dPI_xi, dam)/dt for x = (PI_xi, am), u = (Vt, theta_vs)."""
    e = _pi_input(x, u, m)
    return p.Ki * e, angle_speed(p.Kp * e + x[0], p.fn)


def outputs(x, u, p: PLL2Params, m):
    """(PI_y,) [pu]."""
    return (p.Kp * _pi_input(x, u, m) + x[0],)


def _start(given, p: PLL2Params) -> tuple:
    return equilibrium(np.array([float(given["Vt"]), start_angle(given, "PLL2")]), p), {}


def equilibrium(u, p: PLL2Params) -> np.ndarray:
    """The steady state [2] at a constant bus voltage: the measured angle on the bus angle, the
    integrator at 0."""
    _, theta = finite_inputs(u, "PLL2")
    return np.array([0.0, theta])


PLL2 = Component(
    name="pll2",
    description="PLL2 synchronously rotating reference frame phase-locked loop (ANDES)",
    states=(Quantity("PI_xi", "pu", "PI controller integrator"),
            Quantity("am", "rad", "measured angle (network frame)")),
    inputs=(Quantity("Vt", "pu", "bus voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
            Quantity("theta_vs", "rad", "bus voltage angle", start=0.0, operating_range=(-0.5, 0.5))),
    outputs=(Quantity("PI_y", "pu", "estimated frequency deviation (pu of fn)"),),
    params_type=PLL2Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.01, 0.1),
    ports=Ports(inputs=(Link("terminal_voltage", "Vt"), Link("terminal_voltage_angle", "theta_vs")),
                outputs=(Link("pll_angle", "am"),)),
    initialisation=Initialisation((), _start),
)
