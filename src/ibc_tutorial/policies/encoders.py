"""Observation encoders shared by every policy.

An encoder maps a batch of observations to embeddings of size ``embed_dim``; every policy
head (regression, Beta, classifier, MDN, energy) sits on top of one, so a chapter can swap
the small MLP of the toy worlds for the bird's-eye-view CNN of the driving chapters.
"""

from __future__ import annotations

import torch
from torch import nn

from ibc_tutorial.utils import check_int


class ObservationEncoder(nn.Module):
    """Interface: ``forward(obs) -> (B, embed_dim)``; subclasses set ``embed_dim``."""

    embed_dim: int

    def batch_size(self, obs) -> int:
        """Number of observations in ``obs`` (a tensor, or a dict of tensors)."""
        if isinstance(obs, dict):
            return len(next(iter(obs.values())))
        return len(obs)


class MLPEncoder(ObservationEncoder):
    """Vector observations (B, obs_dim) -> (B, embed_dim) through ``layers`` ReLU layers."""

    def __init__(self, obs_dim: int, embed_dim: int = 64, hidden: int = 64, layers: int = 2):
        super().__init__()
        self.obs_dim = check_int("obs_dim", obs_dim, minimum=1)
        self.embed_dim = check_int("embed_dim", embed_dim, minimum=1)
        check_int("hidden", hidden, minimum=1)
        check_int("layers", layers, minimum=1)
        dims = [obs_dim] + [hidden] * (layers - 1) + [embed_dim]
        mods: list[nn.Module] = []
        for i, (a, b) in enumerate(zip(dims[:-1], dims[1:])):
            mods.append(nn.Linear(a, b))
            mods.append(nn.ReLU())
        self.net = nn.Sequential(*mods)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        if not isinstance(obs, torch.Tensor) or obs.ndim != 2 or obs.shape[1] != self.obs_dim:
            got = tuple(obs.shape) if isinstance(obs, torch.Tensor) else type(obs).__name__
            raise ValueError(f"obs must be a tensor of shape (B, {self.obs_dim}), got {got}")
        return self.net(obs)  # (B, embed_dim)
