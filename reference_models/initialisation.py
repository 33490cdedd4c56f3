"""Start values of a machine (SM4) and its exciter (IEEE1) from a load-flow result.

Sauer & Pai, Power System Dynamics and Stability, section 7.6.3 (the two-axis model), with the
machine's own external impedance Re + jXep (zero where transformers are network branches, as in
the grid). The load flow gives the bus voltage V e^{j theta} and the power P + jQ the generator
injects into the bus, the sign convention of SM4's outputs P and Q:

    I       = conj((P + jQ) / (V e^{j theta}))                   bus current, network frame
    E       = V e^{j theta} + (Rs + Re + j (Xq + Xep)) I         delta = angle(E) (|E| > 0)
    Id + jIq = I e^{-j (delta - pi/2)},   Vd + jVq = V e^{j theta} e^{-j (delta - pi/2)}
    Ed_p    = (Xq - Xq_p) Iq                                     d Ed_p/dt = 0
    Eq_p    = Vq + (Rs + Re) Iq + (Xd_p + Xep) Id                the stator equation
    Efd     = Eq_p + (Xd - Xd_p) Id                              d Eq_p/dt = 0
    Pm      = Ed_p Id + Eq_p Iq + (Xq_p - Xd_p) Id Iq            d omega/dt = 0 at omega = 0
    Vt      = |V e^{j theta} + (Re + jXep) I|                    terminal voltage (= V for Re = Xep = 0)

The exciter then holds that Efd at that terminal voltage (IEEE1's steady state solved backwards):

    VR = (KE + SE(Efd)) Efd,   RF = KF / TF Efd,   Vref = Vt + VR / KA

The results are exact equilibria of the components' own right-hand sides (to rounding). Angles in
rad, everything else in pu on the machine base.
"""
from __future__ import annotations

import cmath
import math
from dataclasses import dataclass
from numbers import Real

import numpy as np

from .ieee1 import IEEE1, IEEE1Params, regulator_limits
from .sm4 import SM4, SM4Params

MACHINE, EXCITER = SM4, IEEE1  # the components whose start values these equations give

# The physical ranges of a load-flow point and of the start values it gives (pu on the machine
# base): a number outside them is a typing error or a point no machine is held at (P = 100 pu asks
# the default machine for a field voltage of 70 pu and its exciter for VR = 1e90 pu).
VOLTAGE_RANGE = (0.5, 1.5)  # pu: the bus voltage V
ANGLE_LIMIT = 2 * math.pi  # rad: |theta|
POWER_LIMIT = 10.0  # pu: |P| and |Q|, ten times the machine's rating (its base)
FIELD_LIMIT = 10.0  # pu: |Efd|, the field voltage the machine needs there
REGULATOR_LIMIT = 100.0  # pu: |VR|, the exciter's regulator output
REFERENCE_RANGE = (0.0, 10.0)  # pu: the exciter's voltage set point Vref


@dataclass(frozen=True)
class MachineStart:
    """SM4 at rest at a load-flow point: x0 [4] = (delta [rad], omega = 0, Ed_p, Eq_p), the inputs
    Pm and Efd that hold it there, the terminal voltage magnitude Vt behind Re + jXep from the bus
    (the exciter's input), the bus current I_re + j I_im (network frame) and the stator currents Id, Iq."""

    x0: np.ndarray
    Pm: float
    Efd: float
    Vt: float
    I_re: float
    I_im: float
    Id: float
    Iq: float


@dataclass(frozen=True)
class ExciterStart:
    """IEEE1 at rest holding a field voltage: x0 [3] = (Efd, RF, VR) and the set point Vref."""

    x0: np.ndarray
    Vref: float


def _number(name: str, value) -> float:
    """value as a finite float; ValueError naming it otherwise."""
    if isinstance(value, bool) or not isinstance(value, Real):
        raise ValueError(f"{name} must be a number, got {str(value)[:40]!r}")
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} must be a finite number, got {str(value)[:40]}") from None
    if not math.isfinite(number):
        raise ValueError(f"{name} must be a finite number, got {number!r}")
    return number


def _within(what: str, value: float, low: float, high: float, unit: str, context: str = "") -> None:
    """ValueError "WHAT = VALUE UNIT CONTEXT lies outside its physical range [LOW, HIGH] UNIT" unless
    low <= value <= high."""
    if not low <= value <= high:
        raise ValueError(f"{what} = {value:.6g} {unit}{context} lies outside its physical range "
                         f"[{low:.6g}, {high:.6g}] {unit}")


def _frozen(values) -> np.ndarray:
    array = np.array(values, dtype=float)
    array.flags.writeable = False
    return array


