"""GENCLS: the classical synchronous machine (constant voltage behind the transient reactance),
PSS/E and ANDES, on a bus.

States  x = (delta [rad], omega [pu])
Inputs  u = (Vs [pu], theta_vs [rad]: the bus voltage; Pm [pu] mechanical power (ANDES' tm);
        Efd [pu] the internal voltage behind xd1 (ANDES' vf, constant unless an input drives it))
Outputs y = (I_re, I_im [pu, system base]: the current into the bus, network frame; P, Q [pu,
        system base]; Pe [pu, machine base]: air-gap power (ANDES' te))

Equations (ANDES 2.0 model reference, SynGen: GENCLS; Flux0, xq = xd1):

    vd = Vs sin(delta - theta_vs),  vq = Vs cos(delta - theta_vs)
    stator: xd1 Id + ra Iq = Efd - vq,  ra Id - xd1 Iq = -vd
    d delta/dt = 2 pi fn (omega - 1),  M d omega/dt = Pm - Pe - D (omega - 1),
    Pe = psid Iq - psiq Id,  psid = ra Iq + vq,  psiq = -(ra Id + vd)

Bases as GENROU (reference_models/models/genrou.py): parameters, Pm, Efd, Pe on the machine base
Sn; the bus port and P, Q on the system base Sb.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..component import Component, Parameters, Quantity
from ..drift import Drift
from ..ports import BusPort, Link, Ports
from .common import check_ranges, dq_voltage, finite_inputs, machine_initialisation, network_current, stator_currents

PARAMETER_RANGES = {
    "fn": (16.0, 400.0, "Hz"), "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA"),
    "M": (0.01, 2000.0, "s"), "D": (0.0, 1000.0, "pu"), "ra": (0.0, 1.0, "pu"),  # M: ieee14_wt3n has 0.01
    "xd1": (1e-5, 10.0, "pu"),  # EI_33 models stiff sources as GENCLS with xd1 = 1e-4
}


@dataclass(frozen=True)
class GENCLSParams(Parameters):
    """ANDES/PSS/E GENCLS data: xd1, ra [pu], M = 2H [s], D [pu] on the machine base Sn [MVA]; Sb
    [MVA] the system base of the bus port; fn [Hz]."""

    fn: float = 60.0
    Sn: float = 100.0
    Sb: float = 100.0
    M: float = 6.0
    D: float = 0.0
    ra: float = 0.0
    xd1: float = 0.302

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)


def _currents(x, u, p: GENCLSParams, m):
    vd, vq = dq_voltage(x[0], u[0], u[1], m)
    Id, Iq = stator_currents(u[3], 0.0 * vd, vd, vq, p.ra, p.xd1, p.xd1)
    return vd, vq, Id, Iq


def _air_gap_power(vd, vq, Id, Iq, p: GENCLSParams):
    psid, psiq = p.ra * Iq + vq, -(p.ra * Id + vd)
    return psid * Iq - psiq * Id


def derivatives(x, u, p: GENCLSParams, m):
    """(d delta, d omega)/dt for x = (delta, omega), u = (Vs, theta_vs, Pm, Efd)."""
    vd, vq, Id, Iq = _currents(x, u, p, m)
    return (2.0 * math.pi * p.fn * (x[1] - 1.0),
            (u[2] - _air_gap_power(vd, vq, Id, Iq, p) - p.D * (x[1] - 1.0)) / p.M)


def outputs(x, u, p: GENCLSParams, m):
    """(I_re, I_im, P, Q) [pu, system base], Pe [pu, machine base]."""
    vd, vq, Id, Iq = _currents(x, u, p, m)
    k = p.Sn / p.Sb
    I_re, I_im = network_current(x[0], Id, Iq, m)
    return (I_re * k, I_im * k, (vd * Id + vq * Iq) * k, (vq * Id - vd * Iq) * k,
            _air_gap_power(vd, vq, Id, Iq, p))


def operating_point(Vs: float, theta_vs: float, P: float, Q: float, p: GENCLSParams) -> tuple:
    """The steady state from the load flow: (x [2], Pm, Efd [pu]) of the machine delivering
    P + jQ [pu, system base] into a bus at Vs [pu], theta_vs [rad]: E = V + (ra + j xd1) I,
    delta = arg E, Efd = |E|, Pm = Pe (ANDES' initialisation)."""
    V = Vs * complex(math.cos(theta_vs), math.sin(theta_vs))
    current = (complex(P, -Q) / V.conjugate()) * (p.Sb / p.Sn)
    E = V + complex(p.ra, p.xd1) * current
    delta = float(np.angle(E))
    turn = complex(math.sin(delta), math.cos(delta))  # exp(j (pi/2 - delta))
    Idq, vdq = current * turn, V * turn
    Efd = (vdq.imag + p.ra * Idq.imag) + p.xd1 * Idq.real
    return np.array([delta, 1.0]), _air_gap_power(vdq.real, vdq.imag, Idq.real, Idq.imag, p), Efd


def equilibrium(u, p: GENCLSParams) -> np.ndarray:
    """The stable steady state [2] at constant (Vs, theta_vs, Pm, Efd): omega = 1 and the rotor
    angle on the rising side of Pe(delta) = Pm; ValueError where there is none."""
    from scipy.optimize import brentq

    Vs, theta_vs, Pm, Efd = finite_inputs(u, "GENCLS")

    def power(angle):
        vd, vq, Id, Iq = _currents((theta_vs + angle, 1.0), u, p, math)
        return _air_gap_power(vd, vq, Id, Iq, p) - Pm

    angles = np.linspace(-math.pi / 2, math.pi, 301)
    values = np.array([power(a) for a in angles])
    rising = np.nonzero((values[:-1] < 0) & (values[1:] >= 0))[0]
    if Vs <= 0 or rising.size == 0:
        raise ValueError(f"GENCLS: no stable steady state at Vs = {Vs} pu, Pm = {Pm} pu, Efd = {Efd} pu")
    i = rising[0]
    angle = brentq(power, angles[i], angles[i + 1], xtol=1e-15, rtol=1e-15)
    return np.array([theta_vs + angle, 1.0])


GENCLS = Component(
    name="gencls",
    description="GENCLS classical synchronous machine (PSS/E, ANDES) on a bus",
    states=(Quantity("delta", "rad", "rotor angle"),
            Quantity("omega", "pu", "rotor speed (1: synchronous)")),
    inputs=(Quantity("Vs", "pu", "bus voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
            Quantity("theta_vs", "rad", "bus voltage angle", start=0.0, operating_range=(-0.5, 0.5)),
            Quantity("Pm", "pu", "mechanical power (machine base)", start=0.7, operating_range=(0.3, 1.0)),
            Quantity("Efd", "pu", "internal voltage behind xd1", start=1.1, operating_range=(0.9, 1.4))),
    outputs=(Quantity("I_re", "pu", "bus current, real part (network frame, system base)"),
             Quantity("I_im", "pu", "bus current, imaginary part (network frame, system base)"),
             Quantity("P", "pu", "active power into the bus (system base)"),
             Quantity("Q", "pu", "reactive power into the bus (system base)"),
             Quantity("Pe", "pu", "air-gap power (machine base)")),
    params_type=GENCLSParams,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.5, 0.01),
    # M d omega/dt = Pm - Pe(delta, fluxes, u) - D (omega - 1): affine in omega alone
    affine_states=(1,),
    ports=Ports(bus=BusPort(voltage=("Vs", "theta_vs"), current=("I_re", "I_im")),
                inputs=(Link("mechanical_power", "Pm"), Link("field_voltage", "Efd")),
                outputs=(Link("rotor_angle", "delta"), Link("rotor_speed", "omega"), Link("electrical_power", "Pe"))),
    # the equations see delta and theta_vs only through delta - theta_vs, and omega through
    # d delta/dt = 2 pi fn (omega - 1) and the damping torque D (omega - 1) (reference_models/drift.py)
    drift=Drift(angle_states=(0,), angle_inputs=(1,), speed_state=1, torque_inputs=((2, "D"),), speed_step=0.005,
                speed_scale=(2.0 * math.pi, "fn"), speed_rest=1.0),
    initialisation=machine_initialisation(operating_point),
    affine_current=True,
)
