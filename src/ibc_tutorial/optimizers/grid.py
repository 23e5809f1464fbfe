"""Exhaustive inference over a fixed grid of actions: the steering-EBM paper's (chapter 03).

- ``action_grid``: a regular grid of candidate actions in any number of dimensions.
- ``symmetric_axis``: n values over [-1, 1], exactly symmetric on every CPU (the energy readings' axis).
- ``grid_energies``: the energies of a shared grid for a batch of embeddings, in cache-sized blocks.
- ``grid_argmin``: ŷ = argmin over the grid of E(x, y) (eq. 1 and Fig. 3 of the steering-EBM paper).
- ``GridOptimizer``: ``grid_argmin`` as an ``ActionOptimizer``.
"""

from __future__ import annotations

import torch

from ibc_tutorial.utils import check_box, check_int, check_tensor

CHUNK_ELEMENTS = 1 << 20
"""``grid_energies`` scores at most about this many (observation, candidate, hidden unit)
activations at once: small blocks stay in the CPU's cache and run several times faster
than one huge (B, G, H) tensor, which is bound by memory bandwidth."""


def action_grid(n_per_dim: int, action_dim: int = 1, low: float = -1.0, high: float = 1.0) -> torch.Tensor:
    """A regular grid of candidate actions: (n_per_dim ** action_dim, action_dim).

    Every action dimension takes the ``n_per_dim`` values of ``torch.linspace(low, high,
    n_per_dim)``; the rows are their Cartesian product, the first dimension varying slowest
    (row i·n + j of a 2-D grid is (axis[i], axis[j])).
    """
    check_int("n_per_dim", n_per_dim, minimum=2)
    check_int("action_dim", action_dim, minimum=1)
    check_box(low, high, 1)  # numbers, finite, low < high
    axis = torch.linspace(low, high, n_per_dim)  # (n,)
    return torch.cartesian_prod(*[axis] * action_dim).reshape(-1, action_dim)  # (n^D, D)


def symmetric_axis(n: int, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """``n`` evenly spaced values over [-1, 1] (n,) of ``dtype``, exactly symmetric on every CPU.

    Value i is (2i - (n - 1)) / (n - 1), computed in float64 and rounded once: value n-1-i is exactly
    -value i, and the middle value of an odd ``n`` is exactly 0. ``torch.linspace(-1, 1, n)`` is not:
    its vectorised kernels give a middle value of -1.5e-8 for n = 41 or 81 with AVX2 and 0 without, so
    a reading that splits a profile at straight (``driving.energy_profiles.boltzmann_sides``) would
    count the straight value as left on one CPU and as half left on another.
    """
    check_int("n", n, minimum=2)
    i = torch.arange(n, dtype=torch.float64)
    if dtype not in (torch.float32, torch.float64):
        raise ValueError(f"dtype must be torch.float32 or torch.float64, got {dtype!r}")
    return ((2 * i - (n - 1)) / (n - 1)).to(dtype)  # (n,)


def steer_accel_grid(n: int, n_accel: int | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """The driving agents' (steering, acceleration) grid: its steering axis (n,) (``symmetric_axis``:
    straight is exactly 0) and its n x m actions (n m, 2) with m = ``n_accel`` (default n) acceleration
    values, rows (steer, accel) with the acceleration varying slowest, so that energies of the grid reshape
    to (m accel, n steer)."""
    v = symmetric_axis(n)  # (n,)
    a = v if n_accel is None else symmetric_axis(n_accel)  # (m,)
    acc, steer = torch.meshgrid(a, v, indexing="ij")  # (m, n) each
    return v, torch.stack([steer.reshape(-1), acc.reshape(-1)], dim=1)  # (n,), (m n, 2)


def grid_energies(
    model, z: torch.Tensor, grid: torch.Tensor, *, chunk_elements: int = CHUNK_ELEMENTS
) -> torch.Tensor:
    """Energies of a shared grid of candidates for embeddings ``z`` (B, E), in blocks of observations.

    Same result as ``model.energy_from_embedding(z, grid)`` (B, G), computed over blocks of
    observations so that each block holds about ``chunk_elements`` hidden activations.
    """
    check_int("chunk_elements", chunk_elements, minimum=1)
    hidden = int(getattr(model, "hidden", 1))
    rows = max(1, chunk_elements // max(1, len(grid) * hidden))
    return torch.cat([model.energy_from_embedding(block, grid) for block in z.split(rows)], dim=0)  # (B, G)


@torch.no_grad()
def grid_argmin(model, obs, grid: torch.Tensor, *, return_energies: bool = False):
    """ŷ = argmin over a fixed grid of E(x, y): exhaustive inference.

    The steering-EBM paper's inference (its sec. 3 and Fig. 3, right): every candidate of a
    constant, linearly spaced grid is scored and the lowest energy wins (eq. 1 of that paper).
    The observation is encoded once (``model.embed``) and the grid, shared by every
    observation, is scored against the embedding (``model.energy_from_embedding``), so the
    cost per candidate is only the energy model's action head. The grid grows as n^D, so
    this suits low-dimensional actions (D = 1 or 2 in the book).

    Args:
        model: an ``EnergyModel`` (anything with ``embed`` and ``energy_from_embedding``).
        obs: a batch of B observations (tensor, or dict of tensors).
        grid: (G, D) candidate actions, e.g. ``action_grid(201)``.
        return_energies: also return the (B, G) energies.
    Returns:
        (B, D) actions, or ``(actions, energies)``.
    """
    check_tensor("grid", grid, ndim=2)
    if len(grid) < 1:
        raise ValueError("grid must hold at least one candidate action")
    z = model.embed(obs)  # (B, E), once per observation
    energies = grid_energies(model, z, grid)  # (B, G), in cache-sized blocks
    best = energies.argmin(dim=1)  # (B,)
    actions = grid[best]  # (B, D)
    return (actions, energies) if return_energies else actions


class GridOptimizer:
    """``grid_argmin`` over a fixed grid, an ``ActionOptimizer``.

    Args:
        grid: (G, D) candidate actions, e.g. ``action_grid(201)``.
    """

    def __init__(self, grid: torch.Tensor):
        check_tensor("grid", grid, ndim=2)
        if len(grid) < 1:
            raise ValueError("grid must hold at least one candidate action")
        self.grid = grid

    def infer(self, model, obs, *, generator: torch.Generator | None = None) -> torch.Tensor:
        """(B, D) the grid's lowest-energy action for each observation (``generator`` is unused: no draws)."""
        return grid_argmin(model, obs, self.grid)
