"""A grid case: the network (buses, branches, shunts, loads), its load flow, the devices at the
generator buses (each a component with its parameters, grouped into units) and the case's events.
Everything that simulates a case (the co-simulation master, the monolithic DAE) is built from it.

Units. The devices of one load-flow generator form a unit (a bus may hold several generators):
one machine (the device whose component has a bus port, reference_models.ports) and its control
components (exciters, governors, stabilisers).
Within a unit an input link takes the output link of the same signal; `terminal_voltage` comes
from the bus (the magnitude of the bus voltage plus the drop over the machine's external
impedance, `external_impedance`); an input link nothing gives is a set point, held at its start
value. `Case.starts` holds every device's start values, from the load flow.

Files. A network file (JSON): base_mva, f_hz, buses [{number, kv}], branches [{from, to, r, x, b,
kind, tap, phi}] (tap ratio and phase shift [rad] at the from side, default 1 and 0), loads [{bus,
P, Q}], shunts [{bus, G, B}], generators [{bus, kind slack|pv, V, P, name}] and the solved load flow
(V, theta per bus, P, Q per generator; per unit on base_mva, rad), and optionally the case's own
events [{kind, time, ...}] (`Event`). A dynamic-data file (JSON): "generators": [{"bus": n,
"generator": name, "<device>": {"component": name, "file": machine file | "params": {...}}, ...,
"fmu": {...}}] - every key besides bus, generator, takes and fmu is a device, in file order;
`generator` (optional) names the load-flow generator where a bus has several; `fmu` is kept as it is
for the co-simulation layer (which FMUs run the unit); `takes` (optional) {signal: {"generator":
name, "signal": given}}: a signal the unit takes from a device of another generator's unit (`Remote`:
a turbine's second machine takes its mechanical power from the first one's governor).

Every device starts at rest from the load flow by the initialisation its component declares
(Component.initialisation, `unit_start`, `at_rest`): the bus device from its share of the load-flow
point, its controls in the order the ports impose (a stabiliser whose signal an exciter takes
before the exciter; the exciter holding the field voltage the machine solved for, the governor its
mechanical power, each with the set point that does). A `loads` entry of a dynamic-data file is a
unit at a load bus with the power P, Q it draws; a device entry's `measures` names what it measures
in the network (`Measurement`).

Shipped cases (`shipped_case(name)`, `SHIPPED_CASES`): data/NAME_network.json + data/NAME.json.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np


class CaseError(ValueError):
    """A case file that cannot be used (one line, naming the file and the entry)."""


@dataclass(frozen=True)
class Branch:
    """A pi branch between two buses: series R + jX and total shunt susceptance B [pu]."""

    from_bus: int
    to_bus: int
    r: float
    x: float
    b: float
    kind: str  # "line" or "transformer"
    tap: float = 1.0  # off-nominal turns ratio at the from side
    phi: float = 0.0  # phase shift [rad] of the from side
    parallel: int = 1  # 1-based position among the branches between the same two buses (file order)

    @property
    def name(self) -> str:
        return f"{self.from_bus}-{self.to_bus}" + (f":{self.parallel}" if self.parallel > 1 else "")

    def connects(self, bus: int) -> bool:
        return bus in (self.from_bus, self.to_bus)


@dataclass(frozen=True)
class GeneratorData:
    """A generator in the load flow: the slack (V, angle 0) or a PV bus (P, V) [pu]."""

    bus: int
    kind: str  # "slack" or "pv"
    V: float
    P: float | None = None
    name: str | None = None  # the generator's name in its source (where a bus has several)


@dataclass(frozen=True)
class Event:
    """One of a case's own events at `time` [s]: kind "fault" (a shunt of `impedance` [pu] at
    `bus` from `time` to `clear`), "branch" (branch `branch`, named as Network.branch takes it,
    switched to `status`: 0 open, 1 closed), "generator" (the unit of generator `generator`
    switched to `status`: 0 tripped) or "load" (the load `name` at `bus`, drawing `power` [pu] at
    the load flow, switched to `status`: 0 off, 1 on again)."""

    kind: str
    time: float
    bus: int | None = None
    clear: float | None = None
    impedance: complex | None = None
    branch: str | None = None
    generator: str | None = None
    status: int | None = None
    name: str | None = None
    power: complex | None = None


@dataclass(frozen=True)
class Network:
    """Buses (numbers, in file order), branches, loads {bus: P + jQ} and shunts {bus: G + jB} [pu on
    base_mva], the load-flow generators, nominal voltages {bus: kV}."""

    name: str
    base_mva: float
    f_hz: float
    buses: tuple
    branches: tuple
    loads: dict
    shunts: dict
    generators: tuple
    kv: dict = field(default_factory=dict)

    @property
    def generator_buses(self) -> tuple:
        return tuple(g.bus for g in self.generators)

    def bus_index(self, bus: int) -> int:
        """Row of bus number `bus` in the arrays of the case (bus order of the file)."""
        if bus not in self.buses:
            raise ValueError(f"{self.name} has no bus {bus!r} (buses {', '.join(map(str, self.buses))})")
        return self.buses.index(bus)

    def branch(self, name) -> Branch:
        """The branch named "a-b" (or given as a pair (a, b)), in either order; "a-b:K" the K-th
        (1-based, file order) of the parallel branches between a and b."""
        if isinstance(name, Branch):
            return name
        k = 1
        try:
            if isinstance(name, str) and ":" in name:
                name, k = name.split(":", 1)
                k = int(k)
            a, b = (int(v) for v in (name.split("-") if isinstance(name, str) else name))
        except (ValueError, TypeError):
            raise ValueError(f"a branch is named FROM-TO, e.g. 5-7; got {str(name)[:40]!r}") from None
        for br in self.branches:
            if {a, b} == {br.from_bus, br.to_bus}:
                k -= 1
                if k == 0:
                    return br
        raise ValueError(f"{self.name} has no branch {a}-{b} (branches: {', '.join(br.name for br in self.branches)})")

    def connected_buses(self, out_of_service=(), start: int | None = None) -> set:
        """The buses connected to bus `start` (default: the first generator's) with the given branches open."""
        removed = {self.branch(b) for b in out_of_service}
        neighbours = {}
        for br in self.branches:
            if br not in removed:
                neighbours.setdefault(br.from_bus, []).append(br.to_bus)
                neighbours.setdefault(br.to_bus, []).append(br.from_bus)
        start = self.generators[0].bus if start is None else start
        reach, frontier = {start}, [start]
        while frontier:
            for other in neighbours.get(frontier.pop(), ()):
                if other not in reach:
                    reach.add(other)
                    frontier.append(other)
        return reach

    def islands(self, out_of_service=()) -> list:
        """The sets of buses connected to each other with the given branches open (bus order of
        their first bus)."""
        left, out = list(self.buses), []
        while left:
            island = self.connected_buses(out_of_service, left[0])
            out.append(island)
            left = [b for b in left if b not in island]
        return out

    def disconnects_generator(self, trip) -> bool:
        """Whether opening branch `trip` leaves a generator bus cut off from the others."""
        return not set(self.generator_buses) <= self.connected_buses([trip])

    def openable(self, name) -> Branch:
        """The branch `name` (see `branch`); ValueError naming the branches that may open instead when
        opening it would cut a generator off."""
        br = self.branch(name)
        if self.disconnects_generator(br):
            raise ValueError(f"opening branch {br.name} disconnects a generator (branches that may open at its "
                             f"buses: {', '.join(self.trips_at(br.from_bus))}; {', '.join(self.trips_at(br.to_bus))})")
        return br

    def trips_at(self, bus: int) -> tuple:
        """The branches at `bus` whose opening keeps every generator connected (names "a-b")."""
        self.bus_index(bus)
        return tuple(br.name for br in self.branches if br.connects(bus) and not self.disconnects_generator(br))

    def ybus(self, out_of_service=()) -> np.ndarray:
        """The bus admittance matrix [n, n] (complex, pu, bus order) of the branches and shunts,
        without loads; `out_of_service`: branches left out."""
        removed = {self.branch(b) for b in out_of_service}
        n = len(self.buses)
        Y = np.zeros((n, n), dtype=complex)
        for br in self.branches:
            if br in removed:
                continue
            i, k = self.bus_index(br.from_bus), self.bus_index(br.to_bus)
            y = 1.0 / complex(br.r, br.x)
            if br.tap == 1.0 and br.phi == 0.0:
                Y[i, i] += y + 0.5j * br.b
                Y[k, k] += y + 0.5j * br.b
                Y[i, k] -= y
                Y[k, i] -= y
            else:  # ideal transformer tap e^{j phi} : 1 at the from side, then the pi branch
                m = br.tap * np.exp(1j * br.phi)
                Y[i, i] += (y + 0.5j * br.b) / br.tap ** 2
                Y[k, k] += y + 0.5j * br.b
                Y[i, k] -= y / np.conj(m)
                Y[k, i] -= y / m
        for bus, s in self.shunts.items():
            Y[self.bus_index(bus), self.bus_index(bus)] += s
        return Y


@dataclass(frozen=True)
class LoadFlow:
    """The load-flow solution: V, theta [n buses] (pu, rad, bus order); P_gen, Q_gen [n generators]
    (pu, generator order); S_load [n buses] the loads' P + jQ (0 where none)."""

    buses: tuple
    generator_buses: tuple
    V: np.ndarray
    theta: np.ndarray
    P_gen: np.ndarray
    Q_gen: np.ndarray
    S_load: np.ndarray

    @property
    def V_complex(self) -> np.ndarray:
        return self.V * np.exp(1j * self.theta)

    def load_admittances(self) -> np.ndarray:
        """The constant-impedance loads [n] (complex, pu) drawing S_load at the load-flow voltages."""
        return np.conj(self.S_load) / self.V ** 2

    def generator(self, bus: int) -> dict:
        """V, theta, P, Q of the (first) generator at `bus`."""
        return self.generator_at(self.generator_buses.index(bus))

    def generator_at(self, k: int) -> dict:
        """V, theta, P, Q of generator k (generator order)."""
        i = self.buses.index(self.generator_buses[k])
        return {"V": float(self.V[i]), "theta": float(self.theta[i]),
                "P": float(self.P_gen[k]), "Q": float(self.Q_gen[k])}


@dataclass(frozen=True)
class Measurement:
    """What a device measures in the network beyond its own bus (a plant controller): the voltage of
    `bus`, and the flow into `branch` (a name Network.branch takes; None: no branch) at its end `end`
    (one of the branch's buses)."""

    bus: int
    branch: str | None = None
    end: int | None = None


@dataclass(frozen=True)
class Device:
    """A component at a bus: `name` (the dynamic-data key, e.g. machine), the reference_models
    Component, its parameters and where they came from (`source`: a file, or None); `measures`:
    what it measures in the network (its measured_* and branch_* input links), or None."""

    name: str
    component: object
    params: object
    source: Path | None = None
    measures: Measurement | None = None


@dataclass(frozen=True)
class DeviceStart:
    """A device's start: its states (component order) and the value of every input, by name."""

    states: tuple
    inputs: dict


@dataclass(frozen=True)
class Remote:
    """A signal a unit takes from a device of another unit (a turbine driving a second machine): its
    input links of `signal` take the output link of signal `gives` of the unit of load-flow generator
    `generator` (its name, or its bus number where the bus has one generator)."""

    signal: str
    generator: str
    gives: str


@dataclass(frozen=True)
class Unit:
    """The devices at `bus` around one bus device (the one with a bus port: a machine, an inverter's
    converter, a load), which comes first, then its control components; `fmu`: the dynamic data's
    fmu entry, as given (for the co-simulation); `generator`: the load-flow generator's name where
    the data give one; `load`: for a unit that is a load (not a generator), the power it draws at
    the load-flow point, P + jQ [pu, system base] (None: a generator's unit); `takes`: the signals
    its devices take from a device of another unit (`Remote`)."""

    bus: int
    devices: tuple
    fmu: object = None
    generator: str | None = None
    load: complex | None = None
    takes: tuple = ()  # Remote: the signals it takes from a device of another unit

    @property
    def machine(self) -> Device:
        return self.devices[0]

    @property
    def controls(self) -> tuple:
        return self.devices[1:]


def external_impedance(device: Device) -> complex:
    """Re + j Xep [pu]: the impedance between a machine's terminals and its bus, where its parameters
    declare one (0 otherwise). The exciter's terminal voltage is measured behind it."""
    return complex(float(getattr(device.params, "Re", 0.0)), float(getattr(device.params, "Xep", 0.0)))


@dataclass(frozen=True)
class Reduced:
    """One topology: the full admittance matrix Y [buses, buses] with loads and any fault shunt, its
    reduction to the generator buses in real form Y_real [2g, 2g] on v = (V_re, V_im) per generator
    (I = Y_real v), and the recovery of every bus voltage from the generator ones (V_bus = recovery
    @ V_gen, complex [buses, g]), the branches open (`open`, their names)."""

    Y: np.ndarray
    Y_real: np.ndarray
    recovery: np.ndarray
    description: str
    open: tuple = ()  # the branches open in this topology


@dataclass(frozen=True)
class Case:
    """A grid case (see the module docstring): network, load flow, units (generator order) with their
    start values (starts[k][j]: unit k, device j), the case's own events, the dynamic-data file and,
    for a case converted from a file ANDES reads, that file (`source`: (case file, dyr file or None),
    absolute paths) so that ANDES can run the very file as the reference."""

    name: str
    network: Network
    flow: LoadFlow
    units: tuple
    starts: tuple
    events: tuple = ()
    dynamic_data: Path | None = None
    source: tuple | None = None  # (case file, dyr file or None) of a case converted from a file ANDES reads

    @property
    def generator_buses(self) -> tuple:
        return tuple(u.bus for u in self.units)

    @property
    def buses(self) -> tuple:
        return self.network.buses

    def reduced(self, fault_bus: int | None = None, fault_impedance: complex = 1e-6, out_of_service=(),
                loads_off=()) -> Reduced:
        """The topology with the loads (constant impedances at the load-flow voltages; `loads_off`:
        (bus, P + jQ) of loads switched off), a fault shunt of `fault_impedance` [pu] at `fault_bus`
        (None: none) and the named branches open, reduced to the generator buses (Kron; each bus
        once, in unit order, where several units share one)."""
        net = self.network
        opened = tuple(net.branch(b) for b in out_of_service)  # what may open: Contingency checks it
        S = self.flow.S_load.copy()
        for bus, power in loads_off:
            S[net.bus_index(bus)] -= power
        Y = net.ybus(opened) + np.diag(np.conj(S) / self.flow.V ** 2)
        parts = []
        if fault_bus is not None:
            z = complex(fault_impedance)
            if z == 0 or not np.isfinite(z):
                raise ValueError(f"fault impedance must be finite and nonzero, got {fault_impedance!r}")
            i = net.bus_index(fault_bus)
            Y[i, i] += 1.0 / z
            parts.append(f"fault at bus {fault_bus}")
        if opened:
            parts.append("open " + ", ".join(br.name for br in opened))
            for island in net.islands(tuple(br.name for br in opened)):  # an island with no load or shunt is dead:
                rows = [net.bus_index(b) for b in island]  # one bus grounded, its voltages 0 (undefined otherwise)
                if not np.any(np.abs(np.sum(Y[np.ix_(rows, rows)], axis=1)) > 0):
                    Y[rows[0], rows[0]] += 1.0
        if loads_off:
            parts.append(f"{len(loads_off)} load{'s' if len(loads_off) > 1 else ''} off")
        g = list(dict.fromkeys(net.bus_index(u.bus) for u in self.units))  # units at one bus share it
        o = [i for i in range(len(net.buses)) if i not in g]
        n = len(g)
        Y_oo_inv_Y_og = np.linalg.solve(Y[np.ix_(o, o)], Y[np.ix_(o, g)])
        Y_red = Y[np.ix_(g, g)] - Y[np.ix_(g, o)] @ Y_oo_inv_Y_og
        recovery = np.zeros((len(net.buses), n), dtype=complex)
        recovery[g, :] = np.eye(n)
        recovery[o, :] = -Y_oo_inv_Y_og
        Y_real = np.zeros((2 * n, 2 * n))
        Y_real[0::2, 0::2] = Y_red.real
        Y_real[0::2, 1::2] = -Y_red.imag
        Y_real[1::2, 0::2] = Y_red.imag
        Y_real[1::2, 1::2] = Y_red.real
        for a in (Y, Y_real, recovery):
            a.setflags(write=False)
        return Reduced(Y=Y, Y_real=Y_real, recovery=recovery, description="; ".join(parts) or "intact",
                       open=tuple(br.name for br in opened))


def _number(path, where: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CaseError(f"{path}: {where} must be a finite number, got {str(value)[:40]!r}")
    return float(value)


def _entries(path, data, key: str) -> list:
    value = data.get(key, [])
    if not isinstance(value, list) or not all(isinstance(e, dict) for e in value):
        raise CaseError(f"{path}: {key} must be a list of objects")
    return value


def _read_json(path: Path) -> dict:
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CaseError(f"no case file {path}") from None
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise CaseError(f"{path} is not a readable JSON file ({' '.join(str(exc).split())[:120]})") from None
    if not isinstance(data, dict):
        raise CaseError(f"{path}: a JSON object is needed")
    return data


def load_network(path) -> tuple:
    """(Network, LoadFlow) from a network file (see the module docstring)."""
    data = _read_json(path)
    try:
        buses = tuple(int(b["number"]) for b in _entries(path, data, "buses"))
        kv = {int(b["number"]): _number(path, "bus kv", b["kv"]) for b in _entries(path, data, "buses")}
        branches, seen = [], {}
        for e in _entries(path, data, "branches"):
            ends = frozenset((int(e["from"]), int(e["to"])))
            seen[ends] = seen.get(ends, 0) + 1
            branches.append(Branch(int(e["from"]), int(e["to"]), _number(path, "r", e["r"]), _number(path, "x", e["x"]),
                                   _number(path, "b", e.get("b", 0.0)), str(e.get("kind", "line")),
                                   _number(path, "tap", e.get("tap", 1.0)), _number(path, "phi", e.get("phi", 0.0)),
                                   seen[ends]))
        branches = tuple(branches)
        loads = {int(e["bus"]): complex(_number(path, "load P", e["P"]), _number(path, "load Q", e["Q"]))
                 for e in _entries(path, data, "loads")}
        shunts = {int(e["bus"]): complex(_number(path, "shunt G", e["G"]), _number(path, "shunt B", e["B"]))
                  for e in _entries(path, data, "shunts")}
        generators = tuple(GeneratorData(int(e["bus"]), str(e["kind"]), _number(path, "generator V", e["V"]),
                                         None if e.get("P") is None else _number(path, "generator P", e["P"]),
                                         None if e.get("name") is None else str(e["name"]))
                           for e in _entries(path, data, "generators"))
        network = Network(str(data.get("name", Path(path).stem)), _number(path, "base_mva", data["base_mva"]),
                          _number(path, "f_hz", data["f_hz"]), buses, branches, loads, shunts, generators, kv)
        lf = data["load_flow"]
        V, theta = (np.array([_number(path, f"load_flow {k}", v) for v in lf[k]]) for k in ("V", "theta"))
        P, Q = (np.array([_number(path, f"load_flow {k}", v) for v in lf[k]]) for k in ("P", "Q"))
    except (KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, CaseError):
            raise
        raise CaseError(f"{path}: malformed network data ({type(exc).__name__}: {str(exc)[:80]})") from None
    if len(set(buses)) != len(buses) or not buses:
        raise CaseError(f"{path}: bus numbers must be unique")
    if any(br.tap <= 0 for br in branches):
        raise CaseError(f"{path}: a branch's tap must be > 0")
    for bus in [b for br in branches for b in (br.from_bus, br.to_bus)] + list(loads) + list(shunts) + \
            [g.bus for g in generators]:
        if bus not in buses:
            raise CaseError(f"{path}: bus {bus} is not among the buses")
    if len(V) != len(buses) or len(theta) != len(buses) or len(P) != len(generators) or len(Q) != len(generators):
        raise CaseError(f"{path}: the load flow needs V, theta per bus and P, Q per generator")
    S_load = np.zeros(len(buses), dtype=complex)
    for bus, s in loads.items():
        S_load[buses.index(bus)] = s
    flow = LoadFlow(buses, network.generator_buses, V, theta, P, Q, S_load)
    for a in (flow.V, flow.theta, flow.P_gen, flow.Q_gen, flow.S_load):
        a.setflags(write=False)
    return network, flow


def load_units(path, generator_buses, generator_names=None) -> tuple:
    """The units of a dynamic-data file (see the module docstring), in `generator_buses` order
    (`generator_names`: the load-flow generators' names, None where they have none; a unit is
    matched by bus and, where it gives one, generator name). CaseError for an unknown component, a
    unit without exactly one machine first, a generator at a bus that has none in the load flow,
    or two entries for one generator."""

    path = Path(path)
    data = _read_json(path)
    names = list(generator_names) if generator_names is not None else [None] * len(generator_buses)
    by_key = {}
    for g in _entries(path, data, "generators"):
        try:
            bus = int(g["bus"])
        except (KeyError, TypeError, ValueError):
            raise CaseError(f"{path}: every generator needs its bus number") from None
        generator = None if g.get("generator") is None else str(g["generator"])
        where = f"{path}: generator at bus {bus}" + (f" ({generator})" if generator else "")
        if (bus, generator) in by_key:
            raise CaseError(f"{where}: the bus has two generator entries")
        by_key[(bus, generator)] = Unit(bus, _devices(path, g, where, ("bus", "fmu", "generator", "takes")),
                                        g.get("fmu"), generator, takes=_takes(g.get("takes"), where))
    keys = [(bus, name if (bus, name) in by_key else None) for bus, name in zip(generator_buses, names)]
    if sorted(by_key, key=str) != sorted(keys, key=str):
        raise CaseError(f"{path}: needs one generator at each of the buses {tuple(generator_buses)}, "
                        f"got {sorted(bus for bus, _ in by_key)}")
    loads = []
    for e in _entries(path, data, "loads"):
        try:
            bus = int(e["bus"])
            drawn = complex(_number(path, "load P", e["P"]), _number(path, "load Q", e["Q"]))
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, CaseError):
                raise
            raise CaseError(f"{path}: every load needs its bus number and the P, Q it draws") from None
        where = f"{path}: load at bus {bus}" + (f" ({e['load']})" if e.get("load") is not None else "")
        loads.append(Unit(bus, _devices(path, e, where, ("bus", "fmu", "load", "P", "Q")), e.get("fmu"), None, drawn))
    return tuple(by_key[key] for key in keys) + tuple(loads)


def _takes(entry, where: str) -> tuple:
    """The Remote links of a unit entry's "takes" {signal: {"generator": name, "signal": the signal
    given there}} (none where it has none)."""
    from ..ports import SIGNALS

    if entry is None:
        return ()
    out = []
    try:
        for signal, source in entry.items():
            remote = Remote(str(signal), str(source["generator"]), str(source["signal"]))
            unknown = [n for n in (remote.signal, remote.gives) if n not in SIGNALS]
            if unknown:
                raise CaseError(f"{where}: takes the unknown signal {unknown[0][:40]!r}")
            out.append(remote)
    except (AttributeError, KeyError, TypeError):
        raise CaseError(f"{where}: takes must map each signal to the generator and the signal it comes from") from None
    return tuple(out)


def remote_wiring(units) -> tuple:
    """Per unit {signal: Source} of the signals it takes from other units (Unit.takes), each the
    device of the named generator's unit that gives the signal; CaseError where no unit or no device
    there gives it."""
    out = []
    for k, unit in enumerate(units):
        wires = {}
        for remote in unit.takes:
            found = [i for i, u in enumerate(units) if u.load is None and i != k and
                     (u.generator == remote.generator or (u.generator is None and str(u.bus) == remote.generator))]
            where = f"generator at bus {unit.bus}" + (f" ({unit.generator})" if unit.generator else "")
            if len(found) != 1:
                raise CaseError(f"{where} takes {remote.signal} from generator {remote.generator[:40]}, which the case "
                                "does not have (or has twice)")
            giver = units[found[0]]
            devices = [(j, d.component.ports.output(remote.gives)) for j, d in enumerate(giver.devices)
                       if d.component.ports is not None and d.component.ports.output(remote.gives)]
            if len(devices) != 1:
                raise CaseError(f"{where} takes {remote.signal} from generator {remote.generator}, where "
                                f"{'no device' if not devices else 'more than one device'} gives {remote.gives}")
            wires[remote.signal] = Source("device", device=devices[0][0], variable=devices[0][1], unit=found[0])
        out.append(wires)
    return tuple(out)


def _measurement(entry, where: str) -> Measurement | None:
    """The Measurement of a device entry's "measures" {"bus": n, "branch": "a-b[:k]", "end": n}
    (branch and end optional; end defaults to the branch's from bus), or None."""
    if entry is None:
        return None
    try:
        branch = None if entry.get("branch") is None else str(entry["branch"])
        end = None if entry.get("end") is None else int(entry["end"])
        return Measurement(int(entry["bus"]), branch, end)
    except (KeyError, TypeError, ValueError, AttributeError):
        raise CaseError(f"{where}: measures must be an object with the measured bus (and a branch, its end)") from None


def _devices(path: Path, entry: dict, where: str, keys: tuple) -> tuple:
    """The Devices of a unit's entry in a dynamic-data file: every key but `keys`, in file order, the
    one with a bus port first."""
    from ..components import component

    devices = []
    for name, value in entry.items():
        if name in keys:
            continue
        if not isinstance(value, dict):
            raise CaseError(f"{where}: {name} must be an object with its component")
        try:
            comp = component(value.get("component"))
        except ValueError as exc:
            raise CaseError(f"{where}: {name}: {exc}") from None
        try:
            if "file" in value:
                source = path.parent / str(value["file"])
                params = comp.load_params(source)
            else:
                source = None
                params = comp.params(value.get("params", {}))
        except (ValueError, OSError, TypeError) as exc:
            raise CaseError(f"{where}: {name}: {' '.join(str(exc).split())[:160]}") from None
        devices.append(Device(name, comp, params, source, _measurement(value.get("measures"), f"{where}: {name}")))
    bus_devices = [d for d in devices if d.component.ports.bus is not None]
    if len(bus_devices) != 1 or devices[0] is not bus_devices[0]:
        raise CaseError(f"{where}: a unit needs exactly one device with a bus port (a machine, a converter, a "
                        "load), listed first")
    return tuple(devices)


def load_events(path) -> tuple:
    """The events of a network file (see `Event`; none where it has no "events"), by time."""
    data = _read_json(path)
    events = []
    for e in _entries(path, data, "events"):
        try:
            kind, time = str(e["kind"]), _number(path, "event time", e["time"])
            if kind == "fault":
                event = Event(kind, time, bus=int(e["bus"]), clear=_number(path, "fault clear", e["clear"]),
                              impedance=complex(_number(path, "fault r", e.get("r", 0.0)),
                                                _number(path, "fault x", e["x"])))
            elif kind == "branch":
                event = Event(kind, time, branch=str(e["branch"]), status=int(e["status"]))
            elif kind == "generator":
                event = Event(kind, time, bus=int(e["bus"]), generator=str(e["generator"]), status=int(e["status"]))
            elif kind == "load":
                event = Event(kind, time, bus=int(e["bus"]), name=str(e["load"]), status=int(e["status"]),
                              power=complex(_number(path, "load P", e["P"]), _number(path, "load Q", e["Q"])))
            else:
                raise CaseError(f"{path}: unknown event kind {kind[:20]!r} (known: fault, branch, generator, load)")
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, CaseError):
                raise
            raise CaseError(f"{path}: malformed event ({type(exc).__name__}: {str(exc)[:80]})") from None
        events.append(event)
    return tuple(sorted(events, key=lambda ev: ev.time))


