"""Full-batch training of an operator network on a dataset directory, with exact resume.

A run directory holds
    config.json      the TrainConfig and the dataset it trains on (path, fingerprint)
    checkpoint.pt    model, optimizer, RNG, epoch and early-stopping state (written atomically)
    model.pt         the best model so far by validation MSE, loadable with `load_model`
    metrics.jsonl    one JSON line per epoch: epoch, loss (weighted total), data, physics_data and
                     physics_collocation (when on), val_mse (standardised), wall_s (cumulative
                     seconds spent in epochs)
    result.json      summary, written when the run ends

`train` on a directory with a checkpoint continues from it; the continued run gives the same
parameters as one that was never interrupted (same machine and thread count). A resumed run may
raise `epochs`; every other setting must match (with the cosine schedule, a raised `epochs`
stretches the remaining schedule: the rate rises again, like a warm restart). A run that stopped early stays stopped. The
learning rate follows `lr_schedule` (a cosine decay by default; "constant" is the paper's).
"""
from __future__ import annotations

import bisect
import contextlib
import json
import math
import warnings
import time
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

import numpy as np
import torch

from reference_models.files import atomic_path, write_json
from reference_models.messages import one_line
from reference_models.progress import progress_bar

from .data import load_metadata, load_split, machine_of
from .errors import TrainError
from .heap import freed_memory_kept
from .losses import (LossWeights, data_loss, physics_collocation_loss, physics_data_loss, physics_scale,
                     residual_scale, standardise)
from .models import NormStats, OperatorConfig, OperatorModel, build_model

OPTIMIZERS = ("soap", "adam")
LR_SCHEDULES = ("constant", "cosine")
# A causally trained operator learns window time t with weight 1 - t/T (a uniform cut), so its last
# part is its least trained: rolled over before it, at this share of the horizon, the shipped one's
# omega error under slowly moving inputs fell from 0.013 to 0.005 rad/s (README, long co-simulations).
CAUSAL_ROLLOVER_SHARE = 0.8


@dataclass(frozen=True)
class TrainConfig:
    """Training settings (defaults: paper IV-C).

    optimizer: "soap" (heavyball.SOAP; factors of size <= max_precond_dim are preconditioned, the
        4008-wide branch input of 1001 sensors of 4 inputs is not) or "adam" (AdamW: decoupled weight decay like SOAP's).
    epochs: maximum number of full-batch epochs; early stopping ends the run when the validation
        MSE (standardised states) has not improved by min_delta for `patience` epochs.
    physics: add the physics losses (eqs. 6, 7) with `weights`; off, only the data loss is used.
    time_points: if set, each epoch uses this many grid times drawn at random (without
        replacement) for all terms; None uses the whole grid. The defaults (2000 epochs, 200 times)
        are the recipe of the Table II runs: paper-scale training within 15 minutes on 2 cores
        (docs/results.md, "Default training").
    checkpoint_every: epochs between checkpoints (one is also written when the run ends).
    lr_schedule: "constant" (the paper) or "cosine": lr decays along a half cosine to lr * lr_final
        at `epochs`. A constant rate leaves the validation MSE jumping by orders of magnitude late
        in training, which also fires early stopping while the model still improves.
    causal: train the operator as a co-simulation FMU uses it. Each epoch every trajectory gets a
        random cut time; its input after the cut is replaced by the value at the cut (held, as the
        FMU fills the sensor slots it does not know yet), and the data and labeled-physics terms
        count only up to the cut, where the reference states are those of the held input too. The
        collocation term, which needs no labels, uses cut inputs over the whole window. The operator
        thus learns states that do not depend on inputs after their time.
    state_weights: weights of delta, omega, Ed_p, Eq_p in the data loss (divided by their mean).
    rollover_share: where a training window starts at the rollover of another window of the same
        run (at CAUSAL_ROLLOVER_SHARE of the horizon when causal, else at its end: where a
        co-simulation starts its next window), each epoch this share of them, drawn at random, starts
        its learned states (Component.learned_states) from the operator's own answer at that
        rollover, computed without gradient, instead of the recorded ones; its targets stay recorded.
        A co-simulation chains windows that way, so the operator learns to return from its own error
        at a rollover instead of carrying it on (the pushforward of neural PDE solvers, Brandstetter
        et al. 2022). Needs learned states that no window frame moves; 0 is off.
    """

    model: OperatorConfig = field(default_factory=OperatorConfig)
    optimizer: str = "soap"
    lr: float = 3e-3
    lr_schedule: str = "cosine"
    lr_final: float = 0.01
    weight_decay: float = 0.01
    max_precond_dim: int = 256
    precondition_frequency: int = 10
    epochs: int = 2000
    patience: int = 200
    min_delta: float = 1e-6
    seed: int = 0
    physics: bool = False
    weights: LossWeights = field(default_factory=LossWeights)
    time_points: int | None = 200
    checkpoint_every: int = 100
    causal: bool = False
    state_weights: tuple = (1.0, 1.0, 1.0, 1.0)
    rollover_share: float = 0.0

    def __post_init__(self):
        if self.lr_schedule not in LR_SCHEDULES:
            raise ValueError(f"unknown lr_schedule {self.lr_schedule!r} (known: {', '.join(LR_SCHEDULES)})")
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"unknown optimizer {self.optimizer!r} (known: {', '.join(OPTIMIZERS)})")
        if self.epochs < 0 or self.patience < 1 or self.checkpoint_every < 1:
            raise ValueError("epochs must be >= 0, patience and checkpoint_every >= 1")
        if self.time_points is not None and self.time_points < 1:
            raise ValueError("time_points must be >= 1 (or None for the whole grid)")
        if len(self.state_weights) < 1 or min(self.state_weights) < 0 or max(self.state_weights) <= 0:
            raise ValueError(f"state_weights must be one weight >= 0 per state, not all 0; got {self.state_weights}")
        if not 0.0 <= self.rollover_share <= 1.0:
            raise ValueError(f"rollover_share must lie in [0, 1]; got {self.rollover_share}")
        object.__setattr__(self, "state_weights", tuple(float(w) for w in self.state_weights))

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "TrainConfig":
        known = {f.name for f in fields(cls)}
        data = {k: v for k, v in data.items() if k in known}
        if "model" in data:
            data["model"] = OperatorConfig.from_dict(data["model"])
        if "weights" in data:
            data["weights"] = LossWeights(**data["weights"])
        return cls(**data)


