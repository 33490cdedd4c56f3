"""Input-signal families of a machine on a bus: named, seeded samplers of its input signals.

The families drive a component that declares (reference_models.ports) a bus port and the input
links `mechanical_power` and `field_voltage`: the four channels are its bus voltage magnitude and
angle, its mechanical power and its field voltage, whatever its variables are called (SM4: Vs,
theta_vs, Pm, Efd; ports.MachineInputs). Any further input of the component holds its start value.

Each family maps points of the unit hypercube (from Latin hypercube sampling) to signals, one
parameter per dimension, each uniform in its range. A range is either numbers (low, high) or the
name of an input, which stands for that input's level range: the component's operating range
unless a dataset preset gives its own (`levels`, e.g. one machine's dispatch and field voltages).

Bus families move the bus voltage and hold Pm and Efd at levels drawn from their ranges: the paper's
`slow` and `fast` are exactly section IV-A.2; `step`, `dip`, `ramp`, `zoh` and `mix` are the inputs
a co-simulation master sends (`mix`: levels held for a while, changed now and then, one change in
five a fault; `jump`: the same starting with a change at t = 0, which is how the surrogate FMU meets
a jump: it starts a window there). Control families move Pm and Efd: `governor` (steps and ramps of
Pm), `exciter` (a fault with the field forced towards a ceiling and returning after it, and
set-point steps of Efd). `drift` is a faulted bus seen from a frame that turns with the network:
the bus angle as a zero-order-hold master delivers a drifting network's angle (a sawtooth, see
signals.Sawtooth) with the exciter's field response. `network` windows are recorded from the machine
itself in a closed loop with its exciter and a network that accelerates in a fault (smib.py): the bus
angle swings with the machine, and the window's initial state comes with the signal (Signal.x0).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Callable

import numpy as np

from . import smib
from .ports import machine_inputs
from .signals import Dip, FirstOrder, Forcing, Piecewise, Ramp, Sawtooth, SecondOrder, Signal, Table, held
from .sm4 import SM4

Ranges = dict  # parameter name -> (low, high), or the name of the input whose level range it takes
COMPONENT = SM4  # the component whose inputs these families drive
WIRING = machine_inputs(COMPONENT)
VS, THETA, PM, EFD = WIRING.magnitude, WIRING.angle, WIRING.power, WIRING.field  # its input names
_INPUT = {q.name: q for q in COMPONENT.inputs}
VS_RANGE = _INPUT[VS].operating_range  # pu, bus voltage levels a window may start from
THETA_RANGE = _INPUT[THETA].operating_range  # rad
PM_START, EFD_START = _INPUT[PM].start, _INPUT[EFD].start  # pu: the operating point the inputs start at


def default_levels(component=COMPONENT) -> dict:
    """{input name: (low, high)}: the operating ranges of the component's inputs."""
    return {q.name: tuple(q.operating_range) for q in component.inputs}


@dataclass(frozen=True)
class Family:
    """A parametric signal family: `ranges` [name -> (low, high) or input name] and
    `build(params, horizon)`."""

    name: str
    ranges: Ranges
    build: Callable[[dict, float], Signal]
    component: object = COMPONENT
    needs_machine: bool = False  # build(params, horizon, machine): the signal depends on the machine

    @property
    def dim(self) -> int:
        return len(self.ranges)

    def bounds(self, levels: dict | None = None) -> tuple:
        """(lows [dim], highs [dim]) with input names resolved to their level ranges."""
        levels = {**default_levels(self.component), **(levels or {})}
        pairs = [levels[r] if isinstance(r, str) else r for r in self.ranges.values()]
        return np.array([p[0] for p in pairs], dtype=float), np.array([p[1] for p in pairs], dtype=float)

    def sample(self, unit: np.ndarray, horizon: float, levels: dict | None = None, machine=None) -> list[Signal]:
        """Signals for unit-cube points unit [n, dim] over a window of `horizon` seconds, with input
        levels from `levels` [input name -> (low, high)] (default: the operating ranges), for the
        component's parameters `machine` (default: its defaults; only families that need_machine
        use them)."""
        unit = np.atleast_2d(unit)
        if unit.shape[1] != self.dim:
            raise ValueError(f"family {self.name!r} takes {self.dim} parameters, got {unit.shape[1]}")
        lows, highs = self.bounds(levels)
        values = lows + unit * (highs - lows)
        rows = [dict(zip(self.ranges, map(float, row))) for row in values]
        if self.needs_machine:
            machine = self.component.params() if machine is None else machine
            return [self.build(row, horizon, machine) for row in rows]
        return [self.build(row, horizon) for row in rows]