def _measured_at_rest(network: Network, flow: LoadFlow, unit: Unit) -> dict:
    """{device index: the MEASURED values of its Measurement at the load flow} of a unit's devices;
    CaseError for a measured bus or branch the network does not have."""
    out = {}
    for j, d in enumerate(unit.devices):
        if d.measures is not None:
            try:
                out[j] = measured_values(network, flow.V_complex, d.measures)
            except ValueError as exc:
                raise CaseError(f"{d.component.name.upper()} at bus {unit.bus} measures {exc}") from None
    return out


def operating_point(unit: Unit, k: int, flow: LoadFlow) -> dict:
    """V, theta, P, Q of unit k at the load flow: its generator's, or for a load unit minus the
    power it draws (generator convention)."""
    if unit.load is None:
        return flow.generator_at(k)
    i = flow.buses.index(unit.bus)
    return {"V": float(flow.V[i]), "theta": float(flow.theta[i]), "P": -unit.load.real, "Q": -unit.load.imag}


def unit_start(unit: Unit, op: dict, measured: dict | None = None, remote=None) -> tuple:
    """The DeviceStart of every device of `unit` at the load-flow operating point op (V, theta, P, Q
    of its share of the bus injection): the bus device from its own initialisation (Component.start
    with the load-flow point), then its control devices (`at_rest`); measured {device index: the
    MEASURED values of its Measurement at the load flow}; remote: what it takes from other units
    (RemoteStart)."""
    device = unit.machine
    component = device.component
    bus = component.ports.bus
    given = {bus.voltage[0]: op["V"], bus.voltage[1]: op["theta"], "V0": op["V"], "theta0": op["theta"],
             "P0": op["P"], "Q0": op["Q"]}
    where = f"{component.name.upper()} at bus {unit.bus}"
    try:
        x0, inputs = component.start(given, device.params)
    except ValueError as exc:
        raise CaseError(f"{where} has no start at the load flow: {' '.join(str(exc).split())[:160]}") from None
    return at_rest(unit.devices, x0, inputs, where, measured, remote)


