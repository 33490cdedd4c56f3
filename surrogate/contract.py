"""The ONNX operator contract that needs no torch: the export tolerance and in-envelope test inputs.

Used by the export (against torch) and by the FMU builder (the compiled kernel against onnxruntime),
which must not import torch.
"""
from __future__ import annotations

import numpy as np

TOLERANCE = 1e-5  # max abs difference allowed between onnxruntime and torch, or the C kernel and onnxruntime


def random_inputs(envelope: dict, t_grid: np.ndarray, n: int, rng: np.random.Generator):
    """In-envelope test inputs: x0 [n, n_x] uniform in the box; u [n, S, n_u] ramps between two
    random levels per channel plus a random-amplitude sine, clipped to the box; t [M]: the grid and
    random times. The envelope's groups `x0` and `u` map names to [low, high] in the operator's order."""
    lo_x, hi_x = np.array(list(envelope["x0"].values()), dtype=float).T
    lo_u, hi_u = np.array(list(envelope["u"].values()), dtype=float).T
    n_x, n_u = lo_x.size, lo_u.size
    x0 = rng.uniform(lo_x, hi_x, (n, n_x))
    frac = t_grid / t_grid[-1]
    a, b = rng.uniform(lo_u, hi_u, (n, n_u)), rng.uniform(lo_u, hi_u, (n, n_u))
    wiggle = (0.1 * (hi_u - lo_u) * rng.uniform(0, 1, (n, 1, n_u))
              * np.sin(2 * np.pi * rng.uniform(1, 8, (n, 1, n_u)) * frac[None, :, None]))
    u = np.clip(a[:, None] + (b - a)[:, None] * frac[None, :, None] + wiggle, lo_u, hi_u)
    t = np.sort(np.concatenate([t_grid, rng.uniform(0, t_grid[-1], 37)]))
    return x0.astype(np.float32), u.astype(np.float32), t.astype(np.float32)
