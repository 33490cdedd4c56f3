"""Dataset generation, storage and loading.

A dataset directory holds one `.npz` per split with
    x0 [N, n_x]    initial states (physical units)
    u  [N, S, n_u] the component's inputs at the S sensor times (SM4: Vs, theta_vs, Pm, Efd)
    t  [S]         sensor = query times [s], uniform from 0 to the horizon
    x  [N, S, n_x] reference states at t (labeled splits only)
    family [N]  input family of each trajectory;  signal [N]  its exact signal as JSON
and `metadata.json` (written last: its presence marks a complete dataset), which records the
component and its parameters (`component`, `params`): the machine every solve, loss and export uses. Solves run in chunks
cached under `.partial/`; a rerun with the same preset and seed skips finished chunks, so an
interrupted generation resumes and gives the same files. Everything is deterministic for a seed.

Files hold the windows as solved (absolute angles and speeds). A component with a drift symmetry
(reference_models.drift) is read back in the frame of each window (`load_split`), which is what
operators learn, and the envelope in the metadata is the one in that frame.
"""
from __future__ import annotations

import hashlib
import json
import math
import platform
import shutil
import time
from pathlib import Path

import numpy as np

from reference_models.version import __version__
from reference_models.component import Component
from reference_models.components import component
from reference_models.drift import frame_of, to_frame, trajectories_to_frame
from reference_models.files import write_json, write_npz
from reference_models.messages import explain
from reference_models.progress import progress_bar

from ..errors import DatasetError
from .envelope import probe_plan, reachable_box, reachable_summary
from .presets import LABELED, SPLITS, Preset
from .runner import SolveRunner
from .sampling import sample_split

FORMAT_VERSION = 3


def time_grid(preset: Preset) -> np.ndarray:
    return np.linspace(0.0, preset.horizon, preset.n_points)


