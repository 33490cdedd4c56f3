"""The SM4 equations: one definition, numpy and torch, equilibrium and derived outputs."""
import numpy as np
import pytest
import torch

from reference_models.sm4 import (SM4, SM4Params, min_voltage_with_equilibrium, outputs, rhs,
                                  steady_state)


def random_points(n=200, seed=0):
    rng = np.random.default_rng(seed)
    x = np.column_stack([rng.uniform(-3, 3, n), rng.uniform(-2, 2, n), rng.uniform(-0.5, 0.5, n),
                         rng.uniform(0.2, 1.3, n)])
    u = np.column_stack([rng.uniform(0.2, 1.3, n), rng.uniform(-1, 1, n), rng.uniform(0, 1.5, n),
                         rng.uniform(0.5, 3, n)])
    return x, u

PM, EFD = SM4.inputs[2].start, SM4.inputs[3].start


def test_numpy_and_torch_right_hand_sides_agree_in_float64():
    x, u = random_points()
    expected = rhs(x, u)
    got = rhs(torch.tensor(x), torch.tensor(u)).numpy()
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)  # d omega/dt reaches hundreds


def test_numpy_and_torch_derived_outputs_agree_in_float64():
    x, u = random_points()
    np.testing.assert_allclose(outputs(torch.tensor(x), torch.tensor(u)).numpy(), outputs(x, u), rtol=1e-12,
                               atol=1e-12)


def test_torch_right_hand_side_is_differentiable_and_batched():
    x, u = random_points(6)
    xt = torch.tensor(x.reshape(2, 3, 4), requires_grad=True)
    ut = torch.tensor(u.reshape(2, 3, 4))
    assert rhs(xt, ut).shape == (2, 3, 4)
    assert torch.autograd.gradcheck(lambda z: rhs(z, ut), (xt,))


@pytest.mark.parametrize("Vs, theta, Pm, Efd", [(1.0, 0.0, PM, EFD), (0.9, -0.5, PM, EFD), (1.2, 0.5, 0.3, 1.5),
                                                (1.05, 0.2, 1.0, 2.4), (0.5, 3.0, 0.2, 1.0)])
def test_steady_state_has_zero_derivative(Vs, theta, Pm, Efd):
    x = steady_state(Vs, theta, Pm=Pm, Efd=Efd)
    assert np.max(np.abs(rhs(x, np.array([Vs, theta, Pm, Efd])))) < 1e-12


def test_the_equations_see_angles_only_through_their_difference_and_speed_through_pm_minus_d_omega():
    x, u = random_points()
    p = SM4Params()
    a, c = 30.0, 12.0
    turned_x, turned_u = x + [a, c, 0, 0], u + [0, a, p.D * c, 0]
    expected = rhs(x, u) + [c, 0, 0, 0]  # d delta/dt = omega carries the extra speed
    np.testing.assert_allclose(rhs(turned_x, turned_u), expected, rtol=1e-9, atol=1e-9)
    # the stator currents, the power and the speed too: only the network-frame current turns with the angle
    same = [0, 1, 4, 5, 6]
    np.testing.assert_allclose(outputs(x + [a, 0, 0, 0], u + [0, a, 0, 0])[:, same], outputs(x, u)[:, same], atol=1e-9)


def test_steady_state_at_nominal_voltage_is_the_documented_equilibrium():
    np.testing.assert_allclose(steady_state(1.0, 0.0), [1.0593, 0.0, 0.3336, 0.6347], atol=5e-5)


def test_steady_state_is_stable():
    x, u = steady_state(1.0, 0.0), np.array([1.0, 0.0, PM, EFD])
    eps = 1e-7
    jac = np.column_stack([(rhs(x + eps * e, u) - rhs(x - eps * e, u)) / (2 * eps) for e in np.eye(4)])
    assert np.all(np.linalg.eigvals(jac).real < 0)


def test_no_equilibrium_below_the_minimum_voltage():
    v_min = min_voltage_with_equilibrium()
    assert 0.85 < v_min < 0.9
    steady_state(v_min + 1e-6)
    with pytest.raises(ValueError, match="no stable equilibrium"):
        steady_state(v_min - 1e-3)


