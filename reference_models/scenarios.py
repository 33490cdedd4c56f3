"""Built-in co-simulation scenarios: one signal of a machine's inputs over a whole run, drawn with a seed.

The machine is the component the input families drive (families.COMPONENT), its inputs found by its
ports (families.MachineInputs): the bus voltage magnitude and angle of its bus port (Vs, theta_vs
for SM4), its mechanical power and field voltage links (Pm, Efd). Below they go by SM4's names.

Bus scenarios move the bus voltage and hold Pm and Efd at their start values (the operating point
of Table I). A bus scenario is a signal of one input family (families.py) sampled over the run's
length instead of one operator window: `slow` and `fast` are the paper's families (their transients
settle within the first seconds), `dip` is a fault (Vs drops to 0.2-0.9 pu for 20-300 ms, then
recovers, with an angle jump), `step` and `ramp` move Vs and theta_vs to new levels somewhere in the
run. `mix` is what a grid tool sends over a long run: levels held for 0.2-0.8 s each (Vs in
[0.9, 1.1] pu, theta_vs moving by up to 0.3 rad within [-0.5, 0.5] rad), one change in five a fault
(Vs down to 0.2-0.9 pu for 20-200 ms).

Scenarios that move the other inputs:
* `governor`: the mix bus voltage, and Pm stepped or ramped (over 0.5-2 s) every 2-4 s, the first
  change after 0.5-2 s, by 10-20 % of its start value each time, within 80-110 % of it (above that
  the mix's lower voltages have no equilibrium and the machine slips poles).
* `drift`: the mix scenario of the same seed seen by a machine whose network turns at a constant
  speed c (|c| in [1, 12] rad/s, drawn after the mix): theta_vs(t) = theta_mix(t) + c t, and the
  machine starts at the mix's rest state turning with it, omega0 = c (Scenario.speed). The machine
  sees its angles only through their differences and its speed through a damping torque (its
  `drift`, reference_models.drift; SM4: delta - theta_vs and D omega), so its torque input carries
  that torque, Pm = Pm_start + D c (for D = 0, the grid's machines, Pm is its start value): then the run is exactly the mix run turned by c t,
  delta_drift(t) = delta_mix(t) + c t and omega_drift(t) = omega_mix(t) + c, and an operator that
  works in its window's frame must give the same errors on both.

Every scenario ends at a bus voltage of at least SETTLED_VS where the machine has an equilibrium at
the final inputs, and in none does the machine lose synchronism (a voltage held far below the lowest
one with an equilibrium for tens of seconds makes it slip poles: a loss of the machine, no test of a
surrogate). The machine starts at rest (in its network's frame for `drift`): at the equilibrium of
the first input value (or, below the lowest bus voltage that has an equilibrium, of that voltage).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .drift import frame_of
from .families import COMPONENT, CONTROL_LEVELS, EFD, EFD_START, PM, PM_START, THETA, VS, family, held_levels, machine
from .ports import machine_inputs
from .signals import Piecewise, Signal, Table
from .simulate import simulate

DEFAULT_PARAMS = COMPONENT.params()
_INDEX = {name: i for i, name in enumerate(COMPONENT.input_names)}

BUS_SCENARIOS = ("slow", "fast", "dip", "step", "ramp", "mix")
SCENARIOS = BUS_SCENARIOS + ("governor", "drift")
# a scenario is redrawn (from the same seed's stream) until its bus voltage ends at or above this [pu]:
# below 0.8809 pu the default machine has no equilibrium at its start Pm, Efd and slowly loses synchronism
SETTLED_VS = 0.9
GOVERNOR_LEVELS = (0.8, 1.1)  # Pm levels of `governor`, as shares of its start value
GOVERNOR_CHANGE = (0.1, 0.2)  # size of one change of Pm, as a share of its start value
DRIFT_SPEEDS = (1.0, 12.0)  # rad/s, |c| of `drift`
MAX_DRAWS = 200  # redraws before a scenario is refused for this machine


@dataclass(frozen=True)
class Scenario:
    """A named input signal over [0, stop_time] s, the machine (its parameters) it drives and the
    speed [rad/s] its network's angles drift at (the machine starts turning with it; 0: at rest)."""

    name: str
    seed: int
    stop_time: float
    signal: Signal
    params: object = DEFAULT_PARAMS
    speed: float = 0.0
    component: object = COMPONENT

    def inputs(self, times: np.ndarray) -> np.ndarray:
        """The machine's inputs [T, n_u] at times [T] (s), in its input order (SM4: Vs [pu],
        theta_vs [rad], Pm [pu], Efd [pu])."""
        return np.asarray(self.signal(np.asarray(times, dtype=float)), dtype=float)

    def initial_state(self) -> np.ndarray:
        """The machine at rest [n_x] under the first input value, in the frame turning at `speed`:
        the state at rest there with its torque input less the damping torque (SM4: Pm - D speed),
        and its speed state raised by `speed` (in the speed's units: divided by the frame's speed scale)."""
        component = self.component
        frame = frame_of(component.drift, self.params)
        c = self.speed / frame.speed_scale  # SM4: rad/s, scale 1
        u0 = self.inputs(np.array([0.0]))[0] - c * frame.input_torques(component.n_inputs)
        x0 = component.rest_state(u0, self.params)
        x0[frame.speed_state] += c
        return x0


