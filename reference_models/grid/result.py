"""A grid simulation's result, the same for the monolithic reference and the co-simulation master.

Rows: one per output time (rows at an event time: the state after it, and with `event_rows` also
the one before it, left limit first). Per unit arrays [n, units] in generator order, per bus
[n, buses] in bus order; angles in rad, speeds rad/s deviation.

`states` holds every device state of the units by its variable name, [n, units] (NaN for a unit
without that state), as the devices' components define them (a standard machine's speed in pu,
1 = synchronous); they read as attributes too (`result.delta`). The result file's first columns
are fixed by the grid's command-line contract (`GridResult.columns(case)`): per unit the rotor
angle `delta_<bus>` [rad], the speed `omega_<bus>` [rad/s deviation from synchronous] and the
field voltage `Efd_<bus>` [pu] (`delta_<bus>_<k>` ... where a bus holds several units, k 1-based
in the case's unit order), then `V_<bus>` [pu] for every bus. `speed_deviation` and
`field_voltage` give those two per unit, decided from the machine's component (the unit of its
speed state, its field-voltage input link), never from a component's name. A run is stable when
no two machines' rotor angles (`ROTOR_ANGLE`) are pi apart.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import math

import numpy as np

ROTOR_ANGLE = "delta"
SPEED = "omega"  # the machines' speed state, where the component links no rotor_speed output
CSV_STATES = ("delta", "omega", "Efd")


def unit_labels(gen_buses) -> tuple:
    """The column suffix of each unit: "<bus>", or "<bus>_<k>" (k 1-based in unit order) where a bus
    holds several units."""
    count = {b: list(gen_buses).count(b) for b in gen_buses}
    seen = {}
    labels = []
    for b in gen_buses:
        seen[b] = seen.get(b, 0) + 1
        labels.append(f"{b}_{seen[b]}" if count[b] > 1 else f"{b}")
    return tuple(labels)


def _speed_state(component) -> str:
    ports = component.ports
    linked = ports.output("rotor_speed") if ports is not None else None
    return linked if linked in component.state_names else SPEED


def speed_deviation(result, case) -> np.ndarray:
    """The machines' speed deviation from synchronous [rad/s], [n, units]: a speed state in pu
    (1 = synchronous) becomes (omega - 1) * 2 pi fn (fn: the machine's own parameter where it has
    one, else the case's frequency), one in rad/s is taken as it is (a deviation); NaN for a unit
    whose machine has no speed state. ValueError for a speed in another unit."""
    n = len(result.time)
    out = np.full((n, len(case.units)), np.nan)
    for k, unit in enumerate(case.units):
        component = unit.machine.component
        name = _speed_state(component)
        quantity = next((q for q in component.states if q.name == name), None)
        if quantity is None or name not in result.states:
            continue
        x = result.states[name][:, k]
        if quantity.unit == "pu":
            fn = float(getattr(unit.machine.params, "fn", case.network.f_hz))
            out[:, k] = (x - 1.0) * 2.0 * math.pi * fn
        elif quantity.unit == "rad/s":
            out[:, k] = x
        else:
            raise ValueError(f"the speed {name} of {component.name} is in {quantity.unit!r}, neither pu nor rad/s")
    return out


def field_voltage(result, case) -> np.ndarray:
    """Each unit's field voltage [pu], [n, units]: the state `Efd` where a device of the unit has it,
    else the machine's field-voltage input (its `field_voltage` link: an exciter's output, or held
    at its start where the unit has no exciter); NaN where neither is in the result."""
    n = len(result.time)
    out = np.full((n, len(case.units)), np.nan)
    for k, unit in enumerate(case.units):
        state = result.states.get("Efd")
        if state is not None and np.all(np.isfinite(state[:, k])):
            out[:, k] = state[:, k]
            continue
        ports = unit.machine.component.ports
        name = ports.input("field_voltage") if ports is not None else None
        if name is not None and name in result.machine_inputs:
            out[:, k] = result.machine_inputs[name][:, k]
    return out


@dataclass(frozen=True)
class GridResult:
    """time [n]; states {name: [n, units]}; Vs, theta_vs, P, Q [n, units] (the bus voltage magnitude
    and continuous angle at each machine, the power it injects); V_bus, theta_bus [n, buses]
    (theta_bus unwrapped along the rows, the generator buses' columns equal to theta_vs); the
    verdict, the events (time, description) and the buses; machine_inputs {input name: [n, units]}:
    every input of each machine (bus voltage, control signals) as it was at each row."""

    time: np.ndarray
    states: dict
    Vs: np.ndarray
    theta_vs: np.ndarray
    P: np.ndarray
    Q: np.ndarray
    V_bus: np.ndarray
    theta_bus: np.ndarray
    stable: bool
    loss_of_synchronism_s: float | None
    events: tuple
    gen_buses: tuple
    buses: tuple
    controls: bool = True
    n_rhs: int = 0
    machine_inputs: dict = field(default_factory=dict)

    def __getattr__(self, name):
        states = self.__dict__.get("states")
        if states is not None and name in states:
            return states[name]
        raise AttributeError(name)

    def __getstate__(self):
        return self.__dict__

    def __setstate__(self, state):
        self.__dict__.update(state)

    def angle_difference(self, bus: int, reference_bus: int | None = None) -> np.ndarray:
        """The rotor angle at `bus` minus that at `reference_bus` (default: the first generator) [n] (rad)."""
        g = self.gen_buses
        delta = self.states[ROTOR_ANGLE]
        return delta[:, g.index(bus)] - delta[:, g.index(reference_bus if reference_bus is not None else g[0])]

    def columns(self, case=None) -> dict:
        """The result as named columns (the grid CSV's names, unit labels by `unit_labels`): time,
        delta_<unit>, omega_<unit>, Efd_<unit>, V_<bus>, then theta_<bus>, Vs_<unit>,
        theta_vs_<unit>, P_<unit>, Q_<unit>. With the `case` the result is of, omega is the speed
        deviation [rad/s] and Efd the field voltage of every unit (`speed_deviation`,
        `field_voltage`); without it, the states of those names as stored."""
        labels = unit_labels(self.gen_buses)
        out = {"time": self.time}
        if case is not None:
            per_unit = {"delta": self.states.get(ROTOR_ANGLE), "omega": speed_deviation(self, case),
                        "Efd": field_voltage(self, case)}
        else:
            per_unit = {name: self.states.get(name) for name in CSV_STATES}
        for name in CSV_STATES:
            if per_unit[name] is not None:
                for k, label in enumerate(labels):
                    out[f"{name}_{label}"] = per_unit[name][:, k]
        for i, bus in enumerate(self.buses):
            out[f"V_{bus}"] = self.V_bus[:, i]
        for i, bus in enumerate(self.buses):
            out[f"theta_{bus}"] = self.theta_bus[:, i]
        for name in ("Vs", "theta_vs", "P", "Q"):
            for k, label in enumerate(labels):
                out[f"{name}_{label}"] = getattr(self, name)[:, k]
        return out