@dataclass(frozen=True)
class RemoteStart:
    """What a unit's start takes from other units: `wiring` (its remote_wiring), `values`
    {(unit, device, variable): the start value of another unit's output it takes}, `demands`
    {device: {output: the value a device of another unit solved for it}}."""

    wiring: dict
    values: dict = field(default_factory=dict)
    demands: dict = field(default_factory=dict)


def at_rest(devices, x0, bus_device_inputs: dict, where: str = "the unit", measured: dict | None = None,
            remote: RemoteStart | None = None) -> tuple:
    """The DeviceStart of every device of a unit whose bus device (devices[0]) is at rest in state x0
    under `bus_device_inputs` (every input by name), the control devices started from what the
    devices they drive need (Component.start).

    Order: a control device starts once every input it does not solve itself is known (the bus, the
    terminal voltage behind the bus device's external impedance, the outputs of devices already
    started) and every device that solves an input it gives has started (that value is what it has
    to give): a stabiliser at rest before the exciter that takes its signal, the exciter after the
    machine that solved the field voltage, a plant controller after the electrical controller that
    solved its references. A device's outputs that others solved for are checked at its start.
    measured: {device index: its MEASURED values} for the devices that measure the network; remote:
    what the unit takes from other units and what they solved for its devices' outputs."""
    devices = list(devices)
    ports = [d.component.ports for d in devices]
    remote = remote or RemoteStart({})
    wiring = unit_wiring(ports, where, remote.wiring)
    machine = devices[0]
    component = machine.component
    bus = component.ports.bus
    x0 = np.asarray(x0, dtype=float)
    starts = {0: DeviceStart(tuple(float(v) for v in x0), {n: float(bus_device_inputs[n]) for n in component.input_names})}
    outputs = {0: _outputs(machine, starts[0])}
    current = complex(outputs[0][bus.current[0]], outputs[0][bus.current[1]])
    V = starts[0].inputs[bus.voltage[0]] * np.exp(1j * starts[0].inputs[bus.voltage[1]])
    Vt = V + external_impedance(machine) * current
    terminal = (float(abs(Vt)), float(np.angle(Vt)))
    bus_values = (starts[0].inputs[bus.voltage[0]], starts[0].inputs[bus.voltage[1]])

    def solves(j) -> tuple:
        init = devices[j].component.initialisation
        return init.solves if init is not None else ()

    def value(source, j):
        """The start value a Source of device j's input gives, or None while its device has not started."""
        if source.kind == "bus":
            return bus_values[source.index]
        if source.kind == "terminal":
            return terminal[source.index]
        if source.kind == "measured":
            if not measured or j not in measured:
                raise CaseError(f"{where}: {devices[j].name} ({devices[j].component.name}) measures the network, "
                                "but its entry names no measured bus (\"measures\")")
            return float(measured[j][source.index])
        if source.kind == "device" and source.unit is not None:
            return remote.values.get((source.unit, source.device, source.variable))
        if source.kind == "device":
            return outputs[source.device][source.variable] if source.device in starts else None
        return None

    def demands(j) -> dict:
        """{output variable of device j: the value a started device solved for it} (None: one that solves
        an input taken from j has not started)."""
        out = dict(remote.demands.get(j, {}))
        for k, wires in enumerate(wiring):
            for name, source in wires.items():
                if source.kind == "device" and source.unit is None and source.device == j and name in solves(k):
                    if k not in starts:
                        return None
                    out[source.variable] = starts[k].inputs[name]
        return out

    pending = list(range(1, len(devices)))
    while pending:
        for j in pending:
            comp = devices[j].component
            wires = wiring[j]
            given = {}
            for name in comp.input_names:
                if name in solves(j):
                    continue
                source = wires.get(name)
                if source is None or source.kind == "held":
                    given[name] = float(next(q.start for q in comp.inputs if q.name == name) or 0.0)
                else:
                    given[name] = value(source, j)
            demanded = demands(j)
            if demanded is None or any(v is None for v in given.values()):
                continue
            break
        else:
            names = ", ".join(f"{devices[j].name} ({devices[j].component.name})" for j in pending)
            raise CaseError(f"{where}: no order in which {names} can start (each waits for another)")
        pending.remove(j)
        device = devices[j]
        try:
            x, inputs = comp.start({**given, **demanded}, device.params)
        except ValueError as exc:
            raise CaseError(f"{where}: {device.name} ({comp.name}) has no rest: {' '.join(str(exc).split())[:160]}") \
                from None
        starts[j] = DeviceStart(tuple(float(v) for v in x), inputs)
        outputs[j] = _outputs(device, starts[j])
        for name, wanted in demanded.items():
            got = outputs[j][name]
            if not abs(got - wanted) <= 1e-8 * max(1.0, abs(wanted)):
                raise CaseError(f"{where}: {device.name} ({comp.name}) starts giving {name} = {got:.10g}, "
                                f"not the {wanted:.10g} its unit needs")
    return tuple(starts[j] for j in range(len(devices)))


