"""Input-signal families of SM4: named, seeded samplers of bus-voltage signals (Vs, theta_vs).

Each family maps points of the unit hypercube (from Latin hypercube sampling) to signals, one
parameter per dimension, each uniform in its range. The paper's `slow` and `fast` families are
exactly section IV-A.2; `step`, `dip`, `ramp`, `zoh` and `mix` are the inputs a co-simulation master
sends (`mix`: levels held for a while, changed now and then, one change in five a fault; `jump`: the
same starting with a change at t = 0, which is how the surrogate FMU meets a jump: it starts a window there).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .signals import Dip, FirstOrder, Piecewise, Ramp, SecondOrder, Signal, held
from .sm4 import SM4

Ranges = dict  # parameter name -> (low, high)

COMPONENT = SM4  # the component whose inputs these families drive
VS_RANGE = SM4.inputs[0].operating_range  # pu, bus voltage levels a window may start from
THETA_RANGE = SM4.inputs[1].operating_range  # rad


@dataclass(frozen=True)
class Family:
    """A parametric signal family: `ranges` [name -> (low, high)] and `build(params, horizon)`."""

    name: str
    ranges: Ranges
    build: Callable[[dict, float], Signal]
    component: object = COMPONENT

    @property
    def dim(self) -> int:
        return len(self.ranges)

    def sample(self, unit: np.ndarray, horizon: float) -> list[Signal]:
        """Signals for unit-cube points unit [n, dim] over a window of `horizon` seconds."""
        unit = np.atleast_2d(unit)
        if unit.shape[1] != self.dim:
            raise ValueError(f"family {self.name!r} takes {self.dim} parameters, got {unit.shape[1]}")
        lows = np.array([r[0] for r in self.ranges.values()])
        highs = np.array([r[1] for r in self.ranges.values()])
        values = lows + unit * (highs - lows)
        return [self.build(dict(zip(self.ranges, map(float, row))), horizon) for row in values]


def bus(Vs, theta_vs, hold: float = 0.0) -> Signal:
    """A signal of SM4's inputs from its bus-voltage magnitude and angle channels."""
    return Signal({"Vs": Vs, "theta_vs": theta_vs}, hold)


def _slow(p, horizon):
    return bus(
        FirstOrder(p["Vs0"], p["k_v"], p["A_v"], p["w_v"], 1.0),
        FirstOrder(p["theta0"], p["k_th"], p["A_th"], p["w_th"], 0.0),
    )


def _fast(p, horizon):
    return bus(
        SecondOrder(p["Vs0"], p["dVs0"], p["zeta_v"], p["wn_v"], 1.0),
        SecondOrder(p["theta0"], p["dtheta0"], p["zeta_th"], p["wn_th"], 0.0),
    )


def _step(p, horizon):
    t_v, t_th = p["t_v"] * horizon, p["t_th"] * horizon
    return bus(
        Piecewise((p["Vs0"], p["Vs1"]), (t_v,)),
        Piecewise((p["theta0"], p["theta0"] + p["jump"]), (t_th,)),
    )


def _dip(p, horizon):
    t_fault = p["t_fault"] * horizon
    t_clear = t_fault + p["duration"]
    return bus(
        Dip(p["Vs0"], p["Vs_fault"], t_fault, p["duration"], p["Vs0"] + p["post_shift"], p["tau"]),
        Piecewise(
            (p["theta0"], p["theta0"] + p["jump"], p["theta0"] + p["jump_post"]), (t_fault, t_clear)
        ),
    )


def _ramp(p, horizon):
    t_v = p["t_v"] * horizon
    t_th = p["t_th"] * horizon
    return bus(
        Ramp(p["Vs0"], p["Vs1"], t_v, t_v + p["len_v"] * horizon),
        Ramp(p["theta0"], p["theta1"], t_th, t_th + p["len_th"] * horizon),
    )


SLOW = Family(
    "slow",
    {"k_v": (1.0, 2.0), "A_v": (0.0, 0.03), "w_v": (0.5, 1.5), "Vs0": VS_RANGE,
     "k_th": (1.0, 3.0), "A_th": (0.0, 0.05), "w_th": (0.1, 0.5), "theta0": THETA_RANGE},
    _slow,
)
FAST = Family(
    "fast",
    {"zeta_v": (0.6, 0.8), "wn_v": (8.0, 12.0), "Vs0": VS_RANGE, "dVs0": (-0.2, 0.2),
     "zeta_th": (0.2, 0.4), "wn_th": (10.0, 18.0), "theta0": THETA_RANGE, "dtheta0": (-0.8, 0.8)},
    _fast,
)
STEP = Family(
    "step",
    {"Vs0": VS_RANGE, "Vs1": VS_RANGE, "t_v": (0.0, 1.0),
     "theta0": THETA_RANGE, "jump": (-0.3, 0.3), "t_th": (0.0, 1.0)},
    _step,
)
DIP = Family(
    "dip",
    {"Vs0": (0.9, 1.1), "Vs_fault": (0.2, 0.9), "t_fault": (0.0, 0.8), "duration": (0.02, 0.3),
     "post_shift": (-0.05, 0.05), "tau": (0.0, 0.2),
     "theta0": THETA_RANGE, "jump": (-0.3, 0.3), "jump_post": (-0.1, 0.1)},
    _dip,
)
RAMP = Family(
    "ramp",
    {"Vs0": VS_RANGE, "Vs1": VS_RANGE, "t_v": (0.0, 0.5), "len_v": (0.05, 1.0),
     "theta0": THETA_RANGE, "theta1": THETA_RANGE, "t_th": (0.0, 0.5), "len_th": (0.05, 1.0)},
    _ramp,
)

