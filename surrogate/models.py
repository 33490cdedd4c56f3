"""Operator networks: Unstacked and Stacked-N DeepONets and the dense PINN baseline.

Networks know no equations: their sizes come from the training split they are fitted to (n_x
states, n_u input channels, S sensor times), and every model maps physical inputs to physical
outputs with one signature,

    model(x0 [N, n_x], u [N, S, n_u], t [M]) -> x [N, M, n_x]

(x0 in state units, u the component's inputs at the S sensor times, t [s] in [0, T]); the
normalisation is part of the model as buffers, fitted from the training split (`NormStats`):

* states (x0 on the way in, x on the way out) are standardised per state with the mean and std of
  the training trajectories x (not of x0, whose Ed_p is constant in the paper's box);
* inputs are standardised per channel and then multiplied by `sensor_gain * sqrt(n_x / S)`, so the
  n_u S sensor values together weigh about as much as the n_x initial-state values in the first layer;
* time enters as features 2 t/T - 1 and exp(-t/tau) for the configured tau (10-100 ms: the omega
  transient at the start of every window is that fast);
* with `features` (Unstacked only), the branch also reads phi = A [x0, sensors], a fixed linear map
  the component gives (`Component.window_features`: a measured frequency at each sensor time),
  standardised per feature and scaled like the sensors. It is a better-conditioned view of inputs
  the branch has anyway, so the export folds it into the first layer (folding.py).

DeepONet output: the branch gives p coefficients per state, [N, n_x, p]; the trunk gives p basis
functions of time shared by the states, [M, p]; x = x_mean + x_std * (B @ tau^T + b0), or
anchored x = x0 + x_std * B @ (tau - tau(0))^T (exactly x0 at t = 0). A shared basis is enough because the states share their time scales (d delta/dt = omega carries the omega
transient into delta) and it keeps the trunk, and its time derivative, at p columns.

The forward pass uses plain tensor ops only (ONNX-exportable); `standardised_with_rate` gives the
time derivative for the physics losses (torch.func forward mode; training only, not exported).
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass, fields

import numpy as np
import torch
from torch import nn

ARCHITECTURES = ("unstacked", "stacked-n", "pinn")
ACTIVATIONS = {"tanh": nn.Tanh, "gelu": nn.GELU, "silu": nn.SiLU}


@dataclass(frozen=True)
class OperatorConfig:
    """Architecture of an operator network.

    arch: "unstacked" (one branch over [x0, sensors]), "stacked-n" (a branch for x0 and one for the
        sensors, combined by elementwise product) or "pinn" (one dense net over [x0, sensors, t]).
    width, depth: hidden units and hidden layers of every sub-network.
    latent: p, basis functions per state (DeepONets only).
    time_taus: time constants [s] of the exp(-t/tau) time features.
    sensor_gain: extra factor on the sqrt(4/S) sensor scale.
    anchored: DeepONets only: x(t) = x0 + B (tau(t) - tau(0)), so the operator returns x0 exactly at
        t = 0 (no jump when a co-simulation starts a new window from the state reached) and has no
        bias term; otherwise x(t) = B tau(t) + bias, free at t = 0 (the paper's form).
    features: Unstacked only: the branch also reads the component's window features (NormStats'
        feature_map), standardised.
    """

    arch: str = "unstacked"
    width: int = 64
    depth: int = 3
    latent: int = 64
    activation: str = "tanh"
    time_taus: tuple = (0.01, 0.03, 0.1)
    sensor_gain: float = 1.0
    anchored: bool = False
    features: bool = False

    def __post_init__(self):
        if self.arch not in ARCHITECTURES:
            raise ValueError(f"unknown architecture {self.arch!r} (known: {', '.join(ARCHITECTURES)})")
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"unknown activation {self.activation!r} (known: {', '.join(ACTIVATIONS)})")
        if self.anchored and self.arch == "pinn":
            raise ValueError("anchored applies to the DeepONets (unstacked, stacked-n), not the pinn")
        if self.features and self.arch != "unstacked":
            raise ValueError(f"features apply to the unstacked DeepONet, not the {self.arch}")
        if min(self.width, self.depth, self.latent) < 1 or any(tau <= 0 for tau in self.time_taus):
            raise ValueError("width, depth, latent and every time tau must be positive")
        object.__setattr__(self, "time_taus", tuple(float(tau) for tau in self.time_taus))

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "OperatorConfig":
        known = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in data.items() if k in known})


@dataclass(frozen=True)
class NormStats:
    """Normalisation fitted from a training split: per-state mean/std of x [n_x], per-input mean/std
    of u [n_u] (physical units), the horizon T [s] and the number of sensor times S; with window
    features, their map A [n_f, n_x + n_u S] (rows) and the mean/std of A [x0, sensors] over the
    split's windows [n_f]."""

    x_mean: tuple
    x_std: tuple
    u_mean: tuple
    u_std: tuple
    horizon: float
    n_sensors: int
    feature_map: tuple = ()
    f_mean: tuple = ()
    f_std: tuple = ()

    @classmethod
    def fit(cls, split: dict, feature_map=None) -> "NormStats":
        """Statistics of a labeled split (dict with x0 [N, n_x], x [N, S, n_x], u [N, S, n_u], t [S]);
        feature_map: A [n_f, n_x + n_u S] (a component's window_features) or None."""
        x = np.asarray(split["x"], dtype=float)
        u = np.asarray(split["u"], dtype=float)
        as_tuple = lambda a: tuple(float(v) for v in a)  # noqa: E731
        features = {}
        if feature_map is not None:
            A = np.asarray(feature_map, dtype=float)
            phi = np.concatenate([np.asarray(split["x0"], dtype=float), u.reshape(len(u), -1)], axis=1) @ A.T
            features = dict(feature_map=tuple(as_tuple(row) for row in A), f_mean=as_tuple(phi.mean(0)),
                            f_std=as_tuple(_safe_std(phi)))
        x, u = x.reshape(-1, x.shape[-1]), u.reshape(-1, u.shape[-1])
        t = np.asarray(split["t"], dtype=float)
        return cls(as_tuple(x.mean(0)), as_tuple(_safe_std(x)), as_tuple(u.mean(0)), as_tuple(_safe_std(u)),
                   float(t[-1]), int(t.size), **features)

    def to_dict(self) -> dict:
        plain = lambda v: [plain(e) for e in v] if isinstance(v, tuple) else v  # noqa: E731
        return {k: plain(v) for k, v in asdict(self).items()}

    @property
    def n_states(self) -> int:
        return len(self.x_mean)

    @property
    def n_inputs(self) -> int:
        return len(self.u_mean)

    @property
    def n_features(self) -> int:
        return len(self.feature_map)

    @classmethod
    def from_dict(cls, data: dict) -> "NormStats":
        frozen = lambda v: tuple(frozen(e) for e in v) if isinstance(v, list) else float(v)  # noqa: E731
        return cls(**{k: frozen(v) if isinstance(v, list) else v for k, v in data.items()})