@dataclass(frozen=True)
class TrainResult:
    """How a run ended: epochs run, the best epoch and its validation MSE (standardised states)."""

    run_dir: str
    epochs: int
    best_epoch: int
    best_val_mse: float
    stopped_early: bool
    wall_s: float

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class _Tensors:
    """The float32 tensors of one training run (shared grid t [S])."""

    t: torch.Tensor
    x0: torch.Tensor
    u: torch.Tensor
    y: torch.Tensor              # standardised reference states, [N, S, n_x]
    f_ref: torch.Tensor          # rhs at the reference states, [N, S, n_x]
    val_x0: torch.Tensor
    val_u: torch.Tensor
    val_y: torch.Tensor
    col_x0: torch.Tensor | None
    col_u: torch.Tensor | None
    scale: torch.Tensor          # per-state residual scale [n_x]
    rhs: object                  # (x, u) -> dx/dt of the dataset's component and parameters (torch)
    rollovers: "Rollovers | None" = None


@dataclass
class Rollovers:
    """The train split's windows that start at another's rollover: window later[k] starts where
    window earlier[k] of the same run rolls over, at sensor index `index`; `learned` the states a
    rolled-over start takes from the operator."""

    earlier: torch.Tensor        # [K] indices into the train split
    later: torch.Tensor          # [K]
    index: int
    learned: torch.Tensor        # [n_learned] state indices


@dataclass
class _State:
    """Everything besides model and optimizer that an exact resume needs."""

    epoch: int = 0
    best_val: float = float("inf")
    best_epoch: int = 0
    best_state: dict | None = None
    ref_val: float = float("inf")   # last value that improved by min_delta (patience reference)
    bad_epochs: int = 0
    wall_s: float = 0.0
    stopped_early: bool = False


