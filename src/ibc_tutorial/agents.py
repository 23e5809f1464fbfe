"""The driving agents of the DA-IBC paper: its Fig. 2 network with a Beta head (BC) or an energy head (IBC, DA-IBC).

The network (the DA-IBC paper's sec. 3.3 and Fig. 2):

- a CNN turns the five-channel bird's-eye view (B, 5, S, S) into a 256-d embedding;
- an MLP turns the state (speed, previous steer, previous acceleration) (B, 3) into a 256-d
  embedding;
- the two are concatenated into the observation's embedding z (B, 512): ``BEVStateEncoder``,
  an ``ObservationEncoder`` taking dict observations ``{"bev", "state"}``;
- on top, either ``policies.BetaPolicy`` (BC, eq. 1; α, β > 0, see ``BC_MIN_CONCENTRATION``) or ``policies.EnergyModel`` (IBC and
  DA-IBC; its first layer factorised, so z is computed once per observation and only the
  action's part runs per candidate).

``Agent`` couples a network with the way it acts (Beta mean; or Algorithm 1 with the method's
initialisation and final selection) and gives the closed-loop callable that
``driving.rollout`` calls on numpy observation batches.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from ibc_tutorial.inference import dfo_batch, dfo_init_weights
from ibc_tutorial.policies.encoders import ObservationEncoder
from ibc_tutorial.policies.energy import EnergyModel
from ibc_tutorial.policies.explicit import BetaPolicy
from ibc_tutorial.presets import METHODS, Preset
from ibc_tutorial.utils import check_choice, check_int, check_tensor

SPEED_SCALE = 10.0
"""The speed entry of the state (m/s) is divided by this before the state MLP (inputs of order 1)."""


BC_MIN_CONCENTRATION = 0.0
"""α, β > 0 for the driving BC agent (not the α, β >= 1 of ``BetaPolicy``'s default).

The expert's accelerations are mostly exactly -1 (braking for a light) or +1 (starting off).
A Beta with α, β >= 1 has zero density at the bounds, so every such label pushes its α or β
down to the floor of 1; with the labels at both bounds the acceleration head collapses to
Beta(1, 1), the flat density, whose mean (0) never moves the car, and softplus's vanishing
gradient keeps it there (seen in a first laptop run: α = β = 1.001 everywhere, town02 score 0).
With the floor at 0 the Beta can put its mass at a bound (α < 1 or β < 1), and after 250
minibatches the predicted mean acceleration follows the label (correlation 0.94)."""


def _conv_out(size: int, n: int) -> int:
    for _ in range(n):
        size = (size + 2 * 1 - 3) // 2 + 1  # kernel 3, stride 2, padding 1
    return size


class BEVStateEncoder(ObservationEncoder):
    """Dict observations ``{"bev": (B, 5, S, S), "state": (B, 3)}`` -> z (B, 2 * embed_dim).

    The BEV (uint8 0/1 or float) goes through ``len(channels)`` 3x3 stride-2 convolutions with
    ReLU, then a linear layer to ``embed_dim`` (the paper's 256-d BEV embedding); the state
    (speed in m/s, previous steer, previous acceleration) through a two-layer MLP to
    ``embed_dim`` (the paper's 256-d state embedding). z is their concatenation.
    """

    def __init__(self, bev_size: int = 64, channels=(16, 32, 32, 64), embed_dim: int = 256, in_channels: int = 5):
        super().__init__()
        self.bev_size = check_int("bev_size", bev_size, minimum=8)
        self.in_channels = check_int("in_channels", in_channels, minimum=1)
        check_int("embed_dim", embed_dim, minimum=1)
        channels = tuple(int(c) for c in channels)
        if not channels or min(channels) < 1:
            raise ValueError(f"channels must be positive integers, got {channels!r}")
        convs: list[nn.Module] = []
        c_in = in_channels
        for c in channels:
            convs += [nn.Conv2d(c_in, c, kernel_size=3, stride=2, padding=1), nn.ReLU()]
            c_in = c
        side = _conv_out(bev_size, len(channels))
        self.cnn = nn.Sequential(*convs, nn.Flatten(), nn.Linear(c_in * side * side, embed_dim), nn.ReLU())
        self.state_mlp = nn.Sequential(nn.Linear(3, embed_dim), nn.ReLU(), nn.Linear(embed_dim, embed_dim), nn.ReLU())
        self.branch_dim = embed_dim
        self.embed_dim = 2 * embed_dim

    def batch_size(self, obs) -> int:
        return len(obs["bev"])

    def forward(self, obs) -> torch.Tensor:
        if not isinstance(obs, dict) or "bev" not in obs or "state" not in obs:
            raise ValueError(f"obs must be a dict with 'bev' and 'state', got {type(obs).__name__}")
        bev, state = obs["bev"], obs["state"]
        s = self.bev_size
        check_tensor("obs['bev']", bev, shape=(None, self.in_channels, s, s), finite=False)
        check_tensor("obs['state']", state, shape=(len(bev), 3))
        x = bev.float()  # (B, 5, S, S) of 0./1.
        st = state.float() * torch.tensor([1.0 / SPEED_SCALE, 1.0, 1.0])  # (B, 3), speed rescaled
        return torch.cat([self.cnn(x), self.state_mlp(st)], dim=1)  # (B, 2 E)


def build_network(method: str, preset: Preset) -> nn.Module:
    """The Fig. 2 network for ``method``: a ``BetaPolicy`` (bc) or an ``EnergyModel`` (ibc, da-ibc)."""
    check_choice("method", method, METHODS)
    enc = BEVStateEncoder(preset.bev_size, preset.cnn_channels, preset.embed_dim)
    if method == "bc":
        return BetaPolicy(enc, action_dim=2, min_concentration=BC_MIN_CONCENTRATION)
    return EnergyModel(enc, action_dim=2, hidden=preset.head_hidden, layers=preset.head_layers)


def to_tensor_obs(obs) -> dict[str, torch.Tensor]:
    """Numpy or torch ``{"bev", "state"}`` batches -> torch tensors (uint8 BEV, float32 state)."""
    bev, state = obs["bev"], obs["state"]
    bev = torch.from_numpy(np.ascontiguousarray(bev)) if isinstance(bev, np.ndarray) else bev
    state = torch.from_numpy(np.asarray(state, dtype=np.float32)) if isinstance(state, np.ndarray) else state.float()
    return {"bev": bev, "state": state}


class Agent:
    """A trained network and how it acts: the closed-loop policy of one method.

    Args:
        method: "bc", "ibc" or "da-ibc" (see ``presets`` for what each means).
        network: from ``build_network(method, preset)``.
        preset: the settings (DFO sizes, KDE bandwidth).
        expert_actions: (M, 2) the training set's expert actions: the support of the DFO
            initialisation of DA-IBC (unused by bc and ibc, but kept for every method).
        init_weights: optional precomputed (M,) DFO initial weights (inverse KDE); computed here
            if None and needed.
    """

    def __init__(self, method: str, network: nn.Module, preset: Preset, expert_actions: torch.Tensor,
                 init_weights: torch.Tensor | None = None):
        self.method = check_choice("method", method, METHODS)
        self.network = network
        self.preset = preset
        self.expert_actions = check_tensor("expert_actions", expert_actions, ndim=2).float()
        if method == "da-ibc" and init_weights is None:
            init_weights = dfo_init_weights(self.expert_actions, "inverse-kde", preset.kde_bandwidth)
        self.init_weights = init_weights

    # how each method runs Algorithm 1 (see presets' docstring)
    @property
    def dfo_settings(self) -> dict:
        """Keyword arguments of ``inference.dfo_batch`` for this agent (energy methods only)."""
        p = self.preset
        common = dict(n_samples=p.dfo_samples, n_iters=p.dfo_iters, sigma_init=p.dfo_sigma_init, shrink=p.dfo_shrink,
                      bandwidth=p.kde_bandwidth)
        if self.method == "ibc":
            return dict(common, init="uniform", select="argmax")  # the original IBC's DFO
        return dict(common, init="inverse-kde", select="sample", init_weights=self.init_weights)  # Algorithm 1

    @torch.no_grad()
    def act(self, obs, generator: torch.Generator | None = None) -> torch.Tensor:
        """Actions (B, 2) in [-1, 1] for a batch of observations (numpy or torch dict)."""
        obs = to_tensor_obs(obs)
        self.network.eval()
        if self.method == "bc":
            return self.network.act(obs, mode="mean")  # (B, 2)
        z = self.network.embed(obs)  # (B, E), once per observation
        return dfo_batch(lambda a: self.network.energy_from_embedding(z, a), self.expert_actions, len(z),
                         generator=generator, **self.dfo_settings)  # (B, 2)

    def policy(self, seed: int = 0):
        """The callable ``numpy obs batch -> numpy actions (B, 2)`` for ``driving.rollout``; seeded."""
        gen = torch.Generator().manual_seed(int(seed))

        def policy(obs):
            return self.act(obs, gen).numpy()

        return policy

    @torch.no_grad()
    def energy_grid(self, obs, n_per_dim: int = 41) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """E over a (steer, acceleration) grid for one observation: (steer (G,), accel (G,), E (G, G)) [accel, steer]."""
        if self.method == "bc":
            raise ValueError("energy_grid needs an energy agent (ibc or da-ibc), got bc")
        obs = to_tensor_obs(obs)
        v = torch.linspace(-1.0, 1.0, n_per_dim)
        acc, steer = torch.meshgrid(v, v, indexing="ij")
        grid = torch.stack([steer.reshape(-1), acc.reshape(-1)], dim=1)  # (G², 2)
        e = self.network.energy_from_embedding(self.network.embed(obs), grid)[0]  # (G²,)
        return v.numpy(), v.numpy(), e.reshape(n_per_dim, n_per_dim).numpy()