def machine(Vs, theta_vs, Pm, Efd, hold: float = 0.0) -> Signal:
    """A signal of the machine's inputs from its four channels: bus voltage magnitude and angle,
    mechanical power, field voltage (a number: held constant); channels in the component's input
    order, any other input held at its start value."""
    def channel(c):
        return Piecewise((float(c),), ()) if isinstance(c, (int, float)) else c

    given = {VS: Vs, THETA: theta_vs, PM: Pm, EFD: Efd}
    return Signal({q.name: channel(given.get(q.name, q.start)) for q in COMPONENT.inputs}, hold)


def bus(Vs, theta_vs, Pm: float = PM_START, Efd: float = EFD_START, hold: float = 0.0) -> Signal:
    """A signal of the machine's inputs from its bus-voltage channels, mechanical power and field
    voltage held (default: their start values)."""
    return machine(Vs, theta_vs, Pm, Efd, hold)


CONTROL_LEVELS = {"Pm": PM, "Efd": EFD}  # the held mechanical power and field levels of the bus families


def _slow(p, horizon):
    return bus(
        FirstOrder(p["Vs0"], p["k_v"], p["A_v"], p["w_v"], 1.0),
        FirstOrder(p["theta0"], p["k_th"], p["A_th"], p["w_th"], 0.0), p["Pm"], p["Efd"],
    )


def _fast(p, horizon):
    return bus(
        SecondOrder(p["Vs0"], p["dVs0"], p["zeta_v"], p["wn_v"], 1.0),
        SecondOrder(p["theta0"], p["dtheta0"], p["zeta_th"], p["wn_th"], 0.0), p["Pm"], p["Efd"],
    )


def _step(p, horizon):
    t_v, t_th = p["t_v"] * horizon, p["t_th"] * horizon
    return bus(
        Piecewise((p["Vs0"], p["Vs1"]), (t_v,)),
        Piecewise((p["theta0"], p["theta0"] + p["jump"]), (t_th,)), p["Pm"], p["Efd"],
    )


def _dip(p, horizon):
    t_fault = p["t_fault"] * horizon
    t_clear = t_fault + p["duration"]
    return bus(
        Dip(p["Vs0"], p["Vs_fault"], t_fault, p["duration"], p["Vs0"] + p["post_shift"], p["tau"]),
        Piecewise(
            (p["theta0"], p["theta0"] + p["jump"], p["theta0"] + p["jump_post"]), (t_fault, t_clear)
        ), p["Pm"], p["Efd"],
    )


def _ramp(p, horizon):
    t_v = p["t_v"] * horizon
    t_th = p["t_th"] * horizon
    return bus(
        Ramp(p["Vs0"], p["Vs1"], t_v, t_v + p["len_v"] * horizon),
        Ramp(p["theta0"], p["theta1"], t_th, t_th + p["len_th"] * horizon), p["Pm"], p["Efd"],
    )


