"""IEEEG1: the IEEE Type 1 speed-governing model (PSS/E IEEEG1, ANDES), driving one machine
from its high-pressure stages and, where the case names one (ANDES' syn2), a second machine from its
low-pressure stages.

States  x = (LL_x [pu] lead-lag state, IAW_y [pu] valve position held within [PMIN, PMAX],
        L4_y, L5_y, L6_y, L7_y [pu] turbine stage lags)
Inputs  u = (omega [pu] speed of the first machine, Pref [pu] power reference: ANDES' tm012)
Outputs y = (Pm [pu] mechanical power of the first machine, on its base Sg;
             Pm2 [pu] mechanical power of the second machine, on its base Sg2; 0 without one)

Equations (ANDES 2.0 model reference, TurbineGov: IEEEG1), on the turbine's base Sn:

    wd = wref0 - omega
    lead-lag K (1 + s T2) / (1 + s T1) of wd (T1 = 0: the gain K) -> LL_y
    vs = (LL_y + Pref - IAW_y) / T3,  vsl = vs clipped to [UC, UO] Sb / Sn (windup limiter)
    non-windup integrator:  dIAW_y/dt = vsl,  PMIN <= IAW_y <= PMAX
        (reset: IAW_y at or beyond a limit while vsl pushes outward is placed on it)
    lags 1 / (1 + s T4..T7) in series: L4 of IAW_y, L5 of L4_y, L6 of L5_y, L7 of L6_y (T = 0:
        the stage passes its input)
    PHP = K1n L4 + K3n L5 + K5n L6 + K7n L7,  PLP = K2n L4 + K4n L5 + K6n L6 + K8n L7,
        Kin = Ki / (K1 + ... + K8)
    Pm = PHP Sn / Sg,  Pm2 = PLP Sn / Sg2

Bases: the turbine's Sn (ANDES: its Tn, or the sum of its machines' bases) for the states and the
limits; each machine's power on that machine's base Sg (0: Sn), Sg2 [MVA] (0: no second machine);
the valve rate limits UO, UC: ANDES 2.0 applies them unconverted to its system-base valve position,
so on the turbine base they are UO Sb / Sn, UC Sb / Sn (Sb the system base [MVA]).

Start: at rest, every stage at the valve position, the valve giving both machines the powers their
load flow asks, Pm Sg + Pm2 Sg2 = IAW_y Sn (K1n + ... + K8n) where there are two (ANDES' tm012):
the high- and low-pressure shares must then stand as the stage fractions do (ANDES checks the same
proportionality at its initialisation and runs off rest where it fails; opfmu refuses). With one
machine the valve gives it Pm from the high-pressure stages alone.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..blocks import clip, integrator_non_windup, integrator_non_windup_reset, lag, lead_lag
from ..component import Component, Initialisation, Parameters, Quantity
from ..ports import Link, Ports
from .common import check_limits, check_ranges, finite_inputs

PARAMETER_RANGES = {"K": (0.0, 1000.0, "pu"), "T1": (0.0, 100.0, "s"), "T2": (0.0, 100.0, "s"),
                    "T3": (0.001, 100.0, "s"), "T4": (0.0, 100.0, "s"), "T5": (0.0, 100.0, "s"),
                    "T6": (0.0, 100.0, "s"), "T7": (0.0, 100.0, "s"), "wref0": (0.5, 1.5, "pu"),
                    "Sn": (1e-3, 1e5, "MVA"), "Sb": (1e-3, 1e5, "MVA"), "Sg": (0.0, 1e5, "MVA"),
                    "Sg2": (0.0, 1e5, "MVA"),
                    **{f"K{i}": (0.0, 1.0, "pu") for i in range(1, 9)}}


@dataclass(frozen=True)
class IEEEG1Params(Parameters):
    """ANDES/PSS/E IEEEG1 data: gain K [pu], time constants [s], valve rate limits UO, UC [pu/s],
    valve limits PMAX, PMIN [pu], stage fractions K1..K8 [pu], speed reference wref0 [pu], the
    turbine's base Sn, the system base Sb (for ANDES' rate limits), the first machine's base Sg (0:
    Sn, a turbine of its machine's rating) and the second machine's Sg2 [MVA] (0: no second
    machine)."""

    K: float = 20.0
    T1: float = 1.0
    T2: float = 1.0
    T3: float = 0.1
    UO: float = 0.1
    UC: float = -0.1
    PMAX: float = 5.0
    PMIN: float = 0.0
    T4: float = 0.4
    K1: float = 0.3
    K2: float = 0.0
    T5: float = 7.0
    K3: float = 0.3
    K4: float = 0.0
    T6: float = 0.6
    K5: float = 0.4
    K6: float = 0.0
    T7: float = 0.0
    K7: float = 0.0
    K8: float = 0.0
    wref0: float = 1.0
    Sn: float = 100.0
    Sb: float = 100.0
    Sg: float = 0.0
    Sg2: float = 0.0

    def check(self) -> None:
        check_ranges(self, PARAMETER_RANGES)
        check_limits(self, "UC", "UO")
        check_limits(self, "PMIN", "PMAX")
        total = sum(getattr(self, f"K{i}") for i in range(1, 9))
        self.require("K1", total > 0, "with K2..K8 sum to more than 0")

    def fractions(self, first: int) -> tuple:
        """The stage fractions normalised by K1 + ... + K8: (K1n, K3n, K5n, K7n) of the high-pressure
        output (first = 1), (K2n, K4n, K6n, K8n) of the low-pressure one (first = 2)."""
        total = sum(getattr(self, f"K{i}") for i in range(1, 9))
        return tuple(getattr(self, f"K{i}") / total for i in range(first, 9, 2))

    @property
    def first_base(self) -> float:
        """The first machine's base [MVA]: Sg, or the turbine's Sn where Sg is 0."""
        return self.Sg if self.Sg > 0 else self.Sn


def _stages(x, p: IEEEG1Params, m):
    """(derivatives of L4..L7, their outputs)."""
    signal, rates, outs = x[1], [], []
    for state, T in zip(x[2:], (p.T4, p.T5, p.T6, p.T7)):
        rate, signal = lag(m, signal, state, 1.0, T)
        rates.append(rate)
        outs.append(signal)
    return rates, outs


def _valve_speed(x, u, p: IEEEG1Params, m):
    """(dLL_x/dt, vsl): the lead-lag's derivative and the valve speed after its windup limiter."""
    omega, Pref = u
    d_LL, LL_y = lead_lag(m, p.wref0 - omega, x[0], p.K, p.T2, p.T1)
    return d_LL, clip(m, (LL_y + Pref - x[1]) / p.T3, p.UC * p.Sb / p.Sn, p.UO * p.Sb / p.Sn)