def train(data_dir, config: TrainConfig, run_dir, progress: bool = True) -> TrainResult:
    """Train (or resume) a model on the dataset in `data_dir`; artefacts go to `run_dir`.

    Raises TrainError when run_dir holds a checkpoint of another configuration or dataset, and
    surrogate.data.DatasetError when data_dir is not a complete dataset.
    """
    data_dir, run_dir = Path(data_dir), Path(run_dir)
    meta = load_metadata(data_dir)
    machine = machine_of(meta)
    if len(config.state_weights) != machine[0].n_states:
        raise TrainError(f"state_weights gives {len(config.state_weights)} weights for the {machine[0].n_states} "
                         f"states of {machine[0].name} ({', '.join(machine[0].state_names)})")
    data_info = {"dir": str(data_dir.resolve()), "fingerprint": meta.get("fingerprint")}
    checkpoint_path = run_dir / "checkpoint.pt"
    resuming = checkpoint_path.exists()
    if resuming:
        _check_resumable(run_dir, config, data_info)
    run_dir.mkdir(parents=True, exist_ok=True)
    write_json(run_dir / "config.json", {"train": config.to_dict(), "data": data_info})

    splits = _load_splits(data_dir, config)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        stats = NormStats.fit(splits["train"], _feature_map(config, machine, splits["train"]))
        model = build_model(config.model, stats)
    tensors = _to_tensors(splits, model, machine)
    if config.rollover_share > 0:
        tensors.rollovers = rollovers(load_split(data_dir, "train", frame=False), machine[0], config.causal)
    with _eager_heavyball(), freed_memory_kept():
        optimizer = _make_optimizer(model, config)
        generator = torch.Generator().manual_seed(config.seed)
        state = _State()
        if resuming:
            state = _restore(checkpoint_path, model, optimizer, generator)
        metrics_path = run_dir / "metrics.jsonl"
        _truncate_metrics(metrics_path, state.epoch)
        _loop(model, optimizer, generator, state, tensors, config, run_dir, progress)
    result = TrainResult(str(run_dir), state.epoch, state.best_epoch, state.best_val, state.stopped_early,
                         round(state.wall_s, 3))
    write_json(run_dir / "result.json", result.to_dict())
    return result


def _loop(model, optimizer, generator, state: _State, tensors: _Tensors, config: TrainConfig, run_dir: Path,
          progress: bool) -> None:
    """Epochs until `config.epochs` or early stopping; checkpoints periodically and at the end."""
    bar = progress_bar(total=config.epochs, initial=state.epoch, desc="training", unit="epoch", enabled=progress)
    with open(run_dir / "metrics.jsonl", "a") as log, warnings.catch_warnings():
        # heavyball notes every rate change of the schedule as "experimental"; it is supported here
        warnings.filterwarnings("ignore", message="Learning rate changed between steps")
        while state.epoch < config.epochs and not state.stopped_early:
            started = time.perf_counter()
            for group in optimizer.param_groups:
                group["lr"] = learning_rate(config, state.epoch)
            parts = _step(model, optimizer, generator, tensors, config)
            val = validation_mse(model, tensors)
            state.epoch += 1
            state.wall_s += time.perf_counter() - started
            _update_early_stopping(state, val, model, config)
            line = {"epoch": state.epoch, **parts, "val_mse": val, "wall_s": round(state.wall_s, 4)}
            log.write(json.dumps(line) + "\n")
            log.flush()
            bar.update(1)
            bar.set_postfix(loss=f"{parts['loss']:.3e}", val=f"{val:.3e}", best=f"{state.best_val:.3e}")
            if state.epoch % config.checkpoint_every == 0:
                _save(run_dir, model, optimizer, generator, state, config)
    bar.close()
    _save(run_dir, model, optimizer, generator, state, config)


def learning_rate(config: TrainConfig, epoch: int) -> float:
    """The rate for (0-based) `epoch`: a function of the epoch alone, so resume needs no state for it."""
    if config.lr_schedule == "constant" or config.epochs <= 1:
        return config.lr
    progress = min(epoch / (config.epochs - 1), 1.0)
    return config.lr * (config.lr_final + (1 - config.lr_final) * 0.5 * (1 + math.cos(math.pi * progress)))


