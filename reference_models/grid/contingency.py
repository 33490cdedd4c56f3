"""A contingency of the grid and the topologies it goes through: a fault at a bus (a shunt of
`fault_impedance` pu, 1e-6: bolted) from `fault_start` to `clear_s` [s, absolute], and optionally a
branch opened at clearing; or, without a fault, a branch opened at `clear_s`; plus the case's own
events (`events`: case.Event, as Case.events holds them; () leaves them out).

`topologies(stop)` lists Topology entries (start time, fault bus and impedance, open branches,
tripped units, description) from t = 0 on: what both the monolithic reference and the
co-simulation master switch between, at exact times. The case's events merge with the user's
fault and trip:
* a case fault is a shunt of its own impedance at its bus from its time to its clearing;
* a branch event opens (status 0) or closes again (status 1) its branch;
* a load event switches a load off (status 0: its constant-impedance admittance leaves the network;
  Topology.loads_off) or on again (status 1);
* a generator event with status 0 trips its unit (Topology.tripped: unit indices in the case's
  unit order, which is its load-flow generator order); a unit does not come back (status 1 after a
  trip is refused);
* changes at one time apply together (one Topology);
* one fault shunt at a time: a case fault whose time on overlaps the user's fault (or another case
  fault) is refused, naming both; leave the case's events out to study the user's fault alone.
Buses and branches are checked against `network` (case.Network; None: the shipped wscc9 network).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

BOLTED_FAULT_IMPEDANCE = 1e-6  # pu
#: The default fault impedance of the cases converted from ANDES [pu]: ANDES' own Fault default
#: (rf = 0, xf = 1e-4), at which its Newton iteration converges through the fault (a bolted 1e-6
#: shunt makes it fail); every runner of those cases takes the same default so runs compare.
ANDES_FAULT_IMPEDANCE = 1e-4j


@dataclass(frozen=True)
class Topology:
    """The network from `start` [s] on: a fault shunt of `fault_impedance` [pu] at `fault_bus`
    (None: none), the branches `open` (names "a-b" or "a-b:K", in the network's branch order) and
    the units `tripped` (indices in the case's unit order: each injects no current from `start` on,
    its devices stand still and its rotor angle leaves the stability check) and the loads switched
    off (`loads_off`: (bus, the power it drew at the load flow [pu])."""

    start: float
    fault_bus: int | None
    open: tuple
    description: str
    tripped: tuple = ()
    fault_impedance: complex | None = None
    loads_off: tuple = ()  # (bus, P + jQ drawn at the load flow) of each load switched off, by time


@dataclass(frozen=True)
class Contingency:
    """A fault and its clearing, plus the case's own events (see the module docstring). ValueError
    for an unknown bus, branch or generator, a trip that disconnects a generator, clearing before
    the fault, a non-finite time, a fault impedance that is zero, not finite or has a negative
    part, two faults at once, or a tripped generator switched back on."""

    fault_bus: int | None = None
    clear_s: float | None = None
    trip: str | None = None
    fault_start: float = 0.0
    fault_impedance: complex = BOLTED_FAULT_IMPEDANCE
    network: object = field(default=None, compare=False, repr=False)
    events: tuple = ()

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
            _check_impedance(self.fault_impedance, "the fault impedance")
        elif self.trip is not None and (self.clear_s is None or self.clear_s < 0):
            raise ValueError("a trip without a fault happens at the clearing time, which must be >= 0 s")
        object.__setattr__(self, "events", tuple(self.events))
        self.topologies(math.inf)  # the case's events checked against the network and the user's fault

    def with_clearing(self, clear_s: float) -> "Contingency":
        """The same contingency (case events included) cleared at `clear_s`."""
        return Contingency(self.fault_bus, clear_s, self.trip, self.fault_start, self.fault_impedance, self.network,
                           self.events)

    def without_case_events(self) -> "Contingency":
        """The same contingency without the case's own events."""
        return Contingency(self.fault_bus, self.clear_s, self.trip, self.fault_start, self.fault_impedance,
                           self.network)

    @property
    def label(self) -> str:
        """e.g. "fault at bus 7, cleared at 0.083 s, 5-7 opened" (the user's contingency only)."""
        if self.fault_bus is None:
            return f"{self.trip} opened at {self.clear_s:g} s" if self.trip else "no contingency"
        text = f"fault at bus {self.fault_bus}"
        if self.fault_start:
            text += f" from {self.fault_start:g} s"
        text += f", cleared at {self.clear_s:g} s"
        return text + (f", {self.trip} opened" if self.trip else "")

    def case_event_labels(self, stop: float = math.inf) -> tuple:
        """The case's own events before `stop` [s] in words, by time, e.g. ("8-9:2 opened at 2 s",)."""
        return tuple(f"{text} at {t:g} s" for t, _, text in self._case_changes() if t < stop)

    def _case_changes(self) -> list:
        """The case's events as (time, change, text): change ("fault", bus, z) / ("clear", bus) /
        ("branch", name, status) / ("trip", unit)."""
        net = self.network
        out = []
        for e in self.events:
            if e.kind == "fault":
                net.bus_index(e.bus)
                z = _check_impedance(e.impedance, f"the case's fault at bus {e.bus}: its impedance")
                if not (e.clear is not None and e.clear > e.time):
                    raise ValueError(f"the case's fault at bus {e.bus} at {e.time:g} s is never cleared")
                out.append((float(e.time), ("fault", e.bus, z), f"fault at bus {e.bus}"))
                out.append((float(e.clear), ("clear", e.bus), f"fault at bus {e.bus} cleared"))
            elif e.kind == "branch":
                name = net.branch(e.branch).name
                if e.status not in (0, 1):
                    raise ValueError(f"the case's event of branch {name} has status {e.status!r} (0 or 1)")
                out.append((float(e.time), ("branch", name, e.status), f"{name} {'closed' if e.status else 'opened'}"))
            elif e.kind == "load":
                net.bus_index(e.bus)
                if e.status not in (0, 1):
                    raise ValueError(f"the case's event of the load {e.name} at bus {e.bus} has status {e.status!r}")
                out.append((float(e.time), ("load", e.name, e.bus, e.power, e.status),
                            f"load {e.name} at bus {e.bus} switched {'on' if e.status else 'off'}"))
            elif e.kind == "generator":
                unit = _unit_of(net, e)
                if e.status != 0:
                    raise ValueError(f"the case switches generator {e.generator} at bus {e.bus} on at {e.time:g} s: "
                                     "a unit coming into service is not modelled (leave the case's events out)")
                out.append((float(e.time), ("trip", unit), f"generator {e.generator} at bus {e.bus} tripped"))
            else:
                raise ValueError(f"unknown case event kind {str(e.kind)[:20]!r}")
        return sorted(out, key=lambda c: c[0])

    def _changes(self) -> list:
        """Every change, the user's and the case's, as (time, change, text), by time (stable)."""
        changes = []
        if self.fault_bus is not None:
            changes.append((float(self.fault_start), ("fault", self.fault_bus, complex(self.fault_impedance)),
                            f"fault at bus {self.fault_bus}"))
            changes.append((float(self.clear_s), ("clear", self.fault_bus), f"fault at bus {self.fault_bus} cleared"
                            + (f", {self.trip} opened" if self.trip else "")))
        if self.trip:
            changes.append((float(self.clear_s), ("branch", self.trip, 0),
                            "" if self.fault_bus is not None else f"open {self.trip}"))
        changes += self._case_changes()
        changes.sort(key=lambda c: (c[0], c[1][0] != "clear"))  # at one time a clearing first
        on = None
        for t, change, _ in changes:
            if change[0] == "fault":
                if on is not None:
                    raise ValueError(f"a fault at bus {change[1]} at {t:g} s while the fault at bus {on} is on: "
                                     "one fault at a time (leave the case's events out to study one alone)")
                on = change[1]
            elif change[0] == "clear":
                on = None
        return changes

    def fault_intervals(self, stop: float) -> tuple:
        """The (start, clear) [s] of every fault on before `stop` (clear: `stop` where later), the
        user's and the case's, by time."""
        topologies = self.topologies(stop)
        out = []
        for tp, end in zip(topologies, [tp.start for tp in topologies[1:]] + [stop]):
            if tp.fault_bus is None:
                continue
            if out and out[-1][1] == tp.start:
                out[-1] = (out[-1][0], end)
            else:
                out.append((tp.start, end))
        return tuple(out)

    def trip_times(self, stop: float) -> dict:
        """{unit index: the time [s] it is tripped} for every unit tripped before `stop` (the user's
        events and the case's)."""
        out = {}
        for topology in self.topologies(stop):
            for k in topology.tripped:
                out.setdefault(k, topology.start)
        return out

    def topologies(self, stop: float) -> list:
        """The Topology sequence up to `stop` [s]: the intact network from 0, then the network after
        each time at which something changes before `stop` (a change at 0 replaces the intact
        start). An island of generators with loads runs on its own (an island with nothing in service
        is dead: Case.reduced grounds it); generators left with nothing to supply (no load, no shunt in their
        island: kundur_gentrip's machine behind its opened step-up transformer) trip, as ANDES holds them."""
        net = self.network
        order = {br.name: i for i, br in enumerate(net.branches)}
        fault, opened, tripped, loads_off = None, set(), set(), {}
        intact = None  # islands of the network as it stands (ANDES' islands held apart: andes_case), once needed
        kept = [Topology(0.0, None, (), "intact")]
        changes = self._changes()
        i = 0
        while i < len(changes):
            t = changes[i][0]
            if t >= stop and t > 0:
                break
            texts = []
            while i < len(changes) and changes[i][0] == t:
                _, change, text = changes[i]
                if change[0] == "fault":
                    fault = change[1:]
                elif change[0] == "clear":
                    fault = None
                elif change[0] == "branch":
                    (opened.discard if change[2] else opened.add)(change[1])
                elif change[0] == "load":
                    if change[4]:
                        loads_off.pop(change[1], None)
                    else:
                        loads_off[change[1]] = (change[2], change[3])
                else:
                    tripped.add(change[1])
                if text:
                    texts.append(text)
                i += 1
            live = {g.bus for k, g in enumerate(net.generators) if k not in tripped}
            if opened and intact is None:
                intact = net.islands()
            for island in net.islands(opened) if opened else ():
                bare = sorted(b for b in island if b not in net.loads and b not in net.shunts)
                if island & live and len(bare) == len(island) and island not in intact:
                    # generators cut off by the opened branches with nothing to supply: tripped, as ANDES has them
                    cut = [k for k, g in enumerate(net.generators) if g.bus in island and k not in tripped]
                    tripped.update(cut)
                    texts.append(f"generator{'s' if len(cut) > 1 else ''} "
                                 f"{', '.join(str(net.generators[k].name or net.generators[k].bus) for k in cut)} "
                                 "open-circuited: tripped")

            topology = Topology(t, None if fault is None else fault[0], tuple(sorted(opened, key=order.get)),
                                "; ".join(texts), tuple(sorted(tripped)), None if fault is None else fault[1],
                                tuple(loads_off.values()))
            if t == 0:
                kept[0] = topology
            else:
                kept.append(topology)
        return kept


def _check_impedance(value, what: str) -> complex:
    z = complex(value) if value is not None else 0j
    if z == 0 or not (math.isfinite(z.real) and math.isfinite(z.imag)) or z.real < 0 or z.imag < 0:
        raise ValueError(f"{what} must be finite, nonzero and without a negative part "
                         f"(bolted: {BOLTED_FAULT_IMPEDANCE} pu), got {value!r}")
    return z


def _unit_of(network, event) -> int:
    """The unit index (load-flow generator order) of a generator event: its generator by name where
    the network names its generators, else the first generator at its bus."""
    gens = network.generators
    for k, g in enumerate(gens):
        if g.bus == event.bus and (event.generator is None or g.name is None or g.name == str(event.generator)):
            return k
    raise ValueError(f"{network.name} has no generator {event.generator} at bus {event.bus}")
