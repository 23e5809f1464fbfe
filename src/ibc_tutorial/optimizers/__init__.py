"""Inference for energy models: the action an implicit policy takes is ŷ = argmin_y E(x, y).

An energy model only scores actions; acting needs a search for a low-energy action. The
modules here are three such searches, each usable as an ``ActionOptimizer``:

- ``optimizers.grid``: exhaustive search over a fixed grid (the steering-EBM paper; chapter 03):
  ``action_grid``, ``grid_energies``, ``grid_argmin``, ``GridOptimizer``.
- ``optimizers.dfo``: derivative-free optimisation, Algorithm 1 of the DA-IBC paper (chapter 06):
  ``DFOConfig``, ``dfo`` (one observation or B), ``dfo_trace``, ``initial_weights``,
  ``initial_samples``, ``DFOOptimizer``, ``dfo_policy``.
- ``optimizers.langevin``: the original IBC's gradient-based "Langevin MCMC" (chapter 06):
  ``LangevinConfig``, ``langevin``, ``langevin_trace``, ``polynomial_schedule``, ``LangevinOptimizer``.
- ``optimizers.common``: what DFO and Langevin share (the action box, the two forms of energy
  function, the final choice).

Import the functions from their modules (``from ibc_tutorial.optimizers.dfo import dfo``); this
package itself defines only the two protocols below.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import torch


class EmbeddingEnergyModel(Protocol):
    """What an optimiser needs of an energy model (``policies.EnergyModel`` is one).

    The observation is encoded once, then any number of candidate actions are scored against
    its embedding: the split that makes scoring thousands of candidates cheap.
    """

    def embed(self, obs) -> torch.Tensor:
        """Observations of batch B (a tensor, or a dict of tensors) -> embeddings z (B, E)."""
        ...

    def energy_from_embedding(self, z: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """z (B, E) and actions (B, N, D), or (N, D) shared by every row -> energies (B, N)."""
        ...


@runtime_checkable
class ActionOptimizer(Protocol):
    """Finds, for each observation, an action of low energy: ŷ ≈ argmin_y E(x, y).

    Implemented by ``grid.GridOptimizer`` (exact over a grid), ``dfo.DFOOptimizer`` (Algorithm 1
    of the DA-IBC paper: ends with a draw, so it need not return the argmin) and
    ``langevin.LangevinOptimizer`` (the IBC reference's gradient-based search). Whatever an
    optimiser needs besides the model and the observations (a grid, expert actions, settings)
    it holds from its construction; random draws come from ``generator``.
    """

    def infer(
        self, model: EmbeddingEnergyModel, obs, *, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """(B, D) one action per observation of the batch ``obs`` (a tensor, or a dict of tensors)."""
        ...


__all__ = ["ActionOptimizer", "EmbeddingEnergyModel"]
