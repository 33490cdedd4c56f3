"""A grid simulation's result, the same for the monolithic reference and the co-simulation master.

Rows: one per output time (rows at an event time: the state after it, and with `event_rows` also
the one before it, left limit first). Per unit arrays [n, units] in generator order, per bus
[n, buses] in bus order; angles in rad, speeds rad/s deviation.

`states` holds every device state of the units by its variable name, [n, units] (NaN for a unit
without that state); they read as attributes too (`result.delta`, `result.Efd`). The result file's
first columns are fixed by the grid's command-line contract (`CSV_STATES`): the rotor angle
`delta`, the speed `omega` and the field voltage `Efd` of the unit at each generator bus, where the
units have them. A run is stable when no two machines' rotor angles (`ROTOR_ANGLE`) are pi apart.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

ROTOR_ANGLE = "delta"
CSV_STATES = ("delta", "omega", "Efd")


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

    def columns(self) -> dict:
        """The result as named columns (the grid CSV's names): time, delta_<gen bus>, omega_<gen bus>,
        Efd_<gen bus>, V_<bus>, then theta_<bus>, Vs_<gen bus>, theta_vs_<gen bus>, P_<gen bus>,
        Q_<gen bus>."""
        out = {"time": self.time}
        for name in CSV_STATES:
            if name in self.states:
                for k, bus in enumerate(self.gen_buses):
                    out[f"{name}_{bus}"] = self.states[name][:, k]
        for i, bus in enumerate(self.buses):
            out[f"V_{bus}"] = self.V_bus[:, i]
        for i, bus in enumerate(self.buses):
            out[f"theta_{bus}"] = self.theta_bus[:, i]
        for name in ("Vs", "theta_vs", "P", "Q"):
            for k, bus in enumerate(self.gen_buses):
                out[f"{name}_{bus}"] = getattr(self, name)[:, k]
        return out
