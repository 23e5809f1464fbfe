"""The six models of the steering-EBM paper's Table 1, from the library's heads and losses.

Every model has the driving agents' BEV encoder (``policies.BEVStateEncoder``: a CNN over the
bird's-eye view and an MLP over the state, here [speed, 0, 0]) and outputs one number, the
steering command in [-1, 1] (+1 = right):

- ``ebm``: ``policies.EnergyModel`` E(x, steer) trained with cross-entropy over a fixed grid of
  ``n_bins`` linearly spaced steering values plus the ground truth (eq. 3 of the steering-EBM
  paper, ``objectives.grid_objective``); it acts by the argmin over the same grid
  (``optimizers.grid.grid_argmin``: no inference-time optimisation, as the paper);
- ``ebm-smooth``: the same with temporal smoothing α‖e_t − e_{t+1}‖ on consecutive frames (eq. 4);
- ``ebm-soft``: the same with soft targets softmax(−(a − a_GT)² / T) (eq. 5 with the sign the
  book corrects, ``losses.soft_targets``; T in steering units, ``presets.book_temperature``);
- ``regression``: ``policies.RegressionPolicy`` with the MAE loss;
- ``classification``: ``policies.ClassifierPolicy`` over ``n_bins`` bins, acting by the argmax;
- ``mdn``: ``policies.MDNPolicy`` with ``mdn_components`` Gaussians, acting with the mean of
  the most likely one (the paper's deployment).

``SteeringModel`` couples a network with the way it acts and with what Fig. 5 shows of it
(``scores``: the energies over the grid, or −log p of the explicit models' densities).
"""

from __future__ import annotations

import torch
from torch import nn

from ibc_tutorial.objectives import grid_objective, likelihood_objective
from ibc_tutorial.optimizers.grid import action_grid, grid_argmin, grid_energies
from ibc_tutorial.policies.encoders import BEVStateEncoder, to_tensor_obs
from ibc_tutorial.policies.energy import EnergyModel
from ibc_tutorial.policies.explicit import ClassifierPolicy, MDNPolicy, RegressionPolicy
from ibc_tutorial.training import Objective
from ibc_tutorial.utils import check_choice

MODELS = ("ebm", "ebm-smooth", "ebm-soft", "regression", "classification", "mdn")
"""The six models, in the order of the paper's Table 1."""
EBMS = ("ebm", "ebm-smooth", "ebm-soft")
"""The energy-based ones."""
LABELS = {
    "ebm": "EBM",
    "ebm-smooth": "EBM Temp. Smoothing",
    "ebm-soft": "EBM Soft Targets",
    "regression": "Regression (MAE)",
    "classification": "Classification",
    "mdn": "MDN",
}
"""The paper's names of the models."""


def encoder(preset) -> BEVStateEncoder:
    """The driving agents' BEV encoder at the preset's sizes."""
    return BEVStateEncoder(preset.bev_size, tuple(preset.cnn_channels), preset.embed_dim)


def build_network(name: str, preset) -> nn.Module:
    """The untrained network of model ``name`` (draws from torch's global generator: seed it first)."""
    check_choice("name", name, MODELS)
    enc = encoder(preset)
    if name in EBMS:
        return EnergyModel(enc, action_dim=1, hidden=preset.head_hidden, layers=preset.head_layers)
    if name == "regression":
        return RegressionPolicy(enc, 1, loss_kind="mae")
    if name == "classification":
        return ClassifierPolicy(enc, 1, n_bins=preset.n_bins)
    return MDNPolicy(enc, 1, n_components=preset.mdn_components)


def steering_grid(preset) -> torch.Tensor:
    """(n_bins, 1) the EBMs' fixed grid: ``n_bins`` linearly spaced values over [-1, 1]."""
    return action_grid(preset.n_bins, 1)


def objective_for(name: str, network: nn.Module, preset) -> Objective:
    """The training objective of model ``name`` (see the module docstring)."""
    check_choice("name", name, MODELS)
    if name not in EBMS:
        return likelihood_objective(network)  # MAE, cross-entropy over bins, or the MDN's NLL
    grid = steering_grid(preset)
    if name == "ebm-smooth":
        return grid_objective(network, grid, smoothing=preset.smoothing_alpha)  # eqs. 3 + 4
    if name == "ebm-soft":
        return grid_objective(network, grid, temperature=preset.soft_temperature)  # eqs. 3 + 5
    return grid_objective(network, grid)  # eq. 3


def uses_pairs(name: str) -> bool:
    """Whether model ``name`` trains on pairs of consecutive frames (temporal smoothing)."""
    return check_choice("name", name, MODELS) == "ebm-smooth"


class SteeringModel:
    """A trained network of one of ``MODELS`` and how it steers.

    ``steer(obs) -> (B,)`` for a batch of steering observations (``task.steering_observation``);
    ``scores(obs) -> (B, G)`` over ``display_grid`` (G = ``n_bins`` values): the energies of an
    EBM, −log of the density of the classifier or the MDN (lower = preferred, like an energy),
    None for the regression, which predicts a single value.
    """

    def __init__(self, name: str, network: nn.Module, preset):
        self.name = check_choice("name", name, MODELS)
        self.network = network.eval()
        self.preset = preset
        self.grid = steering_grid(preset)  # (G, 1)
        self.display_grid = self.grid[:, 0].clamp(-1.0, 1.0)  # (G,)

    @torch.no_grad()
    def steer(self, obs) -> torch.Tensor:
        obs = to_tensor_obs(obs)
        net = self.network
        if self.name in EBMS:
            return grid_argmin(net, obs, self.grid)[:, 0]  # (B,)
        return net.act(obs)[:, 0]  # (B,): the default mode (deterministic / argmax / "paper")

    @torch.no_grad()
    def scores(self, obs) -> torch.Tensor | None:
        obs = to_tensor_obs(obs)
        net = self.network
        if self.name in EBMS:
            return grid_energies(net, net.embed(obs), self.grid)  # (B, G)
        if self.name == "regression":
            return None
        density = net.action_density(obs, self.display_grid)[:, :, 0]  # (B, G)
        return -torch.log(density.clamp_min(1e-30))
