"""Inference for energy models: the action an implicit policy takes is ŷ = argmin_y E(x, y).

An energy model only scores actions; acting needs a search for a low-energy action. The
modules here are three such searches:

- ``optimizers.grid``: exhaustive search over a fixed grid (the steering-EBM paper; chapter 03):
  ``action_grid``, ``grid_energies``, ``grid_argmin``, ``GridOptimizer``.
- ``optimizers.dfo``: derivative-free optimisation, Algorithm 1 of the DA-IBC paper (chapter 06):
  ``DFOConfig``, ``dfo`` (one observation or B), ``dfo_trace``, ``DFOOptimizer``, ``dfo_policy``
  (a ``DFOPolicy``, whose call runs ``dfo`` itself).
- ``optimizers.langevin``: the original IBC's gradient-based "Langevin MCMC" (chapter 06):
  ``LangevinConfig``, ``langevin``, ``langevin_trace``, ``polynomial_schedule``.
- ``optimizers.common``: what DFO and Langevin share (the action box, the initial population
  ``initial_weights`` / ``initial_samples`` of Algorithm 1 line 2, the two forms of energy
  function, the final choice).

This package itself defines how a model acts through a search: the ``ActionOptimizer`` protocol
(``GridOptimizer``, ``DFOOptimizer``) and ``EnergyPolicy``, the closed-loop policy that every
energy model of the book drives with (``policies.GridArgminPolicy``, ``dfo_policy``), with
``eval_mode`` and ``embedded_energy`` (each observation embedded once; the driving ``Agent`` uses
it too). Import the functions from their modules
(``from ibc_tutorial.optimizers.dfo import dfo``).
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import Protocol, runtime_checkable

import torch


@runtime_checkable
class ActionOptimizer(Protocol):
    """Finds, for each observation, an action of low energy: ŷ ≈ argmin_y E(x, y).

    Implemented by ``grid.GridOptimizer`` (exact over a grid) and ``dfo.DFOOptimizer``
    (Algorithm 1 of the DA-IBC paper: ends with a draw, so it need not return the argmin).
    ``model`` has ``embed(obs) -> z (B, E)`` and ``energy_from_embedding(z, actions) -> (B, N)``
    (``policies.EnergyModel``). Whatever an optimiser needs besides the model and the
    observations (a grid, expert actions, settings) it holds from its construction; random
    draws come from ``generator``.
    """

    def infer(self, model, obs, *, generator: torch.Generator | None = None) -> torch.Tensor:
        """(B, D) one action per observation of the batch ``obs`` (a tensor, or a dict of tensors)."""
        ...


class EnergyPolicy:
    """An energy model acting through a search: ``policy(obs) -> optimizer.infer(model, obs)``, (B, D).

    The closed-loop form of an implicit policy (the toy worlds call it on a tensor batch). The
    model is put in eval mode for each decision and restored after it; draws come from
    ``generator``.

    Args:
        model: an energy model (``embed`` and ``energy_from_embedding``).
        optimizer: an ``ActionOptimizer`` (``GridOptimizer``, ``DFOOptimizer``).
        generator: a seeded ``torch.Generator`` for the optimizer's draws (None: torch's global one).
    """

    def __init__(self, model, optimizer: ActionOptimizer, generator: torch.Generator | None = None):
        if not isinstance(optimizer, ActionOptimizer):
            raise ValueError(f"optimizer must be an ActionOptimizer, got {type(optimizer).__name__}")
        self.model, self.optimizer, self.generator = model, optimizer, generator

    def __call__(self, obs) -> torch.Tensor:
        with eval_mode(self.model):
            return self.optimizer.infer(self.model, obs, generator=self.generator)  # (B, D)


@contextmanager
def eval_mode(model):
    """``model`` in eval mode inside the block, restored to training mode after it if it was in it."""
    was_training = getattr(model, "training", False)
    if was_training:
        model.eval()
    try:
        yield model
    finally:
        if was_training:
            model.train()


def embedded_energy(model, obs):
    """``(energy_fn, B)``: each of the B observations embedded once (``model.embed``), and
    ``energy_fn(actions (B, N, D)) -> (B, N)`` running only the action part of the head
    (``model.energy_from_embedding``). B is the embedding's length, so dict observations work too."""
    z = model.embed(obs)  # (B, E), once per observation
    return (lambda actions: model.energy_from_embedding(z, actions)), len(z)


__all__ = ["ActionOptimizer", "EnergyPolicy", "embedded_energy", "eval_mode"]
