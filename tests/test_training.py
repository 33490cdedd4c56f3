"""Training runs (learning, checkpoints, exact resume, early stopping) and evaluation metrics/figures."""
import json

import numpy as np
import pytest
import torch

import surrogate.training as training
from reference_models.sm4 import STATE_NAMES
from surrogate.data import generate, load_split
from surrogate.evaluation import (aggregate, error_metrics, evaluate, plot_error_over_time, plot_trajectories,
                                  predict)
from surrogate.models import OperatorConfig
from surrogate.training import TrainConfig, TrainError, load_model, train

from conftest import tiny

SMALL = OperatorConfig(width=16, depth=2, latent=8)


@pytest.fixture(scope="module")
def learnable(tmp_path_factory):
    """A paper-family dataset with enough training trajectories (40, on a 201-point grid) that
    the validation loss can fall within a few dozen epochs."""
    out = tmp_path_factory.mktemp("learnable")
    recipe = tiny("paper", counts={"train": 40, "collocation": 4, "val": 8, "test": 4}, n_points=201, chunk_size=10)
    generate(recipe, out, seed=5, progress=False)
    return out


def config(**changes):
    """A small, short run over the whole time grid."""
    return TrainConfig(**{"model": SMALL, "epochs": 12, "checkpoint_every": 4, "time_points": None, **changes})


def metrics_lines(run_dir):
    return [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]


def parameters(run_dir):
    return torch.load(run_dir / "checkpoint.pt", weights_only=False)["model"]


def assert_same_parameters(a, b):
    assert a.keys() == b.keys()
    for name in a:
        torch.testing.assert_close(a[name], b[name], rtol=0, atol=0)


@pytest.mark.parametrize("optimizer", ["soap", "adam"])
def test_short_training_lowers_the_validation_loss(learnable, tmp_path, optimizer):
    result = train(learnable, config(model=OperatorConfig(), optimizer=optimizer, epochs=30), tmp_path, progress=False)
    first = metrics_lines(tmp_path)[0]["val_mse"]
    assert result.epochs == 30 and result.best_val_mse < 0.5 * first


def test_physics_informed_training_logs_all_three_loss_terms(paper_tiny, tmp_path):
    train(paper_tiny[1], config(physics=True, epochs=3), tmp_path, progress=False)
    line = metrics_lines(tmp_path)[-1]
    assert {"loss", "data", "physics_data", "physics_collocation", "val_mse", "wall_s"} <= line.keys()
    assert all(np.isfinite(line[k]) for k in ("physics_data", "physics_collocation"))


def test_run_directory_holds_config_checkpoint_best_model_metrics_and_result(paper_tiny, tmp_path):
    result = train(paper_tiny[1], config(), tmp_path, progress=False)
    saved = json.loads((tmp_path / "config.json").read_text())
    assert TrainConfig.from_dict(saved["train"]) == config()
    assert [m["epoch"] for m in metrics_lines(tmp_path)] == list(range(1, 13))
    assert json.loads((tmp_path / "result.json").read_text()) == result.to_dict()
    best = min(metrics_lines(tmp_path), key=lambda m: m["val_mse"])
    assert (result.best_epoch, result.best_val_mse) == (best["epoch"], best["val_mse"])
    model = load_model(tmp_path)
    val = load_split(paper_tiny[1], "val")
    assert evaluate(model, val)["standardised"]["mse"] == pytest.approx(best["val_mse"], rel=1e-4)


def test_extending_a_finished_run_gives_the_parameters_of_an_uninterrupted_one(paper_tiny, tmp_path):
    # physics and per-epoch time sampling on, so the optimizer and RNG states must both carry over;
    # a constant rate, since a cosine schedule is stretched by the new epoch count
    changes = dict(physics=True, time_points=50, weights=training.LossWeights(1.0, 1e-2, 1e-2),
                   lr_schedule="constant")
    train(paper_tiny[1], config(epochs=12, **changes), tmp_path / "straight", progress=False)
    train(paper_tiny[1], config(epochs=6, **changes), tmp_path / "resumed", progress=False)
    train(paper_tiny[1], config(epochs=12, **changes), tmp_path / "resumed", progress=False)
    assert_same_parameters(parameters(tmp_path / "straight"), parameters(tmp_path / "resumed"))
    assert [m["epoch"] for m in metrics_lines(tmp_path / "resumed")] == list(range(1, 13))


