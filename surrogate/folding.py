"""The inference form of a trained operator: the same function with its normalisation folded away.

`fold(model)` returns a module with the signature of the model, (x0 [N, n_x], u [N, S, n_u], t [M]) ->
x [N, M, n_x] in physical units, that computes without any elementwise normalisation pass:

* the standardisation of x0 and of the sensors (and the sensor scale) is folded into the weights and
  bias of the first linear layer that reads them, so the raw [x0, u] go straight into one Gemm; so
  are window features (models.py), linear in [x0, u] themselves;
* the decoding x = x_mean + x_std * y is folded into the last linear layer of the output path. For a
  DeepONet the per-state offset (x_mean + x_std * bias; anchored: x0 - x_std B tau(0), with tau(0)
  a constant) becomes one more coefficient per state, whose basis function is the constant 1
  appended to the trunk, so that the head is a single product
  x[n, :, k] = tau_aug [M, p + 1] @ B_aug[n, k] [p + 1] and nothing else.

The export writes this form (see onnx_export.py) and checks it against the trained model; on 1000
trajectories it halves the work outside the two matrix products (benchmarks/inference_speed.py).
Folding is done in float64 and rounded once to float32.
"""
from __future__ import annotations

import copy

import torch
from torch import nn

from .ensemble import Ensemble
from .models import PINN, DeepONet, OperatorModel, StackedNDeepONet, UnstackedDeepONet


def fold(model: OperatorModel | Ensemble) -> nn.Module:
    """The inference form of `model` (a copy; the model is left as it is)."""
    for kind, folded in ((UnstackedDeepONet, FoldedUnstacked), (StackedNDeepONet, FoldedStackedN), (PINN, FoldedPINN),
                         (Ensemble, FoldedEnsemble)):
        if isinstance(model, kind):
            return folded(copy.deepcopy(model).eval())
    raise TypeError(f"no inference form for {type(model).__name__}")


def fold_input(linear: nn.Linear, mean: torch.Tensor, scale: torch.Tensor) -> nn.Linear:
    """A layer computing linear((v - mean) * scale) from v; mean, scale [in_features]."""
    w, b = linear.weight.double(), linear.bias.double()
    mean, scale = mean.double(), scale.double()
    return _linear(w * scale, b - (w * scale) @ mean)


def fold_output(linear: nn.Linear, gain: torch.Tensor, offset: torch.Tensor) -> nn.Linear:
    """A layer computing offset + gain * linear(h); gain, offset [out_features]."""
    w, b = linear.weight.double(), linear.bias.double()
    gain, offset = gain.double(), offset.double()
    return _linear(gain[:, None] * w, offset + gain * b)


def with_constant_coefficient(linear: nn.Linear, latent: int, constants: torch.Tensor) -> nn.Linear:
    """A layer whose output, seen as [n_x, latent + 1], is linear's [n_x, latent] plus one more
    column holding constants [n_x] whatever the input (zero weights, bias = the constant)."""
    n = constants.numel()
    w = linear.weight.double().reshape(n, latent, -1)
    b = linear.bias.double().reshape(n, latent)
    w = torch.cat([w, torch.zeros(n, 1, w.shape[-1], dtype=w.dtype)], 1).reshape(n * (latent + 1), -1)
    b = torch.cat([b, constants.double().reshape(n, 1)], 1).reshape(-1)
    return _linear(w, b)


def _linear(weight: torch.Tensor, bias: torch.Tensor) -> nn.Linear:
    layer = nn.Linear(weight.shape[1], weight.shape[0])
    with torch.no_grad():
        layer.weight.copy_(weight.float())
        layer.bias.copy_(bias.float())
    return layer


def _replace(sequential: nn.Sequential, index: int, layer: nn.Module) -> nn.Sequential:
    layers = list(sequential)
    layers[index] = layer
    return nn.Sequential(*layers)


def _input_normalisation(model: OperatorModel, with_state: bool):
    """(mean, scale) of the raw inputs [x0 (4) if with_state, sensors flattened time-major (2 S)]."""
    s = model.n_sensors
    mean = model.u_mean.repeat(s)
    scale = (model.sensor_scale / model.u_std).repeat(s)
    if with_state:
        mean = torch.cat([model.x_mean, mean])
        scale = torch.cat([1.0 / model.x_std, scale])
    return mean, scale


