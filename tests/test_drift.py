"""The drift symmetry and the window frame: the operator answers the same whatever the absolute
angle, and whatever the speed its frame turns at (for D = 0; with D > 0 that speed's damping torque
rides on Pm)."""
import numpy as np
import pytest

from reference_models.drift import Frame, frame_of, from_frame, to_frame
from reference_models.sm4 import SM4, SM4Params
from surrogate import Operator
from surrogate.contract import random_inputs


@pytest.fixture(scope="module")
def operator():
    return Operator.default()


def windows(op, n=24, seed=0):
    """In-envelope windows (x0, u, t) of the shipped operator, as physical values."""
    t_grid = np.linspace(0.0, op.horizon, op.n_sensors)
    x0, u, _ = random_inputs(op.envelope, t_grid, n, np.random.default_rng(seed))
    u = u.astype(np.float64)
    low, high = op.envelope["u"]["theta_vs"]
    u[..., 1] = np.clip(u[..., 1] - u[:, :1, 1], low, high)  # in the window frame theta_vs starts at 0
    return x0.astype(np.float64), u, t_grid


@pytest.mark.parametrize("D", [2.0, 0.0])
def test_a_frame_round_trip_gives_the_states_back(D):
    frame = frame_of(SM4.drift, SM4Params(D=D))
    rng = np.random.default_rng(1)
    x0 = rng.uniform(-40, 40, (50, 4))
    u = rng.uniform(-40, 40, (50, 11, 4))
    s = np.linspace(0, 1, 11)
    x0_f, _, shift, c = to_frame(frame, x0, u, s)
    if D:  # the frame turns in whole steps of 2 rad/s: the speed left is in [-1, 1)
        np.testing.assert_array_equal(c, 2.0 * np.round(c / 2.0))
        assert np.all((-1.0 <= x0_f[:, 1]) & (x0_f[:, 1] < 1.0))
    else:  # the frame turns at the start speed
        assert np.all(x0_f[:, 1] == 0)
    assert np.all((-np.pi <= x0_f[:, 0]) & (x0_f[:, 0] < np.pi))  # the rotor angle relative to the bus, wrapped
    np.testing.assert_allclose(np.cos(x0_f[:, 0]), np.cos(x0[:, 0] - u[:, 0, 1]), atol=1e-12)
    np.testing.assert_allclose(from_frame(frame, x0_f[:, None], np.zeros(1), shift, c)[:, 0], x0, atol=1e-12)


def test_the_frame_of_sm4_turns_delta_and_theta_vs_and_lowers_pm_by_d_times_the_speed():
    frame = frame_of(SM4.drift, SM4Params(D=2.5))
    assert frame == Frame((0,), (1,), 1, ((2, 2.5),), 2 * np.pi, 2.0)
    assert frame_of(SM4.drift, SM4Params(D=0.0)) == Frame((0,), (1,), 1, ((2, 0.0),), 2 * np.pi, 0.0)
    assert Frame.from_dict(frame.to_dict()) == frame
    np.testing.assert_array_equal(frame.input_rates(4), [0, 1, 0, 0])
    np.testing.assert_array_equal(frame.input_torques(4), [0, 0, 2.5, 0])


@pytest.mark.parametrize("offset", [3.0, -3.0, 30.0, -30.0])
def test_the_operator_is_blind_to_a_common_angle_offset(operator, offset):
    x0, u, t = windows(operator)
    base = operator.predict(x0, u, t)
    turned = operator.predict(x0 + [offset, 0, 0, 0], u + [0, offset, 0, 0], t)
    np.testing.assert_allclose(turned, base + [offset, 0, 0, 0], rtol=1e-6, atol=3e-5)  # float32 of delta + 30


@pytest.mark.parametrize("speed", [12.0, -12.0, 4.0])
def test_a_frame_turning_at_a_constant_extra_speed_only_turns_the_answer(operator, speed):
    """omega0 + c, theta_vs + c t and Pm + D c (the damping torque of the extra speed): the answer is
    delta + c t, omega + c, the fluxes as they were. With D > 0 the frame turns in whole steps of
    2 rad/s, so this holds exactly for extra speeds in whole steps (the D = 0 operators of the WSCC
    machines take any speed: test_wscc9_operators.py)."""
    x0, u, t = windows(operator)
    D = operator.params.D
    base = operator.predict(x0, u, t)
    x0_c = x0 + [0, speed, 0, 0]
    u_c = u + speed * (t[None, :, None] * [0, 1, 0, 0] + [0, 0, D, 0])
    turned = operator.predict(x0_c, u_c, t)
    expected = base + speed * (t[None, :, None] * [1, 0, 0, 0] + [0, 1, 0, 0])
    np.testing.assert_allclose(turned, expected, atol=5e-5 * max(1.0, abs(speed)))


def test_a_machine_drifting_at_12_rad_s_with_its_network_is_inside_the_envelope(operator):
    x0, u, t = windows(operator, n=8)
    x0_c, u_c = x0 + [0, 12.0, 0, 0], u + 12.0 * (t[None, :, None] * [0, 1, 0, 0] + [0, 0, operator.params.D, 0])
    assert operator.outside_envelope(x0, u) == []
    assert operator.outside_envelope(x0_c, u_c) == []
