"""The 4th-order synchronous machine (Sauer-Pai two-axis model) on a bus of varying voltage.

One definition of the equations, written against a small math namespace, serves numpy arrays
(scipy), torch tensors (physics losses, autograd) and symbolic code generation.

States  x = (delta [rad], omega [rad/s, deviation from synchronous], Ed_p [pu], Eq_p [pu])
Inputs  u = (Vs [pu], theta_vs [rad])
Arrays carry the state or input on their last axis: x [..., 4], u [..., 2].
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

STATE_NAMES = ("delta", "omega", "Ed_p", "Eq_p")
STATE_UNITS = ("rad", "rad/s", "pu", "pu")
INPUT_NAMES = ("Vs", "theta_vs")
INPUT_UNITS = ("pu", "rad")
OUTPUT_NAMES = ("Id", "Iq", "I_re", "I_im", "P", "Q")


@dataclass(frozen=True)
class SM4Params:
    """Machine, network and operating-point parameters (paper Table I); reactances in pu, times in s."""

    D: float = 2.0
    H: float = 5.06
    Rs: float = 0.0
    Td0_p: float = 4.75
    Tq0_p: float = 1.6
    Xd: float = 1.25
    Xd_p: float = 0.232
    Xq: float = 1.22
    Xq_p: float = 0.715
    Xep: float = 0.1
    Re: float = 0.0
    Wb: float = 314.159
    Pm: float = 0.7048
    Efd: float = 1.08

    def to_dict(self) -> dict:
        return asdict(self)


def stator_currents(delta, Ed_p, Eq_p, Vs, theta_vs, p: SM4Params, sin, cos):
    """Id, Iq [pu] from the algebraic stator-network equations, solved in closed form (2x2)."""
    ra = p.Rs + p.Re
    xq = p.Xq_p + p.Xep
    xd = p.Xd_p + p.Xep
    a = Ed_p - Vs * sin(delta - theta_vs)
    b = Eq_p - Vs * cos(delta - theta_vs)
    det = ra * ra + xq * xd
    Id = (ra * a + xq * b) / det
    Iq = (ra * b - xd * a) / det
    return Id, Iq


def electrical_power(Ed_p, Eq_p, Id, Iq, p: SM4Params):
    """Air-gap power Pe [pu]."""
    return Ed_p * Id + Eq_p * Iq + (p.Xq_p - p.Xd_p) * Id * Iq


def derivatives(delta, omega, Ed_p, Eq_p, Vs, theta_vs, p: SM4Params, sin, cos):
    """Time derivatives (d delta, d omega, d Ed_p, d Eq_p) per second; works on any numeric type."""
    Id, Iq = stator_currents(delta, Ed_p, Eq_p, Vs, theta_vs, p, sin, cos)
    Pe = electrical_power(Ed_p, Eq_p, Id, Iq, p)
    d_delta = omega
    d_omega = p.Wb / (2.0 * p.H) * (p.Pm - Pe - p.D * omega)
    d_Ed_p = (-Ed_p + (p.Xq - p.Xq_p) * Iq) / p.Tq0_p
    d_Eq_p = (-Eq_p - (p.Xd - p.Xd_p) * Id + p.Efd) / p.Td0_p
    return d_delta, d_omega, d_Ed_p, d_Eq_p


def _namespace(x):
    """(sin, cos, stack) for numpy arrays or torch tensors."""
    if type(x).__module__.startswith("torch"):
        import torch

        return torch.sin, torch.cos, lambda parts: torch.stack(parts, dim=-1)
    return np.sin, np.cos, lambda parts: np.stack(parts, axis=-1)


def rhs(x, u, p: SM4Params = SM4Params()):
    """dx/dt for states x [..., 4] and inputs u [..., 2] (numpy or torch, broadcast); returns [..., 4]."""
    sin, cos, stack = _namespace(x)
    parts = derivatives(x[..., 0], x[..., 1], x[..., 2], x[..., 3], u[..., 0], u[..., 1], p, sin, cos)
    return stack(list(parts))


def derived(delta, Ed_p, Eq_p, Vs, theta_vs, p: SM4Params, sin, cos):
    """(Id, Iq, I_re, I_im, P, Q) in pu; works on any numeric type.

    Bus current in the network frame: I = (Id + j Iq) exp(j (delta - pi/2));
    power into the bus: P + jQ = Vs exp(j theta_vs) conj(I).
    """
    Id, Iq = stator_currents(delta, Ed_p, Eq_p, Vs, theta_vs, p, sin, cos)
    # exp(j(delta - pi/2)) = sin(delta) - j cos(delta)
    I_re = Id * sin(delta) + Iq * cos(delta)
    I_im = Iq * sin(delta) - Id * cos(delta)
    V_re, V_im = Vs * cos(theta_vs), Vs * sin(theta_vs)
    P = V_re * I_re + V_im * I_im
    Q = V_im * I_re - V_re * I_im
    return Id, Iq, I_re, I_im, P, Q


def outputs(x, u, p: SM4Params = SM4Params()):
    """Derived outputs (Id, Iq, I_re, I_im, P, Q) [..., 6] in pu for x [..., 4], u [..., 2] (see `derived`)."""
    sin, cos, stack = _namespace(x)
    return stack(list(derived(x[..., 0], x[..., 2], x[..., 3], u[..., 0], u[..., 1], p, sin, cos)))


def _steady_fluxes(angle, Vs, p: SM4Params):
    """Ed_p, Eq_p [pu] with d Ed_p/dt = d Eq_p/dt = 0 at rotor angle delta - theta_vs = angle (numpy)."""
    ra, xq, xd = p.Rs + p.Re, p.Xq_p + p.Xep, p.Xd_p + p.Xep
    det = ra * ra + xq * xd
    kq, kd = (p.Xq - p.Xq_p) / det, (p.Xd - p.Xd_p) / det
    # Ed = kq (ra b - xd a), Eq = Efd - kd (ra a + xq b), a = Ed - Vs sin, b = Eq - Vs cos: linear in (Ed, Eq)
    s, c = Vs * np.sin(angle), Vs * np.cos(angle)
    A = np.array([[1 + kq * xd, -kq * ra], [kd * ra, 1 + kd * xq]])
    rhs_ = np.array([kq * (xd * s - ra * c), p.Efd + kd * (ra * s + xq * c)])
    return np.linalg.solve(A, rhs_)


def steady_state(Vs: float = 1.0, theta_vs: float = 0.0, p: SM4Params = SM4Params()) -> np.ndarray:
    """The stable equilibrium x* [4] for constant inputs: omega = 0, Pe = Pm on the rising side of the
    steady-state power-angle curve.

    Raises ValueError when the machine cannot transfer Pm at this voltage (no equilibrium).
    """
    from scipy.optimize import brentq

    def excess_power(angle):
        Ed_p, Eq_p = _steady_fluxes(angle, Vs, p)
        Id, Iq = stator_currents(angle, Ed_p, Eq_p, Vs, 0.0, p, np.sin, np.cos)
        return electrical_power(Ed_p, Eq_p, Id, Iq, p) - p.Pm

    grid = np.linspace(-math.pi / 2, math.pi, 301)
    values = np.array([excess_power(a) for a in grid])
    rising = np.nonzero((values[:-1] < 0) & (values[1:] >= 0))[0]
    if not np.isfinite(Vs) or not np.isfinite(theta_vs) or Vs <= 0 or rising.size == 0:
        raise ValueError(f"no stable equilibrium of SM4 at Vs={Vs} pu, theta_vs={theta_vs} rad")
    i = rising[0]
    angle = brentq(excess_power, grid[i], grid[i + 1], xtol=1e-15, rtol=1e-15)
    Ed_p, Eq_p = _steady_fluxes(angle, Vs, p)
    return np.array([theta_vs + angle, 0.0, Ed_p, Eq_p])


def min_voltage_with_equilibrium(p: SM4Params = SM4Params(), tol: float = 1e-9) -> float:
    """The lowest bus voltage Vs [pu] at which an equilibrium exists (bisection on steady_state).

    With fixed Efd and Pm there is none below it: the machine cannot deliver Pm there and, held
    long enough (Td0_p), loses synchronism.
    """
    low, high = 0.05, 10.0
    while high - low > tol:
        mid = 0.5 * (low + high)
        try:
            steady_state(mid, 0.0, p)
            high = mid
        except ValueError:
            low = mid
    return high
