"""REGCP1: the renewable energy generator/converter model A working in the frame of a phase-locked
loop (ANDES 2.0 REGCP1 with its `pll`), on a bus.

States  x = (S0_y, S1_y, S2_y, q0: REGCA1's, models/regca1.py)
Inputs  u = (Vs [pu], theta_vs [rad]: the bus voltage; Ipcmd, Iqcmd [pu]: the current commands, as
        REGCA1's; am [rad]: the angle its phase-locked loop measures, network frame)
Outputs y = (I_re, I_im [pu]: the current into the bus, network frame; P, Q [pu]: the power into the
        bus; Ipout, Iqout [pu]: the active and reactive currents; Pe, Qe [pu]: ANDES' names of P and Q;
        vd, vq [pu]: the bus voltage in the frame at am)

Equations (ANDES 2.0 model reference, RenGen: REGCP1): REGCA1's states, limits and currents
(everything that reads the bus voltage reads its magnitude Vs), with the d/q voltages in the frame
of the measured angle am instead of the bus angle:

    vd = Vs cos(theta_vs - am),  vq = -Vs sin(theta_vs - am)
    P = Pe = vd Ipout + vq Iqout,  Q = Qe = vd Iqout - vq Ipout
    I = (Ipout - j Iqout) exp(j am)  (P + jQ = Vs exp(j theta_vs) conj(I): the current lies in the
        PLL's frame)

With am = theta_vs this is REGCA1 (ANDES' REGCP1 without a PLL, which the conversion maps to REGCA1).
Bases and parameters: REGCA1's.

Start (ANDES' initialisation): REGCA1's from the load-flow point, and the measured angle its PLL
has to give, am = theta0 (vd = V0, vq = 0).
"""
from __future__ import annotations

import numpy as np

from ..component import Component, Initialisation, Quantity
from ..ports import BusPort, Link, Ports
from . import regca1
from .common import finite_inputs
from .regca1 import REGCA1, REGCA1Params


def _converter_inputs(u):
    """REGCA1's inputs (Vs, theta_vs, Ipcmd, Iqcmd) of u."""
    return u[0], u[1], u[2], u[3]


def derivatives(x, u, p: REGCA1Params, m):
    """(dS0_y, dS1_y, dS2_y, dq0)/dt for x = (S0_y, S1_y, S2_y, q0), u = (Vs, theta_vs, Ipcmd, Iqcmd, am):
    REGCA1's."""
    return regca1.derivatives(x, _converter_inputs(u), p, m)


def reset(x, u, p: REGCA1Params, m):
    """x after REGCA1's reset."""
    return regca1.reset(x, _converter_inputs(u), p, m)


def outputs(x, u, p: REGCA1Params, m):
    """(I_re, I_im, P, Q, Ipout, Iqout, Pe, Qe, vd, vq) [pu, system base]."""
    Vs, theta_vs, Ipcmd, Iqcmd, am = u
    # REGCA1's current on a bus at angle am is the current in the PLL's frame
    I_re, I_im, _, _, Ipout, Iqout, _, _ = regca1.outputs(x, (Vs, am, Ipcmd, Iqcmd), p, m)
    vd, vq = Vs * m.cos(theta_vs - am), -Vs * m.sin(theta_vs - am)
    Pe, Qe = vd * Ipout + vq * Iqout, vd * Iqout - vq * Ipout
    return I_re, I_im, Pe, Qe, Ipout, Iqout, Pe, Qe, vd, vq


def _start(given, p: REGCA1Params) -> tuple:
    x0, Ipcmd, Iqcmd = regca1.operating_point(float(given["V0"]), float(given["P0"]), float(given["Q0"]), p)
    return x0, {"Ipcmd": Ipcmd, "Iqcmd": Iqcmd, "am": float(given["theta0"])}


def equilibrium(u, p: REGCA1Params) -> np.ndarray:
    """The steady state [4] at constant inputs: REGCA1's, q0 the reactive power delivered."""
    u = finite_inputs(u, "REGCP1")
    x = regca1.equilibrium(u[:4], p)
    x[3] = outputs(x, u, p, np)[3]
    return x


REGCP1 = Component(
    name="regcp1",
    description="REGCP1 renewable energy generator/converter model A in a phase-locked loop's frame (ANDES) on a bus",
    states=REGCA1.states,
    inputs=REGCA1.inputs + (Quantity("am", "rad", "angle measured by the phase-locked loop", start=0.0,
                                     operating_range=(-0.5, 0.5)),),
    outputs=REGCA1.outputs + (Quantity("vd", "pu", "d-axis bus voltage (frame of the measured angle)"),
                              Quantity("vq", "pu", "q-axis bus voltage (frame of the measured angle)")),
    params_type=REGCA1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=REGCA1.state_scales,
    reset=reset,
    ports=Ports(bus=BusPort(voltage=("Vs", "theta_vs"), current=("I_re", "I_im")),
                inputs=REGCA1.ports.inputs + (Link("pll_angle", "am"),), outputs=REGCA1.ports.outputs),
    initialisation=Initialisation(("Ipcmd", "Iqcmd", "am"), _start),
)
