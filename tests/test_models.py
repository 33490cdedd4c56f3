"""Operator networks: shapes, normalisation, time features, save/load."""
import math

import numpy as np
import pytest
import torch

from surrogate.models import (ARCHITECTURES, NormStats, OperatorConfig, build_model, count_parameters)
from surrogate.training import TrainConfig, load_model, save_model

S = 21  # sensor times of the small synthetic problems here


def stats(n_sensors=S):
    return NormStats(x_mean=(0.1, 0.2, 0.01, 0.9), x_std=(0.8, 0.6, 0.1, 0.1), u_mean=(1.0, 0.0, 0.7, 1.1),
                     u_std=(0.07, 0.12, 0.1, 0.2), horizon=1.0, n_sensors=n_sensors)


def inputs(n=3, m=7, n_sensors=S, seed=0):
    g = torch.Generator().manual_seed(seed)
    x0 = torch.tensor([0.0, 0.0, 0.0, 1.0]) + 0.3 * torch.randn(n, 4, generator=g)
    u = torch.tensor([1.0, 0.0, 0.7, 1.1]) + 0.1 * torch.randn(n, n_sensors, 4, generator=g)
    t = torch.linspace(0.0, 1.0, m)
    return x0, u, t


def model(arch, **changes):
    torch.manual_seed(0)
    return build_model(OperatorConfig(arch=arch, width=16, depth=2, latent=8, **changes), stats())


@pytest.mark.parametrize("arch", ARCHITECTURES)
def test_every_architecture_maps_x0_u_t_to_states_of_shape_n_m_4(arch):
    x0, u, t = inputs(n=3, m=7)
    assert model(arch)(x0, u, t).shape == (3, 7, 4)


@pytest.mark.parametrize("arch", ["unstacked", "stacked-n"])
def test_deeponet_branch_gives_p_coefficients_per_state_and_trunk_p_basis_functions(arch):
    x0, u, t = inputs(n=3, m=7)
    net = model(arch)
    assert net.branch(x0, u).shape == (3, 4, 8)
    assert net.trunk(t).shape == (7, 8)


@pytest.mark.parametrize("arch", ["unstacked", "stacked-n"])
def test_deeponet_output_is_branch_times_trunk_plus_bias_in_physical_units(arch):
    x0, u, t = inputs()
    net = model(arch)
    y = torch.einsum("nkp,mp->nmk", net.branch(x0, u), net.trunk(t)) + net.bias
    torch.testing.assert_close(net(x0, u, t), net.x_mean + net.x_std * y)


def test_pinn_evaluates_pointwise_so_one_time_gives_the_same_value_alone_or_on_a_grid():
    x0, u, t = inputs(m=5)
    net = model("pinn")
    torch.testing.assert_close(net(x0, u, t)[:, 3], net(x0, u, t[3:4])[:, 0])


def test_pinn_has_a_parameter_count_comparable_to_the_unstacked_deeponet():
    config = OperatorConfig()
    counts = {arch: count_parameters(build_model(OperatorConfig(arch=arch), stats(1001))) for arch in ARCHITECTURES}
    assert config.width == 64 and config.depth == 3 and config.latent == 64
    assert 0.5 < counts["pinn"] / counts["unstacked"] < 2.0
    assert 0.5 < counts["stacked-n"] / counts["unstacked"] < 2.0


def test_sensor_values_are_scaled_by_sqrt_of_4_over_the_number_of_sensors():
    net = model("unstacked", sensor_gain=2.0)
    assert float(net.sensor_scale) == pytest.approx(2.0 * math.sqrt(4 / S))
    u = (net.u_mean + net.u_std).expand(1, S, 4)  # one std above the mean everywhere
    torch.testing.assert_close(net.encode_sensors(u), torch.full((1, 4 * S), float(net.sensor_scale)))


def test_time_features_are_scaled_time_and_decaying_exponentials():
    net = model("unstacked", time_taus=(0.01, 0.1))
    features = net.time_features(torch.tensor([0.0, 0.05, 1.0]))
    expected = torch.tensor([[-1.0, 1.0, 1.0],
                             [-0.9, math.exp(-5), math.exp(-0.5)],
                             [1.0, math.exp(-100), math.exp(-10)]])
    torch.testing.assert_close(features, expected)


def test_norm_stats_give_a_constant_state_unit_std_instead_of_zero():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(5, 11, 4))
    x[..., 2] = 0.0  # Ed_p held at 0 everywhere
    split = {"x": x, "u": rng.normal(size=(5, 11, 4)), "t": np.linspace(0, 0.5, 11)}
    fitted = NormStats.fit(split)
    assert fitted.x_std[2] == 1.0 and fitted.n_sensors == 11 and fitted.horizon == 0.5
    np.testing.assert_allclose(fitted.x_std[0], x[..., 0].std())


@pytest.mark.parametrize("arch", ARCHITECTURES)
def test_normalisation_buffers_and_outputs_survive_save_and_load(arch, tmp_path):
    net = model(arch)
    config = TrainConfig(model=net.config)
    save_model(tmp_path / "model.pt", net, net.state_dict(), config, {"epoch": 0})
    loaded = load_model(tmp_path)
    for name in ("x_mean", "x_std", "u_mean", "u_std", "horizon", "sensor_scale", "time_taus"):
        torch.testing.assert_close(getattr(loaded, name), getattr(net, name), rtol=0, atol=0)
    x0, u, t = inputs()
    torch.testing.assert_close(loaded(x0, u, t), net(x0, u, t), rtol=0, atol=0)
    assert loaded.stats() == net.stats()


def test_unknown_architecture_is_refused_with_the_known_ones_named():
    with pytest.raises(ValueError, match="unstacked"):
        OperatorConfig(arch="stacked")


def test_an_input_held_at_one_value_is_normalised_by_one_not_by_its_rounding_noise():
    """The paper preset holds Efd at 1.08 pu in every window: the std of a million copies is 1e-11
    of rounding noise, which as a divisor made the folded export's float32 weights 1e9 too large."""
    from surrogate.models import NormStats

    rng = np.random.default_rng(0)
    n, s = 200, 1001
    u = np.stack([rng.uniform(0.7, 1.2, (n, s)), rng.uniform(-1, 1, (n, s)), np.full((n, s), 0.7048),
                  np.full((n, s), 1.08)], axis=-1)
    x = rng.normal(size=(n, s, 4))
    stats = NormStats.fit({"x0": x[:, 0], "u": u, "x": x, "t": np.linspace(0.0, 1.0, s)})
    assert stats.u_std[2] == 1.0 and stats.u_std[3] == 1.0
    assert 0.1 < stats.u_std[0] < 0.2
