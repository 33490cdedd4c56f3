"""Losses: autodiff time derivatives, the physics residual against the SM4 model, scaling."""
import numpy as np
import pytest
import torch

from reference_models.families import family
from reference_models.simulate import simulate
from reference_models.sm4 import rhs, steady_state
from surrogate.losses import (data_loss, physics_collocation_loss, physics_data_loss, residual_scale,
                              value_and_time_derivative)
from surrogate.models import ARCHITECTURES, NormStats, OperatorConfig, build_model

S = 21


def small_model(arch):
    torch.manual_seed(0)
    stats = NormStats(x_mean=(0.1, 0.2, 0.01, 0.9), x_std=(0.8, 0.6, 0.1, 0.1), u_mean=(1.0, 0.0, 0.7, 1.1),
                      u_std=(0.07, 0.12, 0.1, 0.2), horizon=1.0, n_sensors=S)
    return build_model(OperatorConfig(arch=arch, width=16, depth=2, latent=8), stats).double()


@pytest.mark.parametrize("arch", ARCHITECTURES)
def test_autodiff_time_derivative_matches_central_finite_differences(arch):
    net = small_model(arch)
    g = torch.Generator().manual_seed(1)
    f64 = dict(generator=g, dtype=torch.float64)
    x0 = torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=torch.float64) + 0.3 * torch.randn(3, 4, **f64)
    u = 1.0 + 0.1 * torch.randn(3, S, 4, **f64)
    t = torch.tensor([0.0, 0.004, 0.02, 0.3, 0.97], dtype=torch.float64)
    x, dxdt = value_and_time_derivative(net, x0, u, t)
    h = 1e-6
    fd = (net(x0, u, t + h) - net(x0, u, t - h)) / (2 * h)
    torch.testing.assert_close(x, net(x0, u, t))
    torch.testing.assert_close(dxdt, fd, rtol=1e-6, atol=1e-8)


def test_time_derivative_is_differentiable_with_respect_to_the_parameters():
    net = small_model("unstacked")
    f64 = dict(dtype=torch.float64)
    x0, u, t = torch.zeros(2, 4, **f64), torch.ones(2, S, 4, **f64), torch.linspace(0, 1, 5, **f64)
    _, dxdt = value_and_time_derivative(net, x0, u, t)
    dxdt.square().sum().backward()
    assert net.trunk_net[0].weight.grad.abs().sum() > 0
    assert net.branch_net[0].weight.grad.abs().sum() > 0


def reference_window():
    """A fast-family reference trajectory on a fine grid: t [S], x [1, S, 4], u [1, S, 4]."""
    signal = family("fast").sample(np.full((1, family("fast").dim), 0.7), 0.3)[0]
    t = np.linspace(0.0, 0.3, 3001)
    x0 = steady_state(1.0, 0.0) + np.array([0.3, 0.5, 0.05, 0.1])
    return t, simulate(x0, signal, t)[None], signal(t)[None]


def test_physics_residual_of_a_reference_trajectory_is_near_zero_and_of_a_perturbed_one_is_not():
    t, x, u = reference_window()
    scale = torch.tensor(residual_scale(x, t))
    perturbed = x + 0.01 * np.sin(2 * np.pi * t / 0.3)[None, :, None] * x.std(axis=(0, 1))

    def residual(states):
        dxdt = np.gradient(states, t, axis=1, edge_order=2)  # derivative of the given trajectory
        return physics_collocation_loss(torch.tensor(states), torch.tensor(dxdt), torch.tensor(u), scale, rhs).item()

    assert residual(x) < 1e-4 * residual(perturbed)
    assert residual(perturbed) > 1e-4


def test_physics_data_loss_compares_the_derivative_with_rhs_at_the_given_states():
    t, x, u = reference_window()
    scale = torch.tensor(residual_scale(x, t))

    f = rhs(torch.tensor(x), torch.tensor(u))
    assert physics_data_loss(f, f, scale).item() == 0.0
    shifted = f + scale  # one residual scale off in every state
    assert physics_data_loss(shifted, f, scale).item() == pytest.approx(1.0)


def test_residual_scale_is_the_per_state_std_of_the_reference_derivative():
    t = np.linspace(0.0, 1.0, 101)
    x = np.stack([np.outer([1.0, 2.0], t ** k) for k in (1, 1, 2, 0)], axis=-1)  # slopes 1 and 2 in state 0
    scale = residual_scale(x, t)
    np.testing.assert_allclose(scale[0], 0.5)  # derivatives 1 and 2, std 0.5
    assert scale[3] == 1.0  # a constant state gets scale 1, never 0


def test_data_loss_is_the_mean_square_of_standardised_errors():
    y = torch.zeros(2, 3, 4)
    y_hat = y.clone()
    y_hat[..., 1] = 2.0  # two stds off in one of four states
    assert data_loss(y_hat, y).item() == pytest.approx(1.0)