def _outputs(device: Device, start: DeviceStart) -> dict:
    """{state or output name: value} of a device at its start."""
    comp = device.component
    x = np.asarray(start.states, dtype=float)
    u = np.array([start.inputs[n] for n in comp.input_names])
    y = comp.output_values(x, u, device.params)
    return {**dict(zip(comp.state_names, (float(v) for v in x))), **dict(zip(comp.output_names, (float(v) for v in y)))}


def _start_units(network: Network, flow: LoadFlow, units) -> tuple:
    """The DeviceStart of every device of every unit (unit_start). A unit that takes a signal from
    another unit (remote_wiring) starts first where its device solves that input (the giver then has
    to give that value: a machine's mechanical power), after the giver otherwise (it needs the value)."""
    remotes = remote_wiring(units)
    links = []  # (taker unit, its device, its input, the giving Source, whether the taker solves it)
    for k, unit in enumerate(units):
        if remotes[k]:
            wiring = unit_wiring([d.component.ports for d in unit.devices], f"generator at bus {unit.bus}", remotes[k])
            for j, (device, wires) in enumerate(zip(unit.devices, wiring)):
                init = device.component.initialisation
                for name, source in wires.items():
                    if source.unit is not None:
                        links.append((k, j, name, source, init is not None and name in init.solves))
    starts, values, demands = {}, {}, {}
    pending = list(range(len(units)))
    while pending:
        ready = [k for k in pending
                 if all(source.unit in starts for taker, _, _, source, solved in links if taker == k and not solved)
                 and all(taker in starts for taker, _, _, source, solved in links if source.unit == k and solved)]
        if not ready:
            raise CaseError("the units that take signals from each other have no order to start in (generators at "
                            f"buses {', '.join(str(units[k].bus) for k in pending)})")
        k = ready[0]
        pending.remove(k)
        unit = units[k]
        remote = RemoteStart(remotes[k], values, {j: d for (unit_k, j), d in demands.items() if unit_k == k})
        starts[k] = unit_start(unit, operating_point(unit, k, flow), _measured_at_rest(network, flow, unit), remote)
        for taker, j, name, source, solved in links:
            if taker == k and solved:
                demands.setdefault((source.unit, source.device), {})[source.variable] = starts[k][j].inputs[name]
            if source.unit == k:
                values[(k, source.device, source.variable)] = _outputs(unit.devices[source.device],
                                                                       starts[k][source.device])[source.variable]
    return tuple(starts[k] for k in range(len(units)))


