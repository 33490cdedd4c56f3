"""The WSCC 9-bus system (Anderson & Fouad): load flow, admittance matrix, start values, and the
monolithic reference against the grid issue's measurements."""
import math

import numpy as np
import pytest

pytest.importorskip("pandapower")

from reference_models.grid import monolithic, wscc9  # noqa: E402
from reference_models.grid.monolithic import simulate_wscc9  # noqa: E402
from reference_models.sm4 import SM4  # noqa: E402

FIVE_CYCLES = 5.0 / 60.0


@pytest.fixture(scope="module")
def grid():
    return monolithic.system()


def test_load_flow_matches_the_published_operating_point():
    flow = wscc9.load_flow()
    assert math.degrees(flow.theta[wscc9.bus_index(2)]) == pytest.approx(9.280, abs=5e-4)
    np.testing.assert_allclose(flow.P_gen, [0.7164, 1.63, 0.85], atol=5e-5)
    np.testing.assert_allclose(flow.Q_gen, [0.2705, 0.0665, -0.1086], atol=5e-5)
    np.testing.assert_allclose(flow.V[:3], [1.04, 1.025, 1.025], atol=1e-12)


def test_pandapower_ybus_is_the_one_assembled_from_the_data():
    flow = wscc9.load_flow()
    Y = wscc9.assemble_ybus()
    assert np.max(np.abs(flow.Ybus - Y)) < 1e-10
    # the load flow's own mismatch with that matrix: the generator and load injections
    S = flow.V_complex * np.conj(Y @ flow.V_complex)
    injected = -flow.S_load
    injected[:3] += flow.P_gen + 1j * flow.Q_gen
    assert np.max(np.abs(S - injected)) < 1e-9


def test_machine_files_are_sm4_machine_files():
    for g in wscc9.dynamic_data():
        assert SM4.load_params(wscc9.machine_file(g.bus)) == g.machine
        assert g.machine.D == 0 and g.machine.Xep == 0 and g.machine.Re == 0
        assert g.machine.Wb == pytest.approx(2 * math.pi * 60)
    assert wscc9.dynamic_data()[2].machine.H == 3.01


def test_trips_that_keep_every_generator_connected():
    assert wscc9.trips_at(7) == ("5-7", "7-8")
    assert wscc9.disconnects_generator("1-4") and not wscc9.disconnects_generator("7-5")
    with pytest.raises(ValueError, match="disconnects a generator"):
        simulate_wscc9(7, 0.05, trip="2-7", stop=0.1)
    with pytest.raises(ValueError, match="no bus"):
        simulate_wscc9(10, 0.05, stop=0.1)
    with pytest.raises(ValueError, match="no branch"):
        simulate_wscc9(7, 0.05, trip="5-9", stop=0.1)
    with pytest.raises(ValueError, match="after the fault start"):
        simulate_wscc9(7, 0.1, fault_start=0.2, stop=0.3)


def test_start_values_match_the_published_ones(grid):
    np.testing.assert_allclose(grid.Efd0, [1.0821, 1.7893, 1.4030], atol=5e-5)
    delta = grid.x0[[grid.machine_slice(k).start for k in range(3)]]
    assert math.degrees(delta[1] - delta[0]) == pytest.approx(57.51, abs=5e-3)
    assert math.degrees(delta[2] - delta[0]) == pytest.approx(50.55, abs=5e-3)
    np.testing.assert_allclose(grid.Pm, wscc9.load_flow().P_gen, rtol=1e-12)


def test_machine_current_is_affine_in_its_bus_voltage(grid):
    rng = np.random.default_rng(1)
    for k, p in enumerate(grid.machines):
        x = list(grid.x0[grid.machine_slice(k)] + rng.normal(0, 0.3, 4))
        c, A = monolithic._current_map(x, p, math)
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
    for name in ("delta", "omega", "Ed_p", "Eq_p", "Efd", "RF", "VR", "Vs", "theta_vs", "V_bus"):
        values = getattr(r, name)
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
    columns = r.columns()
    assert {"time", "delta_1", "omega_3", "Efd_2", "V_9"} <= set(columns)
    assert columns["V_7"] is not None and len(columns["delta_2"]) == len(r.time)


def test_bus7_fault_with_field_voltage_held_loses_synchronism():
    r = simulate_wscc9(7, FIVE_CYCLES, trip="5-7", stop=1.0, exciters=False)
    assert not r.stable
    assert 0.3 < r.loss_of_synchronism_s < 1.0
    np.testing.assert_allclose(r.Efd, np.broadcast_to(r.Efd[0], r.Efd.shape))


def test_solved_voltages_satisfy_the_full_network_equations(grid):
    """Kron reduction and the affine machine currents against KCL on all nine buses, in a fault-on
    and a post-trip topology, at states away from the equilibrium."""
    rng = np.random.default_rng(2)
    y = grid.x0 + rng.normal(0.0, 0.2, (4, grid.x0.size))
    for net in (grid.network(7, 0.01 + 0.02j), grid.network(out_of_service=["6-9"])):
        rows = grid.observe(np.zeros(len(y)), y, net)
        for n in range(len(y)):
            injected = np.zeros(9, dtype=complex)
            for k, p in enumerate(grid.machines):
                u = np.array([rows["Vs"][n, k], rows["theta_vs"][n, k], 0.0, 0.0])
                out = SM4.output_values(y[n, grid.machine_slice(k)], u, p)
                injected[wscc9.bus_index(wscc9.GENERATOR_BUSES[k])] = out[2] + 1j * out[3]
            np.testing.assert_allclose(net.Y @ rows["V_bus"][n], injected, atol=1e-9)


def test_trip_without_fault_and_clearing_after_stop():
    r = simulate_wscc9(None, 0.1, trip="8-9", stop=0.3, step=0.1)
    assert [t for t, _ in r.events] == [0.1] and r.stable
    assert np.max(np.abs(r.omega[1])) < 1e-8 < np.max(np.abs(r.omega[-1]))
    held = simulate_wscc9(8, 1.0, stop=0.2, step=0.1)  # the fault lasts to the end
    assert [t for t, _ in held.events] == [0.0] and held.V_bus[-1, wscc9.bus_index(8)] < 1e-4