def test_interrupted_run_resumes_from_its_last_checkpoint_exactly(paper_tiny, tmp_path, monkeypatch):
    train(paper_tiny[1], config(time_points=50), tmp_path / "straight", progress=False)
    step, calls = training._step, []

    def crash_at_epoch_7(*args):
        calls.append(1)
        if len(calls) == 7:
            raise KeyboardInterrupt
        return step(*args)

    monkeypatch.setattr(training, "_step", crash_at_epoch_7)
    with pytest.raises(KeyboardInterrupt):
        train(paper_tiny[1], config(time_points=50), tmp_path / "resumed", progress=False)
    monkeypatch.setattr(training, "_step", step)
    assert torch.load(tmp_path / "resumed" / "checkpoint.pt", weights_only=False)["state"]["epoch"] == 4
    train(paper_tiny[1], config(time_points=50), tmp_path / "resumed", progress=False)
    assert_same_parameters(parameters(tmp_path / "straight"), parameters(tmp_path / "resumed"))
    assert [m["epoch"] for m in metrics_lines(tmp_path / "resumed")] == list(range(1, 13))


def test_resuming_with_other_settings_is_refused_naming_them(paper_tiny, tmp_path):
    train(paper_tiny[1], config(epochs=2), tmp_path, progress=False)
    with pytest.raises(TrainError, match="lr"):
        train(paper_tiny[1], config(epochs=4, lr=1e-4), tmp_path, progress=False)


def test_cosine_schedule_decays_from_lr_to_lr_times_lr_final():
    cfg = TrainConfig(lr=3e-3, lr_final=0.01, epochs=101)
    rates = [training.learning_rate(cfg, e) for e in range(101)]
    assert rates[0] == pytest.approx(3e-3) and rates[50] == pytest.approx(3e-3 * 0.505)
    assert rates[100] == pytest.approx(3e-5) and all(a >= b for a, b in zip(rates, rates[1:]))


def test_constant_schedule_keeps_the_paper_rate():
    cfg = TrainConfig(lr=3e-3, lr_schedule="constant", epochs=10)
    assert {training.learning_rate(cfg, e) for e in range(10)} == {3e-3}


def test_early_stopping_ends_the_run_after_patience_epochs_without_improvement(paper_tiny, tmp_path):
    result = train(paper_tiny[1], config(patience=2, min_delta=1e3, epochs=50), tmp_path, progress=False)
    assert result.stopped_early and result.epochs == 3  # epoch 1 sets the reference, 2 and 3 fail to beat it


def test_error_metrics_in_physical_and_standardised_units_per_state_and_per_time():
    x = np.zeros((2, 5, 4))
    x_hat = x.copy()
    x_hat[0, :, 1] = 0.3  # omega off by 0.3 rad/s in one of two trajectories
    m = error_metrics(x_hat, x, x_std=[1.0, 0.6, 1.0, 1.0], state_names=STATE_NAMES)
    assert m["physical"] == pytest.approx({"mse": 0.09 / 8, "mae": 0.3 / 8, "maxae": 0.3})
    assert m["standardised"] == pytest.approx({"mse": 0.25 / 8, "mae": 0.5 / 8, "maxae": 0.5})
    assert m["per_state"]["omega"] == pytest.approx({"mse": 0.045, "mae": 0.15, "maxae": 0.3})
    assert m["per_state"]["delta"]["maxae"] == 0.0
    assert m["per_time"]["mae"].shape == (5, 4)
    np.testing.assert_allclose(m["per_time"]["mae"][:, 1], 0.15)
    np.testing.assert_allclose(m["per_time"]["ae_std"][:, 1], 0.15)


def test_aggregate_gives_mean_and_std_over_seeds_of_every_metric():
    x = np.zeros((1, 3, 4))
    runs = [error_metrics(x + e, x, [1.0] * 4, STATE_NAMES) for e in (0.1, 0.3)]
    summary = aggregate(runs)
    assert summary["n"] == 2
    assert summary["mean"]["physical"]["mae"] == pytest.approx(0.2)
    assert summary["std"]["physical"]["mae"] == pytest.approx(0.1)
    np.testing.assert_allclose(summary["mean"]["per_time"]["mae"], 0.2)


