"""The WSCC 9-bus system (Anderson & Fouad) as a case: its shipped load flow (pandapower's, checked),
admittance matrix, units and start values, refusals of malformed dynamic data, and the monolithic
reference against the grid issue's measurements."""
import json
import math

import numpy as np
import pytest

from reference_models.grid import monolithic, wscc9
from reference_models.grid.case import CaseError, Source, load_units, unit_wiring
from reference_models.grid.contingency import Contingency
from reference_models.sm4 import SM4

FIVE_CYCLES = 5.0 / 60.0
CASE = wscc9.case()


@pytest.fixture(scope="module")
def grid():
    return monolithic.System(CASE)


def simulate_wscc9(fault_bus, clear_s, trip=None, fault_start=0.0, stop=5.0, **options):
    return monolithic.simulate(monolithic.System(CASE), Contingency(fault_bus, clear_s, trip, fault_start), stop,
                               **options)


def test_the_shipped_load_flow_is_pandapowers_solution_of_the_network():
    pytest.importorskip("pandapower")
    solved, shipped = wscc9.solve_load_flow(), wscc9.load_flow()
    np.testing.assert_allclose(shipped.V, solved["V"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(shipped.theta, solved["theta"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(shipped.P_gen, solved["P"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(shipped.Q_gen, solved["Q"], rtol=0, atol=1e-12)
    ybus = wscc9.NETWORK.ybus()  # entries up to about 40 pu
    assert np.max(np.abs(solved["Ybus"] - ybus)) < 1e-10 * max(1.0, np.abs(ybus).max())


def test_load_flow_matches_the_published_operating_point():
    flow = wscc9.load_flow()
    assert math.degrees(flow.theta[wscc9.bus_index(2)]) == pytest.approx(9.280, abs=5e-4)
    np.testing.assert_allclose(flow.P_gen, [0.7164, 1.63, 0.85], atol=5e-5)
    np.testing.assert_allclose(flow.Q_gen, [0.2705, 0.0665, -0.1086], atol=5e-5)
    np.testing.assert_allclose(flow.V[:3], [1.04, 1.025, 1.025], atol=1e-12)


def test_the_load_flow_satisfies_the_network_assembled_from_the_data():
    flow = wscc9.load_flow()
    Y = wscc9.NETWORK.ybus()
    # the load flow's own mismatch with that matrix: the generator and load injections
    S = flow.V_complex * np.conj(Y @ flow.V_complex)
    injected = -flow.S_load
    injected[:3] += flow.P_gen + 1j * flow.Q_gen
    assert np.max(np.abs(S - injected)) < 1e-9


def test_units_are_an_sm4_machine_from_its_file_and_an_exciter():
    for unit in CASE.units:
        machine = unit.machine
        assert machine.component is SM4 and SM4.load_params(wscc9.machine_file(unit.bus)) == machine.params
        assert machine.params.D == 0 and machine.params.Xep == 0 and machine.params.Re == 0
        assert machine.params.Wb == pytest.approx(2 * math.pi * 60)
        assert [d.name for d in unit.devices] == ["machine", "exciter"]
    assert CASE.units[2].machine.params.H == 3.01


def dynamic_data(tmp_path, generators):
    path = tmp_path / "dynamic.json"
    path.write_text(json.dumps({"generators": generators}))
    for bus in wscc9.GENERATOR_BUSES:
        (tmp_path / f"wscc9_gen{bus}.json").write_text(wscc9.machine_file(bus).read_text())
    return path


def unit(bus, machine="sm4", exciter="ieee1"):
    first = {"component": machine, "file": f"wscc9_gen{bus}.json"} if machine == "sm4" else {"component": machine}
    return {"bus": bus, "machine": first, "exciter": {"component": exciter, "params": {}}}


@pytest.mark.parametrize("generators, message", [
    ([unit(1), unit(2), unit(2), unit(3)], "bus 2: the bus has two generator entries"),
    ([unit(1), unit(2)], "needs one generator at each of the buses"),
    ([unit(1), unit(2), unit(3, exciter="avr9")], "unknown component"),
    ([unit(1), unit(2), unit(3, machine="ieee1", exciter="ieee1")], "exactly one device with a bus port"),
])
def test_malformed_dynamic_data_is_refused_naming_the_generator(tmp_path, generators, message):
    with pytest.raises(CaseError, match=message):
        load_units(dynamic_data(tmp_path, generators), wscc9.GENERATOR_BUSES)


def test_a_governor_on_an_sm4_machine_takes_its_speed_in_pu(tmp_path):
    """TGOV1 (speed in pu, as GENROU gives it) on generator 1 takes SM4's rotor_speed = 1 + omega / Wb:
    its valve is the lag 1 / (1 + s T1) of Pm0 - (rotor_speed - 1) / R along the run's own speed."""
    governed = dict(unit(1), governor={"component": "tgov1", "params": {}})
    case = wscc9.case(dynamic_data(tmp_path, [governed, unit(2), unit(3)]))
    machine, _, governor = case.units[0].devices
    wiring = unit_wiring([d.component.ports for d in case.units[0].devices])
    assert wiring[2]["omega"] == Source("device", device=0, variable="rotor_speed")
    r = monolithic.simulate(monolithic.System(case), Contingency(7, 0.1), 2.0, step=0.001)
    valve, speed = r.device_states["TGOV1_1_LAG_y"], 1.0 + r.omega[:, 0] / machine.params.Wb
    demand = valve[0] - (speed - 1.0) / governor.params.R  # Pref = R Pm0: at rest the valve is Pm0
    T1, lagged = governor.params.T1, [valve[0]]
    for k in range(1, len(r.time)):  # the lag's exact step with the demand linear between rows
        h = r.time[k] - r.time[k - 1]
        rate = (demand[k] - demand[k - 1]) / h
        lagged.append(demand[k] - rate * T1 + (lagged[-1] - demand[k - 1] + rate * T1) * math.exp(-h / T1))
    assert valve[0] == pytest.approx(wscc9.load_flow().P_gen[0], abs=1e-9)
    assert valve.min() < valve[0] - 0.1  # the machine sped up by several rad/s, the valve closed
    np.testing.assert_allclose(valve, lagged, rtol=0, atol=1e-5)


def test_trips_that_keep_every_generator_connected():
    assert wscc9.NETWORK.trips_at(7) == ("5-7", "7-8")
    assert wscc9.NETWORK.disconnects_generator("1-4") and not wscc9.NETWORK.disconnects_generator("7-5")
    with pytest.raises(ValueError, match="disconnects a generator"):
        simulate_wscc9(7, 0.05, trip="2-7", stop=0.1)
    with pytest.raises(ValueError, match="no bus"):
        simulate_wscc9(10, 0.05, stop=0.1)
    with pytest.raises(ValueError, match="no branch"):
        simulate_wscc9(7, 0.05, trip="5-9", stop=0.1)
    with pytest.raises(ValueError, match="after the fault start"):
        simulate_wscc9(7, 0.1, fault_start=0.2, stop=0.3)


def test_start_values_match_the_published_ones(grid):
    machines = [start[0].inputs for start in CASE.starts]
    np.testing.assert_allclose([m["Efd"] for m in machines], [1.0821, 1.7893, 1.4030], atol=5e-5)
    delta = grid.x0[grid.rotor_angles]
    assert math.degrees(delta[1] - delta[0]) == pytest.approx(57.51, abs=5e-3)
    assert math.degrees(delta[2] - delta[0]) == pytest.approx(50.55, abs=5e-3)
    np.testing.assert_allclose([m["Pm"] for m in machines], wscc9.load_flow().P_gen, rtol=1e-12)


def test_machine_current_is_affine_in_its_bus_voltage(grid):
    rng = np.random.default_rng(1)
    for k, unit in enumerate(CASE.units):
        p = unit.machine.params
        x = list(grid.x0[grid.slices[k][0]] + rng.normal(0, 0.3, 4))
        c, A = monolithic._current_map(SM4, x, p, math)
        for _ in range(3):
            Vs, theta = rng.uniform(0.2, 1.3), rng.uniform(-4, 4)
            y = SM4.output_values(np.array(x), np.array([Vs, theta, 0.0, 0.0]), p)
            v = (Vs * math.cos(theta), Vs * math.sin(theta))
            expected = [c[r] + A[r][0] * v[0] + A[r][1] * v[1] for r in range(2)]
            np.testing.assert_allclose(y[2:4], expected, atol=1e-12)


def test_network_solve_at_the_start_gives_the_load_flow_voltages(grid):
    net = grid.network()
    rows = grid.observe([0.0], grid.x0[None, :], net)
    np.testing.assert_allclose(rows["V_bus"][0], wscc9.load_flow().V_complex, atol=1e-9)
    np.testing.assert_allclose(rows["P"][0] + 1j * rows["Q"][0],
                               wscc9.load_flow().P_gen + 1j * wscc9.load_flow().Q_gen, atol=1e-9)
    assert np.max(np.abs(grid.rhs(0.0, grid.x0, net))) < 1e-7


def test_flat_run_stays_at_the_equilibrium(grid):
    r = simulate_wscc9(None, None, stop=1.0, step=0.05)
    assert r.stable and r.events == ()
    for name, values in {**r.device_states, "Vs": r.Vs, "theta_vs": r.theta_vs, "V_bus": r.V_bus}.items():
        assert np.max(np.abs(values - values[0])) < 1e-8, name
    np.testing.assert_allclose(r.V_bus[0], wscc9.load_flow().V, atol=1e-9)


def test_bus7_fault_cleared_by_tripping_5_7_first_swing():
    """Issue 17: 5 cycles at bus 7, line 5-7 opened; with exciters the machines stay in step,
    first swing delta2 - delta1 = 161.2 deg at 0.77 s."""
    r = simulate_wscc9(7, FIVE_CYCLES, trip="5-7", stop=1.2, step=0.001, event_rows=True)
    assert r.stable and r.loss_of_synchronism_s is None
    assert [t for t, _ in r.events] == pytest.approx([0.0, FIVE_CYCLES])
    swing = np.degrees(r.angle_difference(2))
    i = int(np.argmax(swing))
    assert swing[i] == pytest.approx(161.2, abs=0.3)
    assert r.time[i] == pytest.approx(0.77, abs=0.01)
    # event rows: at t = 0 the pre-fault row (load-flow voltage), then the fault-on one
    assert r.time[0] == r.time[1] == 0.0
    assert r.V_bus[0, wscc9.bus_index(7)] == pytest.approx(wscc9.load_flow().V[6], abs=1e-9)
    assert r.V_bus[1, wscc9.bus_index(7)] < 1e-4
    columns = r.columns(wscc9.case())
    assert {"time", "delta_1", "omega_3", "Efd_2", "V_9"} <= set(columns)
    assert columns["V_7"] is not None and len(columns["delta_2"]) == len(r.time)


def test_bus7_fault_with_field_voltage_held_loses_synchronism():
    r = simulate_wscc9(7, FIVE_CYCLES, trip="5-7", stop=1.0, controls=False)
    assert not r.stable
    assert 0.3 < r.loss_of_synchronism_s < 1.0
    np.testing.assert_allclose(r.machine_inputs["Efd"], np.broadcast_to(r.machine_inputs["Efd"][0], (len(r.time), 3)))


def test_solved_voltages_satisfy_the_full_network_equations(grid):
    """Kron reduction and the affine machine currents against KCL on all nine buses, in a fault-on
    and a post-trip topology, at states away from the equilibrium."""
    rng = np.random.default_rng(2)
    y = grid.x0 + rng.normal(0.0, 0.2, (4, grid.x0.size))
    for net in (grid.network(7, 0.01 + 0.02j), grid.network(out_of_service=["6-9"])):
        rows = grid.observe(np.zeros(len(y)), y, net)
        for n in range(len(y)):
            injected = np.zeros(9, dtype=complex)
            for k, unit in enumerate(CASE.units):
                u = np.array([rows["Vs"][n, k], rows["theta_vs"][n, k], 0.0, 0.0])
                out = SM4.output_values(y[n, grid.slices[k][0]], u, unit.machine.params)
                injected[wscc9.bus_index(wscc9.GENERATOR_BUSES[k])] = out[2] + 1j * out[3]
            np.testing.assert_allclose(net.Y @ rows["V_bus"][n], injected, atol=1e-9)


def test_trip_without_fault_and_clearing_after_stop():
    r = simulate_wscc9(None, 0.1, trip="8-9", stop=0.3, step=0.1)
    assert [t for t, _ in r.events] == [0.1] and r.stable
    assert np.max(np.abs(r.omega[1])) < 1e-8 < np.max(np.abs(r.omega[-1]))
    held = simulate_wscc9(8, 1.0, stop=0.2, step=0.1)  # the fault lasts to the end
    assert [t for t, _ in held.events] == [0.0] and held.V_bus[-1, wscc9.bus_index(8)] < 1e-4