SLOW = Family(
    "slow",
    {"k_v": (1.0, 2.0), "A_v": (0.0, 0.03), "w_v": (0.5, 1.5), "Vs0": VS,
     "k_th": (1.0, 3.0), "A_th": (0.0, 0.05), "w_th": (0.1, 0.5), "theta0": THETA_RANGE, **CONTROL_LEVELS},
    _slow,
)
FAST = Family(
    "fast",
    {"zeta_v": (0.6, 0.8), "wn_v": (8.0, 12.0), "Vs0": VS, "dVs0": (-0.2, 0.2),
     "zeta_th": (0.2, 0.4), "wn_th": (10.0, 18.0), "theta0": THETA_RANGE, "dtheta0": (-0.8, 0.8), **CONTROL_LEVELS},
    _fast,
)
STEP = Family(
    "step",
    {"Vs0": VS, "Vs1": VS, "t_v": (0.0, 1.0),
     "theta0": THETA_RANGE, "jump": (-0.3, 0.3), "t_th": (0.0, 1.0), **CONTROL_LEVELS},
    _step,
)
DIP = Family(
    "dip",
    {"Vs0": (0.9, 1.1), "Vs_fault": (0.2, 0.9), "t_fault": (0.0, 0.8), "duration": (0.02, 0.3),
     "post_shift": (-0.05, 0.05), "tau": (0.0, 0.2),
     "theta0": THETA_RANGE, "jump": (-0.3, 0.3), "jump_post": (-0.1, 0.1), **CONTROL_LEVELS},
    _dip,
)
RAMP = Family(
    "ramp",
    {"Vs0": VS, "Vs1": VS, "t_v": (0.0, 0.5), "len_v": (0.05, 1.0),
     "theta0": THETA_RANGE, "theta1": THETA_RANGE, "t_th": (0.0, 0.5), "len_th": (0.05, 1.0), **CONTROL_LEVELS},
    _ramp,
)

def held_levels(rng: np.random.Generator, stop_time: float, dwell=(0.2, 0.8), fault_share: float = 0.2,
                vs_levels=(0.9, 1.1), change_at_start: bool = False, Pm: float = PM_START,
                Efd: float = EFD_START) -> Signal:
    """Piecewise-constant bus voltage over [0, stop_time] s: levels held for `dwell` seconds (Vs in
    vs_levels pu; theta_vs moving by up to 0.3 rad within [-0.5, 0.5] rad, at half the changes); a
    `fault_share` of the changes are faults (Vs at 0.2-0.9 pu for 20-200 ms, then a new level).
    change_at_start: the signal starts with a change (a fault or a new level) at t = 0, the way a
    window of the surrogate FMU starts at an input jump. Pm and Efd [pu] are held."""
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
    return bus(Piecewise(tuple(vs), tuple(times)), Piecewise(tuple(theta), tuple(times)), Pm, Efd)


def _mix(p, horizon):
    """held_levels over one window, changing every 5-40% of it, drawn from the seed parameter."""
    rng = np.random.default_rng(int(p["seed"] * 2**31))
    return held_levels(rng, horizon, dwell=(0.05 * horizon, 0.4 * horizon), vs_levels=(0.85, 1.15),
                       Pm=p["Pm"], Efd=p["Efd"])


def _jump(p, horizon):
    """_mix with its first change at t = 0, a fault two times in five (drawn from the seed parameter)."""
    rng = np.random.default_rng(int(p["seed"] * 2**31))
    return held_levels(rng, horizon, dwell=(0.05 * horizon, 0.4 * horizon), fault_share=0.4,
                       vs_levels=(0.85, 1.15), change_at_start=True, Pm=p["Pm"], Efd=p["Efd"])


MIX = Family("mix", {"seed": (0.0, 1.0), **CONTROL_LEVELS}, _mix)
JUMP = Family("jump", {"seed": (0.0, 1.0), **CONTROL_LEVELS}, _jump)


def _field(p, horizon) -> Forcing:
    """The exciter's field through the fault of p: forced up by `rise` towards its ceiling, then
    returning to E_post."""
    t_fault = p["t_fault"] * horizon
    return Forcing(p["E0"], p["E0"] + p["rise"], t_fault, p["duration"], p["tau_rise"], p["E_post"], p["tau_return"])


def _fault_voltage(p, horizon) -> Dip:
    """The bus voltage of a fault at t_fault for `duration`."""
    return Dip(p["Vs0"], p["Vs_fault"], p["t_fault"] * horizon, p["duration"], p["Vs0"] + p["post_shift"], p["tau"])


def _governor(p, horizon):
    t_p = p["t_p"] * horizon
    return machine(
        p["Vs0"], Piecewise((p["theta0"], p["theta0"] + p["jump"]), (p["t_th"] * horizon,)),
        Ramp(p["P0"], p["P1"], t_p, t_p + p["len_p"] * horizon), p["Efd"],
    )