def machine_start(V: float, theta: float, P: float, Q: float, p: SM4Params) -> MachineStart:
    """SM4 in equilibrium at bus voltage V [pu] at angle theta [rad], injecting P + jQ [pu] into the
    bus (P + jQ = V e^{j theta} conj(I)); the machine's parameters p.

    Raises ValueError for a non-finite number, a number outside its physical range (V in
    VOLTAGE_RANGE, |theta| <= ANGLE_LIMIT, |P|, |Q| <= POWER_LIMIT), a point no machine of these
    parameters can be in (no internal voltage to give the rotor angle) or one that needs a field
    voltage beyond FIELD_LIMIT."""
    if not isinstance(p, SM4Params):
        raise TypeError(f"machine parameters must be SM4Params, got {type(p).__name__}")
    V, theta, P, Q = (_number(n, v) for n, v in (("V", V), ("theta", theta), ("P", P), ("Q", Q)))
    _within("the bus voltage V", V, *VOLTAGE_RANGE, "pu")
    _within("the bus voltage angle theta", theta, -ANGLE_LIMIT, ANGLE_LIMIT, "rad")
    _within("the active power P", P, -POWER_LIMIT, POWER_LIMIT, "pu")
    _within("the reactive power Q", Q, -POWER_LIMIT, POWER_LIMIT, "pu")
    bus = cmath.rect(V, theta)
    current = ((P + 1j * Q) / bus).conjugate()
    ra = p.Rs + p.Re
    behind_xq = bus + complex(ra, p.Xq + p.Xep) * current
    if not abs(behind_xq) > 1e-9 * max(V, abs(current)):
        raise ValueError(f"no rotor angle at V={V} pu, P={P} pu, Q={Q} pu: the voltage behind Rs + Re + j(Xq + Xep) "
                         "is zero (the machine would absorb more reactive power than it can)")
    delta = cmath.phase(behind_xq)
    to_dq = cmath.exp(-1j * (delta - math.pi / 2))
    Id, Iq = (current * to_dq).real, (current * to_dq).imag
    Vq = (bus * to_dq).imag  # = V cos(delta - theta)
    Ed_p = (p.Xq - p.Xq_p) * Iq
    Eq_p = Vq + ra * Iq + (p.Xd_p + p.Xep) * Id
    Efd = Eq_p + (p.Xd - p.Xd_p) * Id
    Pm = Ed_p * Id + Eq_p * Iq + (p.Xq_p - p.Xd_p) * Id * Iq
    Vt = abs(bus + complex(p.Re, p.Xep) * current)
    values = (delta, Ed_p, Eq_p, Efd, Pm, Vt, Id, Iq)
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"no finite start of the machine at V={V} pu, theta={theta} rad, P={P} pu, Q={Q} pu")
    _within("the field voltage Efd", Efd, -FIELD_LIMIT, FIELD_LIMIT, "pu", " the machine needs there")
    return MachineStart(x0=_frozen([delta, 0.0, Ed_p, Eq_p]), Pm=Pm, Efd=Efd, Vt=Vt, I_re=current.real,
                        I_im=current.imag, Id=Id, Iq=Iq)


def exciter_start(Efd: float, Vt: float, p: IEEE1Params) -> ExciterStart:
    """IEEE1 in equilibrium holding field voltage Efd [pu] at terminal voltage Vt [pu]; parameters p.

    Raises ValueError for a non-finite number, Vt <= 0, |Efd| beyond FIELD_LIMIT, an Efd below -1/Bx
    (off the branch where IEEE1's steady state is unique: (KE + SE(Efd)) Efd increasing), a
    regulator output VR the limits VRmin, VRmax do not allow or beyond REGULATOR_LIMIT, or a set
    point Vref outside REFERENCE_RANGE."""
    if not isinstance(p, IEEE1Params):
        raise TypeError(f"exciter parameters must be IEEE1Params, got {type(p).__name__}")
    Efd, Vt = _number("Efd", Efd), _number("Vt", Vt)
    if Vt <= 0:
        raise ValueError(f"the terminal voltage Vt must be > 0 pu, got {Vt!r}")
    _within("the field voltage Efd", Efd, -FIELD_LIMIT, FIELD_LIMIT, "pu")
    if p.Bx > 0 and Efd < -1.0 / p.Bx:
        raise ValueError(f"the exciter has no unique steady state at Efd = {Efd!r} pu (below -1/Bx = {-1.0 / p.Bx!r})")
    VR = (p.KE + p.Ax * math.exp(p.Bx * Efd)) * Efd
    low, high = regulator_limits(p)
    if not (low <= VR <= high):
        bound = "VRmax" if VR > high else "VRmin"
        raise ValueError(f"the exciter cannot hold Efd = {Efd:.6g} pu: it needs VR = {VR:.6g} pu, beyond the "
                         f"regulator limit {bound} = {getattr(p, bound)!r}")
    _within("the regulator output VR", VR, -REGULATOR_LIMIT, REGULATOR_LIMIT, "pu",
            f" the exciter needs to hold Efd = {Efd:.6g} pu")
    RF = p.KF / p.TF * Efd
    Vref = Vt + VR / p.KA
    _within("the voltage set point Vref", Vref, *REFERENCE_RANGE, "pu", " the exciter needs")
    return ExciterStart(x0=_frozen([Efd, RF, VR]), Vref=Vref)
