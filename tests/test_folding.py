"""The inference form: the trained function with the normalisation folded into the weights."""
import numpy as np
import pytest
import torch

from surrogate.folding import fold
from surrogate.models import NormStats, OperatorConfig, build_model

S = 11
STATS = NormStats(x_mean=(1.0, 0.05, 0.33, 0.7), x_std=(0.4, 0.2, 0.02, 0.15), u_mean=(1.0, 0.1),
                  u_std=(0.08, 0.2), horizon=1.0, n_sensors=S)


def random_inputs(n=5, m=7, seed=0):
    g = torch.Generator().manual_seed(seed)
    x0 = torch.tensor(STATS.x_mean) + torch.tensor(STATS.x_std) * torch.randn(n, 4, generator=g)
    u = torch.tensor(STATS.u_mean) + torch.tensor(STATS.u_std) * torch.randn(n, S, 2, generator=g)
    return x0, u, torch.rand(m, generator=g)


@pytest.mark.parametrize("arch, anchored", [("unstacked", False), ("stacked-n", False), ("pinn", False),
                                           ("unstacked", True), ("stacked-n", True)])
def test_folded_form_computes_the_trained_function(arch, anchored):
    torch.manual_seed(0)
    model = build_model(OperatorConfig(arch=arch, width=16, depth=2, latent=8, anchored=anchored), STATS)
    with torch.no_grad():
        if arch != "pinn" and not anchored:
            model.bias.add_(0.3)  # a per-state bias: folded into the constant coefficient
        expected = model(*random_inputs())
        got = fold(model)(*random_inputs())
    assert got.shape == expected.shape == (5, 7, 4)
    np.testing.assert_allclose(got.numpy(), expected.numpy(), rtol=1e-5, atol=1e-6)


def test_folding_leaves_the_trained_model_unchanged():
    model = build_model(OperatorConfig(width=16, depth=2, latent=8), STATS)
    before = {k: v.clone() for k, v in model.state_dict().items()}
    fold(model)
    assert all(torch.equal(before[k], v) for k, v in model.state_dict().items())


def test_folded_deeponet_basis_ends_with_the_constant_one():
    folded = fold(build_model(OperatorConfig(width=16, depth=2, latent=8), STATS))
    with torch.no_grad():
        basis = folded.trunk(torch.linspace(0, 1, 6))
    assert basis.shape == (6, 9)
    assert torch.all(basis[:, -1] == 1.0)


@pytest.mark.parametrize("arch", ["unstacked", "stacked-n"])
def test_an_anchored_operator_returns_the_initial_state_at_time_zero(arch):
    torch.manual_seed(1)
    model = build_model(OperatorConfig(arch=arch, width=16, depth=2, latent=8, anchored=True), STATS)
    x0, u, _ = random_inputs()
    with torch.no_grad():
        x = model(x0, u, torch.tensor([0.0, 0.5]))
        folded = fold(model)(x0, u, torch.tensor([0.0, 0.5]))
    np.testing.assert_allclose(x[:, 0].numpy(), x0.numpy(), rtol=0, atol=1e-6)
    np.testing.assert_allclose(folded[:, 0].numpy(), x0.numpy(), rtol=0, atol=1e-6)
    assert not torch.allclose(x[:, 1], x0)