def held_levels(rng: np.random.Generator, stop_time: float, dwell=(0.2, 0.8), fault_share: float = 0.2,
                vs_levels=(0.9, 1.1), change_at_start: bool = False) -> Signal:
    """Piecewise-constant bus voltage over [0, stop_time] s: levels held for `dwell` seconds (Vs in
    vs_levels pu; theta_vs moving by up to 0.3 rad within [-0.5, 0.5] rad, at half the changes); a
    `fault_share` of the changes are faults (Vs at 0.2-0.9 pu for 20-200 ms, then a new level).
    change_at_start: the signal starts with a change (a fault or a new level) at t = 0, the way a
    window of the surrogate FMU starts at an input jump."""
    times, vs, theta = [], [float(rng.uniform(*vs_levels))], [float(rng.uniform(-0.3, 0.3))]
    t = 0.0 if change_at_start else float(rng.uniform(*dwell))
    while t < stop_time:
        jump = float(np.clip(theta[-1] + rng.uniform(-0.3, 0.3), *THETA_RANGE))
        if rng.uniform() < fault_share:
            clear = t + float(rng.uniform(0.02, 0.2))
            times += [t, clear]
            vs += [float(rng.uniform(0.2, 0.9)), float(rng.uniform(*vs_levels))]
            theta += [jump, jump]
            t = clear
        else:
            times.append(t)
            vs.append(float(rng.uniform(*vs_levels)))
            theta.append(jump if rng.uniform() < 0.5 else theta[-1])
        t += float(rng.uniform(*dwell))
    if change_at_start:  # the level before t = 0 is never seen: drop it and the breakpoint at 0
        times, vs, theta = times[1:], vs[1:], theta[1:]
    return bus(Piecewise(tuple(vs), tuple(times)), Piecewise(tuple(theta), tuple(times)))


def _mix(p, horizon):
    """held_levels over one window, changing every 5-40% of it, drawn from the seed parameter."""
    rng = np.random.default_rng(int(p["seed"] * 2**31))
    return held_levels(rng, horizon, dwell=(0.05 * horizon, 0.4 * horizon), vs_levels=(0.85, 1.15))


def _jump(p, horizon):
    """_mix with its first change at t = 0, a fault two times in five (drawn from the seed parameter)."""
    rng = np.random.default_rng(int(p["seed"] * 2**31))
    return held_levels(rng, horizon, dwell=(0.05 * horizon, 0.4 * horizon), fault_share=0.4,
                       vs_levels=(0.85, 1.15), change_at_start=True)


MIX = Family("mix", {"seed": (0.0, 1.0)}, _mix)
JUMP = Family("jump", {"seed": (0.0, 1.0)}, _jump)

BASE_FAMILIES = {f.name: f for f in (SLOW, FAST, STEP, DIP, RAMP, MIX, JUMP)}
HOLD_RANGE = (0.001, 0.05)  # s, communication steps a ZOH family holds at (log-uniform)


def zoh(base: str, hold_range: tuple = HOLD_RANGE) -> Family:
    """`base` held piecewise constant at a communication step sampled log-uniformly in hold_range [s]."""
    inner = family(base)
    ranges = {**inner.ranges, "log_hold": (math.log(hold_range[0]), math.log(hold_range[1]))}

    def build(p, horizon):
        hold = math.exp(p.pop("log_hold"))
        return held(inner.build(p, horizon), round(hold, 6))

    return Family(f"zoh-{base}", ranges, build)


def family(name: str) -> Family:
    """A family by name: slow, fast, step, dip, ramp, or zoh-<base> (e.g. zoh-fast)."""
    if name.startswith("zoh-"):
        return zoh(name[4:])
    try:
        return BASE_FAMILIES[name]
    except KeyError:
        known = ", ".join([*BASE_FAMILIES, "zoh-<family>"])
        raise ValueError(f"unknown input family {name!r} (known: {known})") from None
