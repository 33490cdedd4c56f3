"""What a sub-system attached at a host bus exchanges with the host, read from the network alone.

A sub-system attached at host bus B (reference_models.grid.attach) is the set of buses that
removing B cuts off from the case's slack and that attach numbered: `subsystem_buses`. What it injects into B (generator
convention, system base) is the sum over the branches between B and those buses of V_B conj(I)
with I the branch current leaving B towards the host side negated: `boundary_power`. Works for a
radial sub-system behind one bus. Its rating (`subsystem_rating`, MVA) is
the sum of the ratings Sn of its generating devices: the bus devices of the generator units (not
the loads) at its buses that declare a rating Sn (a PVD1, an REGCA1, a machine; a static generator
without a converter declares none).
"""
from __future__ import annotations

import numpy as np


def subsystem_buses(network, bus: int) -> tuple:
    """The buses (numbers, file order) of the sub-system attached at host bus `bus`: the parts of the
    network that removing `bus` cuts off from the case's slack bus (its first load-flow generator
    where none is a slack) and that attach numbered, each from a multiple of attach.BUS_BLOCK (a
    part of the host that hangs off `bus` alone, a generator behind its step-up transformer, is not
    one); ValueError where there are none."""
    from .attach import BUS_BLOCK

    if bus not in network.buses:
        raise ValueError(f"{network.name} has no bus {bus}")
    neighbours = {b: set() for b in network.buses}
    for br in network.branches:
        if br.from_bus != br.to_bus:
            neighbours[br.from_bus].add(br.to_bus)
            neighbours[br.to_bus].add(br.from_bus)
    slack = next((g.bus for g in network.generators if g.kind == "slack"), None)
    if slack is None and network.generators:
        slack = network.generators[0].bus
    behind = set()
    reached = {bus} | (_part(neighbours, slack, {bus}) if slack is not None and slack != bus else set())
    for start in sorted(neighbours[bus] - reached):
        part = _part(neighbours, start, {bus})
        reached |= part
        if min(part) > 0 and min(part) % BUS_BLOCK == 0:
            behind |= part
    if not behind:
        raise ValueError(f"no sub-system is attached at bus {bus} of {network.name}: removing it cuts off no part "
                         f"numbered from a multiple of {BUS_BLOCK}")
    return tuple(b for b in network.buses if b in behind)


def _part(neighbours: dict, start: int, removed: set) -> set:
    """The buses connected to `start` without passing through `removed`."""
    seen, todo = {start}, [start]
    while todo:
        for nb in neighbours[todo.pop()] - seen - removed:
            seen.add(nb)
            todo.append(nb)
    return seen


def boundary_current(network, V_bus: np.ndarray, theta_bus: np.ndarray, bus: int, behind=None) -> np.ndarray:
    """[n] complex: the current [pu, system base, network frame] that the sub-system behind host bus
    `bus` injects into it, from the bus voltages V_bus, theta_bus [n, n_bus] (pu, rad; the network's
    bus order) and the pi model of each branch between `bus` and the buses `behind` (default
    subsystem_buses(network, bus))."""
    behind = set(subsystem_buses(network, bus) if behind is None else behind)
    V = np.asarray(V_bus) * np.exp(1j * np.asarray(theta_bus))
    i = network.bus_index(bus)
    current = np.zeros(V.shape[0], complex)
    for br in network.branches:
        ends = (br.from_bus, br.to_bus)
        if bus not in ends or not behind.intersection(ends):
            continue
        y = 1.0 / complex(br.r, br.x)
        m = br.tap * np.exp(1j * br.phi)
        j = network.bus_index(br.to_bus if br.from_bus == bus else br.from_bus)
        if br.from_bus == bus:  # the current from `bus` into the branch, tap at `bus`
            current -= (y + 0.5j * br.b) / br.tap ** 2 * V[:, i] - y / np.conj(m) * V[:, j]
        else:
            current -= (y + 0.5j * br.b) * V[:, i] - y / m * V[:, j]
    return current


def boundary_power(network, V_bus: np.ndarray, theta_bus: np.ndarray, bus: int, behind=None) -> np.ndarray:
    """[n] complex: P + jQ [pu, system base] that the sub-system behind host bus `bus` injects into
    it (generator convention); arguments as boundary_current."""
    V = np.asarray(V_bus)[:, network.bus_index(bus)] * np.exp(1j * np.asarray(theta_bus)[:, network.bus_index(bus)])
    return V * np.conj(boundary_current(network, V_bus, theta_bus, bus, behind))


