"""A flow-matching policy: actions drawn by integrating a learned velocity field from noise.

Beside the energy models (which score actions and need a search to act) and the explicit
policies (which output a distribution in closed form), a third family learns to *transport*
noise onto the expert's actions. A velocity head v_θ(x, y_t, t) is trained by regression on
straight paths from a noise sample y_0 to the expert action y_1 (conditional flow matching,
Lipman et al. 2023, "Flow Matching for Generative Modeling"; rectified flow, Liu et al. 2023,
"Flow Straight and Fast"):

    y_t = (1 − t) y_0 + t y_1,   target velocity u = y_1 − y_0,   t ~ U(0, 1)
    L = E_{t, y_0, (x, y_1)} ‖v_θ(x, y_t, t) − (y_1 − y_0)‖²

the optimal-transport conditional path of Lipman et al. (their eqs. 20-22, ψ_t(y_0) =
(1 − (1 − σ_min) t) y_0 + t y_1) with σ_min = 0, and its conditional flow-matching loss (their
eq. 23); the same objective is rectified flow's (Liu et al., eq. 1). The minimiser is the
*marginal* velocity E[y_1 − y_0 | y_t, x], whose flow carries the noise distribution onto
p(y | x) at t = 1, modes and their masses included: nothing averages the modes away, as
regression does.

Acting integrates dy/dt = v_θ(x, y, t) from t = 0 to 1 with K Euler steps (``FlowConfig.n_steps``),
N samples per decision in one batch (``FlowConfig.n_samples``): ``sample`` returns all N
(for a histogram), ``act`` one of them (the first: the N are independent draws, so the first
is itself a draw from the model). Late fusion as in ``EnergyModel``: the observation is embedded
once per decision; each Euler step runs only the head, on all N samples at once. A decision
costs one encoder pass and K × N head evaluations (``network_evaluations``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import nn

from ibc_tutorial.losses import flow_matching_loss
from ibc_tutorial.policies.encoders import MLPEncoder, ObservationEncoder
from ibc_tutorial.utils import check_box, check_choice, check_int, check_tensor, draw_device

NOISES = ("gaussian", "uniform")
"""The source distributions of ``FlowConfig.noise``."""


@dataclass(frozen=True)
class FlowConfig:
    """How a ``FlowPolicy`` trains and acts. Validated once, when built.

    **Noise: N(0, I) by default.** Both sources work with straight paths, and both end inside
    the box for the exact velocity field: an Euler step of size h ≤ 1 − t moves y towards
    E[y_1 | y_t] (v = (E[y_1 | y_t] − y_t) / (1 − t) for straight paths), and the last step lands
    on it. The Gaussian is the source the flow-matching papers analyse and use; its density is
    smooth and positive everywhere, so the marginal velocity field is smooth, which is what a
    few Euler steps of a small network need. Uniform noise on the box keeps every path y_t
    inside the box, but its density jumps at the faces, and the velocity field has kinks there.
    """

    n_steps: int = 10
    """K, the Euler steps from t = 0 to t = 1 at inference (each one head evaluation per sample)."""
    n_samples: int = 64
    """N, the samples drawn per decision in one batch (``sample``'s default; ``act`` returns the first)."""
    noise: str = "gaussian"
    """The source y_0: "gaussian" N(0, I) (the default, see above) or "uniform" on the action box."""
    train_draws: int = 8
    """(t, y_0) pairs per expert action and minibatch in the loss: late fusion makes the extra draws cheap
    (the observation is embedded once) and they lower the variance of the loss."""
    time_features: int = 4
    """F: t enters the head as [t, sin(π k t), cos(π k t) for k = 1..F] (2 F + 1 features)."""
    low: float | tuple[float, ...] = -1.0
    """Lower bound of the action box (a number, or one per action dimension): the clip at the end."""
    high: float | tuple[float, ...] = 1.0
    """Upper bound of the action box (a number, or one per action dimension)."""

    def __post_init__(self) -> None:
        check_int("n_steps", self.n_steps, minimum=1)
        check_int("n_samples", self.n_samples, minimum=1)
        check_choice("noise", self.noise, NOISES)
        check_int("train_draws", self.train_draws, minimum=1)
        check_int("time_features", self.time_features, minimum=0)
        check_box(self.low, self.high)


def network_evaluations(n_samples: int, n_steps: int) -> dict[str, int]:
    """What one decision of a ``FlowPolicy`` costs per observation: one encoder pass, K × N head passes."""
    n = check_int("n_samples", n_samples, minimum=1)
    k = check_int("n_steps", n_steps, minimum=1)
    return {"encoder": 1, "head": n * k}


class FlowPolicy(nn.Module):
    """A velocity field v_θ(x, y_t, t) on an observation encoder; acts by K Euler steps from noise.

    Args:
        encoder: an ``ObservationEncoder`` (``MLPEncoder`` for the toys, ``BEVStateEncoder`` in the town).
        action_dim: D.
        hidden: width of the head's hidden layers.
        layers: hidden layers of the head (>= 1); the first is the fused layer.
        config: a ``FlowConfig`` (its defaults if None).

    The head's first layer is the linear map of [z; y_t; φ(t)] computed factorised as in
    ``EnergyModel``: W_z z + b once per observation, W_a y_t and W_t φ(t) per sample, then
    ReLU layers and a linear output of size D. ``forward(obs, y_t, t)`` is ``velocity``.
    """

    def __init__(
        self,
        encoder: ObservationEncoder,
        action_dim: int,
        hidden: int = 64,
        layers: int = 2,
        config: FlowConfig | None = None,
    ):
        super().__init__()
        if not isinstance(encoder, nn.Module) or not hasattr(encoder, "embed_dim"):
            raise ValueError(
                f"encoder must be an ObservationEncoder (an nn.Module with embed_dim), got "
                f"{type(encoder).__name__}"
            )
        self.config = FlowConfig() if config is None else config
        if not isinstance(self.config, FlowConfig):
            raise ValueError(f"config must be a FlowConfig, got {type(self.config).__name__}")
        self.encoder = encoder
        self.action_dim = check_int("action_dim", action_dim, minimum=1)
        self.hidden = check_int("hidden", hidden, minimum=1)
        self.layers = check_int("layers", layers, minimum=1)
        self.embed_dim = int(encoder.embed_dim)
        self.low, self.high = check_box(self.config.low, self.config.high, self.action_dim)  # (D,), (D,)
        n_time = 2 * self.config.time_features + 1
        self.obs_proj = nn.Linear(self.embed_dim, hidden)  # W_z z + b, once per observation
        self.act_proj = nn.Linear(self.action_dim, hidden, bias=False)  # W_a y_t, per sample
        self.time_proj = nn.Linear(n_time, hidden, bias=False)  # W_t φ(t), per time
        mods: list[nn.Module] = []
        for _ in range(layers - 1):
            mods += [nn.Linear(hidden, hidden), nn.ReLU()]
        mods.append(nn.Linear(hidden, self.action_dim))
        self.head = nn.Sequential(*mods)  # (..., H) -> (..., D)

    @classmethod
    def for_vectors(
        cls, obs_dim: int, action_dim: int = 1, *, hidden: int = 64, layers: int = 2, **kwargs
    ) -> FlowPolicy:
        """The policy on an ``MLPEncoder`` of two ReLU layers of width ``hidden`` (the toy worlds)."""
        encoder = MLPEncoder(obs_dim, embed_dim=hidden, hidden=hidden, layers=2)
        return cls(encoder, action_dim, hidden=hidden, layers=layers, **kwargs)

    # ------------------------------------------------------------------ the velocity field
    def embed(self, obs) -> torch.Tensor:
        """Encode observations once: obs of batch B -> z (B, E)."""
        return self.encoder(obs)

    def time_embedding(self, t: torch.Tensor) -> torch.Tensor:
        """φ(t) = [t, sin(π k t), cos(π k t) for k = 1..F]: t (...,) -> (..., 2 F + 1)."""
        k = torch.arange(1, self.config.time_features + 1, dtype=t.dtype, device=t.device)  # (F,)
        angle = math.pi * t[..., None] * k  # (..., F)
        return torch.cat([t[..., None], torch.sin(angle), torch.cos(angle)], dim=-1)

    def velocity_from_embedding(self, z: torch.Tensor, y_t: torch.Tensor, t) -> torch.Tensor:
        """v_θ(x, y_t, t) against embeddings: z (B, E), y_t (B, N, D), t a number or (B, N) -> (B, N, D)."""
        if not isinstance(z, torch.Tensor) or z.ndim != 2 or z.shape[1] != self.embed_dim:
            got = tuple(z.shape) if isinstance(z, torch.Tensor) else type(z).__name__
            raise ValueError(f"z must be a tensor of shape (B, {self.embed_dim}), got {got}")
        b = len(z)
        check_tensor("y_t", y_t, shape=(b, None, self.action_dim))
        if isinstance(t, torch.Tensor):
            check_tensor("t", t, shape=tuple(y_t.shape[:2]))
            h_t = self.time_proj(self.time_embedding(t.to(y_t.dtype)))  # (B, N, H)
        else:
            t_ = torch.tensor(float(t), dtype=y_t.dtype, device=y_t.device)  # one time for all samples
            h_t = self.time_proj(self.time_embedding(t_))[None, None, :]  # (1, 1, H)
        h_obs = self.obs_proj(z)[:, None, :]  # (B, 1, H): W_z z + b, once per observation
        h = torch.relu(h_obs + h_t + y_t @ self.act_proj.weight.T)  # (B, N, H): W [z; y_t; φ(t)] + b
        return self.head(h)  # (B, N, D)

    def velocity(self, obs, y_t: torch.Tensor, t) -> torch.Tensor:
        """v_θ(x, y_t, t): obs of batch B, y_t (B, N, D), t a number or (B, N) -> (B, N, D)."""
        return self.velocity_from_embedding(self.embed(obs), y_t, t)

    def forward(self, obs, y_t: torch.Tensor, t) -> torch.Tensor:
        return self.velocity(obs, y_t, t)

    # ------------------------------------------------------------------ noise and training
    def draw_noise(
        self, b: int, n: int, generator: torch.Generator | None, like: torch.Tensor
    ) -> torch.Tensor:
        """y_0 (B, N, D) from ``config.noise``, drawn on the generator's device, returned in ``like``'s
        dtype and device."""
        shape, where = (b, n, self.action_dim), draw_device(generator)
        if self.config.noise == "gaussian":
            y0 = torch.randn(shape, generator=generator, device=where, dtype=like.dtype)  # N(0, I)
        else:
            u = torch.rand(shape, generator=generator, device=where, dtype=like.dtype)  # U[0, 1)
            y0 = self.low.to(where, like.dtype) + (self.high - self.low).to(where, like.dtype) * u
        return y0.to(like.device)

    def loss(self, obs, actions: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
        """The conditional flow-matching loss on a minibatch (eq. 23 of Lipman et al. 2023, σ_min = 0).

        Per expert action y_1 = ``actions[i]`` (B, D), ``config.train_draws`` pairs t ~ U(0, 1),
        y_0 ~ noise; y_t = (1 − t) y_0 + t y_1 and the target velocity y_1 − y_0 (the straight,
        optimal-transport conditional path); ``losses.flow_matching_loss`` averages the squared error.
        """
        z = self.embed(obs)  # (B, E), once per observation
        check_tensor("actions", actions, shape=(len(z), self.action_dim))
        b, m = len(z), self.config.train_draws
        y1 = actions.to(z.dtype)[:, None, :].expand(b, m, self.action_dim)  # (B, M, D)
        y0 = self.draw_noise(b, m, generator, z)  # (B, M, D)
        t = torch.rand(b, m, generator=generator, device=draw_device(generator), dtype=z.dtype).to(z.device)
        y_t = (1.0 - t[..., None]) * y0 + t[..., None] * y1  # (B, M, D): the straight path
        return flow_matching_loss(self.velocity_from_embedding(z, y_t, t), y0, y1)

    # ------------------------------------------------------------------ acting
    @torch.no_grad()
    def sample(
        self,
        obs,
        n_samples: int | None = None,
        n_steps: int | None = None,
        generator: torch.Generator | None = None,
    ) -> torch.Tensor:
        """N actions per observation by K Euler steps of dy/dt = v_θ(x, y, t) from noise: (B, N, D).

        y ← y + (1/K) v_θ(x, y, k/K) for k = 0..K−1, all N samples of all B observations in one
        batch, the observation embedded once. The samples are clipped to the action box **only at the
        end**: the steps in between are not clipped (the flow may pass outside the box on its way).
        Evaluated in eval mode (restored after), without gradients.

        Args:
            obs: a batch of B observations.
            n_samples: N (default ``config.n_samples``).
            n_steps: K (default ``config.n_steps``).
            generator: seeds the noise.
        """
        n = self.config.n_samples if n_samples is None else check_int("n_samples", n_samples, minimum=1)
        k = self.config.n_steps if n_steps is None else check_int("n_steps", n_steps, minimum=1)
        was_training = self.training
        self.eval()
        try:
            z = self.embed(obs)  # (B, E), once per decision
            y = self.draw_noise(len(z), n, generator, z)  # (B, N, D): y_0
            for step in range(k):
                y = y + self.velocity_from_embedding(z, y, step / k) / k  # Euler step, t = step / K
        finally:
            self.train(was_training)
        return torch.clamp(y, self.low.to(y), self.high.to(y))  # (B, N, D), the box only at the end

    @torch.no_grad()
    def act(self, obs, generator: torch.Generator | None = None, n_steps: int | None = None) -> torch.Tensor:
        """One action per observation, (B, D): the first of ``sample``'s N (a draw from the model).

        The N samples are independent, so the first is distributed as any of them. A closed loop that
        needs no histogram may set ``config.n_samples = 1``: the same distribution at 1/N of the cost.
        """
        return self.sample(obs, None, n_steps, generator)[:, 0]  # (B, D)

    def controller(
        self, generator: torch.Generator | None = None, n_steps: int | None = None
    ) -> Callable[[torch.Tensor], torch.Tensor]:
        """The callable ``obs -> act(obs, generator)`` that the toy worlds' rollouts call."""

        def policy(obs):
            return self.act(obs, generator=generator, n_steps=n_steps)

        return policy