def fingerprint(preset: Preset, seed: int, params) -> str:
    # the version too: finished chunks of another opfmu version are not mixed into a resumed run
    text = json.dumps({"preset": preset.to_dict(), "seed": seed, "params": params.to_dict(),
                       "format": FORMAT_VERSION, "opfmu": __version__}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def generate(preset: Preset, out: str | Path, seed: int = 0, runner: SolveRunner | None = None,
             progress: bool = True, params=None) -> dict:
    """Generate (or resume, or find complete) the dataset of `preset` in `out` for the component's
    parameters `params` (default: its defaults, e.g. Table I's machine); returns its metadata."""
    out = Path(out)
    partial = out / ".partial"
    try:
        model = component(preset.component)
    except ValueError as exc:
        raise DatasetError(f"preset {preset.name!r}: {exc}") from None
    params = model.params() if params is None else params
    if not isinstance(params, model.params_type):
        raise DatasetError(f"parameters of {type(params).__name__} given for a {model.name} dataset")
    key = fingerprint(preset, seed, params)
    meta_path = out / "metadata.json"
    if meta_path.exists():
        meta = load_metadata(out)
        if meta.get("fingerprint") != key:
            raise DatasetError(f"{out} holds a different dataset (preset {meta.get('preset', {}).get('name')!r}, "
                               f"seed {meta.get('seed')}); choose another --out")
        return meta
    plan_path = partial / "plan.json"
    if plan_path.exists() and _json_object(plan_path).get("fingerprint") != key:
        raise DatasetError(f"{out} holds an unfinished different dataset; remove {partial} or choose another --out")
    write_json(plan_path, {"fingerprint": key, "preset": preset.to_dict(), "seed": seed})

    started = time.perf_counter()
    runner = runner or SolveRunner(workers=0)
    t = time_grid(preset)
    rngs = dict(zip(("probe", *SPLITS), (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(5))))
    meta = {"format": FORMAT_VERSION, "fingerprint": key, "preset": preset.to_dict(), "seed": seed,
            "component": model.name, "params": params.to_dict(),
            "state_names": list(model.state_names), "input_names": list(model.input_names),
            "horizon_s": preset.horizon, "n_points": preset.n_points}
    machine = (model, params)
    with runner:
        ic_box, pool = _ordered_box(preset.ic_box, model), None
        if preset.ic == "reachable":
            x0s, signals, names = probe_plan(preset.families, preset.probes_per_family, preset.horizon, rngs["probe"],
                                             model, params, preset.levels)
            x = _solve(runner, "probe", x0s, signals, t, preset, partial, progress, machine)
            meta["reachable"] = reachable_summary(x, names, model, params, preset.levels)
            ic_box, pool = reachable_box(meta["reachable"]), x.reshape(-1, model.n_states)
        meta["ic_box"] = {s: list(r) for s, r in ic_box.items()}
        trained_on = []  # (x0, u) of the splits a model trains on: its envelope
        for split in SPLITS:
            x0, signals, names = sample_split(preset.counts[split], preset.families, ic_box, preset.horizon,
                                              rngs[split], pool, preset.reachable_fraction, preset.levels, params,
                                              progress, f"sampling {split}")
            _check_channels(signals, model)
            arrays = {"x0": x0, "u": np.stack([s(t) for s in signals]), "t": t,
                      "family": np.array(names), "signal": np.array([json.dumps(s.to_dict()) for s in signals])}
            if LABELED[split]:
                arrays["x"] = _solve(runner, split, x0, signals, t, preset, partial, progress, machine)
            write_npz(out / f"{split}.npz", **arrays)
            if split in ("train", "collocation"):
                trained_on.append(in_frame(arrays, model, params)[:2])
    meta["counts"] = {s: preset.counts[s] for s in SPLITS}
    meta["envelope"] = envelope_of(np.concatenate([x for x, _ in trained_on]),
                                   np.concatenate([u for _, u in trained_on]), model)
    meta["versions"] = _versions()
    meta["wall_time_s"] = round(time.perf_counter() - started, 2)
    write_json(meta_path, meta)
    shutil.rmtree(partial, ignore_errors=True)
    return meta


def _ordered_box(box: dict, model: Component) -> dict:
    """The initial-condition box in the component's state order; DatasetError if a state is missing."""
    missing = [s for s in model.state_names if s not in box]
    if missing:
        raise DatasetError(f"the preset's ic_box gives no range for {', '.join(missing)}")
    return {s: tuple(box[s]) for s in model.state_names}


def _check_channels(signals, model: Component) -> None:
    """Every signal drives exactly the component's inputs, in its order."""
    for s in signals[:1]:
        if s.names != model.input_names:
            raise DatasetError(f"input family channels {', '.join(s.names)} are not the inputs of {model.name} "
                               f"({', '.join(model.input_names)})")


def _solve(runner, name, x0s, signals, t, preset, partial: Path, progress: bool, machine) -> np.ndarray:
    """Reference states [N, S, n_x] of machine (component, params), reusing chunks cached in
    `partial` and caching new ones."""
    size = preset.chunk_size
    results, todo = {}, {}
    for k, start in enumerate(range(0, len(x0s), size)):
        key = f"{name}-{k:05d}"
        path = partial / f"{key}.npz"
        if path.exists():
            results[key] = np.load(path)["x"]
        else:
            todo[key] = (x0s[start:start + size], [s.to_dict() for s in signals[start:start + size]])
    bar = progress_bar(total=len(x0s), initial=sum(len(r) for r in results.values()), desc=f"solving {name}",
                       unit="traj", enabled=progress)

    def done(key, x):
        write_npz(partial / f"{key}.npz", x=x)
        results[key] = x
        bar.update(len(x))

    runner.run(todo, t, preset.solver, done, *machine)
    bar.close()
    return np.concatenate([results[k] for k in sorted(results)])


def in_frame(arrays: dict, model: Component, params) -> tuple:
    """(x0, u[, x]) of a split's arrays in the frame of each window (reference_models.drift); as
    they are for a component without a drift symmetry."""
    if model.drift is None:
        return (arrays["x0"], arrays["u"]) + ((arrays["x"],) if "x" in arrays else ())
    frame = frame_of(model.drift, params)
    if "x" in arrays:
        return trajectories_to_frame(frame, arrays["x0"], arrays["u"], arrays["x"], arrays["t"])
    x0_f, u_f, _, _ = to_frame(frame, arrays["x0"], arrays["u"], arrays["t"])
    return x0_f, u_f


def envelope_of(x0: np.ndarray, u: np.ndarray, model: Component) -> dict:
    """Min/max of every initial state (x0 [N, n_x]) and input (u [N, S, n_u]): what a model trained
    on them has seen, by the component's names."""
    return {
        "x0": {n: [float(x0[:, i].min()), float(x0[:, i].max())] for i, n in enumerate(model.state_names)},
        "u": {n: [float(u[..., i].min()), float(u[..., i].max())] for i, n in enumerate(model.input_names)},
    }


def _versions() -> dict:
    import scipy

    return {"opfmu": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__}


def load_split(directory: str | Path, split: str, frame: bool = True) -> dict:
    """Arrays of one split as a dict (see module docstring for names and shapes), and under
    `component` the component the dataset was solved for. frame: x0, u and x in the frame of each
    window (see in_frame), as operators learn them; False: as solved."""
    path = Path(directory) / f"{split}.npz"
    if not path.exists():
        raise DatasetError(f"no {split} split at {path}; run `opfmu data` first")
    meta = load_metadata(directory)
    if meta.get("format") != FORMAT_VERSION:
        raise DatasetError(f"{directory} was made by an older opfmu (dataset format {meta.get('format')}, "
                           f"now {FORMAT_VERSION}): regenerate it")
    model, params = machine_of(meta)
    try:
        with np.load(path) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError, EOFError):  # not an npz archive, or one holding pickled objects
        raise DatasetError(f"{path} is not a readable split (not an .npz archive of plain arrays): "
                           "regenerate the dataset") from None
    missing = [k for k in ("x0", "u", "t") + (("x",) if LABELED.get(split) else ()) if k not in arrays]
    if missing:
        raise DatasetError(f"{path} lacks the arrays {', '.join(missing)}: regenerate the dataset")
    if frame:
        arrays.update(zip(("x0", "u", "x"), in_frame(arrays, model, params)))
    return {**arrays, "component": model}


