"""Training losses (paper eqs. 5-7) on the shared time grid.

* data loss (eq. 5): MSE between predicted and reference states, both standardised per state
  (model.standardised vs (x - x_mean) / x_std), so omega [rad/s] and the fluxes [pu] count alike;
* physics loss on labeled data (eq. 6): d x_hat/dt against f(x, u) at the reference state x;
* physics loss on collocation trajectories (eq. 7): d x_hat/dt against f(x_hat, u) at the
  predicted state.

f is the right-hand side of the dataset's component with its parameters, passed in as a function
`rhs(x, u)` (the losses know no equations); u at a grid time is the sensor sample at that time (sensor and
query grids coincide). Residuals are divided per state by `residual_scale` (the std of the
reference dx/dt over the training split) before squaring: unscaled, omega's residual (its dx/dt
reaches ~200 rad/s^2 in the first tens of ms) would be the whole loss. d x_hat/dt comes from
forward-mode autodiff w.r.t. t (model.standardised_with_rate: torch.func.jvp with a unit tangent
on every time; for a DeepONet through the trunk only, d x_hat/dt = B @ d tau/dt).
"""
from __future__ import annotations

import math

from dataclasses import asdict, dataclass

import numpy as np
import torch



@dataclass(frozen=True)
class LossWeights:
    """Static weights of the data, labeled-physics and collocation-physics terms (paper IV-C)."""

    data: float = 1.0
    physics_data: float = 1e-3
    physics_collocation: float = 1e-4

    def to_dict(self) -> dict:
        return asdict(self)


def residual_scale(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Per-state std [n_x] of dx/dt (units of state per s) of reference trajectories x [N, S, n_x] on t [S]."""
    dxdt = np.gradient(np.asarray(x, dtype=float), np.asarray(t, dtype=float), axis=1)
    std = dxdt.reshape(-1, dxdt.shape[-1]).std(0)
    return np.where(std > 1e-9, std, 1.0)  # a state that does not move gets 1, not round-off


def physics_scale(scale: torch.Tensor, component) -> torch.Tensor:
    """The residual scale [n_x] with the component's learned states (Component.learned_states) at
    infinity: residuals divided by it leave them out (no equation gives their rate)."""
    scale = scale.clone()
    scale[list(component.learned_states)] = math.inf
    return scale


def value_and_time_derivative(model, x0: torch.Tensor, u: torch.Tensor, t: torch.Tensor):
    """(x_hat, d x_hat/dt), both [N, M, n_x] in physical units (per s), differentiable w.r.t. the parameters."""
    y, dydt = model.standardised_with_rate(x0, u, t)
    return model.decode(y), model.x_std * dydt


def standardise(x: torch.Tensor, model) -> torch.Tensor:
    """Physical states [..., n_x] -> (x - x_mean) / x_std with the model's normalisation."""
    return (x - model.x_mean) / model.x_std


def masked_mean(squares: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """Mean of squares [N, M, n_x] over all entries, or over the (n, m) where mask [N, M] is true."""
    if mask is None:
        return squares.mean()
    weights = mask.to(squares.dtype).unsqueeze(-1)
    return (squares * weights).sum() / (weights.sum() * squares.shape[-1]).clamp_min(1.0)


def data_loss(y_hat: torch.Tensor, y: torch.Tensor, mask: torch.Tensor | None = None,
              state_weights: torch.Tensor | None = None) -> torch.Tensor:
    """Eq. 5 on standardised states y_hat, y [N, M, n_x]: mean of (y_hat - y)^2 (where mask [N, M]),
    each state's square times state_weights [n_x] / their mean if given."""
    squares = (y_hat - y) ** 2
    if state_weights is not None:
        squares = squares * (state_weights / state_weights.mean())
    return masked_mean(squares, mask)


def physics_data_loss(dxdt_hat: torch.Tensor, f_ref: torch.Tensor, scale: torch.Tensor,
                      mask: torch.Tensor | None = None) -> torch.Tensor:
    """Eq. 6: mean of ((d x_hat/dt - f(x, u)) / scale)^2 (where mask [N, M]); f_ref = rhs at the
    reference states [N, M, n_x]."""
    return masked_mean(((dxdt_hat - f_ref) / scale) ** 2, mask)


def physics_collocation_loss(x_hat: torch.Tensor, dxdt_hat: torch.Tensor, u: torch.Tensor, scale: torch.Tensor,
                             rhs) -> torch.Tensor:
    """Eq. 7: mean of ((d x_hat/dt - rhs(x_hat, u)) / scale)^2; u [N, M, n_u] the inputs at the same
    times, rhs the component's right-hand side with its parameters bound (e.g. a lambda over
    Component.rhs)."""
    return (((dxdt_hat - rhs(x_hat, u)) / scale) ** 2).mean()
