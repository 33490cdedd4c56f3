"""A grid simulation's result, the same for the monolithic reference and the co-simulation master.

Rows: one per output time (rows at an event time: the state after it, and with `event_rows` also
the one before it, left limit first). Per unit arrays [n, units] in unit order, per bus
[n, buses] in bus order; angles in rad, speeds rad/s deviation.

`states` holds the states of each unit's bus device by its variable name, [n, units] (NaN for a
unit whose bus device has no state of that name); they read as attributes too. `device_states`
holds every state of every device, control devices included, under its result column
`<device>_<state>` [n], the device named `<MODEL>_<unit label>` (`device_labels`). `rotor_angle`
[n, units] is each unit's rotor angle where its bus device gives one (the `rotor_angle` signal of
its ports: a synchronous machine; NaN for an inverter or a load): a run is stable when no two
rotor angles in service are pi apart. The result file's first columns are fixed by the grid's
command-line contract (`GridResult.columns(case)`): per unit with a rotor angle `delta_<unit>`
[rad], the speed `omega_<unit>` [rad/s deviation from synchronous] and the field voltage
`Efd_<unit>` [pu] (unit labels `<bus>`, or `<bus>_<k>` where a bus holds several units, k 1-based
in the case's unit order), then `V_<bus>` [pu] for every bus, then `theta_<bus>`, then every
device's states and each bus device's `P`, `Q` and current `I_re`, `I_im` at its bus (system base,
generator convention, network frame). `speed_deviation` and `field_voltage`
are decided from the ports (the speed output link and its unit, the field-voltage input link),
never from a component's name.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import math

import numpy as np

SPEED_SIGNALS = ("rotor_speed", "speed")  # the output links that give a machine's speed


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


def device_labels(units) -> tuple:
    """Per unit (case.Unit) the label of each of its devices: `<MODEL>_<bus>` (the component's name in
    capitals), `<MODEL>_<bus>_<k>` (k 1-based in unit order) where the bus holds that model in
    several units, and the device's key appended where a unit holds two of one model."""
    models = [tuple(d.component.name.upper() for d in u.devices) for u in units]
    keys = [(m, u.bus) for u, ms in zip(units, models) for m in dict.fromkeys(ms)]
    seen = {}
    out = []
    for unit, ms in zip(units, models):
        labels = []
        for m in dict.fromkeys(ms):
            seen[(m, unit.bus)] = seen.get((m, unit.bus), 0) + 1
        for m, d in zip(ms, unit.devices):
            label = f"{m}_{unit.bus}" + (f"_{seen[(m, unit.bus)]}" if keys.count((m, unit.bus)) > 1 else "")
            labels.append(label if ms.count(m) == 1 else f"{label}_{d.name}")
        out.append(tuple(labels))
    return tuple(out)


def rotor_angle_state(component) -> str | None:
    """The state a component links as its rotor angle (its `rotor_angle` output link), or None."""
    linked = component.ports.output("rotor_angle")
    return linked if linked in component.state_names else None


def _speed_state(component) -> str | None:
    for signal in SPEED_SIGNALS:
        linked = component.ports.output(signal)
        if linked in component.state_names:
            return linked
    return None


def speed_deviation(result, case) -> np.ndarray:
    """The machines' speed deviation from synchronous [rad/s], [n, units]: a speed state in pu
    (1 = synchronous) becomes (omega - 1) * 2 pi fn (fn: the machine's own parameter where it has
    one, else the case's frequency), one in rad/s is taken as it is (a deviation); NaN for a unit
    whose bus device links no speed state. ValueError for a speed in another unit."""
    n = len(result.time)
    out = np.full((n, len(case.units)), np.nan)
    for k, unit in enumerate(case.units):
        component = unit.machine.component
        name = _speed_state(component)
        if name is None or name not in result.states:
            continue
        quantity = next(q for q in component.states if q.name == name)
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
    """Each unit's field voltage [pu], [n, units]: its bus device's field-voltage input (its
    `field_voltage` link: an exciter's output, or held at its start where the unit has no exciter);
    NaN where it has none."""
    n = len(result.time)
    out = np.full((n, len(case.units)), np.nan)
    for k, unit in enumerate(case.units):
        name = unit.machine.component.ports.input("field_voltage")
        if name is not None and name in result.machine_inputs:
            out[:, k] = result.machine_inputs[name][:, k]
    return out


