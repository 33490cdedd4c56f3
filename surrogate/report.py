"""Evaluation of trained runs as a user sees it: metrics.json, a text table and the paper's figures."""
from __future__ import annotations

from pathlib import Path

from reference_models.files import write_json

from .data import load_split
from .evaluation import aggregate, evaluate, plot_error_over_time, plot_trajectories, predict, to_jsonable
from .training import load_model


def evaluate_runs(runs, data_dir, split: str = "test", out=None) -> str:
    """Evaluate each run's best model on `split` of `data_dir`; aggregate over runs (e.g. seeds).

    Writes `metrics.json` (per run and aggregate), `trajectories.png` (Fig. 3) and
    `error_over_time.png` (Fig. 4) into `out` (default: the first run); returns a text table.
    """
    runs = [Path(r) for r in runs]
    for run in runs:
        if not (run / "model.pt").exists():
            raise ValueError(f"{run} holds no trained model (model.pt); run `opfmu train` first")
    data = load_split(data_dir, split)
    if "x" not in data:
        raise ValueError(f"the {split} split has no reference states to evaluate against")
    out = Path(out) if out else runs[0]
    models = [load_model(run) for run in runs]
    per_run = [evaluate(model, data) for model in models]
    summary = aggregate(per_run)
    write_json(out / "metrics.json", {"split": split, "data": str(data_dir), "runs": [str(r) for r in runs],
                                      "per_run": [to_jsonable(m) for m in per_run], "aggregate": to_jsonable(summary)})
    predictions = {"operator" if len(runs) == 1 else runs[0].name: predict(models[0], data["x0"], data["u"], data["t"])}
    plot_trajectories(data, predictions, out / "trajectories.png")
    plot_error_over_time(data, predictions, out / "error_over_time.png")
    return format_table(summary, f"{summary['n']} run(s) on the {split} split; metrics.json and figures in {out}")


def check_operator(operator, data_dir, out, split: str = "test") -> str:
    """An exported operator (surrogate.operator.Operator) against the reference trajectories of a
    dataset split: metrics.json, trajectories.png and error_over_time.png in `out`; returns a table."""
    import warnings

    import numpy as np

    from .evaluation import error_metrics
    from .operator import EnvelopeWarning

    data = load_split(data_dir, split)
    outside = sum(bool(operator.outside_envelope(data["x0"][i:i + 1], data["u"][i:i + 1]))
                  for i in range(len(data["x0"])))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EnvelopeWarning)
        x_hat = operator.predict(data["x0"], data["u"], data["t"]).astype(np.float64)
    n_x = data["x"].shape[-1]
    metrics = error_metrics(x_hat, data["x"], data["x"].reshape(-1, n_x).std(0),  # standardised by this split
                            data["component"].state_names)
    out = Path(out)
    write_json(out / "metrics.json", {"operator": str(operator.path), "data": str(data_dir), "split": split,
                                      "outside_envelope": outside, "metrics": to_jsonable(metrics)})
    plot_trajectories(data, {"operator": x_hat}, out / "trajectories.png")
    plot_error_over_time(data, {"operator": x_hat}, out / "error_over_time.png")
    title = (f"{operator.path.name} on {len(x_hat)} {split} trajectories of {data_dir} ({outside} partly outside "
             f"its envelope); metrics.json and figures in {out}")
    return format_table({"n": 1, "mean": metrics, "std": _zeros_like(metrics)}, title)


def _zeros_like(tree):
    return {k: _zeros_like(v) for k, v in tree.items()} if isinstance(tree, dict) else 0.0


def format_table(summary: dict, title: str) -> str:
    """Mean (+- std over runs) of MSE, MAE, MaxAE, overall and per state, physical and standardised."""
    mean, std = summary["mean"], summary["std"]
    lines = [title,
             f"{'':<24}{'MSE':>22}{'MAE':>22}{'MaxAE':>22}"]

    def row(label, m, s):
        spread = (lambda k: f" ±{s[k]:.1e}") if summary["n"] > 1 else (lambda k: " " * 9)  # noqa: E731
        cells = "".join(f"{m[k]:>12.3e}{spread(k)}" for k in ("mse", "mae", "maxae"))
        lines.append(f"{label:<24}{cells}")

    row("all (physical units)", mean["physical"], std["physical"])
    row("all (standardised)", mean["standardised"], std["standardised"])
    for name in mean["per_state"]:
        row(f"  {name}", mean["per_state"][name], std["per_state"][name])
    return "\n".join(lines)
