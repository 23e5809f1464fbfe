"""Observation encoders shared by every policy.

An encoder maps a batch of observations to embeddings of size ``embed_dim``; every policy
head (regression, Beta, classifier, MDN, energy) sits on top of one, so a chapter can swap
the small MLP of the toy worlds (``MLPEncoder``) for the bird's-eye-view CNN of the driving
chapters (``BEVStateEncoder``, the DA-IBC paper's Fig. 2).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from ibc_tutorial.utils import check_int, check_tensor

SPEED_SCALE = 10.0
"""``BEVStateEncoder`` divides the speed entry of the state (m/s) by this before its MLP (inputs of order 1).
"""


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
        for a, b in zip(dims[:-1], dims[1:], strict=True):
            mods.append(nn.Linear(a, b))
            mods.append(nn.ReLU())
        self.net = nn.Sequential(*mods)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        if not isinstance(obs, torch.Tensor) or obs.ndim != 2 or obs.shape[1] != self.obs_dim:
            got = tuple(obs.shape) if isinstance(obs, torch.Tensor) else type(obs).__name__
            raise ValueError(f"obs must be a tensor of shape (B, {self.obs_dim}), got {got}")
        return self.net(obs)  # (B, embed_dim)


def _conv_out(size: int, n: int) -> int:
    for _ in range(n):
        size = (size + 2 * 1 - 3) // 2 + 1  # kernel 3, stride 2, padding 1
    return size


class BEVStateEncoder(ObservationEncoder):
    """Dict observations ``{"bev": (B, 5, S, S), "state": (B, 3)}`` -> z (B, 2 * embed_dim): the DA-IBC
    paper's Fig. 2.

    The BEV (float32: road channels 0/1, light channels 0.3 / 0.6 / 1.0) goes through ``len(channels)`` 3x3
    stride-2 convolutions with
    ReLU, then a linear layer to ``embed_dim`` (the paper's 256-d BEV embedding); the state
    (speed in m/s, previous steer, previous acceleration) through a two-layer MLP to
    ``embed_dim`` (the paper's 256-d state embedding). z is their concatenation (sec. 3.3).

    With ``n_commands`` > 0 (chapter 11: the DA-IBC paper's future work, a goal-directed agent) the
    observation also holds ``"command"`` (B,) integer indices, one of CIL's high-level commands
    (``driving.commands``), fed one-hot beside the state into the state MLP: E(x, c, y) for an energy head.
    An observation without a command is refused by such an encoder, one with a command by a routeless one.

    With ``command_branches`` as well, the command also chooses one of ``n_commands`` branch layers on the
    joint embedding: z_c = ReLU(W_c z + b_c), each W_c (2E, 2E), so the output keeps its size and every head
    sits on it unchanged. This is the *branched* network of conditional imitation learning (CIL: Codevilla
    et al., 2018, who put one whole action head per command; here one layer per command under the shared
    head), where the command as one input among the state's is CIL's *command input* network.
    """

    def __init__(
        self,
        bev_size: int = 64,
        channels=(16, 32, 32, 64),
        embed_dim: int = 256,
        in_channels: int = 5,
        n_commands: int = 0,
        command_branches: bool = False,
    ):
        super().__init__()
        self.bev_size = check_int("bev_size", bev_size, minimum=8)
        self.in_channels = check_int("in_channels", in_channels, minimum=1)
        check_int("embed_dim", embed_dim, minimum=1)
        channels = tuple(int(c) for c in channels)
        if not channels or min(channels) < 1:
            raise ValueError(f"channels must be positive integers, got {channels!r}")
        self.channels = channels
        convs: list[nn.Module] = []
        c_in = in_channels
        for c in channels:
            convs += [nn.Conv2d(c_in, c, kernel_size=3, stride=2, padding=1), nn.ReLU()]
            c_in = c
        side = _conv_out(bev_size, len(channels))
        self.cnn = nn.Sequential(*convs, nn.Flatten(), nn.Linear(c_in * side * side, embed_dim), nn.ReLU())
        self.n_commands = check_int("n_commands", n_commands, minimum=0)
        self.state_mlp = nn.Sequential(
            nn.Linear(3 + self.n_commands, embed_dim), nn.ReLU(), nn.Linear(embed_dim, embed_dim), nn.ReLU()
        )
        self.branch_dim = embed_dim
        self.embed_dim = 2 * embed_dim
        if not isinstance(command_branches, bool):
            raise ValueError(f"command_branches must be True or False, got {command_branches!r}")
        if command_branches and not self.n_commands:
            raise ValueError("command_branches needs n_commands > 0: a routeless encoder has no command")
        self.command_branches = command_branches
        # CIL's branches: one (2E -> 2E) layer per command, on the joint embedding (empty when not taken)
        self.branches = nn.ModuleList(
            [
                nn.Linear(self.embed_dim, self.embed_dim)
                for _ in range(self.n_commands if command_branches else 0)
            ]
        )

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
        scale = torch.tensor(
            [1.0 / SPEED_SCALE, 1.0, 1.0], device=state.device
        )  # (3,), on the state's device
        st = state.float() * scale  # (B, 3), speed rescaled
        if self.n_commands:
            if "command" not in obs:
                raise ValueError(
                    f"obs must hold 'command' ((B,) indices of {self.n_commands} commands): this encoder "
                    "takes a route command"
                )
            cmd = obs["command"]
            check_tensor("obs['command']", cmd, shape=(len(bev),))
            if cmd.is_floating_point() or (len(cmd) and (cmd.min() < 0 or cmd.max() >= self.n_commands)):
                raise ValueError(f"obs['command'] must hold integer indices in [0, {self.n_commands})")
            one_hot = nn.functional.one_hot(cmd.long(), self.n_commands).to(st.dtype)  # (B, C)
            st = torch.cat([st, one_hot], dim=1)  # (B, 3 + C)
        elif "command" in obs:
            raise ValueError(
                "obs holds a 'command', but this encoder is routeless (n_commands=0): it takes none"
            )
        z = torch.cat([self.cnn(x), self.state_mlp(st)], dim=1)  # (B, 2 E)
        if self.command_branches:
            every = torch.stack([torch.relu(b(z)) for b in self.branches], dim=1)  # (B, C, 2 E)
            z = every[torch.arange(len(z), device=z.device), obs["command"].long()]  # (B, 2 E): z_c
        return z


def to_tensor_obs(obs, device: torch.device | str | None = None) -> dict[str, torch.Tensor]:
    """A numpy or torch ``{"bev", "state"[, "command"]}`` batch (``BEVStateEncoder``'s input) as torch
    tensors (the BEV's dtype kept, the state float32, the command int64), moved to ``device`` if given."""
    bev, state = obs["bev"], obs["state"]
    bev = torch.from_numpy(np.ascontiguousarray(bev)) if isinstance(bev, np.ndarray) else bev
    state = (
        torch.from_numpy(np.asarray(state, dtype=np.float32))
        if isinstance(state, np.ndarray)
        else state.float()
    )
    out = {"bev": bev, "state": state}
    if "command" in obs:
        cmd = obs["command"]
        out["command"] = torch.as_tensor(cmd if isinstance(cmd, torch.Tensor) else np.asarray(cmd)).long()
    if device is not None:
        out = {k: v.to(device) for k, v in out.items()}
    return out
