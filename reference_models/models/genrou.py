"""GENROU: the round-rotor synchronous machine with quadratic saturation (PSS/E, ANDES), on a bus.

States  x = (delta [rad], omega [pu], e1q, e1d, e2d, e2q [pu])
Inputs  u = (Vs [pu], theta_vs [rad]: the bus voltage; Pm [pu] mechanical power (ANDES' tm),
        Efd [pu] field voltage (ANDES' vf))
Outputs y = (I_re, I_im [pu, system base]: the current into the bus, network frame; P, Q [pu,
        system base]: the power into the bus; Pe [pu]: air-gap power (ANDES' te); XadIfd [pu]:
        the field current times the d-axis mutual reactance)

Equations (ANDES 2.0 model reference, SynGen: GENROU; PSS/E GENROU; Flux0, no stator transients):

    vd = Vs sin(delta - theta_vs),  vq = Vs cos(delta - theta_vs)
    psi2d = gd1 e1q + gd2 (xd1 - xl) e2d,  psi2q = gq1 e1d + (1 - gq1) e2q,  psi2 = |(psi2d, psi2q)|
    stator: xd2 Id + ra Iq = psi2d - vq,  ra Id - xq2 Iq = psi2q - vd
    Se psi2 = B (psi2 - A)^2 for psi2 >= A (quadratic saturation through S(1.0) = S10, S(1.2) = S12)
    XadIfd = e1q + (xd - xd1) (gd1 Id - gd2 e2d + gd2 e1q) + Se psi2d
    XaqI1q = e1d + (xq - xq1) (gq2 e1d - gq2 e2q - gq1 Iq) + Se gqd psi2q
    d delta/dt = 2 pi fn (omega - 1),  M d omega/dt = Pm - Pe - D (omega - 1),  Pe = psid Iq - psiq Id
    Td10 de1q/dt = Efd - XadIfd,  Tq10 de1d/dt = -XaqI1q
    Td20 de2d/dt = -e2d + e1q - (xd1 - xl) Id,  Tq20 de2q/dt = -e2q + e1d + (xq1 - xl) Iq

with gd1 = (xd2 - xl) / (xd1 - xl), gq1 = (xq2 - xl) / (xq1 - xl), gd2 = (xd1 - xd2) / (xd1 - xl)^2,
gq2 = (xq1 - xq2) / (xq1 - xl)^2, gqd = (xq - xl) / (xd - xl), psid = ra Iq + vq, psiq = -(ra Id + vd).

Bases: the parameters (reactances, M, D) and Pm, Efd, Pe, XadIfd are on the machine base Sn, as
the case files give them; the bus port (I_re, I_im) and P, Q are on the system base Sb, which the
network uses (I_system = I_machine Sn / Sb). ANDES converts the parameters to the system base
instead; the equations are the same.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..blocks import quadratic_saturation_coefficients, quadratic_saturation_product
from ..component import Component, Parameters, Quantity
from ..drift import Drift
from ..ports import BusPort, Link, Ports
from .common import check_ranges, dq_voltage, finite_inputs, machine_initialisation, network_current, stator_currents

PARAMETER_RANGES = {
    "fn": (16.0, 400.0, "Hz"), "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA"),
    "M": (0.1, 2000.0, "s"), "D": (0.0, 1000.0, "pu"), "ra": (0.0, 1.0, "pu"), "xl": (0.0, 5.0, "pu"),
    "xd": (0.01, 10.0, "pu"), "xq": (0.01, 10.0, "pu"), "xd1": (0.01, 10.0, "pu"), "xq1": (0.01, 10.0, "pu"),
    "xd2": (0.001, 10.0, "pu"), "xq2": (0.001, 10.0, "pu"),
    "Td10": (0.01, 100.0, "s"), "Tq10": (0.01, 100.0, "s"), "Td20": (0.001, 10.0, "s"), "Tq20": (0.001, 10.0, "s"),
    "S10": (0.0, 100.0, "pu"), "S12": (0.0, 100.0, "pu"),  # wecc_full gives S12 = 11
}


@dataclass(frozen=True)
class GENROUParams(Parameters):
    """ANDES/PSS/E GENROU data: reactances [pu] and M = 2H [s], D [pu] on the machine base Sn [MVA];
    Sb [MVA] the system base of the bus port; fn [Hz]; time constants [s]; S10, S12 the saturation
    at 1.0 and 1.2 pu (S12 = 0 read as 1, as ANDES; S10 = 0: no saturation)."""

    fn: float = 60.0
    Sn: float = 900.0
    Sb: float = 100.0
    M: float = 13.0
    D: float = 0.0
    ra: float = 0.0025
    xl: float = 0.2
    xd: float = 1.8
    xq: float = 1.7
    xd1: float = 0.3
    xq1: float = 0.55
    xd2: float = 0.25
    xq2: float = 0.25
    Td10: float = 8.0
    Tq10: float = 0.4
    Td20: float = 0.03
    Tq20: float = 0.05
    S10: float = 0.0
    S12: float = 1.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        self.require("xq2", self.xq2 == self.xd2, f"equal xd2 = {self.xd2!r} (GENROU's subtransient saliency is none)")
        self.require("xd1", self.xd1 != self.xl, f"differ from xl = {self.xl!r}")
        self.require("xq1", self.xq1 != self.xl, f"differ from xl = {self.xl!r}")
        self.require("xd", self.xd != self.xl, f"differ from xl = {self.xl!r}")

    @property
    def saturation(self) -> tuple:
        """(A, B) of Se psi2 = B (psi2 - A)^2 (ANDES: ExcQuadSat(1.0, S10, 1.2, S12 or 1))."""
        return quadratic_saturation_coefficients(1.0, self.S10, 1.2, self.S12 if self.S12 != 0 else 1.0)


def _coefficients(p: GENROUParams) -> tuple:
    gd1 = (p.xd2 - p.xl) / (p.xd1 - p.xl)
    gq1 = (p.xq2 - p.xl) / (p.xq1 - p.xl)
    gd2 = (p.xd1 - p.xd2) / (p.xd1 - p.xl) ** 2
    gq2 = (p.xq1 - p.xq2) / (p.xq1 - p.xl) ** 2
    gqd = (p.xq - p.xl) / (p.xd - p.xl)
    return gd1, gq1, gd2, gq2, gqd


def _algebraic(x, u, p: GENROUParams, m) -> dict:
    """The machine's algebraic variables (ANDES' names) at states x and inputs u."""
    delta, omega, e1q, e1d, e2d, e2q = x
    Vs, theta_vs = u[0], u[1]
    gd1, gq1, gd2, gq2, gqd = _coefficients(p)
    A, B = p.saturation
    vd, vq = dq_voltage(delta, Vs, theta_vs, m)
    psi2d = gd1 * e1q + gd2 * (p.xd1 - p.xl) * e2d
    psi2q = gq1 * e1d + (1.0 - gq1) * e2q
    psi2 = m.sqrt(psi2d * psi2d + psi2q * psi2q)
    Se = quadratic_saturation_product(m, psi2, A, B) / psi2
    Id, Iq = stator_currents(psi2d, psi2q, vd, vq, p.ra, p.xd2, p.xq2)
    psid, psiq = p.ra * Iq + vq, -(p.ra * Id + vd)
    return dict(vd=vd, vq=vq, Id=Id, Iq=Iq, psi2d=psi2d, psi2q=psi2q, Se=Se, psid=psid, psiq=psiq,
                te=psid * Iq - psiq * Id,
                XadIfd=e1q + (p.xd - p.xd1) * (gd1 * Id - gd2 * e2d + gd2 * e1q) + Se * psi2d,
                XaqI1q=e1d + (p.xq - p.xq1) * (gq2 * e1d - gq2 * e2q - gq1 * Iq) + Se * gqd * psi2q)


def derivatives(x, u, p: GENROUParams, m):
    """(d delta, d omega, d e1q, d e1d, d e2d, d e2q)/dt for x = (delta, omega, e1q, e1d, e2d, e2q),
    u = (Vs, theta_vs, Pm, Efd)."""
    delta, omega, e1q, e1d, e2d, e2q = x
    Pm, Efd = u[2], u[3]
    a = _algebraic(x, u, p, m)
    return (2.0 * math.pi * p.fn * (omega - 1.0),
            (Pm - a["te"] - p.D * (omega - 1.0)) / p.M,
            (Efd - a["XadIfd"]) / p.Td10,
            -a["XaqI1q"] / p.Tq10,
            (-e2d + e1q - (p.xd1 - p.xl) * a["Id"]) / p.Td20,
            (-e2q + e1d + (p.xq1 - p.xl) * a["Iq"]) / p.Tq20)


def outputs(x, u, p: GENROUParams, m):
    """(I_re, I_im, P, Q) [pu, system base], Pe, XadIfd [pu, machine base]."""
    a = _algebraic(x, u, p, m)
    k = p.Sn / p.Sb
    I_re, I_im = network_current(x[0], a["Id"], a["Iq"], m)
    P = (a["vd"] * a["Id"] + a["vq"] * a["Iq"]) * k
    Q = (a["vq"] * a["Id"] - a["vd"] * a["Iq"]) * k
    return I_re * k, I_im * k, P, Q, a["te"], a["XadIfd"]


def operating_point(Vs: float, theta_vs: float, P: float, Q: float, p: GENROUParams) -> tuple:
    """The steady state from the load flow: (x [6], Pm, Efd [pu]) of the machine delivering
    P + jQ [pu, system base] into a bus at Vs [pu], theta_vs [rad] (ANDES' initialisation).

    The subtransient flux psi'' = V + (ra + j xd2) I; at rest the q axis gives
    psi2q (1 + Se gqd) = (xq - xq2) Iq, so the rotor angle is the angle of
    (1 + Se gqd) psi'' + j (xq - xq2) I; the rest follows in closed form."""
    gd1, gq1, gd2, gq2, gqd = _coefficients(p)
    A, B = p.saturation
    V = Vs * complex(math.cos(theta_vs), math.sin(theta_vs))
    current = (complex(P, -Q) / V.conjugate()) * (p.Sb / p.Sn)
    psi = V + complex(p.ra, p.xd2) * current
    Se = B * (abs(psi) - A) ** 2 / abs(psi) if abs(psi) >= A else 0.0
    delta = float(np.angle((1.0 + Se * gqd) * psi + 1j * (p.xq - p.xq2) * current))
    turn = complex(math.sin(delta), math.cos(delta))  # exp(j (pi/2 - delta))
    Idq, vdq, psidq = current * turn, V * turn, psi * turn
    Id, Iq, vd, vq = Idq.real, Idq.imag, vdq.real, vdq.imag
    psi2q, psi2d = psidq.real, psidq.imag
    e1d = psi2q - (p.xq1 - p.xq2) * Iq
    e2q = e1d + (p.xq1 - p.xl) * Iq
    e1q = psi2d + (p.xd1 - p.xd2) * Id
    e2d = e1q - (p.xd1 - p.xl) * Id
    Efd = e1q + (p.xd - p.xd1) * Id + Se * psi2d
    psid, psiq = p.ra * Iq + vq, -(p.ra * Id + vd)
    Pm = psid * Iq - psiq * Id
    return np.array([delta, 1.0, e1q, e1d, e2d, e2q]), Pm, Efd


def equilibrium(u, p: GENROUParams) -> np.ndarray:
    """The steady state [6] at constant (Vs, theta_vs, Pm, Efd): the power P + jQ into the bus at
    which operating_point gives these Pm and Efd (Newton from P = Pm Sn / Sb, Q = 0); ValueError
    where there is none."""
    from scipy.optimize import fsolve

    Vs, theta_vs, Pm, Efd = finite_inputs(u, "GENROU")
    if Vs <= 0:
        raise ValueError(f"GENROU: no steady state at Vs = {Vs} pu")
    k = p.Sn / p.Sb

    def miss(s):
        _, pm, efd = operating_point(Vs, theta_vs, s[0], s[1], p)
        return [(pm - Pm), (efd - Efd)]

    # fsolve's flag may say "xtol too small" at a 1e-16 residual: the residuals below decide
    s = fsolve(miss, [Pm * k, 0.0], full_output=True, xtol=1e-14)[0]
    x, pm, efd = operating_point(Vs, theta_vs, s[0], s[1], p)
    if abs(pm - Pm) > 1e-9 or abs(efd - Efd) > 1e-9 or abs(x[0] - theta_vs) >= math.pi / 2:
        raise ValueError(f"GENROU: no stable steady state at Vs = {Vs} pu, Pm = {Pm} pu, Efd = {Efd} pu")
    return x


GENROU = Component(
    name="genrou",
    description="GENROU round-rotor synchronous machine with quadratic saturation (PSS/E, ANDES) on a bus",
    states=(Quantity("delta", "rad", "rotor angle"),
            Quantity("omega", "pu", "rotor speed (1: synchronous)"),
            Quantity("e1q", "pu", "q-axis transient voltage"),
            Quantity("e1d", "pu", "d-axis transient voltage"),
            Quantity("e2d", "pu", "d-axis subtransient flux"),
            Quantity("e2q", "pu", "q-axis subtransient flux")),
    inputs=(Quantity("Vs", "pu", "bus voltage magnitude", start=1.0, operating_range=(0.7, 1.2), minimum=0.0),
            Quantity("theta_vs", "rad", "bus voltage angle", start=0.0, operating_range=(-0.5, 0.5)),
            Quantity("Pm", "pu", "mechanical power (machine base)", start=0.7, operating_range=(0.3, 1.0)),
            Quantity("Efd", "pu", "field voltage", start=1.8, operating_range=(1.0, 3.0))),
    outputs=(Quantity("I_re", "pu", "bus current, real part (network frame, system base)"),
             Quantity("I_im", "pu", "bus current, imaginary part (network frame, system base)"),
             Quantity("P", "pu", "active power into the bus (system base)"),
             Quantity("Q", "pu", "reactive power into the bus (system base)"),
             Quantity("Pe", "pu", "air-gap power (machine base)"),
             Quantity("XadIfd", "pu", "field current times the d-axis mutual reactance")),
    params_type=GENROUParams,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.5, 0.01, 0.1, 0.1, 0.1, 0.1),
    # M d omega/dt = Pm - Pe(delta, fluxes, u) - D (omega - 1): affine in omega alone
    affine_states=(1,),
    ports=Ports(bus=BusPort(voltage=("Vs", "theta_vs"), current=("I_re", "I_im")),
                inputs=(Link("mechanical_power", "Pm"), Link("field_voltage", "Efd")),
                outputs=(Link("rotor_angle", "delta"), Link("rotor_speed", "omega"), Link("electrical_power", "Pe"),
                         Link("field_current", "XadIfd"))),
    # the equations see delta and theta_vs only through delta - theta_vs, and omega through
    # d delta/dt = 2 pi fn (omega - 1) and the damping torque D (omega - 1) (reference_models/drift.py)
    drift=Drift(angle_states=(0,), angle_inputs=(1,), speed_state=1, torque_inputs=((2, "D"),), speed_step=0.005,
                speed_scale=(2.0 * math.pi, "fn"), speed_rest=1.0),
    initialisation=machine_initialisation(operating_point),
    affine_current=True,
)
