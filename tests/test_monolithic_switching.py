"""The monolithic DAE through limiter switchings: its right-hand side runs on locked branches, the
switchings are located and the solve restarts there with the limit resets applied, so cases whose
exciters hit their ceilings get through a fault; tripped units inject nothing and stand still; and
(with ANDES) the rotor angles follow ANDES' own simulation of the same fault."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from reference_models.grid.case import shipped_case
from reference_models.grid.contingency import Contingency, Topology
from reference_models.grid.monolithic import System, simulate


def test_ieee39_gets_through_a_fault_that_drives_its_exciters_onto_their_ceilings():
    """ieee39, fault at bus 16 0.05-0.15 s: the regulators (LA_y) of several IEEEX1 reach their
    ceiling VRMAX and stay on it while the fault lasts, none goes beyond it, and the solve reaches
    its end within the budget of right-hand-side evaluations."""
    case = shipped_case("ieee39")
    result = simulate(System(case), Contingency(16, 0.15, None, 0.05, 1e-4j, case.network), 0.3, step=0.001,
                      rtol=1e-9, atol=1e-11)
    assert result.time[-1] == pytest.approx(0.3)
    ceilings = np.array([next(d for d in u.devices if d.component.name == "ieeex1").params.VRMAX for u in case.units])
    margin = ceilings - result.device_column("ieeex1", "LA_y")
    assert np.min(margin) > -1e-9
    on = np.abs(margin) < 1e-9
    assert np.sum(np.any(on, axis=0)) >= 2
    fault = (result.time > 0.12) & (result.time < 0.15)
    assert np.sum(np.all(on[fault], axis=0)) >= 2  # held on the ceiling to the clearing


def test_a_locked_solve_agrees_with_one_at_a_hundred_times_tighter_tolerance_through_switchings():
    """Kundur, fault at bus 8 1.0-1.1 s (its EXDC2 regulators hit their limits during the fault and
    leave them after): DOP853 at rtol 1e-7 and RK45 at rtol 1e-9 give the same rotor angles to
    1e-4 deg, as the switchings are located rather than stepped over."""
    case = shipped_case("kundur")
    system = System(case)
    contingency = Contingency(8, 1.1, None, 1.0, 1e-4j, case.network)
    coarse = simulate(system, contingency, 1.6, step=0.01, rtol=1e-7, atol=1e-9)
    tight = simulate(system, contingency, 1.6, step=0.01, method="RK45", rtol=1e-9, atol=1e-11)
    assert np.max(np.ptp(tight.device_column("exdc2", "LA_y"), axis=0)) > 0.5  # the regulators move far (to their limits)
    delta_c, delta_t = coarse.angles, tight.angles
    error = np.max(np.abs((delta_c - delta_c[:, :1]) - (delta_t - delta_t[:, :1])))
    assert math.degrees(error) < 1e-4


@dataclass(frozen=True)
class _UnitTrip:
    """Topologies (Contingency.topologies' interface): intact, then unit `unit` tripped from `at`."""

    unit: int
    at: float
    fault_impedance: complex = 1e-6

    def topologies(self, stop: float) -> list:
        return [Topology(0.0, None, (), "intact"),
                Topology(self.at, None, (), f"unit {self.unit} tripped", tripped=(self.unit,))]


def test_a_tripped_unit_injects_nothing_its_devices_stand_still_and_the_rest_move():
    case = shipped_case("kundur")
    system = System(case)
    result = simulate(system, _UnitTrip(1, 0.2), 1.0, step=0.01)
    after = result.time > 0.2
    assert np.all(result.P[after, 1] == 0) and np.all(result.Q[after, 1] == 0)
    for name, values in result.states.items():
        column = values[after, 1]
        assert np.all(column == column[0]), name  # every state of the tripped unit stands still
    delta = result.states["delta"]
    assert np.ptp(delta[after, 0] - delta[after, 2]) > math.radians(0.5)  # the others swing on the lost power
    assert result.stable


def test_a_tripped_unit_leaves_the_voltages_as_a_network_without_its_injection():
    """System level: the bus voltages with unit k tripped are those of the reduced network with unit
    k's current set to zero, and its derivatives are zero."""
    case = shipped_case("kundur")
    system = System(case)
    network = system.network()
    V_re, V_im = system.generator_voltages(system.x0, network, tripped=(2,))
    V = V_re + 1j * V_im
    v = np.empty(2 * len(system.first_unit))  # the reduced network's bus voltages, re/im interleaved
    for k, slot in enumerate(system.bus_slot):
        v[2 * slot], v[2 * slot + 1] = V[k].real, V[k].imag
    injected = np.asarray(network.Y_real) @ v  # the currents the units inject, I = Y_red V
    slot = system.bus_slot[2]
    assert abs(complex(injected[2 * slot], injected[2 * slot + 1])) < 1e-9
    assert abs(complex(injected[0], injected[1])) > 0.1
    rates = system.rhs(0.0, system.x0, network, tripped=(2,))
    for j in range(len(case.units[2].devices)):
        assert np.all(rates[system.slices[2][j]] == 0)
    others = system.rhs(0.0, system.x0, network)
    assert np.max(np.abs(others)) < 1e-9 < np.max(np.abs(np.delete(rates, np.r_[system.slices[2][0]])))


@pytest.mark.andes
def test_ieee39_rotor_angles_follow_andes_through_exciter_ceilings():
    """ieee39, fault (1e-4j pu) at bus 16 0.2-0.3 s, 1 s, ANDES at h = 1 ms: the exciters of the
    units near the fault go to their ceilings and back, and every rotor-angle difference stays
    within 0.1 deg of ANDES' (measured 0.0225 deg over 3 s for the fault at 1.0-1.1 s)."""
    from cosim.andes_runner import AndesRunner
    from cosim.outputs import on_times

    case = shipped_case("ieee39")
    contingency = Contingency(16, 0.3, None, 0.2, 1e-4j, case.network)
    andes, _ = AndesRunner(case, 0.001).run(contingency, 1.0)
    mono = simulate(System(case), contingency, 1.0, step=0.001, rtol=1e-9, atol=1e-11)
    a = andes.states["delta"]
    m = on_times(mono, andes.time, mono.states["delta"])
    assert math.degrees(np.max(np.abs((m - m[:, :1]) - (a - a[:, :1])))) < 0.1
