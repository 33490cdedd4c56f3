"""An ensemble of trained operators: their mean, exported as one operator.

Independently trained operators err in different directions where the data is thin (the first tens
of ms of a deep fault): the mean cancels part of that. In 144 co-simulations of 60 s the mean of two
anchored causal Unstacked DeepONets met the accuracy goal in 140-143 where one alone met it in 134;
with the FMU's exact swing step it trims the worst errors by 10-25% at twice the step cost (README,
"Fourth round").

`Ensemble(models)` has the interface the export, the evaluation and the residual level need: the
call model(x0 [N, 4], u [N, S, 2], t [M]) -> x [N, M, 4] (physical units, the members' mean),
`x_mean`/`x_std`/`decode` and `standardised_with_rate`, standardised with the first member's
statistics. Its inference form (folding.FoldedEnsemble) is one anchored DeepONet whose latent
size is the members' together, so the exported graph and the FMU's C kernel treat it as any other.
"""
from __future__ import annotations

import torch
from torch import nn

from .models import UnstackedDeepONet


class EnsembleError(ValueError):
    """Operators that cannot be averaged into one exported operator."""


class Ensemble(nn.Module):
    """The mean of K >= 2 anchored Unstacked DeepONets of one shape (width, depth, latent,
    activation) that read the same sensor times over the same horizon."""

    def __init__(self, members: list):
        super().__init__()
        check_compatible(members)
        self.members = nn.ModuleList(members)
        self.register_buffer("x_mean", members[0].x_mean.clone())
        self.register_buffer("x_std", members[0].x_std.clone())

    def forward(self, x0: torch.Tensor, u: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """States [N, M, 4] (physical units): the mean of the members'."""
        return torch.stack([m(x0, u, t) for m in self.members]).mean(0)

    def decode(self, y: torch.Tensor) -> torch.Tensor:
        """Standardised states [..., 4] (by the first member's statistics) -> physical units."""
        return self.x_mean + self.x_std * y

    def standardised_with_rate(self, x0: torch.Tensor, u: torch.Tensor, t: torch.Tensor):
        """(y, dy/dt) [N, M, 4] each: the members' mean state and rate, standardised as `decode` inverts."""
        states, rates = [], []
        for m in self.members:
            y, dydt = m.standardised_with_rate(x0, u, t)
            states.append(m.decode(y))
            rates.append(m.x_std * dydt)
        x, dxdt = torch.stack(states).mean(0), torch.stack(rates).mean(0)
        return (x - self.x_mean) / self.x_std, dxdt / self.x_std

    def architecture(self) -> dict:
        """What the export writes as `architecture`: the members' shape, their count and each one's time features."""
        first = self.members[0].config.to_dict()
        return {**first, "ensemble": len(self.members), "member_time_taus": [list(m.config.time_taus) for m in self.members]}


def check_compatible(members: list) -> None:
    """Raise EnsembleError unless the members can be folded into one DeepONet (see Ensemble)."""
    if len(members) < 2:
        raise EnsembleError("an ensemble needs at least two operators")
    for i, m in enumerate(members):
        if not (isinstance(m, UnstackedDeepONet) and m.config.anchored):
            kind = f"{'anchored ' if getattr(m.config, 'anchored', False) else ''}{m.config.arch}"
            raise EnsembleError(f"operator {i + 1} is {kind}: only anchored Unstacked DeepONets can be averaged into one")
    first = members[0]
    shape = lambda m: (m.config.width, m.config.depth, m.config.latent, m.config.activation)  # noqa: E731
    for i, m in enumerate(members[1:], start=2):
        if shape(m) != shape(first):
            raise EnsembleError(f"operator {i} has width/depth/latent/activation {shape(m)}, operator 1 {shape(first)}")
        if m.n_sensors != first.n_sensors or float(m.horizon) != float(first.horizon):
            raise EnsembleError(f"operator {i} reads {m.n_sensors} sensors over {float(m.horizon)} s, "
                                f"operator 1 {first.n_sensors} over {float(first.horizon)} s")


def architecture(model) -> dict:
    """The `architecture` metadata of a single operator or an ensemble."""
    return model.architecture() if isinstance(model, Ensemble) else model.config.to_dict()


def describe(architecture_metadata: dict) -> str:
    """A short name of an exported operator's kind from its `architecture` metadata, e.g. "unstacked"
    or "mean of 2 unstacked"."""
    kind = architecture_metadata["arch"]
    return f"mean of {architecture_metadata['ensemble']} {kind}" if "ensemble" in architecture_metadata else kind
