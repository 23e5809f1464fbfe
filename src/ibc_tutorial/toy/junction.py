"""The junction world: a 2-D action problem shaped like urban driving (chapters 04-06).

Small enough to train dozens of energy models on a laptop CPU in a minute, and with a known
expert density, so that a model's held-out NLL can be compared with the best achievable one.
There is no closed loop: ``sample`` draws observations of the road ahead and the expert's
action for each.

An observation x = (κ, j, r, v) describes the road ahead: its curvature κ, a T-junction ahead
(j = 1), a red light ahead (r = 1), and the speed v. The action is y = (steer, acceleration) in
[-1, 1]², **steer +1 turning right and -1 left** (the book's convention, as in the tree and
side-road worlds), negative acceleration braking (sec. 3.2 of the DA-IBC paper). κ is signed
like the steering: κ > 0 is a road that bends to the right. The expert, in three situations:

- *cruise* (most samples): steer = 0.8 κ with κ mostly near 0, acceleration 0.5 − 0.5 v
  (moderate): the expert's actions crowd into a small region of the action box;
- *junction* (rarer): turn left, go straight or turn right, one third each: **three valid
  actions for the same observation** (steer −0.7, 0 or +0.7; slower in the turns);
- *red light* (rarer): brake, the harder the faster: acceleration −0.5 − 0.45 v.

Every expert action carries Gaussian noise of standard deviation ``expert_noise`` per
dimension, so the expert's conditional density p(y|x) is a known mixture of Gaussians
(``log_density``). The experiment of chapter 04 around this world is in
``ibc_tutorial.experiments.counter_examples``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch

from ibc_tutorial.utils import (
    check_int,
    check_positive,
    check_positive_fields,
    check_probability,
    check_tensor,
)

SITUATIONS = ("cruise", "junction", "red light")
"""Names of the situations, indexed by ``JunctionWorld.sample(...)["situation"]``."""


@dataclass
class JunctionConfig:
    """The junction world's settings (actions in [-1, 1]², steer +1 = right)."""

    p_junction: float = 0.15
    """Share of observations with a T-junction ahead (three valid actions)."""
    p_red: float = 0.15
    """Share of observations with a red light ahead (braking)."""
    curvature_std: float = 0.2
    """Standard deviation of the road curvature κ while cruising (clipped to ±0.6)."""
    turn_steer: float = 0.7
    """|steer| of a turn at a junction: −turn_steer turns left, +turn_steer right."""
    turn_accel: float = 0.1
    """Acceleration while turning at a junction."""
    straight_accel: float = 0.35
    """Acceleration while going straight over a junction."""
    expert_noise: float = 0.02
    """Standard deviation of the expert's Gaussian noise on each action dimension (sharp modes)."""