def passive_admittance(network, load_admittances: np.ndarray, bus: int, behind=None) -> complex:
    """Y [pu, system base]: the admittance the sub-system behind host bus `bus` presents there with
    every device's current taken out (its branches, shunts and constant-impedance loads
    `load_admittances` [n_bus], Kron-reduced onto `bus`): it draws Y V from the bus."""
    behind = list(subsystem_buses(network, bus) if behind is None else behind)
    inside = [network.bus_index(b) for b in behind]
    b = network.bus_index(bus)
    Y = network.ybus() + np.diag(np.asarray(load_admittances, complex))
    own = 0j  # what the branches into the sub-system add to Y[b, b]
    for br in network.branches:
        if bus in (br.from_bus, br.to_bus) and set(behind).intersection((br.from_bus, br.to_bus)):
            y = 1.0 / complex(br.r, br.x) + 0.5j * br.b
            own += y / br.tap ** 2 if br.from_bus == bus else y
    Y_ii, Y_ib, Y_bi = Y[np.ix_(inside, inside)], Y[inside, b], Y[b, inside]
    return complex(own - Y_bi @ np.linalg.solve(Y_ii, Y_ib))


def with_equivalent(case, bus: int, device, fmu=None):
    """`case` with the sub-system behind host bus `bus` replaced by the one bus device `device` at
    `bus` (a `subsystem` equivalent: reference_models.models.subsystem), started from the load
    flow's injection into `bus`; `fmu`: the unit's FMU entry (e.g. {"kind": "surrogate", "operator":
    path}). The network, load flow, units and events keep what lies on the host's side; the new unit
    is a load unit drawing minus that injection (case.operating_point)."""
    from dataclasses import replace

    from .case import Unit, operating_point, unit_start

    net, flow = case.network, case.flow
    behind = set(subsystem_buses(net, bus))
    injected = boundary_power(net, flow.V[None, :], flow.theta[None, :], bus, behind)[0]
    host = [b for b in net.buses if b not in behind]
    rows = [net.bus_index(b) for b in host]
    kept = [k for k, g in enumerate(net.generators) if g.bus not in behind]
    network = replace(net, buses=tuple(host),
                      branches=tuple(br for br in net.branches if not behind.intersection((br.from_bus, br.to_bus))),
                      loads={b: s for b, s in net.loads.items() if b not in behind},
                      shunts={b: s for b, s in net.shunts.items() if b not in behind},
                      generators=tuple(net.generators[k] for k in kept),
                      kv={b: v for b, v in net.kv.items() if b not in behind})
    load_flow = replace(flow, buses=tuple(host), generator_buses=tuple(net.generators[k].bus for k in kept),
                        V=flow.V[rows], theta=flow.theta[rows], P_gen=flow.P_gen[kept], Q_gen=flow.Q_gen[kept],
                        S_load=flow.S_load[rows])
    pairs = [(u, s) for u, s in zip(case.units, case.starts) if u.bus not in behind]
    unit = Unit(bus, (device,), fmu, load=-complex(injected))
    start = unit_start(unit, operating_point(unit, len(pairs), load_flow))
    events = tuple(e for e in case.events if not behind.intersection(
        b for b in (e.bus, *(_ends(net, e.branch) if e.branch else ())) if b is not None))
    return replace(case, name=f"{case.name} with an equivalent at bus {bus}", network=network, flow=load_flow,
                   units=tuple(u for u, _ in pairs) + (unit,), starts=tuple(s for _, s in pairs) + (start,),
                   events=events, source=None)


def _ends(network, branch: str) -> tuple:
    br = network.branch(branch)
    return br.from_bus, br.to_bus


def equivalent_units(case, bus: int) -> list:
    """Indices of the units at `bus` that stand for a whole sub-system (with_equivalent: a bus
    device whose rates are partly learned, a `subsystem`)."""
    return [k for k, u in enumerate(case.units) if u.bus == bus and u.machine.component.learned_states]


def subsystem_rating(case, bus: int, behind=None) -> float:
    """The rating [MVA] of the sub-system behind host bus `bus` of `case` (reference_models.grid.case.
    Case): the sum of Sn over the bus devices of its generator units (Unit.load None) at the buses
    `behind` (default subsystem_buses(case.network, bus)) that have a parameter Sn; for a sub-system
    run as its equivalent (equivalent_units), the equivalent's rating S."""
    if behind is None and equivalent_units(case, bus):
        return float(sum(case.units[k].machine.params.S for k in equivalent_units(case, bus)))
    behind = set(subsystem_buses(case.network, bus) if behind is None else behind)
    return float(sum(getattr(u.machine.params, "Sn", 0.0) for u in case.units
                     if u.bus in behind and u.load is None))