def load_metadata(directory: str | Path) -> dict:
    """The metadata.json of a dataset directory (a JSON object); DatasetError naming the file otherwise."""
    path = Path(directory) / "metadata.json"
    if not path.is_file():
        raise DatasetError(f"{directory} is not a complete dataset (no metadata.json)")
    return _json_object(path)


def _json_object(path: Path) -> dict:
    """The JSON object in `path`; DatasetError naming the file when it is unreadable or not an object."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        reason = explain(exc)
        raise DatasetError(f"{path} is not readable JSON ({reason}): remove the dataset and regenerate it") from None
    if not isinstance(data, dict):
        raise DatasetError(f"{path} must be a JSON object: remove the dataset and regenerate it")
    _check_metadata_types(data, path)
    return data


def _check_metadata_types(meta: dict, path: Path) -> None:
    """DatasetError naming the field unless each field the later stages read, where present, has its type."""
    def number(value) -> bool:
        return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)

    def pair(value) -> bool:
        return isinstance(value, list) and len(value) == 2 and all(number(v) for v in value)

    envelope = meta.get("envelope", {"x0": {}, "u": {}})
    checks = {
        "horizon_s": ("a number > 0", number(meta.get("horizon_s", 1.0)) and meta.get("horizon_s", 1.0) > 0),
        "n_points": ("an integer >= 2", isinstance(meta.get("n_points", 2), int)
                     and not isinstance(meta.get("n_points", 2), bool) and meta.get("n_points", 2) >= 2),
        "state_names": ("a list of names", isinstance(meta.get("state_names", []), list)
                        and all(isinstance(n, str) for n in meta.get("state_names", []))),
        "input_names": ("a list of names", isinstance(meta.get("input_names", []), list)
                        and all(isinstance(n, str) for n in meta.get("input_names", []))),
        "envelope": ('{"x0": {state: [low, high]}, "u": {input: [low, high]}}', isinstance(envelope, dict)
                     and all(isinstance(envelope.get(g), dict) and all(pair(r) for r in envelope[g].values())
                             for g in ("x0", "u"))),
        "preset": ("an object", isinstance(meta.get("preset", {}), dict)),
        "counts": ("an object", isinstance(meta.get("counts", {}), dict)),
        "fingerprint": ("a string", isinstance(meta.get("fingerprint", ""), str)),
    }
    for field, (expected, good) in checks.items():
        if not good:
            raise DatasetError(f"{path}: {field} must be {expected}: remove the dataset and regenerate it")


def machine_of(meta: dict):
    """(component, parameters) a dataset (its metadata) was solved for."""
    if "component" not in meta or "params" not in meta:
        raise DatasetError("the dataset records no component and parameters (made by an older opfmu): regenerate it")
    try:
        model = component(meta["component"])
        return model, model.params(meta["params"])
    except ValueError as exc:
        raise DatasetError(f"the dataset's machine is not usable: {exc}") from None
