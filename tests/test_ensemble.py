"""Ensembles: several trained operators averaged into one, and what they refuse."""
import numpy as np
import pytest
import torch

from surrogate.ensemble import Ensemble, EnsembleError
from surrogate.folding import fold
from surrogate.models import NormStats, OperatorConfig, build_model

S = 11
STATS = NormStats(x_mean=(1.0, 0.05, 0.33, 0.7), x_std=(0.4, 0.2, 0.02, 0.15), u_mean=(1.0, 0.1, 0.7, 1.1),
                  u_std=(0.08, 0.2, 0.1, 0.2), horizon=1.0, n_sensors=S)
OTHER_STATS = NormStats(x_mean=(0.9, 0.0, 0.3, 0.75), x_std=(0.5, 0.25, 0.03, 0.1), u_mean=(0.95, 0.0, 0.6, 1.2),
                        u_std=(0.1, 0.25, 0.15, 0.3), horizon=1.0, n_sensors=S)
ANCHORED = OperatorConfig(width=16, depth=2, latent=8, anchored=True)


def member(seed, config=ANCHORED, stats=STATS):
    torch.manual_seed(seed)
    return build_model(config, stats)


def inputs(n=5, m=7):
    g = torch.Generator().manual_seed(0)
    x0 = torch.tensor(STATS.x_mean) + torch.tensor(STATS.x_std) * torch.randn(n, 4, generator=g)
    u = torch.tensor(STATS.u_mean) + torch.tensor(STATS.u_std) * torch.randn(n, S, 4, generator=g)
    return x0, u, torch.rand(m, generator=g)


def test_an_ensemble_computes_the_mean_of_its_members():
    members = [member(0), member(1, stats=OTHER_STATS)]
    with torch.no_grad():
        expected = (members[0](*inputs()) + members[1](*inputs())) / 2
        got = Ensemble(members)(*inputs())
    np.testing.assert_allclose(got.numpy(), expected.numpy(), rtol=0, atol=1e-6)


def test_the_folded_ensemble_computes_the_members_mean_as_one_deeponet():
    taus = OperatorConfig(**{**ANCHORED.to_dict(), "time_taus": (0.02, 0.2)})
    ensemble = Ensemble([member(0), member(1, stats=OTHER_STATS), member(2, config=taus)])
    with torch.no_grad():
        expected = ensemble(*inputs())
        folded = fold(ensemble)
        got = folded(*inputs())
    assert folded.latent == 3 * 8 and folded.trunk(torch.zeros(2)).shape == (2, 3 * 8 + 1)
    np.testing.assert_allclose(got.numpy(), expected.numpy(), rtol=1e-5, atol=1e-6)


def test_an_ensemble_returns_the_initial_state_at_time_zero():
    x0, u, _ = inputs()
    with torch.no_grad():
        x = fold(Ensemble([member(0), member(1)]))(x0, u, torch.tensor([0.0]))
    np.testing.assert_allclose(x[:, 0].numpy(), x0.numpy(), rtol=0, atol=1e-6)


def test_an_ensembles_rate_is_the_mean_of_its_members_rates():
    members = [member(0), member(1, stats=OTHER_STATS)]
    ensemble = Ensemble(members)
    x0, u, t = inputs()
    rates = [m.x_std * m.standardised_with_rate(x0, u, t)[1] for m in members]
    _, dydt = ensemble.standardised_with_rate(x0, u, t)
    np.testing.assert_allclose((ensemble.x_std * dydt).detach().numpy(), ((rates[0] + rates[1]) / 2).detach().numpy(),
                               rtol=1e-5, atol=1e-5)


def test_an_ensemble_needs_at_least_two_operators():
    with pytest.raises(EnsembleError, match="at least two"):
        Ensemble([member(0)])


@pytest.mark.parametrize("config", [OperatorConfig(width=16, depth=2, latent=8),
                                    OperatorConfig(arch="stacked-n", width=16, depth=2, latent=8, anchored=True)])
def test_only_anchored_unstacked_deeponets_are_averaged(config):
    with pytest.raises(EnsembleError, match="operator 2 is .*only anchored Unstacked"):
        Ensemble([member(0), member(1, config=config)])


def test_members_of_different_shapes_are_refused_with_both_shapes_named():
    wider = OperatorConfig(**{**ANCHORED.to_dict(), "width": 32})
    with pytest.raises(EnsembleError, match=r"operator 2 has .*\(32, 2, 8, 'tanh'\).*\(16, 2, 8, 'tanh'\)"):
        Ensemble([member(0), member(1, config=wider)])


def test_members_reading_different_sensor_times_are_refused():
    fewer = NormStats(**{**STATS.to_dict(), "n_sensors": 6})
    with pytest.raises(EnsembleError, match="reads 6 sensors"):
        Ensemble([member(0), member(1, stats=fewer)])
