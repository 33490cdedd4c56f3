"""The inference form: the trained function with the normalisation folded into the weights."""
from dataclasses import replace

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


def featured_stats(seed=3):
    """STATS with a fixed linear map of 3 window features over [x0 (4), sensors (2 S)]."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(3, 4 + 2 * S))
    return replace(STATS, feature_map=tuple(map(tuple, A)), f_mean=(0.2, -0.1, 0.05), f_std=(0.01, 2.0, 0.3))


@pytest.mark.parametrize("anchored", [False, True])
def test_window_features_fold_into_the_first_layer_and_the_export_needs_no_more_inputs(anchored):
    torch.manual_seed(2)
    model = build_model(OperatorConfig(width=16, depth=2, latent=8, anchored=anchored, features=True), featured_stats())
    plain = build_model(OperatorConfig(width=16, depth=2, latent=8, anchored=anchored), STATS)
    assert model.branch_net[0].in_features == plain.branch_net[0].in_features + 3
    with torch.no_grad():
        expected = model(*random_inputs())
        folded = fold(model)
        got = folded(*random_inputs())
    assert folded.branch_net[0].in_features == plain.branch_net[0].in_features
    np.testing.assert_allclose(got.numpy(), expected.numpy(), rtol=1e-5, atol=1e-5)


def test_a_model_reads_its_window_features_it_does_not_only_carry_them():
    torch.manual_seed(2)
    model = build_model(OperatorConfig(width=16, depth=2, latent=8, features=True), featured_stats())
    with torch.no_grad():
        model.branch_net[0].weight[:, -3:] *= 0.0
        silenced = model(*random_inputs())
        model.branch_net[0].weight[:, -3:] += 0.5
        read = model(*random_inputs())
    assert not torch.allclose(silenced, read, atol=1e-3)


def test_window_features_need_a_feature_map_and_the_unstacked_branch():
    with pytest.raises(ValueError, match="no feature map"):
        build_model(OperatorConfig(width=16, depth=2, latent=8, features=True), STATS)
    with pytest.raises(ValueError, match="unstacked"):
        OperatorConfig(arch="stacked-n", features=True)


def test_the_normalisation_with_window_features_survives_its_round_trip():
    stats = featured_stats()
    assert NormStats.from_dict(stats.to_dict()) == stats
    kept = build_model(OperatorConfig(width=16, depth=2, latent=8, features=True), stats).stats()  # float32 buffers
    for name in ("feature_map", "f_mean", "f_std"):
        np.testing.assert_allclose(np.array(getattr(kept, name)), np.array(getattr(stats, name)), rtol=1e-6)
