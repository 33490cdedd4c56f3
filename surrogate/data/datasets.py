"""Dataset generation, storage and loading.

A dataset directory holds one `.npz` per split with
    x0 [N, 4]   initial states (physical units)
    u  [N, S, 2] inputs (Vs, theta_vs) at the S sensor times
    t  [S]      sensor = query times [s], uniform from 0 to the horizon
    x  [N, S, 4] reference states at t (labeled splits only)
    family [N]  input family of each trajectory;  signal [N]  its exact signal as JSON
and `metadata.json` (written last: its presence marks a complete dataset). Solves run in chunks
cached under `.partial/`; a rerun with the same preset and seed skips finished chunks, so an
interrupted generation resumes and gives the same files. Everything is deterministic for a seed.
"""
from __future__ import annotations

import hashlib
import json
import platform
import shutil
import time
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from reference_models.version import __version__
from reference_models.files import write_json, write_npz
from reference_models.sm4 import INPUT_NAMES, STATE_NAMES, SM4Params

from .envelope import probe_plan, reachable_box, reachable_summary
from .presets import LABELED, SPLITS, Preset
from .runner import SolveRunner
from .sampling import sample_split

FORMAT_VERSION = 1


def time_grid(preset: Preset) -> np.ndarray:
    return np.linspace(0.0, preset.horizon, preset.n_points)


def fingerprint(preset: Preset, seed: int) -> str:
    # the version too: finished chunks of another opfmu version are not mixed into a resumed run
    text = json.dumps({"preset": preset.to_dict(), "seed": seed, "format": FORMAT_VERSION, "opfmu": __version__},
                      sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


class DatasetError(ValueError):
    """A dataset directory that cannot be used as asked."""


def generate(preset: Preset, out: str | Path, seed: int = 0, runner: SolveRunner | None = None,
             progress: bool = True) -> dict:
    """Generate (or resume, or find complete) the dataset of `preset` in `out`; returns its metadata."""
    out = Path(out)
    partial = out / ".partial"
    key = fingerprint(preset, seed)
    meta_path = out / "metadata.json"
    if meta_path.exists():
        meta = json.loads(meta_path.read_text())
        if meta.get("fingerprint") != key:
            raise DatasetError(f"{out} holds a different dataset (preset {meta.get('preset', {}).get('name')!r}, "
                               f"seed {meta.get('seed')}); choose another --out")
        return meta
    plan_path = partial / "plan.json"
    if plan_path.exists() and json.loads(plan_path.read_text()).get("fingerprint") != key:
        raise DatasetError(f"{out} holds an unfinished different dataset; remove {partial} or choose another --out")
    write_json(plan_path, {"fingerprint": key, "preset": preset.to_dict(), "seed": seed})

    started = time.perf_counter()
    runner = runner or SolveRunner(workers=0)
    t = time_grid(preset)
    rngs = dict(zip(("probe", *SPLITS), (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(5))))
    meta = {"format": FORMAT_VERSION, "fingerprint": key, "preset": preset.to_dict(), "seed": seed,
            "state_names": list(STATE_NAMES), "input_names": list(INPUT_NAMES),
            "params": SM4Params().to_dict(), "horizon_s": preset.horizon, "n_points": preset.n_points}
    with runner:
        ic_box, pool = preset.ic_box, None
        if preset.ic == "reachable":
            x0s, signals, names = probe_plan(preset.families, preset.probes_per_family, preset.horizon, rngs["probe"])
            x = _solve(runner, "probe", x0s, signals, t, preset, partial, progress)
            meta["reachable"] = reachable_summary(x, names)
            ic_box, pool = reachable_box(meta["reachable"]), x.reshape(-1, 4)
        meta["ic_box"] = {s: list(r) for s, r in ic_box.items()}
        trained_on = []  # (x0, u) of the splits a model trains on: its envelope
        for split in SPLITS:
            x0, signals, names = sample_split(preset.counts[split], preset.families, ic_box, preset.horizon,
                                              rngs[split], pool, preset.reachable_fraction)
            arrays = {"x0": x0, "u": np.stack([s(t) for s in signals]), "t": t,
                      "family": np.array(names), "signal": np.array([json.dumps(s.to_dict()) for s in signals])}
            if LABELED[split]:
                arrays["x"] = _solve(runner, split, x0, signals, t, preset, partial, progress)
            write_npz(out / f"{split}.npz", **arrays)
            if split in ("train", "collocation"):
                trained_on.append((arrays["x0"], arrays["u"]))
    meta["counts"] = {s: preset.counts[s] for s in SPLITS}
    meta["envelope"] = envelope_of(np.concatenate([x for x, _ in trained_on]),
                                   np.concatenate([u for _, u in trained_on]))
    meta["versions"] = _versions()
    meta["wall_time_s"] = round(time.perf_counter() - started, 2)
    write_json(meta_path, meta)
    shutil.rmtree(partial, ignore_errors=True)
    return meta


def _solve(runner, name, x0s, signals, t, preset, partial: Path, progress: bool) -> np.ndarray:
    """Reference states [N, S, 4], reusing chunks cached in `partial` and caching new ones."""
    size = preset.chunk_size
    results, todo = {}, {}
    for k, start in enumerate(range(0, len(x0s), size)):
        key = f"{name}-{k:05d}"
        path = partial / f"{key}.npz"
        if path.exists():
            results[key] = np.load(path)["x"]
        else:
            todo[key] = (x0s[start:start + size], [s.to_dict() for s in signals[start:start + size]])
    bar = tqdm(total=len(x0s), initial=sum(len(r) for r in results.values()), desc=f"solving {name}",
               unit="traj", disable=not progress)

    def done(key, x):
        write_npz(partial / f"{key}.npz", x=x)
        results[key] = x
        bar.update(len(x))

    runner.run(todo, t, preset.solver, done)
    bar.close()
    return np.concatenate([results[k] for k in sorted(results)])


def envelope_of(x0: np.ndarray, u: np.ndarray) -> dict:
    """Min/max of every initial state (x0 [N, 4]) and input (u [N, S, 2]): what a model trained on them has seen."""
    return {
        "x0": {n: [float(x0[:, i].min()), float(x0[:, i].max())] for i, n in enumerate(STATE_NAMES)},
        "u": {n: [float(u[..., i].min()), float(u[..., i].max())] for i, n in enumerate(INPUT_NAMES)},
    }


def _versions() -> dict:
    import scipy

    return {"opfmu": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__}


def load_split(directory: str | Path, split: str) -> dict:
    """Arrays of one split as a dict (see module docstring for names and shapes)."""
    path = Path(directory) / f"{split}.npz"
    if not path.exists():
        raise DatasetError(f"no {split} split at {path}; run `opfmu data` first")
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def load_metadata(directory: str | Path) -> dict:
    path = Path(directory) / "metadata.json"
    if not path.exists():
        raise DatasetError(f"{directory} is not a complete dataset (no metadata.json)")
    return json.loads(path.read_text())