def rest_state(Vs: float, theta_vs: float, p=DEFAULT_PARAMS, Pm: float = PM_START,
               Efd: float = EFD_START) -> np.ndarray:
    """The machine p at rest [n_x] at constant bus voltage Vs [pu] at angle theta_vs [rad],
    mechanical power Pm and field voltage Efd [pu] (its other inputs at their start values): the
    equilibrium, or where there is none the state at rest it declares (SM4: Vs raised to the lowest
    voltage that has one)."""
    given = {VS: Vs, THETA: theta_vs, PM: Pm, EFD: Efd}
    return COMPONENT.rest_state(tuple(given.get(q.name, q.start) for q in COMPONENT.inputs), p)


def scenario(name: str, seed: int = 0, stop_time: float = 10.0, params=DEFAULT_PARAMS,
             operating: tuple | None = None, component=COMPONENT) -> Scenario:
    """The built-in scenario `name` (one of SCENARIOS) drawn with `seed` over stop_time seconds for
    the machine `params` at the operating point `operating` = (Pm, Efd) [pu] (default: their start
    values), which the scenarios hold or move from. component: the machine on a bus it drives (any
    component with a bus port and the mechanical_power and field_voltage links; default SM4, whose
    parameters `params` must then be): the same draws, its inputs found by its ports, any other input
    held at its start value. ValueError for an unknown name, a stop time that is not positive, a
    component that is no machine on a bus, or a machine that no draw keeps in synchronism."""
    if name not in SCENARIOS:
        raise ValueError(f"unknown scenario {name!r} (built in: {', '.join(SCENARIOS)})")
    if not stop_time > 0:
        raise ValueError(f"stop time must be positive, got {stop_time}")
    if component is not COMPONENT:
        machine_inputs(component)  # PortError (a ValueError) where it is no machine on a bus
        if component.drift is None:
            raise ValueError(f"the {component.name} component declares no rotor angle and speed (drift): the "
                             "scenarios judge synchronism by them")
        if operating is None:
            wiring, start = machine_inputs(component), {q.name: q.start for q in component.inputs}
            operating = (start[wiring.power], start[wiring.field])
    stop_time = float(stop_time)
    pm, efd = (PM_START, EFD_START) if operating is None else (float(operating[0]), float(operating[1]))
    if name == "mix":
        return Scenario(name, seed, stop_time, _for(held_levels(np.random.default_rng(seed), stop_time, Pm=pm,
                                                                Efd=efd), component), params, component=component)
    if name == "drift":
        return _drift(seed, stop_time, params, pm, efd, component)
    rng = np.random.default_rng(seed)
    for _ in range(MAX_DRAWS):  # a run must end where the machine has an equilibrium (see SETTLED_VS), in step
        signal = _governor(rng, stop_time, pm, efd) if name == "governor" else _bus(name, rng, stop_time, pm, efd)
        drawn = Scenario(name, seed, stop_time, _for(signal, component), params, component=component)
        if ends_settled(drawn) and keeps_synchronism(drawn):
            return drawn
    raise ValueError(f"no draw of scenario {name!r} (seed {seed}) keeps this machine in synchronism "
                     f"over {stop_time:g} s")


def _for(signal: Signal, component) -> Signal:
    """The families' signal (channels by SM4's input names) as the inputs of `component`, a machine
    on a bus: each channel to the input its ports give that role, any other input held at its start."""
    if component is COMPONENT:
        return signal
    ours, theirs = machine_inputs(COMPONENT), machine_inputs(component)
    role = {ours.magnitude: theirs.magnitude, ours.angle: theirs.angle, ours.power: theirs.power,
            ours.field: theirs.field}
    channels = {role[n]: c for n, c in signal.channels.items() if n in role}
    return Signal({q.name: channels.get(q.name) or Piecewise((float(q.start),), ()) for q in component.inputs},
                  signal.hold, signal.x0)


