"""Explicit policies: an observation goes in, an action (or a distribution over actions) comes out.

The four baselines of chapter 02, all heads on one ``ObservationEncoder`` (an MLP for the toy
worlds' vectors, a CNN over the bird's-eye view in the driving chapters):

- ``RegressionPolicy``: one action per observation, trained with MAE (the steering-EBM paper's
  regression baseline) or MSE.
- ``BetaPolicy``: (α, β) per action dimension, trained with the Beta NLL of eq. 1 of the DA-IBC
  paper (its BC baseline).
- ``ClassifierPolicy``: N bins per action dimension with cross-entropy (the steering-EBM
  paper's classification baseline; it used N = 512).
- ``MDNPolicy``: a mixture of K diagonal Gaussians (the steering-EBM paper's MDN, K from 1 to 5).

Common interface (``ExplicitPolicy``):

- ``forward(obs)``: the head's parameters (a tuple of tensors, documented per policy);
- ``loss(obs, actions) -> scalar``: the training loss on a minibatch;
- ``act(obs, mode=..., generator=None) -> (B, D)``: actions in [-1, 1] (no gradients); ``modes`` lists the
  names of the ways of acting, the first one is the default;
- ``action_density(obs, values) -> (B, G, D)``: the predicted density of each action
  dimension's marginal at the G action values ``values`` (per unit of action, so it integrates
  to 1 over [-1, 1] like a ``density=True`` histogram of the data); ``RegressionPolicy`` has
  none (``has_density`` is False);
- ``controller(mode, generator) -> callable``: ``obs -> actions`` without gradients, what the
  toy worlds' ``rollout`` calls.

Each class has a ``for_vectors(obs_dim, action_dim, ...)`` constructor with a small MLP encoder.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import nn
from torch.nn import functional as F

from ibc_tutorial.losses import beta_nll, bin_centers, classification_loss, mdn_nll, regression_loss
from ibc_tutorial.policies.encoders import MLPEncoder, ObservationEncoder
from ibc_tutorial.utils import check_choice, check_int, check_positive, check_tensor, draw_device


class ExplicitPolicy(nn.Module):
    """An encoder followed by a linear head with ``head_features`` outputs per observation."""

    modes: tuple[str, ...] = ()
    """Names accepted by ``act(mode=...)``; the first is the default."""
    has_density: bool = True
    """Whether ``action_density`` exists (False for a point prediction)."""

    def __init__(self, encoder: ObservationEncoder, action_dim: int, head_features: int):
        super().__init__()
        if not isinstance(encoder, ObservationEncoder):
            raise ValueError(f"encoder must be an ObservationEncoder, got {type(encoder).__name__}")
        self.encoder = encoder
        self.action_dim = check_int("action_dim", action_dim, minimum=1)
        self.head = nn.Linear(encoder.embed_dim, head_features)

    @classmethod
    def for_vectors(cls, obs_dim: int, action_dim: int = 1, *, hidden: int = 64, layers: int = 2, **kwargs):
        """The policy on an ``MLPEncoder`` of ``layers`` ReLU layers of width ``hidden``."""
        encoder = MLPEncoder(obs_dim, embed_dim=hidden, hidden=hidden, layers=layers)
        return cls(encoder, action_dim, **kwargs)

    def _features(self, obs) -> torch.Tensor:
        return self.head(self.encoder(obs))  # (B, head_features)

    def _check_actions(self, obs, actions: torch.Tensor) -> torch.Tensor:
        b = self.encoder.batch_size(obs)
        return check_tensor("actions", actions, shape=(b, self.action_dim))

    def _mode(self, mode: str | None) -> str:
        return self.modes[0] if mode is None else check_choice("mode", mode, self.modes)

    def loss(self, obs, actions: torch.Tensor) -> torch.Tensor:
        """Training loss on a minibatch: obs (B, ...) and expert actions (B, D) in [-1, 1]."""
        raise NotImplementedError

    @torch.no_grad()
    def act(self, obs, mode: str | None = None, generator: torch.Generator | None = None) -> torch.Tensor:
        """Actions (B, D) in [-1, 1], without gradients; ``mode`` is one of ``modes`` (default: the
        first); ``generator`` seeds the sampling modes."""
        return self._act(obs, self._mode(mode), generator)

    def _act(self, obs, mode: str, generator: torch.Generator | None) -> torch.Tensor:
        raise NotImplementedError

    def action_density(self, obs, values: torch.Tensor) -> torch.Tensor:
        """Predicted density (B, G, D) of each action dimension at ``values`` (G,) in [-1, 1]."""
        raise NotImplementedError(
            f"{type(self).__name__} predicts one action, not a distribution; plot act(obs) instead"
        )

    def controller(
        self, mode: str | None = None, generator: torch.Generator | None = None
    ) -> Callable[[torch.Tensor], torch.Tensor]:
        """The callable ``obs -> act(obs, mode, generator)`` that the toy worlds' rollouts call."""
        mode = self._mode(mode)

        def policy(obs):
            return self.act(obs, mode=mode, generator=generator)

        return policy

    @staticmethod
    def _check_values(values: torch.Tensor) -> torch.Tensor:
        check_tensor("values", values, ndim=1)
        if (values < -1).any() or (values > 1).any():
            raise ValueError("values must lie in [-1, 1]")
        return values


