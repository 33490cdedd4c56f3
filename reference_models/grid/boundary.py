"""What a sub-system attached at a host bus exchanges with the host, read from the network alone.

A sub-system attached at host bus B (reference_models.grid.attach) is the set of buses that
removing B cuts off from the case's slack: `subsystem_buses`. What it injects into B (generator
convention, system base) is the sum over the branches between B and those buses of V_B conj(I)
with I the branch current leaving B towards the host side negated: `boundary_power`. Works for a
radial sub-system behind one bus, whatever its bus numbers. Its rating (`subsystem_rating`, MVA) is
the sum of the ratings Sn of its generating devices: the bus devices of the generator units (not
the loads) at its buses that declare a rating Sn (a PVD1, an REGCA1, a machine; a static generator
without a converter declares none).
"""
from __future__ import annotations

import numpy as np


def subsystem_buses(network, bus: int) -> tuple:
    """The buses (numbers, file order) that removing host bus `bus` cuts off from the case's slack
    bus (its first load-flow generator where none is a slack); ValueError where none are."""
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
    seen, todo = {bus}, [slack] if slack is not None and slack != bus else []
    seen.update(todo)
    while todo:
        for nb in neighbours[todo.pop()] - seen:
            seen.add(nb)
            todo.append(nb)
    behind = tuple(b for b in network.buses if b not in seen)
    if not behind or slack == bus:
        raise ValueError(f"no sub-system is attached at bus {bus} of {network.name}: removing it cuts no bus "
                         f"off the slack")
    return behind


def boundary_power(network, V_bus: np.ndarray, theta_bus: np.ndarray, bus: int, behind=None) -> np.ndarray:
    """[n] complex: P + jQ [pu, system base] that the sub-system behind host bus `bus` injects into
    it (generator convention), from the bus voltages V_bus, theta_bus [n, n_bus] (pu, rad; the
    network's bus order) and the pi model of each branch between `bus` and the buses `behind`
    (default subsystem_buses(network, bus))."""
    behind = set(subsystem_buses(network, bus) if behind is None else behind)
    V = np.asarray(V_bus) * np.exp(1j * np.asarray(theta_bus))
    i = network.bus_index(bus)
    S = np.zeros(V.shape[0], complex)
    for br in network.branches:
        ends = (br.from_bus, br.to_bus)
        if bus not in ends or not behind.intersection(ends):
            continue
        y = 1.0 / complex(br.r, br.x)
        m = br.tap * np.exp(1j * br.phi)
        j = network.bus_index(br.to_bus if br.from_bus == bus else br.from_bus)
        if br.from_bus == bus:  # the current from `bus` into the branch, tap at `bus`
            into = (y + 0.5j * br.b) / br.tap ** 2 * V[:, i] - y / np.conj(m) * V[:, j]
        else:
            into = (y + 0.5j * br.b) * V[:, i] - y / m * V[:, j]
        S -= V[:, i] * np.conj(into)
    return S


def subsystem_rating(case, bus: int, behind=None) -> float:
    """The rating [MVA] of the sub-system behind host bus `bus` of `case` (reference_models.grid.case.
    Case): the sum of Sn over the bus devices of its generator units (Unit.load None) at the buses
    `behind` (default subsystem_buses(case.network, bus)) that have a parameter Sn."""
    behind = set(subsystem_buses(case.network, bus) if behind is None else behind)
    return float(sum(getattr(u.machine.params, "Sn", 0.0) for u in case.units
                     if u.bus in behind and u.load is None))