def _bus(name: str, rng: np.random.Generator, stop_time: float, pm: float, efd: float) -> Signal:
    """A signal of the bus family `name` over the whole run, Pm and Efd held at pm, efd.
    Only the bus parameters are drawn (from rng, in the family's order), so a seed gives the bus
    voltage it gave before Pm and Efd were inputs."""
    fam = family(name)
    held = [i for i, key in enumerate(fam.ranges) if key in CONTROL_LEVELS]
    free = [i for i in range(fam.dim) if i not in held]
    unit = np.zeros((1, fam.dim))
    unit[0, free] = rng.uniform(size=len(free))
    levels = {PM: (pm, pm), EFD: (efd, efd)}
    return fam.sample(unit, stop_time, levels)[0]


def _governor(rng: np.random.Generator, stop_time: float, pm: float, efd: float) -> Signal:
    """The mix bus voltage with Pm stepped and ramped from pm (see the module docstring), Efd held."""
    bus = held_levels(rng, stop_time, Pm=pm, Efd=efd)
    low, high = (pm * share for share in GOVERNOR_LEVELS)
    times, values = [0.0], [pm]
    t = float(rng.uniform(0.5, 2.0))
    while t < stop_time:
        change = pm * float(rng.uniform(*GOVERNOR_CHANGE)) * (1.0 if rng.uniform() < 0.5 else -1.0)
        level = values[-1] + change
        if not low <= level <= high:
            level = values[-1] - change
        length = float(rng.uniform(0.5, 2.0)) if rng.uniform() < 0.5 else 0.0  # a ramp or a step
        times += [t, t + length]
        values += [values[-1], float(np.clip(level, low, high))]
        t += length + float(rng.uniform(2.0, 4.0))
    return machine(bus.channels[VS], bus.channels[THETA], Table(tuple(times), tuple(values)), efd)


def _drift(seed: int, stop_time: float, params, pm: float, efd: float, component=COMPONENT) -> Scenario:
    """The mix of `seed` in a network turning at c [rad/s] (see the module docstring)."""
    rng = np.random.default_rng(seed)
    mix = held_levels(rng, stop_time)
    c = float(rng.uniform(*DRIFT_SPEEDS)) * (1.0 if rng.uniform() < 0.5 else -1.0)
    theta = mix.channels[THETA]  # Piecewise: values[k] before times[k], values[k + 1] from it on
    times, values = [0.0], [theta.values[0]]
    for k, jump in enumerate(theta.times):
        if 0.0 < jump < stop_time:
            times += [jump, jump]
            values += [theta.values[k] + c * jump, theta.values[k + 1] + c * jump]
    times.append(stop_time)
    values.append(theta(stop_time) + c * stop_time)
    torque = c * _torque(params, component)  # the damping torque of the extra speed, which the turbine supplies
    signal = machine(mix.channels[VS], Table(tuple(times), tuple(values)), pm + torque, efd)
    return Scenario("drift", seed, stop_time, _for(signal, component), params, speed=c, component=component)


def _torque(params, component=COMPONENT) -> float:
    """The damping torque coefficient [pu / (rad/s)] the mechanical power input carries in a frame
    turning at 1 rad/s (SM4: D; a machine whose speed is in other units: per its speed scale), from
    the machine's drift."""
    frame = frame_of(component.drift, params)
    power = component.input_names.index(machine_inputs(component).power)
    return float(frame.input_torques(component.n_inputs)[power]) / frame.speed_scale


def ends_settled(s: Scenario) -> bool:
    """True if the run ends at a bus voltage of at least SETTLED_VS where the machine has an
    equilibrium at the final inputs (Pm less the damping torque of the scenario's speed)."""
    names, wiring = s.component.input_names, machine_inputs(s.component)
    u = s.inputs(np.array([s.stop_time]))[0]
    if not u[names.index(wiring.magnitude)] >= SETTLED_VS:
        return False
    u[names.index(wiring.power)] = u[names.index(wiring.power)] - _torque(s.params, s.component) * s.speed
    try:
        s.component.steady_state(u, s.params)
    except ValueError:
        return False
    return True


def keeps_synchronism(s: Scenario, every: float = 0.05) -> bool:
    """True if the rotor angle (the machine's drift's first angle state) stays within pi of the bus
    angle over the whole run (RK45, checked every `every` seconds): the machine slips no pole."""
    t = np.linspace(0.0, s.stop_time, int(round(s.stop_time / every)) + 1)
    component = s.component
    x = simulate(s.initial_state(), s.signal, t, s.params, component=component)
    angle = x[:, component.drift.angle_states[0]] - s.inputs(t)[:, component.input_names.index(
        machine_inputs(component).angle)]
    return bool(np.all(np.abs(angle) < np.pi))
