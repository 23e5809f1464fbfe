"""The energy model E(x, y) of implicit behavioral cloning, with late fusion.

An implicit policy acts by ŷ = argmin_y E_θ(x, y) (sec. 2.3 of the DA-IBC paper; eq. 1 of the
steering-EBM paper). Inference and training score many candidate actions y for the same
observation x, so the model is split into two parts (the DA-IBC paper's Fig. 2; sec. 3 of the
steering-EBM paper: "the convolutional part of the network runs on an image only once, with
actions fused into the model before the MLP head"):

- an observation encoder (any ``ObservationEncoder``) maps x to an embedding z, once per
  observation;
- an action head maps (z, y) to a scalar energy. Its first layer is the linear map of the
  concatenation [z; y], W·[z; y] + b = (W_z·z + b) + W_a·y, computed *factorised*: the
  observation's part W_z·z + b once per observation, the action's part W_a·y per candidate,
  then a broadcast add. The remaining hidden layers run per candidate.

So scoring N candidates costs one encoder pass plus, per candidate, one small matmul for
W_a·y and the head's hidden layers. ``embed`` and ``energy_from_embedding`` expose the two
halves separately, so an optimiser (grid argmin, DFO, Langevin) encodes x once and then
scores as many candidate sets against z as it likes.

Policies for closed-loop rollouts: ``GridArgminPolicy`` (argmin over a fixed grid) and
``GridSamplePolicy`` (a draw from softmax(−E) over the grid).
"""

from __future__ import annotations

import torch
from torch import nn

from ibc_tutorial.optimizers import EnergyPolicy
from ibc_tutorial.optimizers.grid import GridOptimizer, grid_energies
from ibc_tutorial.policies.encoders import ObservationEncoder
from ibc_tutorial.utils import check_int, check_tensor, draw_device


