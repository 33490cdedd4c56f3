"""What the standard models share: parameter range checks, the machine's network interface and
the search of a controller's set point (the set point at which a given output is at rest)."""
from __future__ import annotations

import math

import numpy as np

from ..component import Initialisation


def check_ranges(params, ranges: dict) -> None:
    """Raise ParameterError unless every parameter named in `ranges` {name: (low, high, unit)} lies
    in [low, high]."""
    for name, (low, high, unit) in ranges.items():
        params.require(name, low <= getattr(params, name) <= high, f"lie in [{low:g}, {high:g}] {unit}")


def check_limits(params, low: str, high: str) -> None:
    """Raise ParameterError unless limit `high` exceeds limit `low`."""
    params.require(high, getattr(params, high) > getattr(params, low), f"exceed {low} = {getattr(params, low)!r}")


def dq_voltage(delta, Vs, theta_vs, m):
    """(vd, vq) [pu]: the bus voltage in the rotor's dq frame, vd + j vq = Vs exp(j (theta_vs + pi/2 - delta))."""
    return Vs * m.sin(delta - theta_vs), Vs * m.cos(delta - theta_vs)


def network_current(delta, Id, Iq, m):
    """(I_re, I_im) [pu]: the dq current in the network frame, I = (Id + j Iq) exp(j (delta - pi/2))."""
    return Id * m.sin(delta) + Iq * m.cos(delta), Iq * m.sin(delta) - Id * m.cos(delta)


def stator_currents(psi2d, psi2q, vd, vq, ra: float, xd2: float, xq2: float):
    """(Id, Iq) [pu, machine base] from the stator equations without transients (ANDES' Flux0):
    xd2 Id + ra Iq = psi2d - vq, ra Id - xq2 Iq = psi2q - vd."""
    det = -xd2 * xq2 - ra * ra
    a, b = psi2d - vq, psi2q - vd
    return (-xq2 * a - ra * b) / det, (xd2 * b - ra * a) / det


SUBDIVISIONS = 16  # pieces of each outward segment of set_point's search


def set_point(output_of, target: float, guess: float, name: str, scale: float = 1.0, accept=None) -> float:
    """The set point s with output_of(s) = target nearest to `guess` (1-D root, searched in segments
    of doubling length outward from `guess` on both sides, so two roots within one symmetric
    bracket are not missed) that `accept(s)` takes (None: any); ValueError naming the component
    where there is none."""
    from scipy.optimize import brentq

    def miss(s):
        return output_of(s) - target

    f_guess = miss(guess)
    if f_guess == 0 and (accept is None or accept(guess)):
        return float(guess)
    inner, f_inner = {1: guess, -1: guess}, {1: f_guess, -1: f_guess}
    step = scale
    for _ in range(60):
        for side in (1, -1):
            reach = abs(inner[side] - guess)
            for k in range(1, SUBDIVISIONS + 1):  # the segment in pieces: a root pair close together is seen
                outer = guess + side * (reach + (step - reach) * k / SUBDIVISIONS)
                f_outer = miss(outer)
                if np.isfinite(f_inner[side]) and np.isfinite(f_outer) and f_inner[side] * f_outer <= 0:
                    low, high = sorted((inner[side], outer))
                    root = brentq(miss, low, high, xtol=1e-14, rtol=1e-15)
                    if accept is None or accept(root):
                        return root
                inner[side], f_inner[side] = outer, f_outer
        step *= 2.0
    raise ValueError(f"{name}: no steady state at these inputs")


def finite_inputs(u, name: str) -> tuple:
    """The inputs as floats; ValueError naming the component unless all are finite."""
    values = tuple(float(v) for v in u)
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{name}: no steady state at non-finite inputs {values}")
    return values


def controller_initialisation(inputs: tuple, output: str, set_point: str, initialise) -> Initialisation:
    """The Initialisation of a controller (an exciter, a governor) whose module gives
    initialise(y, u, p) -> (x0, s): its state at rest giving the output `output` = y and the value s
    of its input `set_point` that holds it, u its inputs (`inputs`: its Quantity tuple, component
    order) with the set point's entry ignored."""
    names = tuple(q.name for q in inputs)

    def start(given, p):
        u = np.array([0.0 if n == set_point else float(given[n]) for n in names])
        x0, value = initialise(float(given[output]), u, p)
        return x0, {set_point: float(value)}

    return Initialisation((set_point,), start)


def machine_initialisation(operating_point, power: str = "Pm", field: str = "Efd") -> Initialisation:
    """The Initialisation of a machine on a bus whose module gives operating_point(V, theta, P, Q, p)
    -> (x0, Pm, Efd): its state at rest delivering the load-flow point and the mechanical power and
    field voltage (its inputs `power`, `field`) holding it."""

    def start(given, p):
        x0, Pm, Efd = operating_point(given["V0"], given["theta0"], given["P0"], given["Q0"], p)
        return x0, {power: float(Pm), field: float(Efd)}

    return Initialisation((power, field), start)