def load_case(network_file, dynamic_data, name: str | None = None, source: tuple | None = None) -> Case:
    """The Case of a network file and a dynamic-data file; `source`: (case file, dyr file or None)
    where they were converted from a file ANDES reads (Case.source)."""
    network, flow = load_network(network_file)
    units = load_units(dynamic_data, network.generator_buses, [g.name for g in network.generators])
    starts = _start_units(network, flow, units)
    return Case(name or network.name, network, flow, units, starts, load_events(network_file), Path(dynamic_data),
                source)


DATA_DIR = Path(__file__).resolve().parent / "data"
#: The cases that ship with opfmu (data/NAME_network.json and data/NAME.json each).
SHIPPED_CASES = ("wscc9", "kundur", "ieee14", "ieee39", "npcc")


def shipped_case(name: str) -> Case:
    """The shipped case `name` (one of SHIPPED_CASES); CaseError naming them otherwise."""
    if name not in SHIPPED_CASES:
        raise CaseError(f"no shipped case {str(name)[:40]!r} (shipped: {', '.join(SHIPPED_CASES)})")
    return _shipped_case(name)


@lru_cache(maxsize=None)
def _shipped_case(name: str) -> Case:
    return load_case(DATA_DIR / f"{name}_network.json", DATA_DIR / f"{name}.json", name)