class EnergyModel(nn.Module):
    """E_θ(x, y): an observation encoder and an action head with a factorised first layer.

    Args:
        encoder: maps a batch of observations (a tensor, or a dict of tensors) to (B, E).
        action_dim: D, the size of an action (1 for steering, 2 for steering and acceleration).
        hidden: width of the head's hidden layers.
        layers: number of hidden layers in the head (>= 1); the first is the fused layer.

    Shapes: ``energy(obs, actions)`` takes obs of batch B and actions (B, N, D), or (N, D)
    shared by every observation, and returns energies (B, N). Lower energy = better action.
    """

    def __init__(self, encoder: ObservationEncoder, action_dim: int, hidden: int = 64, layers: int = 2):
        super().__init__()
        if not isinstance(encoder, nn.Module) or not hasattr(encoder, "embed_dim"):
            raise ValueError(
                f"encoder must be an ObservationEncoder (an nn.Module with embed_dim), got "
                f"{type(encoder).__name__}"
            )
        self.encoder = encoder
        self.action_dim = check_int("action_dim", action_dim, minimum=1)
        self.hidden = check_int("hidden", hidden, minimum=1)
        self.layers = check_int("layers", layers, minimum=1)
        self.embed_dim = int(encoder.embed_dim)
        # First layer of the head, W·[z; y] + b split into its two column blocks.
        self.obs_proj = nn.Linear(self.embed_dim, hidden)  # W_z z + b, once per observation
        self.act_proj = nn.Linear(self.action_dim, hidden, bias=False)  # W_a y, per candidate
        self._init_fused_layer()
        mods: list[nn.Module] = []
        for _ in range(layers - 1):
            mods += [
                nn.Linear(hidden, hidden),
                nn.ReLU(inplace=True),
            ]  # in place: no extra (B, N, H) temporary
        mods.append(nn.Linear(hidden, 1))
        self.head = nn.Sequential(*mods)  # per candidate: (..., hidden) -> (..., 1)

    def _init_fused_layer(self) -> None:
        """Initialise W_z, W_a, b as nn.Linear would initialise the unsplit layer on [z; y]."""
        unsplit = nn.Linear(self.embed_dim + self.action_dim, self.hidden)
        with torch.no_grad():
            self.obs_proj.weight.copy_(unsplit.weight[:, : self.embed_dim])
            self.obs_proj.bias.copy_(unsplit.bias)
            self.act_proj.weight.copy_(unsplit.weight[:, self.embed_dim :])

    # ------------------------------------------------------------------ the two halves
    def embed(self, obs) -> torch.Tensor:
        """Encode observations once: obs of batch B -> z (B, E)."""
        return self.encoder(obs)

    def energy_from_embedding(self, z: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Score candidate actions against embeddings: z (B, E), actions (B, N, D) or (N, D) -> (B, N)."""
        if not isinstance(z, torch.Tensor) or z.ndim != 2 or z.shape[1] != self.embed_dim:
            got = tuple(z.shape) if isinstance(z, torch.Tensor) else type(z).__name__
            raise ValueError(f"z must be a tensor of shape (B, {self.embed_dim}), got {got}")
        actions = self._check_actions(actions, len(z))
        h_obs = self.obs_proj(z)  # (B, H): W_z z + b, once per observation
        if torch.is_grad_enabled():
            # Training: the broadcast form, W_a y per candidate plus W_z z + b.
            h_act = actions @ self.act_proj.weight.T  # (B, N, H) or (N, H): W_a y, per candidate
            h = torch.relu(h_obs[:, None, :] + h_act)  # (B, N, H): broadcast add = W [z; y] + b
        else:
            # Inference (grid argmin, DFO, Langevin's scoring): the same layer as one batched
            # multiply-add with W_z z + b as its bias, ReLU in place: one (B, N, H) temporary
            # instead of three, which halves the time of a DFO decision at 16,384 candidates
            # (benchmarks/bench_dfo.py). Energies agree with the training form to ~1e-7; the
            # training form is kept so that the book's stored training runs reproduce bit for bit.
            if actions.ndim == 2:
                actions = actions.expand(len(z), -1, -1)  # (B, N, D): shared candidates, no copy
            w_a = self.act_proj.weight.T.expand(len(z), -1, -1)  # (B, D, H)
            h = torch.baddbmm(h_obs[:, None, :], actions, w_a).relu_()  # (B, N, H)
        return self.head(h).squeeze(-1)  # (B, N)

    def energy(self, obs, actions: torch.Tensor) -> torch.Tensor:
        """E_θ(x, y) for every candidate: obs of batch B, actions (B, N, D) or (N, D) -> (B, N)."""
        return self.energy_from_embedding(self.embed(obs), actions)

    def forward(self, obs, actions: torch.Tensor) -> torch.Tensor:
        return self.energy(obs, actions)

    # ------------------------------------------------------------------ checks
    def _check_actions(self, actions, batch: int) -> torch.Tensor:
        ok = (
            isinstance(actions, torch.Tensor)
            and actions.ndim in (2, 3)
            and actions.shape[-1] == self.action_dim
        )
        if ok and actions.ndim == 3 and actions.shape[0] != batch:
            ok = False
        if not ok:
            got = tuple(actions.shape) if isinstance(actions, torch.Tensor) else type(actions).__name__
            raise ValueError(
                f"actions must be a tensor of shape ({batch}, N, {self.action_dim}) or (N, "
                f"{self.action_dim}), got {got}"
            )
        return actions


class GridArgminPolicy(EnergyPolicy):
    """An implicit policy for rollouts: obs (B, obs_dim) -> argmin over ``grid`` of E(obs, ·), (B, D).

    A plain callable (the toy worlds' policy interface), evaluated without gradients, with the
    model in eval mode: ``optimizers.EnergyPolicy`` with a ``GridOptimizer``. ``grid`` is (G, D),
    e.g. ``optimizers.grid.action_grid(201)`` for steering.
    """

    def __init__(self, model: EnergyModel, grid: torch.Tensor):
        check_tensor("grid", grid, ndim=2)
        if grid.shape[1] != model.action_dim:
            raise ValueError(f"grid must have shape (G, {model.action_dim}), got {tuple(grid.shape)}")
        super().__init__(model, GridOptimizer(grid))
        self.grid = grid


class GridSamplePolicy:
    """A stochastic implicit policy: obs (B, obs_dim) -> one action per observation drawn from
    p(y | x) = softmax(−E(x, ·)) over ``grid``, (B, D).

    The DA-IBC paper's inference also ends with a draw, not an argmin (the last line of its
    Algorithm 1, ŷ ~ Categorical(p̃)); on a fixed grid the draw is exact. Seeded by ``generator``.
    """

    def __init__(self, model: EnergyModel, grid: torch.Tensor, generator: torch.Generator | None = None):
        check_tensor("grid", grid, ndim=2)
        if grid.shape[1] != model.action_dim:
            raise ValueError(f"grid must have shape (G, {model.action_dim}), got {tuple(grid.shape)}")
        self.model, self.grid, self.generator = model, grid, generator

    @torch.no_grad()
    def __call__(self, obs) -> torch.Tensor:
        was_training = self.model.training
        self.model.eval()
        try:
            energies = grid_energies(self.model, self.model.embed(obs), self.grid)  # (B, G)
        finally:
            self.model.train(was_training)
        probs = torch.softmax(-energies, dim=1).to(
            draw_device(self.generator)
        )  # (B, G), drawn where the generator is
        idx = torch.multinomial(probs, 1, generator=self.generator)[:, 0]  # (B,)
        return self.grid[idx.to(self.grid.device)]  # (B, D)
