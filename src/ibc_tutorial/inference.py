"""Inference for energy models: the action an implicit policy takes is argmin_y E(x, y).

- ``grid_argmin``: exhaustive search over a grid of candidate actions (1-D or 2-D actions).
- ``dfo``: derivative-free optimisation, Algorithm 1 of the DA-IBC paper (chapter 06).
- ``langevin``: gradient-based MCMC of the original IBC paper (chapter 06).
"""

from __future__ import annotations

import torch

from ibc_tutorial.utils import check_int, check_tensor


def action_grid(n_per_dim: int, action_dim: int = 1, low: float = -1.0, high: float = 1.0) -> torch.Tensor:
    """A regular grid of candidate actions: (n_per_dim ** action_dim, action_dim)."""
    check_int("n_per_dim", n_per_dim, minimum=2)
    check_int("action_dim", action_dim, minimum=1, maximum=2)
    if not low < high:
        raise ValueError(f"low must be < high, got low={low}, high={high}")
    axis = torch.linspace(low, high, n_per_dim)
    if action_dim == 1:
        return axis[:, None]  # (G, 1)
    gx, gy = torch.meshgrid(axis, axis, indexing="ij")
    return torch.stack([gx.reshape(-1), gy.reshape(-1)], dim=-1)  # (G, 2)