def _safe_std(a: np.ndarray) -> np.ndarray:
    """Std per column; a constant column gets 1 so it maps to a constant instead of a division by 0
    (a column of one value has a std of rounding noise, 1e-11 for 1e6 values of 1.08: below 1e-9 of
    its size a column counts as constant)."""
    std = a.std(0)
    return np.where(std > 1e-9 * np.maximum(1.0, np.abs(a).max(0)), std, 1.0)


def mlp(n_in: int, width: int, depth: int, n_out: int, activation: str, out_activation: bool = False):
    """Dense net: `depth` hidden layers of `width`, Glorot-normal weights, zero biases."""
    sizes = [n_in] + [width] * depth
    layers = []
    for a, b in zip(sizes[:-1], sizes[1:]):
        layers += [nn.Linear(a, b), ACTIVATIONS[activation]()]
    layers.append(nn.Linear(sizes[-1], n_out))
    if out_activation:
        layers.append(ACTIVATIONS[activation]())
    for layer in layers:
        if isinstance(layer, nn.Linear):
            nn.init.xavier_normal_(layer.weight)
            nn.init.zeros_(layer.bias)
    return nn.Sequential(*layers)


class OperatorModel(nn.Module, ABC):
    """Shared normalisation (buffers) and time features of every architecture."""

    def __init__(self, config: OperatorConfig, stats: NormStats):
        super().__init__()
        self.config = config
        self.n_sensors = stats.n_sensors
        self.n_states, self.n_inputs = stats.n_states, stats.n_inputs
        f32 = dict(dtype=torch.float32)
        self.register_buffer("x_mean", torch.tensor(stats.x_mean, **f32))
        self.register_buffer("x_std", torch.tensor(stats.x_std, **f32))
        self.register_buffer("u_mean", torch.tensor(stats.u_mean, **f32))
        self.register_buffer("u_std", torch.tensor(stats.u_std, **f32))
        self.register_buffer("horizon", torch.tensor(stats.horizon, **f32))
        sensor_scale = config.sensor_gain * math.sqrt(stats.n_states / stats.n_sensors)
        self.register_buffer("sensor_scale", torch.tensor(sensor_scale, **f32))
        self.register_buffer("time_taus", torch.tensor(config.time_taus, **f32))
        if config.features and not stats.n_features:
            raise ValueError("features asked for, but the normalisation holds no feature map")
        if stats.n_features:
            self.register_buffer("feature_map", torch.tensor(stats.feature_map, **f32))
            self.register_buffer("f_mean", torch.tensor(stats.f_mean, **f32))
            self.register_buffer("f_std", torch.tensor(stats.f_std, **f32))

    @property
    def n_time_features(self) -> int:
        return 1 + len(self.config.time_taus)

    def stats(self) -> NormStats:
        """The normalisation as held in the buffers (what `build_model` needs to rebuild this model)."""
        as_tuple = lambda b: tuple(float(v) for v in b.tolist())  # noqa: E731
        features = {}
        if hasattr(self, "feature_map"):
            features = dict(feature_map=tuple(as_tuple(row) for row in self.feature_map),
                            f_mean=as_tuple(self.f_mean), f_std=as_tuple(self.f_std))
        return NormStats(as_tuple(self.x_mean), as_tuple(self.x_std), as_tuple(self.u_mean), as_tuple(self.u_std),
                         float(self.horizon), self.n_sensors, **features)

    def encode_state(self, x0: torch.Tensor) -> torch.Tensor:
        """Standardised initial state [N, n_x]."""
        return (x0 - self.x_mean) / self.x_std

    def encode_sensors(self, u: torch.Tensor) -> torch.Tensor:
        """Scaled, standardised sensor values, flattened time-major: [N, S, n_u] -> [N, n_u S]."""
        return torch.flatten((u - self.u_mean) / self.u_std * self.sensor_scale, 1)

    def encode_features(self, x0: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        """Scaled, standardised window features [N, n_f]: A [x0, u flattened time-major]."""
        phi = torch.cat([x0, torch.flatten(u, 1)], dim=-1) @ self.feature_map.T
        return (phi - self.f_mean) / self.f_std * self.sensor_scale

    def time_features(self, t: torch.Tensor) -> torch.Tensor:
        """[M] times [s] -> [M, 1 + len(time_taus)]: 2 t/T - 1 and exp(-t/tau)."""
        t = t.unsqueeze(-1)
        return torch.cat([2.0 * t / self.horizon - 1.0, torch.exp(-t / self.time_taus)], dim=-1)

    def decode(self, y: torch.Tensor) -> torch.Tensor:
        """Standardised states [..., n_x] -> physical units."""
        return self.x_mean + self.x_std * y

    @abstractmethod
    def standardised(self, x0: torch.Tensor, u: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """Standardised states [N, M, n_x] (x - x_mean) / x_std: what the data loss compares."""

    def forward(self, x0: torch.Tensor, u: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """States [N, M, n_x] (physical units)."""
        return self.decode(self.standardised(x0, u, t))

    def standardised_with_rate(self, x0: torch.Tensor, u: torch.Tensor, t: torch.Tensor):
        """(y, dy/dt): standardised states [N, M, n_x] and their time derivative [1/s], by forward-mode
        autodiff w.r.t. t (y[n, m] depends on t[m] alone, so a unit tangent on every time gives all
        N x M derivatives in one pass). Differentiable w.r.t. the parameters. Not for export."""
        return torch.func.jvp(lambda times: self.standardised(x0, u, times), (t,), (torch.ones_like(t),))


class DeepONet(OperatorModel):
    """Branch coefficients [N, n_x, p] times a shared trunk basis [M, p], plus a bias per state; or,
    anchored, the standardised x0 plus the coefficients times the basis' change since t = 0."""

    def __init__(self, config: OperatorConfig, stats: NormStats):
        super().__init__(config, stats)
        c = config
        self.trunk_net = mlp(self.n_time_features, c.width, c.depth, c.latent, c.activation, out_activation=True)
        if not c.anchored:
            self.bias = nn.Parameter(torch.zeros(self.n_states))

    @abstractmethod
    def branch(self, x0: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        """Coefficients [N, n_x, p] for x0 [N, n_x] and u [N, S, n_u] (physical units)."""

    def trunk(self, t: torch.Tensor) -> torch.Tensor:
        """Basis functions [M, p] at times t [M] (s)."""
        return self.trunk_net(self.time_features(t))

    def offset(self, x0: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        """What is added to B tau^T [N, n_x, M]: the bias [n_x, 1], or anchored y0 - B tau(0) [N, n_x, 1]."""
        if not self.config.anchored:
            return self.bias.unsqueeze(-1)
        tau0 = self.trunk(torch.zeros(1, dtype=x0.dtype, device=x0.device))  # [1, p]
        return self.encode_state(x0).unsqueeze(-1) - torch.matmul(b, tau0.transpose(0, 1))

    def standardised(self, x0, u, t):
        b = self.branch(x0, u)
        y = torch.matmul(b, self.trunk(t).transpose(0, 1)) + self.offset(x0, b)  # [N, n_x, M]
        return y.transpose(1, 2)

    def standardised_with_rate(self, x0, u, t):
        """As OperatorModel's, with d/dt through the trunk only: dy/dt = B @ (d tau/dt)^T."""
        tau, dtau = torch.func.jvp(self.trunk, (t,), (torch.ones_like(t),))  # [M, p] each
        b = self.branch(x0, u)
        y = torch.matmul(b, tau.transpose(0, 1)) + self.offset(x0, b)
        return y.transpose(1, 2), torch.matmul(b, dtau.transpose(0, 1)).transpose(1, 2)


class UnstackedDeepONet(DeepONet):
    """One branch net over the concatenation [x0 (n_x), sensors (n_u S)]."""

    def __init__(self, config: OperatorConfig, stats: NormStats):
        super().__init__(config, stats)
        c = config
        n_in = self.n_states + self.n_inputs * stats.n_sensors + (stats.n_features if c.features else 0)
        self.branch_net = mlp(n_in, c.width, c.depth, self.n_states * c.latent, c.activation)

    def branch(self, x0, u):
        parts = [self.encode_state(x0), self.encode_sensors(u)]
        if self.config.features:
            parts.append(self.encode_features(x0, u))
        z = torch.cat(parts, dim=-1)
        return self.branch_net(z).reshape(-1, self.n_states, self.config.latent)


class StackedNDeepONet(DeepONet):
    """Two branch nets, one over x0 and one over the sensors, combined by elementwise product.

    The product, not a sum: with a sum the output would split into f(x0)(t) + g(u)(t), a
    superposition that cannot hold for a nonlinear machine; the product lets the initial state
    modulate how each input feature enters every coefficient.
    """

    def __init__(self, config: OperatorConfig, stats: NormStats):
        super().__init__(config, stats)
        c = config
        self.state_net = mlp(self.n_states, c.width, c.depth, self.n_states * c.latent, c.activation)
        self.input_net = mlp(self.n_inputs * stats.n_sensors, c.width, c.depth, self.n_states * c.latent, c.activation)

    def branch(self, x0, u):
        b = self.state_net(self.encode_state(x0)) * self.input_net(self.encode_sensors(u))
        return b.reshape(-1, self.n_states, self.config.latent)


class PINN(OperatorModel):
    """One dense net over [x0, sensors, time features] -> n_x states, evaluated at every (n, m).

    The first layer is split into a part for [x0, sensors] and a part for the time features whose
    outputs are added ([N, 1, w] + [1, M, w]): the same net as one layer over the concatenated
    input, without building the [N, M, n_x + n_u S] input. With the same width and depth it has about
    as many parameters as the Unstacked DeepONet (the first layer dominates both).
    """

    def __init__(self, config: OperatorConfig, stats: NormStats):
        super().__init__(config, stats)
        c = config
        n_z = self.n_states + self.n_inputs * stats.n_sensors
        net = mlp(n_z + self.n_time_features, c.width, c.depth, self.n_states, c.activation)
        first = net[0]
        self.input_layer = nn.Linear(n_z, c.width)
        self.time_layer = nn.Linear(self.n_time_features, c.width, bias=False)
        with torch.no_grad():
            self.input_layer.weight.copy_(first.weight[:, :n_z])
            self.input_layer.bias.copy_(first.bias)
            self.time_layer.weight.copy_(first.weight[:, n_z:])
        self.activation = ACTIVATIONS[c.activation]()
        self.hidden = nn.Sequential(*list(net)[2:])

    def standardised(self, x0, u, t):
        z = torch.cat([self.encode_state(x0), self.encode_sensors(u)], dim=-1)
        h = self.input_layer(z).unsqueeze(1) + self.time_layer(self.time_features(t)).unsqueeze(0)
        return self.hidden(self.activation(h))


MODELS = {"unstacked": UnstackedDeepONet, "stacked-n": StackedNDeepONet, "pinn": PINN}


def build_model(config: OperatorConfig, stats: NormStats) -> OperatorModel:
    """A freshly initialised model (uses torch's global RNG: seed it, or fork it, first)."""
    return MODELS[config.arch](config, stats)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters() if p.requires_grad)
