"""IEEEVC: the IEEE voltage compensator (load-drop compensation of an exciter's input voltage, PSS/E
IEEEVC) as ANDES 2.0.0 computes it: the voltage the exciter of its unit regulates instead of the
terminal voltage.

States  x = (held [-]: a held state, rate 0, that nothing reads: IEEEVC has no dynamics, and a
        component has at least one state)
Inputs  u = (Vt [pu], theta_vs [rad]: the terminal voltage phasor; I_re, I_im [pu, system base]:
        the machine's current into the bus)
Outputs y = (Vc [pu] the compensated voltage)

Equation (ANDES 2.0.0, andes/models/vcomp/ieeevc.py):

    Vc = |V + (rc + j xc) I|,  V = Vt exp(j theta_vs), I = I_re + j I_im
    (ANDES' |(vd + j vq) + (rc + j xc)(Id + j Iq)| in the machine's dq frame: both phasors rotate
    alike, so the magnitude is the same)

How the exciter takes it: ANDES' IEEEVC adds vcomp = Vc - V to the equation of its exciter's input
voltage `v` (ExcBase.v: 0 = vbus - v, and the compensator's ExtAlgeb on it adds vcomp), so the
exciter's `v` is Vc, and every use of `v` in the exciter (its sensing lag, ESDC2A's vi and its limits
VRMAX v, VRMIN v, its initial Vref) takes Vc; what an exciter reads from the machine directly (ESST3A's
and IEEET3's VE from vd, vq, Id, Iq) stays uncompensated. Here the compensator gives the unit's signal
`terminal_voltage`, so the exciter of its unit takes Vc through its `terminal_voltage` input link
(an input link takes the output link of the same signal of another device of its unit), and the
compensator's own `terminal_voltage` input comes from the bus (no other device gives it).

ANDES 2.0.0's TDS.init of a case with IEEEVC (ieee14/ieee14_ieeevc2.xlsx) fails: its exciters start
from v = vbus (their initial Vref and states ignore vcomp), the residual of their `v` equations is
vcomp (0.025, 0.033 pu), and ANDES runs on from that point out of rest; the relation exciter
v = |V + (rc + j xc) I| holds at every later step, which is what the tests compare.

Bases: rc, xc on the system base, multiplying the system-base current: ANDES converts them from an
impedance base Vn^2 / Sn that defaults to the system base for IEEEVC (no Sn, Vn, bus of its own),
and its machine currents are on the system base.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..component import Component, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_ranges, finite_inputs
from .esst3a import INPUTS as ESST3A_INPUTS

PARAMETER_RANGES = {"rc": (-1.0, 1.0, "pu"), "xc": (-1.0, 1.0, "pu")}


@dataclass(frozen=True)
class IEEEVCParams(Parameters):
    """ANDES/PSS/E IEEEVC data: compensation resistance rc and reactance xc [pu, system base]."""

    rc: float = 0.0
    xc: float = 0.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)


def derivatives(x, u, p: IEEEVCParams, m):
    """(d held/dt,) = (0,): IEEEVC has no dynamics."""
    return (0.0 * x[0],)


def outputs(x, u, p: IEEEVCParams, m):
    """(Vc,) = |Vt exp(j theta_vs) + (rc + j xc) (I_re + j I_im)|."""
    Vt, theta_vs, I_re, I_im = u
    real = Vt * m.cos(theta_vs) + p.rc * I_re - p.xc * I_im
    imag = Vt * m.sin(theta_vs) + p.rc * I_im + p.xc * I_re
    return (m.sqrt(real * real + imag * imag),)


def equilibrium(u, p: IEEEVCParams) -> np.ndarray:
    """The held state at rest, 0, at any finite inputs."""
    finite_inputs(u, "IEEEVC")
    return np.zeros(1)


IEEEVC = Component(
    name="ieeevc",
    description="IEEEVC IEEE voltage compensator (PSS/E, ANDES 2.0.0)",
    states=(Quantity("held", "1", "held state (IEEEVC has no dynamics; nothing reads it)"),),
    inputs=ESST3A_INPUTS[:4],
    outputs=(Quantity("Vc", "pu", "compensated voltage, the exciter's input"),),
    params_type=IEEEVCParams,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(1.0,),
    ports=Ports(inputs=(Link("terminal_voltage", "Vt"), Link("terminal_voltage_angle", "theta_vs"),
                        Link("terminal_current_real", "I_re"), Link("terminal_current_imaginary", "I_im")),
                outputs=(Link("terminal_voltage", "Vc"),)),
)