def _step(model, optimizer, generator, tensors: _Tensors, config: TrainConfig) -> dict:
    """One optimizer step on the full batch; returns the loss terms as floats."""
    model.train()
    n_times = tensors.t.numel()
    idx = None
    if config.time_points is not None and config.time_points < n_times:
        idx = torch.randperm(n_times, generator=generator)[:config.time_points].sort().values
    pick = (lambda a: a) if idx is None else (lambda a: a[:, idx])  # noqa: E731
    t = tensors.t if idx is None else tensors.t[idx]
    w = config.weights
    use_pd = config.physics and w.physics_data > 0
    use_pc = config.physics and w.physics_collocation > 0 and tensors.col_x0 is not None

    x0, u, col_u, mask = tensors.x0, tensors.u, tensors.col_u, None
    if config.rollover_share > 0:
        x0 = rolled_over_starts(model, tensors, config.rollover_share, generator)
    if config.causal:
        cut = torch.randint(0, n_times, (len(u),), generator=generator)
        u, mask = held_after(u, cut), pick(torch.arange(n_times)[None, :] <= cut[:, None])
        if use_pc:
            col_u = held_after(col_u, torch.randint(0, n_times, (len(col_u),), generator=generator))
    if use_pd:
        y_hat, dydt_hat = model.standardised_with_rate(x0, u, t)
    else:
        y_hat = model.standardised(x0, u, t)
    terms = {"data": data_loss(y_hat, pick(tensors.y), mask, torch.tensor(config.state_weights))}
    total = w.data * terms["data"]
    if use_pd:
        terms["physics_data"] = physics_data_loss(model.x_std * dydt_hat, pick(tensors.f_ref), tensors.scale, mask)
        total = total + w.physics_data * terms["physics_data"]
    if use_pc:
        yc_hat, dyc_hat = model.standardised_with_rate(tensors.col_x0, col_u, t)
        terms["physics_collocation"] = physics_collocation_loss(
            model.decode(yc_hat), model.x_std * dyc_hat, pick(col_u), tensors.scale, tensors.rhs)
        total = total + w.physics_collocation * terms["physics_collocation"]
    optimizer.zero_grad(set_to_none=True)
    total.backward()
    optimizer.step()
    return {"loss": total.item(), **{k: v.item() for k, v in terms.items()}}


def rollover_index(n_times: int, causal: bool) -> int:
    """The sensor index of a window of n_times sensors where a co-simulation starts the next one."""
    return int(round((n_times - 1) * (CAUSAL_ROLLOVER_SHARE if causal else 1.0)))


def rollovers(raw: dict, component, causal: bool) -> Rollovers:
    """The Rollovers of a split as solved (load_split(frame=False): x0 [N, n_x], u [N, S, n_u], x [N,
    S, n_x]): window j starts at window i's rollover r where j's states and inputs over its first
    S - r sensors are i's over its last ones, bit for bit: consecutive windows of one recorded run.
    Of several such i (windows at rest alike in two runs) it takes the last before j, as a run's
    windows come in order. TrainError where the component has no learned states, where a window
    frame moves them, or where no window starts at another's rollover."""
    learned = sorted(component.learned_states)
    moved = () if component.drift is None else (*component.drift.angle_states, component.drift.speed_state)
    if not learned or set(learned) & set(moved):
        raise TrainError(f"rollover_share needs learned states that no window frame moves; {component.name} has "
                         f"{', '.join(component.state_names[i] for i in learned) or 'none'}")
    x, u = np.ascontiguousarray(raw["x"]), np.ascontiguousarray(raw["u"])
    index = rollover_index(x.shape[1], causal)
    tail = {}
    for i in range(len(x)):
        tail.setdefault(x[i, index:].tobytes() + u[i, index:].tobytes(), []).append(i)
    earlier, later = [], []
    overlap = x.shape[1] - index
    for j in range(len(x)):
        candidates = tail.get(x[j, :overlap].tobytes() + u[j, :overlap].tobytes(), [])
        k = bisect.bisect_left(candidates, j)  # candidates ascend
        if k > 0:
            earlier.append(candidates[k - 1])
            later.append(j)
    if not later:
        raise TrainError(f"rollover_share: no training window starts at another's rollover (sensor {index} of "
                         f"{x.shape[1]}): the windows' stride must divide that time")
    return Rollovers(torch.tensor(earlier), torch.tensor(later), index, torch.tensor(learned))


def rolled_over_starts(model: OperatorModel, tensors: _Tensors, share: float, generator) -> torch.Tensor:
    """The train split's start states x0 [N, n_x] with, for `share` of the rolled-over windows (drawn
    from `generator`), the learned states the operator gives at the earlier window's rollover (its
    input held after it, as the FMU holds the slots it does not know yet); no gradient flows there."""
    r = tensors.rollovers
    pick = torch.rand(len(r.later), generator=generator) < share
    earlier, later = r.earlier[pick], r.later[pick]
    x0 = tensors.x0.clone()
    if len(later) == 0:
        return x0
    with torch.no_grad():
        u = held_after(tensors.u[earlier], torch.full((len(earlier),), r.index))
        answer = model.decode(model.standardised(tensors.x0[earlier], u, tensors.t[r.index:r.index + 1]))[:, 0]
    x0[later[:, None], r.learned[None, :]] = answer[:, r.learned]
    return x0