def _first_layer(model: UnstackedDeepONet) -> nn.Linear:
    """The branch's first layer over the raw [x0, u flattened], its normalisation and any window
    features folded in: W_f (A v - f_mean) g / f_std is W_f g / f_std A v plus a constant."""
    mean, scale = _input_normalisation(model, True)
    first = model.branch_net[0]
    if not model.config.features:
        return fold_input(first, mean, scale)
    n_raw = mean.numel()
    w, b = first.weight.double(), first.bias.double()
    w_raw = w[:, :n_raw] * scale.double()
    w_f = w[:, n_raw:] * (model.sensor_scale / model.f_std).double()
    return _linear(w_raw + w_f @ model.feature_map.double(),
                   b - w_raw @ mean.double() - w_f @ model.f_mean.double())


def _per_coefficient(per_state: torch.Tensor, latent: int) -> torch.Tensor:
    """[4] -> [4 * latent]: each state's value repeated over its coefficients (state-major)."""
    return per_state.repeat_interleave(latent)


class FoldedDeepONet(nn.Module):
    """Shared head of the folded DeepONets: x = (B_aug @ tau_aug^T) transposed to [N, M, 4].

    Free form: B_aug = [x_std B, x_mean + x_std bias] straight from the branch's last layer. Anchored:
    the branch gives x_std B, and the constant coefficient x0 - x_std B tau(0) is appended to it."""

    def __init__(self, model: DeepONet):
        super().__init__()
        self.model = model  # its time features and trunk are used as they are
        self.latent = model.config.latent
        self.anchored = model.config.anchored
        self.n_states = model.n_states
        if self.anchored:
            with torch.no_grad():
                tau0 = model.trunk(torch.zeros(1))  # [1, p]
            self.register_buffer("tau0", tau0.transpose(0, 1).contiguous())  # [p, 1]

    def offsets(self, model: DeepONet) -> torch.Tensor:
        """Per-state offset [4] of the decoded free-form output: x_mean + x_std * bias."""
        return model.x_mean + model.x_std * model.bias.detach()

    def last_layer(self, linear: nn.Linear, model: DeepONet) -> nn.Linear:
        """The branch's last layer with the decoding folded in: [4 p] (anchored) or [4 (p + 1)] outputs."""
        p = self.latent
        scaled = fold_output(linear, _per_coefficient(model.x_std, p), torch.zeros(model.n_states * p))
        return scaled if self.anchored else with_constant_coefficient(scaled, p, self.offsets(model))

    def trunk(self, t: torch.Tensor) -> torch.Tensor:
        """Basis [M, p + 1]: the trained basis and the constant 1."""
        tau = self.model.trunk(t)
        return torch.cat([tau, t.unsqueeze(-1) * 0.0 + 1.0], dim=-1)

    def coefficients(self, x0, u) -> torch.Tensor:
        """B_aug [N, 4, p + 1]."""
        if not self.anchored:
            return self.branch(x0, u).reshape(-1, self.n_states, self.latent + 1)
        b = self.branch(x0, u).reshape(-1, self.n_states, self.latent)
        return torch.cat([b, x0.unsqueeze(-1) - torch.matmul(b, self.tau0)], dim=-1)

    def forward(self, x0, u, t):
        return torch.matmul(self.coefficients(x0, u), self.trunk(t).transpose(0, 1)).transpose(1, 2)


class FoldedUnstacked(FoldedDeepONet):
    def __init__(self, model: UnstackedDeepONet):
        super().__init__(model)
        net = _replace(model.branch_net, 0, _first_layer(model))
        self.branch_net = _replace(net, -1, self.last_layer(net[-1], model))

    def branch(self, x0, u):
        return self.branch_net(torch.cat([x0, torch.flatten(u, 1)], dim=-1))