# --------------------------------------------------------------------------- regression
class RegressionPolicy(ExplicitPolicy):
    """One action per observation: ``tanh`` of a linear head, so it lies in (-1, 1).

    ``forward(obs)`` returns the (B, D) prediction. Trained with MAE (``loss_kind="mae"``, the
    steering-EBM paper's regression baseline; its minimiser is a conditional median) or MSE
    (the conditional mean). With two modes in the data either one lands between them.
    """

    modes = ("deterministic",)
    has_density = False

    def __init__(self, encoder: ObservationEncoder, action_dim: int = 1, *, loss_kind: str = "mae"):
        super().__init__(encoder, action_dim, action_dim)
        self.loss_kind = check_choice("loss_kind", loss_kind, ("mae", "mse"))

    def forward(self, obs) -> torch.Tensor:
        return torch.tanh(self._features(obs))  # (B, D)

    def loss(self, obs, actions):
        self._check_actions(obs, actions)
        return regression_loss(self(obs), actions, self.loss_kind)

    def _act(self, obs, mode, generator):
        return self(obs)


# --------------------------------------------------------------------------- Beta
class BetaPolicy(ExplicitPolicy):
    """A Beta distribution per action dimension: the DA-IBC paper's BC baseline (eq. 1).

    ``forward(obs)`` returns ``(alpha, beta)``, each (B, D). The head's outputs u pass through
    ``min_concentration + softplus(u)``. The default ``min_concentration = 1`` keeps α, β ≥ 1,
    the choice of the Beta policy of Chou et al. (2017, "Improving stochastic policy gradients in
    continuous control with deep reinforcement learning using the Beta distribution"): the density
    is then bounded and single-peaked, so "mode" exists and the loss cannot be driven down by
    piling density onto the bounds. ``min_concentration = 0`` lets the head become U-shaped
    (α, β < 1: density piled at both bounds); chapter 02 fits such a free Beta to the tree data
    and shows that it still puts no peak at the experts' two actions.

    Acting: "mean" (α / (α + β), rescaled); "mode", the peak of the density: (α − 1)/(α + β − 2)
    when α, β > 1, otherwise the bound on the side of the smaller concentration (where the
    density is largest; the mean when α = β ≤ 1, e.g. the flat α = β = 1); or "sample" (a
    draw of ``torch.distributions.Beta``, seeded by ``generator``).
    """

    modes = ("mean", "mode", "sample")

    def __init__(
        self,
        encoder: ObservationEncoder,
        action_dim: int = 1,
        *,
        min_concentration: float = 1.0,
        eps: float = 1e-3,
    ):
        super().__init__(encoder, action_dim, 2 * action_dim)
        self.min_concentration = check_positive("min_concentration", min_concentration, allow_zero=True)
        self.eps = check_positive("eps", eps)  # added so that α, β > 0 even when min_concentration = 0

    def forward(self, obs) -> tuple[torch.Tensor, torch.Tensor]:
        u = self._features(obs).view(-1, 2, self.action_dim)  # (B, 2, D)
        conc = self.min_concentration + F.softplus(u) + self.eps
        return conc[:, 0], conc[:, 1]  # alpha (B, D), beta (B, D)

    def loss(self, obs, actions):
        self._check_actions(obs, actions)
        alpha, beta = self(obs)
        return beta_nll(alpha, beta, actions)

    def _act(self, obs, mode, generator):
        alpha, beta = self(obs)  # (B, D)
        if mode == "mean":
            z = alpha / (alpha + beta)
        elif mode == "mode":
            denom = alpha + beta - 2.0
            interior = (alpha - 1.0) / denom.clamp_min(1e-12)
            z = torch.where(
                (alpha > 1) & (beta > 1),
                interior,
                torch.where(
                    alpha > beta,
                    torch.ones_like(alpha),
                    torch.where(beta > alpha, torch.zeros_like(alpha), alpha / (alpha + beta)),
                ),
            )
        else:
            z = _sample_beta(alpha, beta, generator)
        return (2.0 * z - 1.0).clamp(-1.0, 1.0)

    def action_density(self, obs, values):
        self._check_values(values)
        alpha, beta = self(obs)  # (B, D)
        z = ((values + 1.0) / 2.0).clamp(1e-6, 1.0 - 1e-6)[None, :, None]  # (1, G, 1)
        dist = torch.distributions.Beta(alpha[:, None, :], beta[:, None, :])
        return dist.log_prob(z).exp() / 2.0  # (B, G, D): density of y = 2 y' - 1