def test_figures_of_trajectories_and_error_over_time_are_written_as_png(paper_tiny, tmp_path):
    train(paper_tiny[1], config(epochs=2), tmp_path, progress=False)
    test = load_split(paper_tiny[1], "test")
    x_hat = predict(load_model(tmp_path), test["x0"], test["u"], test["t"])
    plot_trajectories(test, {"unstacked": x_hat}, tmp_path / "fig3.png")
    plot_error_over_time(test, {"unstacked": x_hat}, tmp_path / "fig4.png")
    for name in ("fig3.png", "fig4.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_held_after_keeps_inputs_up_to_the_cut_and_holds_the_value_at_the_cut_after_it():
    u = torch.arange(24, dtype=torch.float32).reshape(2, 3, 4)
    held = training.held_after(u, torch.tensor([0, 1]))
    torch.testing.assert_close(held[0], u[0, :1].expand(3, 4))
    torch.testing.assert_close(held[1], torch.stack([u[1, 0], u[1, 1], u[1, 1]]))


def test_state_weights_scale_each_states_share_of_the_data_loss():
    from surrogate.losses import data_loss

    y, y_hat = torch.zeros(2, 3, 4), torch.zeros(2, 3, 4)
    y_hat[..., 1] = 1.0  # wrong in omega only
    assert data_loss(y_hat, y).item() == pytest.approx(0.25)
    assert data_loss(y_hat, y, state_weights=torch.tensor([1.0, 0.0, 1.0, 1.0])).item() == 0.0
    assert data_loss(y_hat, y, state_weights=torch.tensor([1.0, 4.0, 1.0, 1.0])).item() == pytest.approx(4 / 7)


@pytest.mark.parametrize("weights", [(), (1.0, -1.0, 1.0, 1.0), (0.0, 0.0, 0.0, 0.0)])
def test_state_weights_must_be_non_negative_numbers_not_all_zero(weights):
    with pytest.raises(ValueError, match="state_weights"):
        TrainConfig(state_weights=weights)


def test_training_refuses_state_weights_that_do_not_give_one_weight_per_state_of_the_component(paper_tiny, tmp_path):
    with pytest.raises(TrainError, match="3 weights for the 4 states of sm4"):
        train(paper_tiny[1], config(epochs=1, state_weights=(1.0, 1.0, 1.0)), tmp_path, progress=False)


def test_training_refuses_window_features_of_a_component_that_gives_none(paper_tiny, tmp_path):
    with pytest.raises(TrainError, match="sm4 gives no window features"):
        train(paper_tiny[1], config(epochs=1, model=OperatorConfig(width=16, depth=2, latent=8, features=True)),
              tmp_path, progress=False)


def test_masked_data_loss_counts_only_the_times_before_the_cut():
    from surrogate.losses import data_loss

    y = torch.zeros(1, 4, 4)
    y_hat = torch.zeros(1, 4, 4)
    y_hat[0, 2:] = 5.0  # wrong only after the cut
    mask = torch.tensor([[True, True, False, False]])
    assert data_loss(y_hat, y, mask).item() == 0.0
    assert data_loss(y_hat, y).item() > 0.0


def test_causal_anchored_training_runs_resumes_exactly_and_logs_every_term(paper_tiny, tmp_path):
    causal = config(model=OperatorConfig(width=16, depth=2, latent=8, anchored=True), causal=True, physics=True,
                    time_points=50, lr_schedule="constant")  # constant: a cosine one stretches with epochs
    train(paper_tiny[1], causal, tmp_path / "whole", progress=False)
    train(paper_tiny[1], TrainConfig.from_dict({**causal.to_dict(), "epochs": 8}), tmp_path / "split", progress=False)
    train(paper_tiny[1], causal, tmp_path / "split", progress=False)
    assert_same_parameters(parameters(tmp_path / "whole"), parameters(tmp_path / "split"))
    assert {"data", "physics_data", "physics_collocation"} <= set(metrics_lines(tmp_path / "whole")[-1])
    assert "bias" not in parameters(tmp_path / "whole")


def test_the_pinn_cannot_be_anchored():
    with pytest.raises(ValueError, match="anchored"):
        OperatorConfig(arch="pinn", anchored=True)


def _subsystem_windows(seed: int, rows: int):
    """The windows (cosim.subsystem_data.windows: 0.2 s every 20 ms at 10 ms) of a made-up run of
    `rows` steps of the `subsystem` component: states and inputs that never repeat."""
    from cosim.subsystem_data import Plan, windows

    rng = np.random.default_rng(seed)
    t = np.round(np.arange(rows) * 0.01, 12)
    x = np.cumsum(rng.normal(size=(rows, 5)), axis=0) * 1e-3 + [0.0, 0.0, 0.5, 0.1, 1.0]
    u = np.column_stack([1.0 + 1e-3 * np.cumsum(rng.normal(size=rows)), 0.3 + 1e-3 * np.cumsum(rng.normal(size=rows))])
    return windows({"t": t, "x": x, "u": u}, Plan())


def test_the_windows_that_start_at_another_windows_rollover_are_those_of_the_same_run_eight_strides_on():
    """A causal operator rolls over at 0.8 of its 0.2 s horizon (sensor 16 of 21), eight 20 ms strides:
    window j pairs with window j - 8 of its own run and with no other; a run too short has none. A
    component without learned states, or whose learned states a window frame moves, is refused."""
    from reference_models.components import component

    runs = [_subsystem_windows(seed, rows) for seed, rows in ((1, 101), (2, 60), (3, 25))]
    x0, u, x = (np.concatenate(parts) for parts in zip(*runs))
    found = training.rollovers({"x0": x0, "u": u, "x": x}, component("subsystem"), causal=True)
    first = np.cumsum([0] + [len(r[0]) for r in runs])
    expected = [(first[k] + j - 8, first[k] + j) for k, r in enumerate(runs) for j in range(8, len(r[0]))]
    assert found.index == 16 and found.learned.tolist() == [2, 3]
    assert sorted(zip(found.earlier.tolist(), found.later.tolist())) == expected and len(expected) == 33 + 12
    assert training.rollovers({"x0": x0, "u": u, "x": x}, component("subsystem"), causal=False).index == 20
    with pytest.raises(TrainError, match="learned states"):
        training.rollovers({"x0": x0, "u": u, "x": x}, component("sm4"), causal=True)


def test_a_rolled_over_window_starts_its_learned_states_from_the_operators_answer_at_the_earlier_ones_rollover():
    """With rollover_share 1 every window that starts at another's rollover takes Ip and Iq from the
    operator at sensor 16 of the earlier window with its input held after it, and keeps its recorded
    known states; with share 0 nothing changes; the draw comes from the training generator."""
    from reference_models.components import component
    from surrogate.models import NormStats, build_model

    sub = component("subsystem")
    params = sub.params({"S": 5.0, "G": 0.05, "B": -0.02, "V_own": 1.0, "Ip_own": 0.03, "Iq_own": 0.004})
    x0, u, x = (np.concatenate(parts) for parts in zip(*[_subsystem_windows(s, 101) for s in (4, 5)]))
    split = {"x0": x0, "u": u, "x": x, "t": np.round(np.arange(21) * 0.01, 12)}
    torch.manual_seed(0)
    model = build_model(OperatorConfig(width=16, depth=2, latent=8, anchored=True), NormStats.fit(split))
    tensors = training._to_tensors({"train": split, "val": split}, model, (sub, params))
    tensors.rollovers = training.rollovers(split, sub, causal=True)
    generator = torch.Generator().manual_seed(0)
    assert torch.equal(training.rolled_over_starts(model, tensors, 0.0, generator), tensors.x0)
    started = training.rolled_over_starts(model, tensors, 1.0, generator)
    earlier, later = tensors.rollovers.earlier, tensors.rollovers.later
    with torch.no_grad():
        held = training.held_after(tensors.u[earlier], torch.full((len(earlier),), 16))
        answer = model(tensors.x0[earlier], held, tensors.t)[:, 16]
    torch.testing.assert_close(started[later][:, 2:4], answer[:, 2:4], rtol=0, atol=1e-6)
    assert not torch.allclose(started[later][:, 2:4], tensors.x0[later][:, 2:4], rtol=0, atol=1e-4)
    others = torch.ones(len(started), dtype=torch.bool)
    others[later] = False
    assert torch.equal(started[:, [0, 1, 4]], tensors.x0[:, [0, 1, 4]]) and torch.equal(started[others], tensors.x0[others])