#: the signals a device's Measurement gives, in the order measured_values returns them
MEASURED = ("measured_voltage", "measured_voltage_angle", "branch_active_power", "branch_reactive_power",
            "branch_current_real", "branch_current_imaginary")


def measured_values(network: Network, V, measures: Measurement, open_branches=()) -> tuple:
    """The MEASURED quantities of `measures` at the bus voltages V [buses] (complex, bus order; or
    [n, buses]): |V|, angle of V at the measured bus, and the power P, Q [pu] and the current (real,
    imaginary) [pu, network frame] of the measured branch as a plant controller measures it (ANDES'
    REPCA1): over its series impedance alone (no charging, no tap), I = (V_end - V_other) / (r + jx)
    from its measured end, P + jQ = V_from conj(I) with V_from its from bus's voltage; 0 where the
    branch is open or there is none."""
    V = np.asarray(V)
    at = V[..., network.bus_index(measures.bus)]
    current = np.zeros_like(at)
    power = np.zeros_like(at)
    if measures.branch is not None:
        br = network.branch(measures.branch)
        if br not in {network.branch(b) for b in open_branches}:
            Va, Vb = V[..., network.bus_index(br.from_bus)], V[..., network.bus_index(br.to_bus)]
            sign = 1.0 if measures.end == br.from_bus else -1.0
            current = sign * (Va - Vb) / complex(br.r, br.x)
            power = Va * np.conj(current)
    return np.abs(at), np.angle(at), power.real, power.imag, current.real, current.imag