def _sample_beta(alpha: torch.Tensor, beta: torch.Tensor, generator: torch.Generator | None) -> torch.Tensor:
    """Draws (B, D) of Beta(α, β) in [0, 1] by ``torch.distributions.Beta``, seeded by ``generator``.

    ``Beta.sample`` takes no generator and draws from torch's global one, so with a
    ``generator`` it runs under ``torch.random.fork_rng`` with the global generator seeded from
    one draw of ``generator``: reproducible, and the global random state is left as it was.
    Without one, it draws from the global generator. The draws are made on the CPU (where
    ``fork_rng(devices=[])`` applies) and returned on α's device."""
    dist = torch.distributions.Beta(alpha.cpu(), beta.cpu())
    if generator is None:
        return dist.sample().to(alpha.device)
    seed = int(torch.randint(0, 2**62, (), generator=generator, device=draw_device(generator)))
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return dist.sample().to(alpha.device)


# --------------------------------------------------------------------------- classifier
class ClassifierPolicy(ExplicitPolicy):
    """A categorical distribution over ``n_bins`` equal bins of [-1, 1] per action dimension.

    The steering-EBM paper's classification baseline (it used 512 bins for steering), trained
    with cross-entropy (``losses.classification_loss``). ``forward(obs)`` returns the logits
    (B, D, N). With D > 1 the dimensions are classified independently (a joint grid of 512²
    classes would be far too large), so each marginal can hold several modes but correlations
    between dimensions are not modelled. Acting: "argmax" (centre of the most probable bin) or
    "sample" (centre of a sampled bin).
    """

    modes = ("argmax", "sample")

    def __init__(self, encoder: ObservationEncoder, action_dim: int = 1, *, n_bins: int = 512):
        self.n_bins = check_int("n_bins", n_bins, minimum=2)
        super().__init__(encoder, action_dim, action_dim * n_bins)
        self.register_buffer("centers", bin_centers(n_bins), persistent=False)

    def forward(self, obs) -> torch.Tensor:
        return self._features(obs).view(-1, self.action_dim, self.n_bins)  # (B, D, N)

    def loss(self, obs, actions):
        self._check_actions(obs, actions)
        return classification_loss(self(obs), actions)

    def _act(self, obs, mode, generator):
        logits = self(obs)  # (B, D, N)
        if mode == "argmax":
            idx = logits.argmax(dim=-1)  # (B, D)
        else:
            probs = (
                torch.softmax(logits, dim=-1).reshape(-1, self.n_bins).to(draw_device(generator))
            )  # (B*D, N)
            idx = torch.multinomial(probs, 1, generator=generator).view(logits.shape[:2]).to(logits.device)
        return self.centers[idx]  # (B, D)

    def action_density(self, obs, values):
        self._check_values(values)
        probs = torch.softmax(self(obs), dim=-1)  # (B, D, N)
        idx = torch.floor((values + 1.0) / 2.0 * self.n_bins).long().clamp(0, self.n_bins - 1)  # (G,)
        width = 2.0 / self.n_bins
        return probs[:, :, idx].transpose(1, 2) / width  # (B, G, D)


