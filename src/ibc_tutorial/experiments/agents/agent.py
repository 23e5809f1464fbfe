"""The driving agents of the DA-IBC paper: its Fig. 2 network with a Beta head (BC), an energy head (IBC,
DA-IBC, DA-IBC with ranking NCE) or a flow-matching velocity head (flow).

The network (the DA-IBC paper's sec. 3.3 and Fig. 2):

- ``policies.BEVStateEncoder``: a CNN turns the five-channel bird's-eye view (B, 5, S, S) into a
  256-d embedding, an MLP the state (speed, previous steer, previous acceleration) (B, 3) into
  another; their concatenation is the observation's embedding z (B, 512);
- on top, either ``policies.BetaPolicy`` (BC, eq. 1; α, β > 0, see ``BC_MIN_CONCENTRATION``),
  ``policies.EnergyModel`` (IBC, DA-IBC and DA-IBC with ranking NCE; its first layer factorised, so z is
  computed once per observation and only the action's part runs per candidate), or ``policies.FlowPolicy``
  (flow: a velocity head v(z, y_t, t) of the energy head's width and depth, factorised the same way).

**How the flow agent chooses one action from its N samples.** Each decision draws ``preset.flow_samples``
samples by ``preset.flow_steps`` Euler steps (``FlowPolicy.sample``) and keeps the one whose steering is
nearest the *previous* steering, which every observation carries (``state[:, 1]``, the action the car
applied last). At a state with two answers (the stem of a T) independent draws would pick left or right
anew at every step, 10 times a second, and a car whose steering flips sign each step drives the average of
the two, straight into the wall ahead; keeping the sample nearest the previous steering commits to the side
the car has begun to take (the first step at a stem, the previous steering near straight, is a draw
between the two sides that the flow's mass decides) and still follows the flow where it has one mode, whose
samples all lie near each other. Only steering is matched: the expert's accelerations sit at -1 and +1, and
matching them would hold a brake after the light turned green. The agent needs no memory of its own (the
previous action is in the observation), so a batch of episodes of any size is served alike.

``architecture(method, preset)`` is the network's one description (what a checkpoint stores
and checks); ``build_network`` builds from it. ``Agent`` couples a network with the way it acts
(Beta mean; or Algorithm 1 with the method's initialisation and final selection) and gives the
closed-loop ``driving.rollout.DrivingPolicy`` that ``driving.rollout`` calls on numpy observation batches.

**Devices.** ``Agent.to(device)`` puts the network and the expert actions (the DFO population's
support) on a GPU; observations are moved there, the DFO draws are still made with the policy's
seeded CPU generator (``optimizers.common``), and actions come back as CPU tensors (numpy for the
rollout). The DFO initial weights stay on the CPU, where their draws are made.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from ibc_tutorial.driving.commands import COMMANDS, N_COMMANDS
from ibc_tutorial.driving.rollout import DrivingPolicy
from ibc_tutorial.experiments.agents.presets import ALL_METHODS, DA_IBC_METHODS, Preset
from ibc_tutorial.kde import inverse_density_weights
from ibc_tutorial.optimizers.dfo import DFOConfig, act_with_dfo
from ibc_tutorial.optimizers.grid import steer_accel_grid
from ibc_tutorial.policies.encoders import BEVStateEncoder, to_tensor_obs
from ibc_tutorial.policies.energy import EnergyModel
from ibc_tutorial.policies.explicit import BetaPolicy
from ibc_tutorial.policies.flow import FlowConfig, FlowPolicy
from ibc_tutorial.utils import check_choice, check_device, check_tensor

ACTION_DIM = 2
"""(steer, acceleration)."""

BC_MIN_CONCENTRATION = 0.0
"""α, β > 0 for the driving BC agent (not the α, β >= 1 of ``BetaPolicy``'s default).

The expert's accelerations are mostly exactly -1 (braking for a light) or +1 (starting off).
A Beta with α, β >= 1 has zero density at the bounds, so every such label pushes its α or β
down to the floor of 1; with the labels at both bounds the acceleration head collapses to
Beta(1, 1), the flat density, whose mean (0) never moves the car, and softplus's vanishing
gradient keeps it there (seen in a first laptop run: α = β = 1.001 everywhere, town02 score 0).
With the floor at 0 the Beta can put its mass at a bound (α < 1 or β < 1), and after 250
minibatches the predicted mean acceleration follows the label (correlation 0.94)."""


def architecture(method: str, preset: Preset) -> dict:
    """The Fig. 2 network of ``method`` at ``preset``'s sizes, as plain data: what must match for weights to
    be reused."""
    check_choice("method", method, ALL_METHODS)
    network = {"bc": "BetaPolicy", "flow": "FlowPolicy"}.get(method, "EnergyModel")
    arch = {
        "network": network,
        "encoder": "BEVStateEncoder",
        "bev_size": preset.bev_size,
        "cnn_channels": [int(c) for c in preset.cnn_channels],
        "embed_dim": preset.embed_dim,
        "action_dim": ACTION_DIM,
    }
    if preset.commands:  # recorded only when taken: a routeless architecture is that of older checkpoints
        arch["commands"] = N_COMMANDS
    if preset.command_branches:  # likewise: recorded only when taken
        arch["command_branches"] = True
    if method == "bc":
        arch.update(min_concentration=BC_MIN_CONCENTRATION)
    else:
        arch.update(head_hidden=preset.head_hidden, head_layers=preset.head_layers)
    if method == "flow":  # what the velocity head's input is made of (its inference settings are not weights)
        arch.update(time_features=FlowConfig.time_features, noise=FlowConfig.noise)
    return arch


def network_from_architecture(arch: dict) -> nn.Module:
    """Build the (untrained) network an ``architecture`` dict describes."""
    heads = ("BetaPolicy", "EnergyModel", "FlowPolicy")
    if (
        not isinstance(arch, dict)
        or arch.get("encoder") != "BEVStateEncoder"
        or arch.get("network") not in heads
    ):
        raise ValueError(
            f"arch must describe a BEVStateEncoder with a BetaPolicy, EnergyModel or FlowPolicy head, got "
            f"{arch!r}"
        )
    enc = BEVStateEncoder(
        arch["bev_size"],
        tuple(arch["cnn_channels"]),
        arch["embed_dim"],
        n_commands=arch.get("commands", 0),
        command_branches=arch.get("command_branches", False),
    )
    if arch["network"] == "BetaPolicy":
        return BetaPolicy(enc, action_dim=arch["action_dim"], min_concentration=arch["min_concentration"])
    if arch["network"] == "FlowPolicy":
        config = FlowConfig(time_features=arch["time_features"], noise=arch["noise"])
        return FlowPolicy(
            enc,
            action_dim=arch["action_dim"],
            hidden=arch["head_hidden"],
            layers=arch["head_layers"],
            config=config,
        )
    return EnergyModel(
        enc, action_dim=arch["action_dim"], hidden=arch["head_hidden"], layers=arch["head_layers"]
    )


def build_network(method: str, preset: Preset) -> nn.Module:
    """The Fig. 2 network for ``method``: a ``BetaPolicy`` (bc), a ``FlowPolicy`` (flow) or an ``EnergyModel``
    (ibc, da-ibc, da-ibc-rnce)."""
    return network_from_architecture(architecture(method, preset))


def dfo_config(method: str, preset: Preset) -> DFOConfig | None:
    """How ``method`` runs Algorithm 1 (None for bc and flow): ``preset.dfo_config(method)`` (see
    ``presets``)."""
    return preset.dfo_config(method)


class Agent:
    """A trained network and how it acts: the closed-loop policy of one method.

    Args:
        method: "bc", "ibc", "da-ibc", "flow" or "da-ibc-rnce" (see ``presets`` for what each means).
        network: from ``build_network(method, preset)``.
        preset: the settings (DFO sizes, KDE bandwidth, the flow's K and N).
        expert_actions: (M, 2) the training set's expert actions: the support of the DFO
            initialisation of DA-IBC (unused by bc, ibc and flow, but kept for every method).
        init_weights: optional precomputed (M,) DFO initial weights w ∝ 1 / ĝ
            (``kde.inverse_density_weights``); computed here if None and needed (da-ibc, da-ibc-rnce).

    The agent acts on the device of its network's weights (``to`` moves it; the CPU by default).
    """

    def __init__(
        self,
        method: str,
        network: nn.Module,
        preset: Preset,
        expert_actions: torch.Tensor,
        init_weights: torch.Tensor | None = None,
    ):
        self.method = check_choice("method", method, ALL_METHODS)
        want = {"bc": BetaPolicy, "flow": FlowPolicy}.get(method, EnergyModel)
        if not isinstance(network, want):
            raise ValueError(
                f"network must be a {want.__name__} for method {method!r}, got {type(network).__name__}"
            )
        self.network = network
        self.preset = preset
        self.expert_actions = check_tensor("expert_actions", expert_actions, ndim=2).float()  # (M, 2)
        if method in DA_IBC_METHODS and init_weights is None:
            init_weights = inverse_density_weights(
                self.expert_actions.cpu(), preset.kde_bandwidth
            )  # (M,) eqs. 4-5
        self.init_weights = None if init_weights is None else init_weights.cpu()  # drawn from on the CPU
        self.dfo_config = dfo_config(method, preset)
        """Algorithm 1's settings for this agent (None for bc and flow)."""
        self.flow_config = preset.flow_config() if method == "flow" else None
        """The flow's K and N at a decision (None but for flow)."""
        if method == "flow":
            network.config = self.flow_config  # the preset's K and N, not the ones it was built with

    @property
    def device(self) -> torch.device:
        """Where the network's weights are (and the agent computes)."""
        return next(self.network.parameters()).device

    def to(self, device: torch.device | str) -> Agent:
        """Move the network and the expert actions to ``device`` (checked: ``utils.check_device``); returns
        self."""
        device = check_device("device", device)
        self.network.to(device)
        self.expert_actions = self.expert_actions.to(device)  # (M, 2): the DFO population lives here
        return self

    @property
    def has_energy(self) -> bool:
        """Whether the agent's network is an energy model (ibc, da-ibc, da-ibc-rnce); bc and flow have
        none."""
        return self.method not in ("bc", "flow")

    def network_evaluations(self) -> dict[str, int]:
        """Encoder and head passes per observation and decision (``Preset.network_evaluations``)."""
        return self.preset.network_evaluations(self.method)

    @property
    def takes_command(self) -> bool:
        """Whether the agent was trained with route commands (``Preset.commands``): its observations must
        hold ``"command"``; a routeless agent's must not."""
        return bool(self.preset.commands)

    def check_command(self, obs) -> None:
        """ValueError unless ``obs`` holds a ``"command"`` exactly when the agent takes one."""
        has = isinstance(obs, dict) and "command" in obs
        if self.takes_command and not has:
            raise ValueError(
                f"this {self.method} agent takes a route command (trained with commands): obs must hold "
                f"'command', (B,) indices into {COMMANDS}; drive it on routes (driving.route_following)"
            )
        if has and not self.takes_command:
            raise ValueError(
                f"this {self.method} agent is routeless (trained without commands): obs must not hold "
                "'command'; drive it without commands (route_following.drive_routes(..., commands=False))"
            )

    @torch.no_grad()
    def act(self, obs, generator: torch.Generator | None = None) -> torch.Tensor:
        """Actions (B, 2) in [-1, 1], on the CPU, for a batch of observations (numpy or torch dict; with
        ``"command"`` exactly when the agent takes one, else ValueError: ``check_command``)."""
        self.check_command(obs)
        obs = to_tensor_obs(obs, self.device)
        self.network.eval()
        if self.method == "bc":
            return self.network.act(obs, mode="mean").cpu()  # (B, 2)
        if self.method == "flow":
            samples = self.network.sample(obs, generator=generator)  # (B, N, 2): K Euler steps each
            return nearest_previous_steer(samples, obs["state"][:, 1]).cpu()  # (B, 2), module docstring
        weights = self.init_weights if self.method in DA_IBC_METHODS else None
        actions = act_with_dfo(  # Algorithm 1 of the DA-IBC paper
            self.network, obs, self.expert_actions, self.dfo_config, init_weights=weights, generator=generator
        )
        return actions.cpu()  # (B, 2)

    def policy(self, seed: int = 0) -> DrivingPolicy:
        """The seeded ``driving.rollout.DrivingPolicy`` of this agent: numpy obs batch -> numpy actions (B, 2)
        (with ``"command"`` in the batch for an agent that takes one).

        Its DFO draws (a flow agent's noise) come from a CPU generator seeded with ``seed``, whatever the
        agent's device."""
        gen = torch.Generator().manual_seed(int(seed))

        def policy(obs):
            return self.act(obs, gen).numpy()

        return policy

    @torch.no_grad()
    def energy_grid(self, obs, n_per_dim: int = 41) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """E over a (steer, acceleration) grid for one observation: (steer (G,), accel (G,), E (G, G)) [accel,
        steer]."""
        if not self.has_energy:
            raise ValueError(
                f"energy_grid needs an energy agent (ibc, da-ibc, da-ibc-rnce), got {self.method}"
            )
        self.check_command(obs)
        obs = to_tensor_obs(obs, self.device)
        v, grid = steer_accel_grid(n_per_dim)  # (G,) straight exactly 0 on every CPU, (G², 2)
        grid = grid.to(self.device)
        e = self.network.energy_from_embedding(self.network.embed(obs), grid)[0].cpu()  # (G²,)
        return v.numpy(), v.numpy(), e.reshape(n_per_dim, n_per_dim).numpy()


def nearest_previous_steer(samples: torch.Tensor, previous_steer: torch.Tensor) -> torch.Tensor:
    """Of N sampled actions per observation, the one whose steering is nearest the previous steering (ties:
    the first): ``samples`` (B, N, 2), ``previous_steer`` (B,) -> (B, 2). The flow agent's choice (module
    docstring)."""
    check_tensor("samples", samples, ndim=3)
    check_tensor("previous_steer", previous_steer, shape=(len(samples),))
    gap = (samples[..., 0] - previous_steer.to(samples)[:, None]).abs()  # (B, N)
    pick = gap.argmin(dim=1)  # (B,)
    return samples[torch.arange(len(samples), device=samples.device), pick]  # (B, 2)