def held_after(u: torch.Tensor, cut: torch.Tensor) -> torch.Tensor:
    """u [N, S, n_u] with every sensor after index cut[n] set to the value at cut[n] (held)."""
    index = torch.minimum(torch.arange(u.shape[1])[None, :], cut[:, None])
    return torch.gather(u, 1, index.unsqueeze(-1).expand(-1, -1, u.shape[2]))


def validation_mse(model: OperatorModel, tensors: _Tensors) -> float:
    """Data loss (MSE of standardised states) on the validation split over the whole grid."""
    model.eval()
    with torch.no_grad():
        return data_loss(model.standardised(tensors.val_x0, tensors.val_u, tensors.t), tensors.val_y).item()


def _update_early_stopping(state: _State, val: float, model, config: TrainConfig) -> None:
    """Keep the best model (any improvement); reset patience only on an improvement > min_delta."""
    if val < state.best_val:
        state.best_val, state.best_epoch = val, state.epoch
        state.best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
    if val < state.ref_val - config.min_delta:
        state.ref_val, state.bad_epochs = val, 0
    else:
        state.bad_epochs += 1
        state.stopped_early = state.bad_epochs >= config.patience


def _load_splits(data_dir: Path, config: TrainConfig) -> dict:
    """train, val and (if the collocation loss is on) collocation splits, checked for one time grid."""
    names = ["train", "val"] + (["collocation"] if config.physics and config.weights.physics_collocation > 0 else [])
    splits = {name: load_split(data_dir, name) for name in names}
    for name, split in splits.items():
        if not np.array_equal(split["t"], splits["train"]["t"]):
            raise TrainError(f"the {name} split of {data_dir} has another time grid than the train split")
    return splits


def _feature_map(config: TrainConfig, machine, split: dict):
    """The window features' map A [n_f, n_x + n_u S] of the dataset's component at the split's sensor
    times, where the model reads them; None where it does not."""
    if not config.model.features:
        return None
    component, params = machine
    if component.window_features is None:
        raise TrainError(f"features asked for, but {component.name} gives no window features")
    t = np.asarray(split["t"], dtype=float)
    return component.window_features(params, np.linspace(0.0, t[-1], np.shape(split["u"])[1]))


def _to_tensors(splits: dict, model: OperatorModel, machine) -> _Tensors:
    """The splits as float32 tensors; reference states standardised with the model's normalisation;
    the right-hand side is that of the dataset's machine (component, parameters)."""
    train_split, val_split, col = splits["train"], splits["val"], splits.get("collocation")
    f32 = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float32)  # noqa: E731
    t = f32(train_split["t"])
    with torch.no_grad():
        probe = model.standardised(f32(train_split["x0"][:1]), f32(train_split["u"][:1]), t)
    target = lambda x: _laid_out_like(standardise(f32(x), model), probe)  # noqa: E731
    component, params = machine
    f_ref = component.rhs(torch.as_tensor(train_split["x"]), torch.as_tensor(train_split["u"]), params)
    return _Tensors(
        t=t, x0=f32(train_split["x0"]), u=f32(train_split["u"]), y=target(train_split["x"]),
        f_ref=_laid_out_like(f_ref.float(), probe),
        val_x0=f32(val_split["x0"]), val_u=f32(val_split["u"]), val_y=target(val_split["x"]),
        col_x0=None if col is None else f32(col["x0"]), col_u=None if col is None else f32(col["u"]),
        scale=physics_scale(f32(residual_scale(train_split["x"], train_split["t"])), component),
        rhs=lambda x, u: component.rhs(x, u, params),
    )