# --------------------------------------------------------------------------- MDN
class MDNPolicy(ExplicitPolicy):
    """A mixture density network (Bishop 1994): K diagonal Gaussians over the D action dimensions.

    The steering-EBM paper's MDN baseline (1 to 5 components). ``forward(obs)`` returns
    ``(logits (B, K), means (B, K, D), stds (B, K, D))``; stds = softplus(·) + ``min_std``.
    Acting: "paper" (the mean of the most likely component, as the paper deploys it) or
    "sample" (a draw from the mixture). The Gaussians have unbounded support, so both are
    clipped to [-1, 1], as a car's actuators saturate; ``action_density`` is the unclipped
    mixture density.
    """

    modes = ("paper", "sample")

    def __init__(
        self,
        encoder: ObservationEncoder,
        action_dim: int = 1,
        *,
        n_components: int = 5,
        min_std: float = 1e-3,
    ):
        self.n_components = check_int("n_components", n_components, minimum=1)
        super().__init__(encoder, action_dim, n_components * (1 + 2 * action_dim))
        self.min_std = check_positive("min_std", min_std)

    def forward(self, obs):
        h = self._features(obs)  # (B, K (1 + 2 D))
        k, d = self.n_components, self.action_dim
        logits = h[:, :k]  # (B, K)
        means = h[:, k : k + k * d].reshape(-1, k, d)  # (B, K, D)
        stds = F.softplus(h[:, k + k * d :].reshape(-1, k, d)) + self.min_std  # (B, K, D)
        return logits, means, stds

    def loss(self, obs, actions):
        self._check_actions(obs, actions)
        return mdn_nll(*self(obs), actions)

    def _act(self, obs, mode, generator):
        logits, means, stds = self(obs)
        if mode == "paper":
            comp = logits.argmax(dim=1)  # (B,)
            y = means[torch.arange(len(comp), device=comp.device), comp]  # (B, D)
        else:
            where = draw_device(generator)  # drawn where the generator is, used on the means' device
            comp = torch.multinomial(torch.softmax(logits, dim=1).to(where), 1, generator=generator).squeeze(
                1
            )  # (B,)
            comp = comp.to(means.device)
            rows = torch.arange(len(comp), device=means.device)
            noise = torch.randn(means.shape[0], means.shape[2], generator=generator, device=where)  # (B, D)
            noise = noise.to(means.device)
            y = means[rows, comp] + stds[rows, comp] * noise
        return y.clamp(-1.0, 1.0)

    def action_density(self, obs, values):
        self._check_values(values)
        logits, means, stds = self(obs)  # (B, K), (B, K, D), (B, K, D)
        log_w = torch.log_softmax(logits, dim=1)[:, None, :, None]  # (B, 1, K, 1)
        normal = torch.distributions.Normal(means[:, None], stds[:, None])  # (B, 1, K, D)
        log_p = normal.log_prob(values[None, :, None, None]) + log_w  # (B, G, K, D)
        return torch.logsumexp(log_p, dim=2).exp()  # (B, G, D)