def _exciter(p, horizon):
    t_fault = p["t_fault"] * horizon
    theta = Piecewise((p["theta0"], p["theta0"] + p["jump"], p["theta0"] + p["jump_post"]),
                      (t_fault, t_fault + p["duration"]))
    return machine(_fault_voltage(p, horizon), theta, p["Pm"], _field(p, horizon))


def _avr(p, horizon):
    t_e = p["t_e"] * horizon
    return machine(p["Vs0"], p["theta0"], p["Pm"], Forcing(p["E0"], p["E0"], t_e, 0.0, 1.0, p["E1"], p["tau_e"]))


def _drift(p, horizon):
    return machine(_fault_voltage(p, horizon), Sawtooth(p["theta0"], p["rate"], round(math.exp(p["log_period"]), 6)), p["Pm"],
                   _field(p, horizon))


FAULT = {"Vs0": VS, "Vs_fault": (0.0, 0.9), "t_fault": (0.0, 0.7), "duration": (0.02, 0.25),
         "post_shift": (-0.05, 0.05), "tau": (0.0, 0.2)}
FIELD = {"E0": EFD, "rise": (0.0, 4.0), "tau_rise": (0.05, 0.5), "E_post": EFD, "tau_return": (0.2, 2.0)}
GOVERNOR = Family(
    "governor",
    {"Vs0": VS, "theta0": THETA_RANGE, "jump": (-0.2, 0.2), "t_th": (0.0, 1.0),
     "P0": PM, "P1": PM, "t_p": (0.0, 0.8), "len_p": (0.001, 1.0), "Efd": EFD},
    _governor,
)
EXCITER = Family(
    "exciter",
    {**FAULT, "theta0": THETA_RANGE, "jump": (-0.5, 0.5), "jump_post": (-0.2, 0.2), "Pm": PM, **FIELD},
    _exciter,
)
AVR = Family(
    "avr",
    {"Vs0": VS, "theta0": THETA_RANGE, "Pm": PM, "E0": EFD, "E1": EFD, "t_e": (0.0, 0.8),
     "tau_e": (0.05, 1.0)},
    _avr,
)
DRIFT = Family(
    "drift",
    {**FAULT, "theta0": THETA_RANGE, "rate": (-13.0, 13.0), "log_period": (math.log(0.002), math.log(0.02)),
     "Pm": PM, **FIELD},
    _drift,
)

NETWORK_JITTER = {"d_delta": (-0.05, 0.05), "d_omega": (-0.25, 0.25), "d_Ed_p": (-0.05, 0.05), "d_Eq_p": (-0.05, 0.05)}
# rad, rad/s, pu, pu: how far a `network` window's initial state lies off the recorded loop


def _network(p, horizon, machine):
    x0, signal = smib.record(machine, p["E"], p["Vt0"], p["Xe"], p["P0"], p["t_fault"], p["duration"], p["Xf"],
                             p["trip"], p["accel"], p["t0"], horizon)
    # the window starts a little off the loop's state: a co-simulation starts each window from its own
    # last state, and (for Xq = Xq_p, where the loop holds Ed_p at 0) the operator must see the
    # states return, not only the loop's path
    jitter = np.array([p["d_delta"], p["d_omega"], p["d_Ed_p"], p["d_Eq_p"]])
    return replace(signal, x0=tuple(float(v) for v in np.asarray(x0) + jitter))


NETWORK = Family(
    "network",
    {"E": (0.95, 1.2), "Vt0": (0.98, 1.15), "Xe": (0.05, 0.6), "P0": PM, "t_fault": (0.0, 1.0),
     "duration": (0.03, 0.25), "Xf": (0.0, 0.3), "trip": (0.0, 0.8), "accel": (0.0, 30.0), "t0": (0.0, 2.0),
     **NETWORK_JITTER},
    _network,
    needs_machine=True,
)