def derivatives(x, u, p: IEEEG1Params, m):
    """(dLL_x, dIAW_y, dL4_y, dL5_y, dL6_y, dL7_y)/dt for x as the states, u = (omega, Pref)."""
    d_LL, vsl = _valve_speed(x, u, p, m)
    d_IAW, _ = integrator_non_windup(m, vsl, x[1], 1.0, 1.0, p.PMIN, p.PMAX)
    rates, _ = _stages(x, p, m)
    return (d_LL, d_IAW, *rates)


def reset(x, u, p: IEEEG1Params, m):
    """x after the reset of the valve position's non-windup limit (blocks.integrator_non_windup_reset)."""
    IAW_y = integrator_non_windup_reset(m, _valve_speed(x, u, p, m)[1], x[1], 1.0, 1.0, p.PMIN, p.PMAX)
    return (x[0], IAW_y, *x[2:])


def outputs(x, u, p: IEEEG1Params, m):
    """(Pm, Pm2): the high-pressure stages' power on the first machine's base, the low-pressure
    stages' on the second's (0 without one)."""
    _, outs = _stages(x, p, m)
    high = sum(k * y for k, y in zip(p.fractions(1), outs)) * (p.Sn / p.first_base)
    low = sum(k * y for k, y in zip(p.fractions(2), outs)) * (p.Sn / p.Sg2) if p.Sg2 > 0 else 0.0 * outs[0]
    return high, low