TERMINAL = ("terminal_voltage", "terminal_voltage_angle")  # what the bus gives a unit: |Vt|, angle of Vt
TERMINAL_CURRENT = ("terminal_current_real", "terminal_current_imaginary")  # the machine's bus-port current


@dataclass(frozen=True)
class Source:
    """Where a device input comes from: `bus` (the bus voltage: index 0 its magnitude, 1 its
    angle), `device` (output `variable` of device `device` of the unit, or of unit `unit`),
    `terminal` (the terminal voltage: index 0 its magnitude, 1 its angle), `measured` (MEASURED[index]
    of the device's Measurement) or `held` (a set point at its start value)."""

    kind: str
    device: int | None = None
    variable: str | None = None
    index: int | None = None
    unit: int | None = None  # a device of another unit (its index in the case): a signal the unit takes (Unit.takes)


def unit_wiring(ports, where: str = "a unit", remote=None) -> tuple:
    """The wiring of a unit from its devices' Ports (the machine, with the bus port, first): per
    device a dict {input variable: Source} over its bus-port and link inputs. An input link takes
    the output link of the same signal of another device; `terminal_voltage` and
    `terminal_voltage_angle` with no giver come from the bus (behind the machine's external
    impedance), `terminal_current_real` and `_imaginary` with no giver from the machine's bus-port
    current outputs (system base, network frame); any other input link nothing gives is held. A
    device that takes and gives one signal sits in series on it (a multi-mass shaft between the
    governor and the rotor: `mechanical_power`): it takes the other giver's, and the other takers
    take its. A signal no device of the unit gives and the unit takes from another (`remote`: its
    remote_wiring, {signal: Source}) comes from there. CaseError where two devices give one signal
    otherwise or the first device has no bus port."""
    ports = list(ports)
    if not ports or ports[0] is None or ports[0].bus is None:
        raise CaseError(f"{where}: its machine declares no bus port")
    wiring = []
    for j, p in enumerate(ports):
        wires = {}
        if p is None:
            raise CaseError(f"{where}: device {j + 1} declares no ports")
        if p.bus is not None:
            if j > 0:
                raise CaseError(f"{where}: only the machine may have a bus port")
            wires[p.bus.voltage[0]] = Source("bus", index=0)
            wires[p.bus.voltage[1]] = Source("bus", index=1)
        for link in p.inputs:
            givers = [(i, q.output(link.signal)) for i, q in enumerate(ports) if i != j and q.output(link.signal)]
            series = [(i, v) for i, v in givers if ports[i].input(link.signal)]
            if len(givers) == 2 and len(series) == 1:  # a device in series on the signal gives it to the rest
                givers = series
            if len(givers) > 1:
                raise CaseError(f"{where}: {len(givers)} devices give the signal {link.signal}")
            if givers and remote and link.signal in remote:
                raise CaseError(f"{where}: takes {link.signal} from another unit, and a device of its own gives it")
            if givers:
                wires[link.variable] = Source("device", device=givers[0][0], variable=givers[0][1])
            elif remote and link.signal in remote:
                wires[link.variable] = remote[link.signal]
            elif link.signal in TERMINAL:
                wires[link.variable] = Source("terminal", index=TERMINAL.index(link.signal))
            elif link.signal in MEASURED:
                wires[link.variable] = Source("measured", index=MEASURED.index(link.signal))
            elif link.signal in TERMINAL_CURRENT and j > 0:
                wires[link.variable] = Source("device", device=0,
                                              variable=ports[0].bus.current[TERMINAL_CURRENT.index(link.signal)])
            else:
                wires[link.variable] = Source("held")
        wiring.append(wires)
    return tuple(wiring)


def step_order(wiring) -> tuple:
    """The order in which a master steps a unit's devices: the control devices, each after the
    control devices it takes a signal from (where they do not take one from each other), then the
    machine (device 0) last, so that it gets every control signal at the step's end (a signal from
    another unit: as the master's pass has it)."""
    controls = list(range(1, len(wiring)))
    order = []
    while controls:
        ready = [j for j in controls if all(s.device in order or s.device in (0, j) or s.kind != "device"
                                            or s.unit is not None for s in wiring[j].values())] or controls[:1]
        order.append(ready[0])
        controls.remove(ready[0])
    return tuple(order) + (0,)


def held_inputs(ports, wires) -> tuple:
    """The link inputs of a device (its Ports and wiring) that nothing in its unit gives (set
    points), in its ports' order."""
    return tuple(link.variable for link in ports.inputs if wires[link.variable].kind == "held")