def _laid_out_like(a: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """`a` stored with the dimension order of `like`'s memory (a DeepONet's output is [N, M, 4] as a
    view of [N, 4, M]), so the loss compares the two without strided access."""
    order = sorted(range(like.dim()), key=lambda d: -like.stride(d))
    inverse = sorted(range(len(order)), key=order.__getitem__)
    return a.permute(order).contiguous().permute(inverse)


def _make_optimizer(model, config: TrainConfig):
    if config.optimizer == "adam":
        return torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    import heavyball

    return heavyball.SOAP(model.parameters(), lr=config.lr, weight_decay=config.weight_decay,
                          max_precond_dim=config.max_precond_dim,
                          precondition_frequency=config.precondition_frequency)


@contextlib.contextmanager
def _eager_heavyball():
    """Run heavyball's kernels eagerly: its default torch.compile autotuning costs minutes on a CPU
    and buys little for a model of this size. Restores the setting afterwards."""
    try:
        import heavyball.utils as hb
    except ImportError:
        yield
        return
    saved = hb.compile_mode
    hb.compile_mode = None
    try:
        yield
    finally:
        hb.compile_mode = saved


def _save(run_dir: Path, model, optimizer, generator, state: _State, config: TrainConfig) -> None:
    """checkpoint.pt (everything to resume) and model.pt (the best model), each written atomically."""
    checkpoint = {"model": model.state_dict(), "optimizer": optimizer.state_dict(),
                  "generator": generator.get_state(), "state": asdict(state)}
    with atomic_path(run_dir / "checkpoint.pt") as tmp:
        torch.save(checkpoint, tmp)
    if state.best_state is not None:
        save_model(run_dir / "model.pt", model, state.best_state, config,
                   {"epoch": state.best_epoch, "val_mse": state.best_val})


def _restore(path: Path, model, optimizer, generator) -> _State:
    try:
        checkpoint = torch.load(path, weights_only=False)
    except Exception as exc:  # torch.load raises pickle's, zipfile's and its own errors for a damaged file
        raise TrainError(f"{path} is not a readable checkpoint ({one_line(exc)}): remove it to train again") from None
    model.load_state_dict(checkpoint["model"])
    optimizer.load_state_dict(checkpoint["optimizer"])
    generator.set_state(checkpoint["generator"])
    return _State(**checkpoint["state"])


def _check_resumable(run_dir: Path, config: TrainConfig, data_info: dict) -> None:
    """Raise TrainError unless the run in `run_dir` trained with `config` (but for epochs) on this data."""
    try:
        saved = json.loads((run_dir / "config.json").read_text())
        saved_config = TrainConfig.from_dict(saved["train"])
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise TrainError(f"{run_dir} has a checkpoint but no readable config.json ({error})") from None
    if saved.get("data", {}).get("fingerprint") != data_info["fingerprint"]:
        raise TrainError(f"{run_dir} holds a run on another dataset; choose another run directory")
    if replace(saved_config, epochs=config.epochs) != config:
        a, b = saved_config.to_dict(), config.to_dict()
        changed = sorted(k for k in a if k != "epochs" and a[k] != b[k])
        raise TrainError(f"{run_dir} holds a run with other settings ({', '.join(changed)}); "
                         "only epochs may change on resume")


def _truncate_metrics(path: Path, epoch: int) -> None:
    """Drop log lines past `epoch` (written after the checkpoint a resumed run restarts from)."""
    if not path.exists():
        return
    lines = [line for line in path.read_text().splitlines() if line.strip()]
    kept = [line for line in lines if json.loads(line)["epoch"] <= epoch]
    if len(kept) != len(lines):
        with atomic_path(path) as tmp:
            tmp.write_text("".join(line + "\n" for line in kept))


def save_model(path, model: OperatorModel, state_dict: dict, config: TrainConfig, info: dict) -> None:
    """Write a model file: architecture, normalisation, weights and training info (atomically)."""
    payload = {"model_config": config.model.to_dict(), "stats": model.stats().to_dict(), "state_dict": state_dict,
               "train_config": config.to_dict(), "info": info}
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)


def load_model(path) -> OperatorModel:
    """The model in a run directory's model.pt (or a model file), in eval mode."""
    path = Path(path)
    if path.is_dir():
        path = path / "model.pt"
    if not path.is_file():
        raise TrainError(f"no trained model at {path}")
    try:
        payload = torch.load(path, weights_only=False)
    except Exception as exc:  # torch.load raises pickle's, zipfile's and its own errors for a damaged file
        raise TrainError(f"{path} is not a readable model file ({one_line(exc)})") from None
    model = build_model(OperatorConfig.from_dict(payload["model_config"]), NormStats.from_dict(payload["stats"]))
    model.load_state_dict(payload["state_dict"])
    return model.eval()