def _start(given, p: IEEEG1Params) -> tuple:
    """(x [6], {"Pref": value}): the state at rest giving the first machine Pm = given["Pm"] and,
    with a second machine, Pm2 = given["Pm2"] [pu, each on its machine's base] at the speed
    given["omega"]; ValueError where the two powers do not stand as the stage fractions do."""
    wd = p.wref0 - float(given["omega"])
    high, low = sum(p.fractions(1)), sum(p.fractions(2))
    if p.Sg2 > 0 and "Pm2" in given:
        P1, P2 = float(given["Pm"]) * p.first_base, float(given["Pm2"]) * p.Sg2  # [MVA]
        if not abs(P1 * low - P2 * high) <= 1e-6 * max(abs(P1), abs(P2), 1e-9 * p.Sn):
            raise ValueError(f"IEEEG1: its machines' load-flow powers {P1:.6g} and {P2:.6g} MW do not stand as its "
                             f"high- and low-pressure stage fractions {high:.4g} : {low:.4g} (K1+K3+K5+K7 : "
                             "K2+K4+K6+K8): the turbine cannot start at rest")
        valve = (P1 + P2) / (p.Sn * (high + low))
    else:
        valve = float(given["Pm"]) * p.first_base / (p.Sn * high)
    return np.array([wd, valve, valve, valve, valve, valve]), {"Pref": float(valve - p.K * wd)}


def equilibrium(u, p: IEEEG1Params) -> np.ndarray:
    """The steady state [6] at constant (omega, Pref); ValueError outside the valve limits."""
    omega, Pref = finite_inputs(u, "IEEEG1")
    wd = p.wref0 - omega
    valve = Pref + p.K * wd
    if not p.PMIN <= valve <= p.PMAX:
        raise ValueError(f"IEEEG1: the valve position {valve:.6g} pu at rest lies outside [PMIN, PMAX]")
    return np.array([wd, valve, valve, valve, valve, valve])


INPUTS = (Quantity("omega", "pu", "rotor speed", start=1.0, operating_range=(0.95, 1.05), minimum=0.0),
          Quantity("Pref", "pu", "power reference", start=0.7, operating_range=(0.0, 1.2)))

IEEEG1 = Component(
    name="ieeeg1",
    description="IEEEG1 IEEE Type 1 speed-governing model (PSS/E, ANDES), one machine",
    states=(Quantity("LL_x", "pu", "lead-lag state"),
            Quantity("IAW_y", "pu", "valve position (non-windup limited)"),
            Quantity("L4_y", "pu", "first stage"), Quantity("L5_y", "pu", "second stage"),
            Quantity("L6_y", "pu", "third stage"), Quantity("L7_y", "pu", "fourth stage")),
    inputs=INPUTS,
    outputs=(Quantity("Pm", "pu", "mechanical power of the first machine, its base"),
             Quantity("Pm2", "pu", "mechanical power of the second machine, its base (0: none)")),
    params_type=IEEEG1Params,
    derivatives=derivatives,
    output_equations=outputs,
    equilibrium=equilibrium,
    state_scales=(0.01, 0.2, 0.2, 0.2, 0.2, 0.2),
    reset=reset,
    ports=Ports(inputs=(Link("rotor_speed", "omega"), Link("power_reference", "Pref")),
                outputs=(Link("mechanical_power", "Pm"), Link("second_mechanical_power", "Pm2"))),
    initialisation=Initialisation(("Pref",), _start),
)