@dataclass(frozen=True)
class GridResult:
    """time [n]; states {name: [n, units]} (the bus devices' states); Vs, theta_vs, P, Q [n, units]
    (the bus voltage magnitude and continuous angle at each unit's bus device, the power it
    injects); V_bus, theta_bus [n, buses] (theta_bus unwrapped along the rows, the unit buses'
    columns equal to theta_vs); the verdict, the events (time, description) and the buses;
    machine_inputs {input name: [n, units]}: every input of each bus device (bus voltage, control
    signals) as it was at each row; rotor_angle [n, units] (NaN where a unit's bus device has
    none; None: none at all); device_states {column: [n]}:
    every device's states (module docstring)."""

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
    rotor_angle: np.ndarray | None = None
    device_states: dict = field(default_factory=dict)

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
        """The rotor angle at `bus` minus that at `reference_bus` (default: the first unit with a rotor
        angle) [n] (rad); NaN where either has none."""
        g = self.gen_buses
        delta = self.angles
        if reference_bus is None:
            first = next((k for k in range(len(g)) if np.any(np.isfinite(delta[:, k]))), 0)
            return delta[:, g.index(bus)] - delta[:, first]
        return delta[:, g.index(bus)] - delta[:, g.index(reference_bus)]

    def device_column(self, model: str, state: str) -> np.ndarray:
        """[n, m]: the state `state` of every device of the model `model` (its label's prefix, in
        capitals), in unit order; KeyError where no device has it."""
        columns = [v for k, v in self.device_states.items()
                   if k.startswith(f"{model.upper()}_") and k.endswith(f"_{state}")]
        if not columns:
            raise KeyError(f"no {model.upper()} device has a state {state}")
        return np.column_stack(columns)

    @property
    def angles(self) -> np.ndarray:
        """[n, units] rad: `rotor_angle` (all NaN where the result carries none)."""
        if self.rotor_angle is not None:
            return self.rotor_angle
        return np.full((len(self.time), len(self.gen_buses)), np.nan)

    def columns(self, case=None) -> dict:
        """The result as named columns (the grid CSV's names, unit labels by `unit_labels`): time,
        delta_<machine>, omega_<machine>, Efd_<machine> (the units with a rotor angle, labelled among
        themselves), V_<bus>, theta_<bus>,
        then every device state `<device>_<state>` (`device_states`), Vs_<unit>, theta_vs_<unit>,
        P_<unit>, Q_<unit>. With the `case` the result is of, omega is the speed deviation [rad/s]
        and Efd the field voltage of every unit (`speed_deviation`, `field_voltage`); without it,
        only delta."""
        labels = unit_labels(self.gen_buses)
        out = {"time": self.time}
        angles = self.angles
        machines = [k for k in range(len(labels)) if np.any(np.isfinite(angles[:, k]))]
        machine_labels = dict(zip(machines, unit_labels([self.gen_buses[k] for k in machines])))
        if case is not None:
            per_unit = {"delta": angles, "omega": speed_deviation(self, case), "Efd": field_voltage(self, case)}
        else:
            per_unit = {"delta": angles, "omega": None, "Efd": None}
        for name in ("delta", "omega", "Efd"):
            if per_unit[name] is not None:
                for k in machines:
                    out[f"{name}_{machine_labels[k]}"] = per_unit[name][:, k]
        for i, bus in enumerate(self.buses):
            out[f"V_{bus}"] = self.V_bus[:, i]
        for i, bus in enumerate(self.buses):
            out[f"theta_{bus}"] = self.theta_bus[:, i]
        out.update(self.device_states)
        for name in ("Vs", "theta_vs", "P", "Q"):
            for k, label in enumerate(labels):
                out[f"{name}_{label}"] = getattr(self, name)[:, k]
        return out