def test_more_field_or_less_power_lowers_the_minimum_voltage():
    p = SM4Params()
    v_min = min_voltage_with_equilibrium(p, PM, EFD)
    assert min_voltage_with_equilibrium(p, PM, 2.0 * EFD) < v_min
    assert min_voltage_with_equilibrium(p, 0.5 * PM, EFD) < v_min
    steady_state(0.8, 0.0, p, Pm=PM, Efd=2.0 * EFD)


def test_bus_power_equals_air_gap_power_without_resistance():
    x, u = random_points()
    p = SM4Params()
    Id, Iq, _, _, P, _, _ = outputs(x, u).T
    Pe = x[:, 2] * Id + x[:, 3] * Iq + (p.Xq_p - p.Xd_p) * Id * Iq
    np.testing.assert_allclose(P, Pe, rtol=0, atol=1e-12)


def test_network_frame_current_has_the_dq_current_magnitude():
    x, u = random_points()
    Id, Iq, I_re, I_im, _, _, _ = outputs(x, u).T
    np.testing.assert_allclose(np.hypot(I_re, I_im), np.hypot(Id, Iq), rtol=1e-12)


def test_rotor_speed_is_in_pu_of_synchronous_speed_as_the_standard_machines_speed():
    from reference_models.models.genrou import GENROU
    from reference_models.ports import SIGNALS

    x, u = random_points()
    p = SM4Params(Wb=2 * np.pi * 60.0)
    np.testing.assert_allclose(outputs(x, u, p)[:, 6], 1.0 + x[:, 1] / p.Wb, rtol=1e-15)
    assert outputs(steady_state(1.0, 0.0, p), np.array([1.0, 0.0, PM, EFD]), p)[6] == 1.0
    # the port link a governor or stabiliser takes: the same signal and unit as GENROU's omega
    units = {q.name: q.unit for q in SM4.states + SM4.outputs}
    genrou = {q.name: q.unit for q in GENROU.states + GENROU.outputs}
    assert SM4.ports.output("rotor_speed") == "rotor_speed" and GENROU.ports.output("rotor_speed") == "omega"
    assert units["rotor_speed"] == genrou["omega"] == SIGNALS["rotor_speed"][1] == "pu"


def test_resistance_makes_bus_power_smaller_than_air_gap_power():
    p = SM4Params(Re=0.05)
    x = steady_state(1.0, 0.0, p)
    Id, Iq, _, _, P, _, _ = outputs(x, np.array([1.0, 0.0, PM, EFD]), p)
    assert P == pytest.approx(PM - 0.05 * (Id**2 + Iq**2), abs=1e-10)


@pytest.mark.parametrize("values, says", [
    ({"H": 1e-9}, "parameter H = 1e-09 must lie in [0.1, 1000] s"),
    ({"H": 1e308, "D": 1e308}, "parameter H = 1e+308 must lie in [0.1, 1000] s"),
    ({"D": 1e308}, "parameter D = 1e+308 must lie in [0, 100] pu"),
    ({"H": 0.1, "D": 10.0, "Wb": 3000.0},
     "parameter D = 10.0 must keep the speed's damping rate Wb D / (2 H) = 1.5e+05 1/s at most 10000 1/s"),
    ({"Td0_p": 1e-6}, "parameter Td0_p = 1e-06 must lie in [0.01, 100] s"),
    ({"Xd": 1e5}, "parameter Xd = 100000.0 must lie in [0.01, 10] pu"),
    ({"Wb": 1.0}, "parameter Wb = 1.0 must lie in [50, 3000] rad/s"),
])
def test_parameters_outside_their_physical_range_are_refused_naming_the_field_and_the_range(values, says):
    from reference_models.component import ParameterError

    with pytest.raises(ParameterError) as caught:
        SM4.params(values)
    assert str(caught.value) == says


def test_the_shipped_machines_lie_within_the_physical_ranges():
    from pathlib import Path

    data = Path(__file__).resolve().parents[1] / "reference_models" / "grid" / "data"
    machines = sorted(data.glob("wscc9_gen*.json"))
    assert len(machines) == 3
    for path in machines:
        SM4.load_params(path)  # raises ParameterError outside a range