# The `case-<name>` families: windows recorded from a shipped grid case (reference_models/grid) run
# monolithically through faults at each of its buses. A run per (bus, clearing time, fault
# impedance, trip): the fault from CASE_FAULT_START_S to that plus the clearing time, with no trip or
# with one circuit of each corridor at the faulted bus opened at the clearing (Network.trips_at).
# Clearing times reach 700 ms, past the CCTs of the shipped cases' faults (kundur: 320-490 ms with a
# trip, 560-660 ms at its buses 8 and 9 without), so the windows cover the long faults a CCT
# bisection runs. Every other clearing time carries the case's own events (as `grid run` and `grid
# cct` apply them by default: kundur opens 8-9:2 at 2 s, into the swings), the rest go without (as
# --no-case-events and benchmarks/cases_cct.py run); where the case's events refuse a contingency
# (e.g. its trip and theirs would cut the network apart), that run goes without them. Each run
# lasts CASE_STOP_S (cut where two rotor angles get pi apart), rows every CASE_SAMPLE_S s and both
# sides of each event; the window starts at one of the events (as a surrogate FMU's window does at an
# input jump) a share CASE_EVENT_SHARE of the time, else anywhere in the run; its initial state is the
# unit's state there, moved by up to CASE_JITTER times the component's state scales (a co-simulation
# starts each window from its own last state); its inputs are the unit's machine inputs as recorded.
CASE_CLEARING_S = tuple(round(0.05 * k, 2) for k in range(1, 15))  # s: 0.05, 0.1, ..., 0.7
CASE_FAULT_IMPEDANCES = (1e-4j, 0.05j)  # pu: bolted, and a fault that leaves some voltage
CASE_FAULT_START_S, CASE_STOP_S, CASE_SAMPLE_S = 0.5, 4.0, 0.005
CASE_EVENT_SHARE, CASE_JITTER = 0.3, 0.1


def case_trips(network, bus: int) -> tuple:
    """None (no trip) and one branch of each corridor at `bus` that may open (parallel circuits
    between the same two buses count once)."""
    corridors = {}
    for name in network.trips_at(bus):
        branch = network.branch(name)
        corridors.setdefault(frozenset((branch.from_bus, branch.to_bus)), name)
    return (None, *corridors.values())


def case_contingencies(case) -> list:
    """The contingencies (reference_models.grid.contingency) the `case-` family of `case` records:
    per bus, trip, clearing time and fault impedance one, the case's own events included at every
    other clearing time (see CASE_CLEARING_S)."""
    from .grid.contingency import Contingency

    network = case.network

    opened_by_events = tuple(e.branch for e in case.events if e.kind == "branch" and e.status == 0)
    whole = len(network.islands())

    def contingency(bus, trip, k, z):
        args = (bus, CASE_FAULT_START_S + CASE_CLEARING_S[k], trip, CASE_FAULT_START_S, z, network)
        apart = trip is not None and len(network.islands(opened_by_events + (trip,))) > whole
        if k % 2 == 1 and case.events and not apart:  # not where both together cut the network apart
            try:
                return Contingency(*args, case.events)
            except ValueError:  # the case's events and this contingency exclude each other
                pass
        return Contingency(*args)

    return [contingency(bus, trip, k, z) for bus in network.buses for trip in case_trips(network, bus)
            for k in range(len(CASE_CLEARING_S)) for z in CASE_FAULT_IMPEDANCES]


_CASE_RUNS: dict = {}  # (case name, contingency index) -> GridResult: each run serves many windows


@lru_cache(maxsize=None)
def _shipped_case_contingencies(name: str) -> tuple:
    """case_contingencies of the shipped case `name`, built once (ieee39's take seconds)."""
    from .grid.case import shipped_case

    return tuple(case_contingencies(shipped_case(name)))


def _case_run(name: str, index: int):
    if (name, index) not in _CASE_RUNS:
        from .grid.case import shipped_case
        from .grid.monolithic import System, simulate

        contingency = _shipped_case_contingencies(name)[index]
        _CASE_RUNS[name, index] = simulate(System(shipped_case(name)), contingency, stop=CASE_STOP_S, step=CASE_SAMPLE_S,
                                           rtol=1e-8, atol=1e-10, event_rows=True, stop_at_loss=True)
    return _CASE_RUNS[name, index]