class JunctionWorld:
    """Observations (κ, j, r, v) and expert actions (steer, acceleration); see the module docstring."""

    obs_dim = 4
    action_dim = 2
    mode_names = ("turn left", "go straight", "turn right")
    """The three valid actions at a junction: the columns of ``modes`` (steer −, 0, +)."""

    def __init__(self, config: JunctionConfig | None = None):
        config = JunctionConfig() if config is None else config
        check_positive_fields(config, ("expert_noise", "turn_steer"))
        check_positive_fields(config, ("curvature_std",), allow_zero=True)
        check_probability("config.p_junction", config.p_junction)
        check_probability("config.p_red", config.p_red)
        if not config.p_junction + config.p_red < 1:
            raise ValueError(
                f"config.p_junction + config.p_red must be < 1 (some cruising), got {config.p_junction} + "
                f"{config.p_red}"
            )
        self.config = config

    # ------------------------------------------------------------------ the expert
    def modes(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The expert's noise-free valid actions: obs (B, 4) -> modes (B, 3, 2) and valid (B, 3) bool.

        A cruise or red-light observation has one valid action (in column 0); a junction three
        (columns: turn left, go straight, turn right, as in ``mode_names``).
        """
        check_tensor("obs", obs, shape=(None, self.obs_dim))
        c = self.config
        kappa, junction, red, v = obs[:, 0], obs[:, 1] > 0.5, obs[:, 2] > 0.5, obs[:, 3]
        b = len(obs)
        steer = (0.8 * kappa)[:, None].repeat(1, 3)  # (B, 3)
        accel = (0.5 - 0.5 * v)[:, None].repeat(1, 3)
        accel = torch.where(red[:, None], (-0.5 - 0.45 * v)[:, None].expand(b, 3), accel)
        turn = torch.tensor([-c.turn_steer, 0.0, c.turn_steer])  # left, straight, right
        turn_acc = torch.tensor([c.turn_accel, c.straight_accel, c.turn_accel])
        steer = torch.where(junction[:, None], turn.expand(b, 3), steer)
        accel = torch.where(junction[:, None], turn_acc.expand(b, 3), accel)
        valid = torch.zeros(b, 3, dtype=torch.bool)
        valid[:, 0] = True
        valid[junction] = True
        return torch.stack([steer, accel], dim=-1), valid  # (B, 3, 2), (B, 3)

    def log_density(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """log p(y|x) of the expert (a mixture of Gaussians over its valid actions): (B,)."""
        check_tensor("actions", actions, shape=(len(obs), self.action_dim))
        s = self.config.expert_noise
        modes, valid = self.modes(obs)
        sq = (actions[:, None, :] - modes).square().sum(-1)  # (B, 3)
        log_n = -0.5 * sq / s**2 - math.log(2 * math.pi * s**2)  # (B, 3)
        log_w = torch.where(valid, -torch.log(valid.sum(1, keepdim=True).float()), torch.tensor(-math.inf))
        return torch.logsumexp(log_n + log_w, dim=1)

    def expert_energy(self, obs: torch.Tensor, floor: float = 0.0) -> Callable[[torch.Tensor], torch.Tensor]:
        """The expert's own density at one observation as an energy, E(y) = −log(p(y|x) + ``floor``)
        (chapter 06): ``obs`` (1, 4) -> a function (B, N, 2) -> (B, N).

        With ``floor`` = 0 it is −``log_density``; a ``floor`` > 0 makes the landscape flat away from the
        valid actions, with narrow valleys at them: the hard case for DFO.
        """
        check_tensor("obs", obs, shape=(1, self.obs_dim))
        floor = check_positive("floor", floor, allow_zero=True)
        modes, valid = self.modes(obs)  # (1, 3, 2) the valid actions, (1, 3) which are valid
        s = self.config.expert_noise
        # (3,): equal shares of the valid actions, −inf for the others
        log_w = torch.log(valid[0].float() / valid.sum())

        def energy(y: torch.Tensor) -> torch.Tensor:
            sq = ((y[..., None, :] - modes[0]) ** 2).sum(-1)  # (B, N, 3)
            log_terms = log_w - sq / (2 * s**2) - math.log(2 * math.pi * s**2)  # (B, N, 3): the mixture
            if floor == 0:
                return -torch.logsumexp(log_terms, dim=-1)  # (B, N)
            return -torch.log(log_terms.exp().sum(-1) + floor)  # (B, N)

        return energy

    def hits(
        self, actions: torch.Tensor, obs: torch.Tensor, radius: float = 0.15
    ) -> tuple[float, torch.Tensor]:
        """Of ``actions`` (B, 2) taken at one observation ``obs`` (1, 4): the share within ``radius`` of a
        valid action, and (3,) the share near each valid action (left, straight, right; chapter 06)."""
        check_tensor("actions", actions, shape=(None, self.action_dim))
        check_tensor("obs", obs, shape=(1, self.obs_dim))
        radius = check_positive("radius", radius)
        modes, valid = self.modes(obs)  # (1, 3, 2), (1, 3)
        d = (actions[:, None, :] - modes[0][None]).norm(dim=-1)  # (B, 3)
        d = d.masked_fill(~valid[0][None], math.inf)
        near = d.min(1).values < radius  # (B,)
        per_mode = torch.bincount(d.argmin(1)[near], minlength=3).float() / len(actions)  # (3,)
        return float(near.float().mean()), per_mode

    def sample(self, n: int, generator: torch.Generator) -> dict[str, torch.Tensor]:
        """n observations with expert actions: {obs (n, 4), actions (n, 2), situation (n,) int64}."""
        n = check_int("n", n, minimum=1)
        c = self.config
        u = torch.rand(n, generator=generator)
        situation = torch.zeros(n, dtype=torch.long)
        situation[u < c.p_junction + c.p_red] = 2
        situation[u < c.p_junction] = 1
        kappa = (c.curvature_std * torch.randn(n, generator=generator)).clamp(-0.6, 0.6)
        kappa = torch.where(situation == 1, torch.zeros(n), kappa)  # junctions on straight roads
        v = 0.2 + 0.7 * torch.rand(n, generator=generator)
        obs = torch.stack([kappa, (situation == 1).float(), (situation == 2).float(), v], dim=1)  # (n, 4)
        modes, valid = self.modes(obs)
        pick = torch.multinomial(valid.float(), 1, generator=generator)[:, 0]  # uniform over valid modes
        actions = modes[torch.arange(n), pick] + c.expert_noise * torch.randn(n, 2, generator=generator)
        return {"obs": obs, "actions": actions.clamp(-1.0, 1.0), "situation": situation}
