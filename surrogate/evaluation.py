"""Accuracy metrics of a trained operator on a labeled split, their aggregation over seeds, and
the paper's figures (Fig. 3: trajectories against the reference; Fig. 4: absolute error over time),
drawn on bare matplotlib Figures (PNG, no pyplot state, no display needed).

Metrics are reported in physical units (errors in rad, rad/s, pu mixed over states: what the
paper's table most likely reports) and per-state standardised (each state's error divided by its
std over the training trajectories, the model's x_std), over all points, per state and per time step.
"""
from __future__ import annotations

import matplotlib
import numpy as np
import torch
from matplotlib.figure import Figure


from .models import OperatorModel


def predict(model: OperatorModel, x0, u, t, batch: int = 256) -> np.ndarray:
    """States [N, M, n_x] (float64, physical units) for x0 [N, n_x], u [N, S, n_u], t [M], in batches of trajectories."""
    f32 = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float32)  # noqa: E731
    x0, u, t = f32(x0), f32(u), f32(t)
    model.eval()
    with torch.no_grad():
        parts = [model(x0[i:i + batch], u[i:i + batch], t) for i in range(0, len(x0), batch)]
    return torch.cat(parts).double().numpy()


def error_metrics(x_hat: np.ndarray, x: np.ndarray, x_std, state_names) -> dict:
    """Metrics of predictions x_hat against references x, both [N, S, n_x]; x_std [n_x] for
    standardising; state_names [n_x] name the per-state entries.

    Returns {"n_trajectories", "n_times",
             "physical" / "standardised": {"mse", "mae", "maxae"} over all points and states,
             "per_state" / "per_state_standardised": {state name: {"mse", "mae", "maxae"}},
             "per_time": {"mae", "ae_std", "mse", "maxae"}: arrays [S, n_x] over trajectories (physical)}.
    """
    err = np.asarray(x_hat, dtype=float) - np.asarray(x, dtype=float)
    ae, ae_std = np.abs(err), np.abs(err) / np.asarray(x_std, dtype=float)
    return {
        "n_trajectories": int(err.shape[0]),
        "n_times": int(err.shape[1]),
        "physical": _summary(ae),
        "standardised": _summary(ae_std),
        "per_state": {name: _summary(ae[..., i]) for i, name in enumerate(state_names)},
        "per_state_standardised": {name: _summary(ae_std[..., i]) for i, name in enumerate(state_names)},
        "per_time": {"mae": ae.mean(0), "ae_std": ae.std(0), "mse": (ae ** 2).mean(0), "maxae": ae.max(0)},
    }


def _summary(ae: np.ndarray) -> dict:
    return {"mse": float(np.mean(ae ** 2)), "mae": float(np.mean(ae)), "maxae": float(np.max(ae))}


def evaluate(model: OperatorModel, split: dict) -> dict:
    """error_metrics of the model on a labeled split (from load_split: x0, u, t, x and the component),
    standardised by the model's x_std."""
    x_hat = predict(model, split["x0"], split["u"], split["t"])
    return error_metrics(x_hat, split["x"], model.x_std.double().numpy(), split["component"].state_names)


def aggregate(metrics: list) -> dict:
    """Mean and (population) std over runs, e.g. seeds: {"n": k, "mean": tree, "std": tree} where each
    tree has the structure of one `error_metrics` result (arrays averaged elementwise)."""
    if not metrics:
        raise ValueError("nothing to aggregate")

    def combine(values, reduce):
        first = values[0]
        if isinstance(first, dict):
            return {k: combine([v[k] for v in values], reduce) for k in first}
        return reduce(np.stack([np.asarray(v, dtype=float) for v in values]))

    mean = combine(metrics, lambda a: _plain(a.mean(0)))
    std = combine(metrics, lambda a: _plain(a.std(0)))
    return {"n": len(metrics), "mean": mean, "std": std}


def _plain(a: np.ndarray):
    return float(a) if a.ndim == 0 else a


def to_jsonable(tree):
    """A metrics tree with arrays turned into nested lists (for json.dump)."""
    if isinstance(tree, dict):
        return {k: to_jsonable(v) for k, v in tree.items()}
    if isinstance(tree, np.ndarray):
        return tree.tolist()
    return tree


def plot_trajectories(split: dict, predictions: dict, path, indices=(0, 1, 2)) -> None:
    """Fig. 3: the states of a few trajectories, reference against each model's prediction
    (predictions: label -> x_hat [N, S, n_x]), above the inputs. Writes a PNG."""
    t, x, u, component = split["t"], split["x"], split["u"], split["component"]
    n_x, n_u = component.n_states, component.n_inputs
    fig = Figure(figsize=(7, 1.8 * (n_x + n_u) + 0.2))
    axes = fig.subplots(n_x + n_u, 1, sharex=True)
    colors = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    styles = ["--", "-.", ":", (0, (5, 1))]
    for j, n in enumerate(indices):
        c = colors[j % len(colors)]
        for i in range(n_x):
            axes[i].plot(t, x[n, :, i], color=c, lw=1.5, label="reference" if j == 0 else None)
            for k, (label, x_hat) in enumerate(predictions.items()):
                axes[i].plot(t, x_hat[n, :, i], color=c, lw=1.2, ls=styles[k % len(styles)],
                             label=label if j == 0 else None)
        for i in range(n_u):
            axes[n_x + i].plot(t, u[n, :, i], color=c, lw=1.2)
    labels = [f"{q.name} [{q.unit}]" for q in component.states + component.inputs]
    for ax, label in zip(axes, labels):
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize="small")
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def plot_error_over_time(split: dict, predictions: dict, path) -> None:
    """Fig. 4: absolute error per state over time, mean over trajectories with a +-1 std band,
    for each model (predictions: label -> x_hat [N, S, n_x]). Writes a PNG."""
    t, states = split["t"], split["component"].states
    fig = Figure(figsize=(7, 2.2 * len(states) + 0.2))
    axes = fig.subplots(len(states), 1, sharex=True)
    for label, x_hat in predictions.items():
        ae = np.abs(np.asarray(x_hat) - split["x"])
        mean, std = ae.mean(0), ae.std(0)
        for i, ax in enumerate(axes):
            line, = ax.plot(t, mean[:, i], lw=1.2, label=label)
            ax.fill_between(t, np.maximum(mean[:, i] - std[:, i], 0), mean[:, i] + std[:, i],
                            color=line.get_color(), alpha=0.25, lw=0)
    for ax, q in zip(axes, states):
        ax.set_ylabel(f"AE {q.name} [{q.unit}]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize="small")
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