def case_units(case, component, machine) -> list:
    """Indices of the units of `case` whose machine is `component` with the parameters `machine`."""
    return [k for k, u in enumerate(case.units) if u.machine.component is component and u.machine.params == machine]


def case_family(name: str) -> Family:
    """The `case-<name>` family of the shipped case `name` (see CASE_CLEARING_S): windows of the
    units whose machine has the dataset's component parameters."""
    from .grid.case import shipped_case

    case = shipped_case(name)
    component = case.units[0].machine.component
    runs = len(_shipped_case_contingencies(name))

    def build(p, horizon, machine):
        units = case_units(case, component, machine)
        if not units:
            raise ValueError(f"no unit of case {name} has this machine's parameters")
        k = units[min(int(p["unit"] * len(units)), len(units) - 1)]
        result = _case_run(name, min(int(p["run"] * runs), runs - 1))
        t = result.time
        last = float(t[-1]) - horizon
        events = [e for e, _ in result.events if e <= last]
        if p["t0"] < CASE_EVENT_SHARE and events:
            t0 = events[min(int(p["t0"] / CASE_EVENT_SHARE * len(events)), len(events) - 1)]
        else:
            t0 = max(last, 0.0) * (p["t0"] - CASE_EVENT_SHARE) / (1.0 - CASE_EVENT_SHARE) if events else max(last, 0.0) * p["t0"]
        start = int(np.nonzero(t <= t0 + 1e-12)[0][-1])  # the row after an event at t0
        stop = int(np.searchsorted(t, t0 + horizon, side="right"))
        rows = slice(start, min(stop + 1, len(t)))
        times = tuple(float(v) for v in np.maximum(t[rows] - t[start], 0.0))
        channels = {q.name: Table(times, tuple(float(v) for v in result.machine_inputs[q.name][rows, k]))
                    for q in component.inputs}
        rng = np.random.default_rng(int(p["jitter"] * 2**31))
        x0 = np.array([result.states[n][start, k] for n in component.state_names])
        x0 = x0 + CASE_JITTER * np.asarray(component.state_scales) * rng.uniform(-1.0, 1.0, x0.shape)
        return Signal(channels, 0.0, tuple(float(v) for v in x0))

    return Family(f"case-{name}", {"run": (0.0, 1.0), "unit": (0.0, 1.0), "t0": (0.0, 1.0), "jitter": (0.0, 1.0)},
                  build, component, needs_machine=True)


BASE_FAMILIES = {f.name: f for f in (SLOW, FAST, STEP, DIP, RAMP, MIX, JUMP, GOVERNOR, EXCITER, AVR, DRIFT, NETWORK)}
HOLD_RANGE = (0.001, 0.05)  # s, communication steps a ZOH family holds at (log-uniform)


def zoh(base: str, hold_range: tuple = HOLD_RANGE) -> Family:
    """`base` held piecewise constant at a communication step sampled log-uniformly in hold_range [s]."""
    inner = family(base)
    ranges = {**inner.ranges, "log_hold": (math.log(hold_range[0]), math.log(hold_range[1]))}

    def build(p, horizon, *machine):
        hold = math.exp(p.pop("log_hold"))
        return held(inner.build(p, horizon, *machine), round(hold, 6))

    return Family(f"zoh-{base}", ranges, build, inner.component, inner.needs_machine)


def family(name: str) -> Family:
    """A family by name (BASE_FAMILIES), or zoh-<base> (e.g. zoh-fast)."""
    if name.startswith("zoh-"):
        return zoh(name[4:])
    if name.startswith("case-"):
        from .grid.case import CaseError

        try:
            return case_family(name[5:])
        except CaseError as exc:
            raise ValueError(f"unknown input family {name!r}: {exc}") from None
    try:
        return BASE_FAMILIES[name]
    except KeyError:
        known = ", ".join([*BASE_FAMILIES, "zoh-<family>", "case-<shipped case>"])
        raise ValueError(f"unknown input family {name!r} (known: {known})") from None
