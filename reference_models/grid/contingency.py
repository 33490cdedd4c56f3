"""A contingency of the grid and the topologies it goes through: a fault at a bus (a shunt of
`fault_impedance` pu, 1e-6: bolted) from `fault_start` to `clear_s` [s, absolute], and optionally a
branch opened at clearing; or, without a fault, a branch opened at `clear_s`.

`topologies(stop)` lists (start time, fault bus or None, open branches, description) from t = 0 on:
what both the monolithic reference and the co-simulation master switch between, at exact times.
Buses and branches are checked against `network` (case.Network; None: the shipped wscc9 network).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

BOLTED_FAULT_IMPEDANCE = 1e-6  # pu


@dataclass(frozen=True)
class Topology:
    """The network from `start` [s] on: a fault shunt at `fault_bus` (None: none), the branches
    `open` (names "a-b") and the units `tripped` (indices in the case's unit order: each injects no
    current from `start` on, its devices stand still and its rotor angle leaves the stability
    check)."""

    start: float
    fault_bus: int | None
    open: tuple
    description: str
    tripped: tuple = ()


@dataclass(frozen=True)
class Contingency:
    """A fault and its clearing (see the module docstring). ValueError for an unknown bus or branch,
    a trip that disconnects a generator, clearing before the fault, a non-finite time or a fault
    impedance that is zero, not finite or has a negative part."""

    fault_bus: int | None = None
    clear_s: float | None = None
    trip: str | None = None
    fault_start: float = 0.0
    fault_impedance: complex = BOLTED_FAULT_IMPEDANCE
    network: object = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        if self.network is None:
            from .wscc9 import NETWORK

            object.__setattr__(self, "network", NETWORK)
        if self.trip is not None:
            object.__setattr__(self, "trip", self.network.openable(self.trip).name)
        if not (isinstance(self.fault_start, (int, float)) and math.isfinite(self.fault_start) and self.fault_start >= 0):
            raise ValueError(f"the fault start must be a time >= 0 s, got {self.fault_start!r}")
        if self.clear_s is not None and not (isinstance(self.clear_s, (int, float)) and math.isfinite(self.clear_s)):
            raise ValueError(f"the clearing time must be a finite time in s, got {self.clear_s!r}")
        if self.fault_bus is not None:
            self.network.bus_index(self.fault_bus)
            if self.clear_s is None or not self.clear_s > self.fault_start:
                raise ValueError(f"the clearing time must come after the fault start ({self.fault_start} s), "
                                 f"got {self.clear_s!r}")
            z = complex(self.fault_impedance)
            if z == 0 or not (math.isfinite(z.real) and math.isfinite(z.imag)) or z.real < 0 or z.imag < 0:
                raise ValueError(f"the fault impedance must be finite, nonzero and without a negative part "
                                 f"(bolted: {BOLTED_FAULT_IMPEDANCE} pu), got {self.fault_impedance!r}")
        elif self.trip is not None and (self.clear_s is None or self.clear_s < 0):
            raise ValueError("a trip without a fault happens at the clearing time, which must be >= 0 s")

    def with_clearing(self, clear_s: float) -> "Contingency":
        """The same contingency cleared at `clear_s`."""
        return Contingency(self.fault_bus, clear_s, self.trip, self.fault_start, self.fault_impedance, self.network)

    @property
    def label(self) -> str:
        """e.g. "fault at bus 7, cleared at 0.083 s, 5-7 opened"."""
        if self.fault_bus is None:
            return f"{self.trip} opened at {self.clear_s:g} s" if self.trip else "no contingency"
        text = f"fault at bus {self.fault_bus}"
        if self.fault_start:
            text += f" from {self.fault_start:g} s"
        text += f", cleared at {self.clear_s:g} s"
        return text + (f", {self.trip} opened" if self.trip else "")

    def topologies(self, stop: float) -> list:
        """The Topology sequence up to `stop` [s]: the intact network from 0, then each change that
        happens before `stop` (a change at 0 replaces the intact start)."""
        after = (self.trip,) if self.trip else ()
        if self.fault_bus is None:
            changes = [Topology(0.0, None, (), "intact")]
            if self.trip:
                changes.append(Topology(float(self.clear_s), None, after, f"open {self.trip}"))
        else:
            cleared = f"fault at bus {self.fault_bus} cleared" + (f", {self.trip} opened" if self.trip else "")
            changes = [Topology(0.0, None, (), "intact"),
                       Topology(float(self.fault_start), self.fault_bus, (), f"fault at bus {self.fault_bus}"),
                       Topology(float(self.clear_s), None, after, cleared)]
        kept = []
        for change in changes:
            if change.start >= stop and kept:
                break
            if kept and change.start == kept[-1].start:
                kept[-1] = change
            else:
                kept.append(change)
        return kept