class FoldedStackedN(FoldedDeepONet):
    def __init__(self, model: StackedNDeepONet):
        super().__init__(model)
        p = self.latent
        state = _replace(model.state_net, 0, fold_input(model.state_net[0], model.x_mean, 1.0 / model.x_std))
        self.state_net = _replace(state, -1, self.last_layer(state[-1], model))
        inputs = _replace(model.input_net, 0, fold_input(model.input_net[0], *_input_normalisation(model, False)))
        if not self.anchored:
            inputs = _replace(inputs, -1, with_constant_coefficient(inputs[-1], p, torch.ones(model.n_states)))
        self.input_net = inputs

    def branch(self, x0, u):
        return self.state_net(x0) * self.input_net(torch.flatten(u, 1))


class FoldedEnsemble(FoldedDeepONet):
    """An Ensemble's mean as one anchored DeepONet with latent size K p (K members of latent p).

    x = x0 + sum_k B_k (tau_k(t) - tau_k(0)) / K is a DeepONet whose basis is the members' bases side
    by side [M, K p] and whose coefficients are theirs divided by K, so the head is FoldedDeepONet's.
    The branch keeps the members apart without block-diagonal waste:
    * the members' first layers (normalisation folded in) are stacked into one Gemm [4 + 2 S -> K H]:
      the one sensor layer the FMU updates incrementally;
    * every later layer is one batched MatMul over the members, [N, K, 1, H] @ [K, H, H'] + [K, 1, H'];
    * the last (decoding and 1/K folded in) gives [N, K, 1, 4 p], reordered to [N, 4, K p] state-major."""

    def __init__(self, ensemble: Ensemble):
        nn.Module.__init__(self)
        members = [FoldedUnstacked(m) for m in ensemble.members]
        self.k, self.p, self.n_states = len(members), members[0].latent, members[0].n_states
        self.latent, self.anchored = self.k * self.p, True
        self.members = nn.ModuleList(f.model for f in members)  # their time features and trunks
        self.register_buffer("tau0", torch.cat([f.tau0 for f in members]))  # [K p, 1]
        nets = [list(f.branch_net) for f in members]
        linears = [i for i, layer in enumerate(nets[0]) if isinstance(layer, nn.Linear)]
        self.width = nets[0][linears[0]].out_features
        self.first_layer = _linear(torch.cat([net[linears[0]].weight.double() for net in nets]),
                                   torch.cat([net[linears[0]].bias.double() for net in nets]))
        self.activation = nets[0][linears[0] + 1]
        gain = [1.0] * (len(linears) - 2) + [1.0 / self.k]
        for j, (i, g) in enumerate(zip(linears[1:], gain)):
            self.register_buffer(f"weight{j}", torch.stack([net[i].weight.double().T * g for net in nets]).float())
            self.register_buffer(f"bias{j}", torch.stack([net[i].bias.double()[None] * g for net in nets]).float())
        self.n_later = len(linears) - 1

    def trunk(self, t: torch.Tensor) -> torch.Tensor:
        """Basis [M, K p + 1]: the members' bases and the constant 1."""
        return torch.cat([m.trunk(t) for m in self.members] + [t.unsqueeze(-1) * 0.0 + 1.0], dim=-1)

    def branch(self, x0, u):
        h = self.first_layer(torch.cat([x0, torch.flatten(u, 1)], dim=-1)).reshape(-1, self.k, 1, self.width)
        for j in range(self.n_later):
            h = torch.matmul(self.activation(h), getattr(self, f"weight{j}")) + getattr(self, f"bias{j}")
        return h.reshape(-1, self.k, self.n_states, self.p).transpose(1, 2).reshape(-1, self.n_states * self.latent)


class FoldedPINN(nn.Module):
    def __init__(self, model: PINN):
        super().__init__()
        self.model = model
        self.input_layer = fold_input(model.input_layer, *_input_normalisation(model, True))
        self.hidden = _replace(model.hidden, -1, fold_output(model.hidden[-1], model.x_std, model.x_mean))

    def forward(self, x0, u, t):
        m = self.model
        h = self.input_layer(torch.cat([x0, torch.flatten(u, 1)], dim=-1)).unsqueeze(1)
        h = h + m.time_layer(m.time_features(t)).unsqueeze(0)
        return self.hidden(m.activation(h))
