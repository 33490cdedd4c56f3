"""WTARA1: the aerodynamics of a type-3 wind turbine without wind speed (PSS/E WTARA1, WECC WTGAR_A, ANDES).

States  none
Inputs  u = (theta [deg] blade pitch angle (the pitch controller's output; 0 without one); Pm0 [pu]
        the mechanical power at zero pitch, a set point (ANDES' Pe0))
Outputs y = (Pm [pu]: the mechanical power into the drive train)

Equation (ANDES 2.0 model reference, RenAerodynamics: WTARA1), on the system base:

    Pm = Pm0 - Ka theta (theta - theta0)

Ka [pu/deg] multiplies the system-base power as ANDES computes it (unconverted). theta0 must be 0:
ANDES 2.0.0 compares its pitch angle in radians, rad(theta0) at the start, with theta0 in degrees,
and its initialisation fails (a mismatch in Pm and theta) for any other value. The pitch angle is
the pitch controller's lag output in the degrees of its limits, which ANDES adds to its own angle
unconverted.

Start: Pm0 = Pm + Ka theta (theta - theta0), the set point at which it gives the mechanical power
its drive train demands at the pitch angle given (ANDES: Pm0 = Pe0, the converter's power, with the
pitch at 0).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_ranges, finite_inputs

PARAMETER_RANGES = {"Ka": (0.0, 100.0, "pu/deg")}


@dataclass(frozen=True)
class WTARA1Params(Parameters):
    """ANDES/PSS/E WTARA1 data: the aerodynamic gain Ka [pu/deg] and the initial pitch angle theta0
    [deg] (0, as ANDES 2.0.0 starts only there)."""

    Ka: float = 1.0
    theta0: float = 0.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        self.require("theta0", self.theta0 == 0.0,
                     "be 0 (ANDES 2.0.0 compares it in degrees with its pitch in radians and starts nowhere else)")


def derivatives(x, u, p: WTARA1Params, m):
    """No states: ()."""
    return ()


def mechanical_power(theta, Pm0, p: WTARA1Params):
    """Pm [pu] at pitch angle theta [deg] and set point Pm0 [pu]."""
    return Pm0 - p.Ka * theta * (theta - p.theta0)


def outputs(x, u, p: WTARA1Params, m):
    """(Pm,) [pu, system base]."""
    return (mechanical_power(u[0], u[1], p),)


def _start(given, p: WTARA1Params) -> tuple:
    theta = float(given["theta"])
    return np.zeros(0), {"Pm0": float(given["Pm"]) - mechanical_power(theta, 0.0, p)}


def equilibrium(u, p: WTARA1Params) -> np.ndarray:
    """The (empty) state at rest at finite inputs."""
    finite_inputs(u, "WTARA1")
    return np.zeros(0)


WTARA1 = Component(
    name="wtara1",
    description="WTARA1 aerodynamics of a type-3 wind turbine (PSS/E, WECC WTGAR_A, ANDES)",
    states=(),
    inputs=(Quantity("theta", "deg", "blade pitch angle", start=0.0, operating_range=(0.0, 30.0)),
            Quantity("Pm0", "pu", "mechanical power at zero pitch, set point (system base)", start=0.5,
                     operating_range=(0.0, 1.0))),
    outputs=(Quantity("Pm", "pu", "mechanical power (system base)"),),
    params_type=WTARA1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(),
    ports=Ports(inputs=(Link("pitch_angle", "theta"), Link("power_reference", "Pm0")),
                outputs=(Link("mechanical_power", "Pm"),)),
    initialisation=Initialisation(("Pm0",), _start),
)
