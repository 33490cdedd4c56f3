"""The RK45 reference simulation."""
import numpy as np
from scipy.integrate import solve_ivp

from reference_models.families import bus, family
from reference_models.signals import Piecewise
from reference_models.simulate import SolverConfig, simulate
from reference_models.sm4 import SM4, rhs, steady_state

T = np.linspace(0.0, 1.0, 1001)


def test_rk45_at_default_tolerances_matches_dop853_at_1e_12():
    for name in ("slow", "fast", "dip"):
        fam = family(name)
        for s in fam.sample(np.random.default_rng(3).random((2, fam.dim)), 1.0):
            x0 = steady_state(1.0, 0.0) + np.array([0.3, 0.5, 0.0, 0.05])
            ref = simulate(x0, s, T, solver=SolverConfig("DOP853", 1e-12, 1e-12))
            np.testing.assert_allclose(simulate(x0, s, T), ref, rtol=0, atol=1e-6)


def test_machine_at_equilibrium_under_constant_voltage_stays_there():
    x0 = steady_state(1.1, 0.3)
    s = bus(Piecewise((1.1,), ()), Piecewise((0.3,), ()))
    np.testing.assert_allclose(simulate(x0, s, T), np.tile(x0, (T.size, 1)), rtol=0, atol=1e-9)


def test_step_input_is_integrated_piecewise_like_two_separate_solves():
    s = bus(Piecewise((1.0, 0.8), (0.3037,)), Piecewise((0.0, 0.2), (0.6511,)))
    x0 = steady_state(1.0, 0.0)
    f = lambda u: (lambda t, x: rhs(x, np.array(u)))
    tight = dict(method="DOP853", rtol=1e-12, atol=1e-12)
    pm, efd = SM4.inputs[2].start, SM4.inputs[3].start
    a = solve_ivp(f([1.0, 0.0, pm, efd]), (0, 0.3037), x0, **tight).y[:, -1]
    b = solve_ivp(f([0.8, 0.0, pm, efd]), (0.3037, 0.6511), a, **tight).y[:, -1]
    c = solve_ivp(f([0.8, 0.2, pm, efd]), (0.6511, 1.0), b, t_eval=[1.0], **tight).y[:, -1]
    np.testing.assert_allclose(simulate(x0, s, T)[-1], c, rtol=0, atol=1e-7)


def test_breakpoints_closer_than_the_output_grid_are_integrated_through():
    from reference_models.signals import Ramp

    s = bus(Ramp(1.0, 0.8, 0.5001, 0.5004), Piecewise((0.0, 0.1), (0.50015,)))
    x0 = steady_state(1.0, 0.0)
    tight = simulate(x0, s, T, solver=SolverConfig("DOP853", 1e-12, 1e-12))
    np.testing.assert_allclose(simulate(x0, s, T), tight, rtol=0, atol=1e-6)


def test_many_trajectories_are_the_single_solves_stacked():
    from reference_models.simulate import simulate_many

    fam = family("fast")
    signals = fam.sample(np.random.default_rng(9).random((3, fam.dim)), 1.0)
    x0s = np.array([steady_state(1.0, 0.0)] * 3)
    np.testing.assert_array_equal(simulate_many(x0s, signals, T), np.stack([simulate(x0s[0], s, T) for s in signals]))
