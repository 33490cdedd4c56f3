"""The paper's Table II on this machine: five surrogates x several seeds, trained and tested here.

    python benchmarks/accuracy_table.py --data runs/paper/data --runs runs/table [--seeds 0 1 2]
           [--jobs 2] [--epochs 10000] [--test DIR]

Trains every (row, seed) with `opfmu train` (one torch thread each, `--jobs` at a time; finished
runs are reused, interrupted ones resume), evaluates each on the test split (or on the test split of
an independent dataset given by --test), and prints mean +- std over seeds next to the paper's
numbers, with the training wall time per run. Writes table.json and error_over_time.png in --runs.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from reference_models.files import write_json
from surrogate.data import load_split
from surrogate.evaluation import aggregate, evaluate, plot_error_over_time, predict
from surrogate.training import load_model

ROWS = {  # label -> (arch, physics-informed)
    "PINN": ("pinn", False),
    "Unstacked DeepONet": ("unstacked", False),
    "Unstacked PI-DeepONet": ("unstacked", True),
    "Stacked-N DeepONet": ("stacked-n", False),
    "Stacked-N PI-DeepONet": ("stacked-n", True),
}
# The settings every run of the table trains with (beside the TrainConfig defaults: SOAP, lr 3e-3
# with a cosine decay, weight decay 0.01, patience 200): the same epoch budget for every row, 200 of
# the 1001 grid times per epoch; the PINN, whose hidden activations are [N, M, width], sees 50.
SETTINGS = {"epochs": 2000, "time_points": 200}
ROW_SETTINGS = {"PINN": {"time_points": 50}}
PAPER = {  # Table II: MSE, MAE, MaxAE (mean of three seeds)
    "PINN": (38.67e-6, 3.87e-3, 172.93e-3),
    "Unstacked DeepONet": (38.25e-6, 3.66e-3, 117.23e-3),
    "Unstacked PI-DeepONet": (26.87e-6, 3.26e-3, 73.03e-3),
    "Stacked-N DeepONet": (38.6e-6, 3.68e-3, 157.44e-3),
    "Stacked-N PI-DeepONet": (36.14e-6, 3.36e-3, 104.69e-3),
}


def run_dir(root: Path, label: str, seed: int) -> Path:
    return root / f"{label.lower().replace(' ', '-')}-seed{seed}"


def train_one(data: str, out: Path, label: str, seed: int, epochs: int | None) -> None:
    arch, physics = ROWS[label]
    settings = {**SETTINGS, **ROW_SETTINGS.get(label, {}), **({"epochs": epochs} if epochs else {})}
    config = out.parent / f"{out.name}.json"
    write_json(config, settings)
    cmd = [sys.executable, "-m", "opfmu", "train", "--data", data, "--arch", arch, "--out", str(out),
           "--seed", str(seed), "--config", str(config), "--threads", "1", "--quiet"]
    cmd += ["--physics"] if physics else []
    subprocess.run(cmd, check=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="paper-preset dataset directory")
    parser.add_argument("--runs", required=True, help="directory for the runs and the table")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--jobs", type=int, default=2, help="trainings at a time (default 2)")
    parser.add_argument("--epochs", type=int, default=None, help=f"epochs (default {SETTINGS['epochs']})")
    parser.add_argument("--rows", nargs="+", default=list(ROWS), choices=list(ROWS), metavar="ROW")
    parser.add_argument("--test", default=None, help="dataset whose test split to evaluate on (default --data)")
    args = parser.parse_args()

    root = Path(args.runs)
    jobs = [(label, seed) for label in args.rows for seed in args.seeds]
    with ThreadPoolExecutor(args.jobs) as pool:
        list(pool.map(lambda job: train_one(args.data, run_dir(root, *job), *job, args.epochs), jobs))

    test = load_split(args.test or args.data, "test")
    table, curves = {}, {}
    for label in args.rows:
        dirs = [run_dir(root, label, seed) for seed in args.seeds]
        models = [load_model(d) for d in dirs]
        metrics = [evaluate(m, test) for m in models]
        walls = [json.loads((d / "result.json").read_text())["wall_s"] for d in dirs]
        epochs = [json.loads((d / "result.json").read_text())["epochs"] for d in dirs]
        summary = aggregate(metrics)
        table[label] = {"physical": {"mean": summary["mean"]["physical"], "std": summary["std"]["physical"]},
                        "standardised": summary["mean"]["standardised"],
                        "per_state_maxae": {k: v["maxae"] for k, v in summary["mean"]["per_state"].items()},
                        "train_wall_s": walls, "epochs": epochs, "paper": dict(zip(("mse", "mae", "maxae"), PAPER[label]))}
        best = int(np.argmin([m["physical"]["mse"] for m in metrics]))
        curves[label] = predict(models[best], test["x0"], test["u"], test["t"])

    print(f"Test split of {args.test or args.data}: {len(test['x0'])} trajectories; mean ± std over seeds "
          f"{args.seeds}; physical units (paper's numbers beside)")
    print(f"{'surrogate':<23}{'MSE':>21}{'paper':>10}{'MAE':>21}{'paper':>10}{'MaxAE':>21}{'paper':>10}"
          f"{'train s':>9}{'beats':>7}")
    for label, row in table.items():
        m, s, p = row["physical"]["mean"], row["physical"]["std"], row["paper"]
        cells = "".join(f"{m[k]:>12.3e} ±{s[k]:.1e}{p[k]:>10.2e}" for k in ("mse", "mae", "maxae"))
        beats = all(m[k] < p[k] for k in ("mse", "mae", "maxae"))
        print(f"{label:<23}{cells}{np.mean(row['train_wall_s']):>9.0f}{'yes' if beats else 'no':>7}")
    print("standardised (per-state std of the training trajectories):")
    for label, row in table.items():
        st = row["standardised"]
        print(f"  {label:<21} MSE {st['mse']:.3e}  MAE {st['mae']:.3e}  MaxAE {st['maxae']:.3e}   "
              f"MaxAE per state: " + ", ".join(f"{k} {v:.3f}" for k, v in row["per_state_maxae"].items()))
    write_json(root / "table.json", table)
    plot_error_over_time(test, curves, root / "error_over_time.png")


if __name__ == "__main__":
    main()
