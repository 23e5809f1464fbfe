"""Counter-example samplers for InfoNCE training of energy models.

InfoNCE (eqs. 2-3 of the DA-IBC paper) estimates the normalising constant Z(x) from a set of
counter-examples ỹ_i^1..ỹ_i^N per observation. Where they come from decides where the model
learns to raise the energy:

- ``uniform_negatives``: uniform over the action box [y_min, y_max], as in the original IBC
  (Florence et al. 2022; sec. 2.4 of the DA-IBC paper: ỹ ~ U(y_min, y_max)).
- ``expert_negatives``: DA-IBC (sec. 2.4 of the DA-IBC paper): expert actions drawn with
  replacement, plus Gaussian noise N(0, σ²I).

Both are also available as *samplers*, callables ``sampler(actions, n_neg, generator)`` that
``objectives.info_nce_objective`` calls once per minibatch with that minibatch's expert actions.

**Clipping expert negatives (the paper does not say).** ``expert_negatives`` does not clip by
default. Clipping y + ε to the bounds would put a point mass of counter-examples exactly on the
bounds, where the expert itself often acts (full brake, full steering lock): counter-examples
identical to expert actions cannot be told apart from them and only flatten the landscape
there. Unclipped counter-examples that fall outside the box cost nothing but the share of the
budget they use (for σ = 0.1 and actions at most 0.8 from the edge, well under 1 %); they shape
the energy just beyond the bounds, where no optimiser looks. Pass ``low`` and ``high`` to clip
anyway (e.g. to compare).

**The samplers' densities (for ranking NCE).** ``losses.ranking_nce`` subtracts log q(y | x) of the
counter-examples' proposal from each logit. Both samplers give it exactly (``log_prob``):
``UniformSampler``'s is the constant −log vol(box) inside the box, so ranking NCE with it equals
InfoNCE. ``ExpertSampler``'s is the Gaussian mixture (1/M) Σ_m N(y; a_m, σ² I) centred on the
minibatch's M expert actions a_m, which is what it draws from when it does not clip (the default).
When it clips, its law piles the mass that falls outside onto the box's faces: a point mass per
face (per dimension). ``log_prob`` then returns the density of that law with respect to the
measure it lives on (Lebesgue inside, counting on a face): a coordinate on a face scores
log Φ((low − a)/σ) (or log Φ((a − high)/σ)), the mass the clip moved there. Nothing in the
sampler is changed. This is exact for the sampler, but ranking NCE's argument (the posterior of
"which candidate came from p") assumes p and q have densities with respect to the same measure,
and p ∝ exp(−E) has no atom on the faces: the logits of clipped counter-examples compare a
probability with a density, an approximation confined to the share of counter-examples on the
faces, which ``ExpertSampler.boundary_mass`` computes exactly (for the junction world's expert actions
and σ = 0.1 it is 0.5 %, measured in tests/test_ranking_nce.py; clipping is off by default anyway).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import torch

from ibc_tutorial.utils import check_box, check_int, check_positive, check_tensor, draw_device


def uniform_negatives(
    batch_size: int,
    n_neg: int,
    low: float | Sequence[float] | torch.Tensor,
    high: float | Sequence[float] | torch.Tensor,
    generator: torch.Generator | None = None,
    *,
    device: torch.device | str | None = None,
) -> torch.Tensor:
    """Counter-examples uniform in the box [low, high]: the original IBC's sampler.

    ỹ_i^j ~ U(y_min, y_max), independently for every sample i and counter-example j.

    Args:
        batch_size: B.
        n_neg: N, counter-examples per sample.
        low, high: the action bounds y_min, y_max, each of length D.
        generator: a seeded ``torch.Generator`` (None = torch's global one).
        device: where the result goes (default: the generator's, the CPU). The draws are made on
            the generator's device (``utils.draw_device``) and moved: the same numbers on every device.
    Returns:
        (B, N, D) in torch's default dtype, on ``device``.
    """
    b = check_int("batch_size", batch_size, minimum=1)
    n = check_int("n_neg", n_neg, minimum=1)
    lo, hi = check_box(low, high)
    u = torch.rand(b, n, len(lo), generator=generator, device=draw_device(generator))  # (B, N, D) in [0, 1)
    device = u.device if device is None else torch.device(device)
    return lo.to(device) + (hi - lo).to(device) * u.to(device)  # (B, N, D)


def expert_negatives(
    expert_actions: torch.Tensor,
    batch_size: int,
    n_neg: int,
    sigma: float,
    generator: torch.Generator | None = None,
    *,
    low: float | Sequence[float] | torch.Tensor | None = None,
    high: float | Sequence[float] | torch.Tensor | None = None,
) -> torch.Tensor:
    """DA-IBC counter-examples: expert actions drawn with replacement, plus N(0, σ²I) noise.

    Sec. 2.4 of the DA-IBC paper: for each sample i of the batch, N actions are drawn with
    replacement from ``expert_actions`` (in the paper, and in ``ExpertSampler``, the actions of
    the current minibatch: its footnote 1) and each is perturbed with Gaussian noise of
    standard deviation σ in every dimension. The draws are independent of the observation x_i
    and independent between samples.

    Statistics: each counter-example has the mean of the expert set and per-dimension variance
    Var(expert set) + σ² (the set's variance with divisor M) when not clipped.

    Clipping: none by default (see the module's docstring for why); with ``low`` and ``high``
    given, each counter-example is clipped to [low, high] after adding the noise.

    Args:
        expert_actions: (M, D) expert actions to draw from.
        batch_size: B.
        n_neg: N, counter-examples per sample.
        sigma: σ >= 0, standard deviation of the noise (σ = 0: exact copies of expert actions).
        generator: a seeded ``torch.Generator`` (None = torch's global one).
        low, high: optional bounds to clip to (both or neither).
    Returns:
        (B, N, D) in torch's default dtype, on ``expert_actions``' device (the draws are made on the
        generator's device, ``utils.draw_device``, and moved: the same numbers on every device).
    """
    check_tensor("expert_actions", expert_actions, ndim=2)
    m, d = expert_actions.shape
    if m == 0:
        raise ValueError("expert_actions must hold at least one action, got shape (0, D)")
    b = check_int("batch_size", batch_size, minimum=1)
    n = check_int("n_neg", n_neg, minimum=1)
    sigma = check_positive("sigma", sigma, allow_zero=True)
    if (low is None) != (high is None):
        raise ValueError("low and high must be given together (to clip) or both left None (no clipping)")
    device, where = expert_actions.device, draw_device(generator)
    idx = torch.randint(0, m, (b, n), generator=generator, device=where)  # (B, N): with replacement
    neg = expert_actions.to(torch.get_default_dtype())[idx.to(device)]  # (B, N, D)
    if sigma > 0:
        neg = neg + sigma * torch.randn(b, n, d, generator=generator, device=where).to(device)  # + N(0, σ²I)
    if low is not None:
        lo, hi = check_box(low, high, d)  # (D,), (D,)
        neg = torch.clamp(neg, lo.to(device), hi.to(device))  # (B, N, D), per-dimension bounds (D,)
    return neg  # (B, N, D)


# --------------------------------------------------------------------------- samplers
@runtime_checkable
class NegativeSampler(Protocol):
    """What the training objective (``objectives.info_nce_objective``) calls once per minibatch:
    ``UniformSampler``, ``ExpertSampler``, or any callable of this form."""

    def __call__(
        self, actions: torch.Tensor, n_neg: int, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """``actions`` (B, D), the minibatch's expert actions -> counter-examples (B, N, D)."""
        ...


class UniformSampler:
    """IBC: counter-examples uniform in [low, high], whatever the minibatch holds."""

    def __init__(self, low: float | Sequence[float] = -1.0, high: float | Sequence[float] = 1.0):
        self.low, self.high = check_box(low, high)

    def __call__(
        self, actions: torch.Tensor, n_neg: int, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        check_tensor("actions", actions, ndim=2)
        low, high = self.low, self.high
        if len(low) == 1 and actions.shape[1] > 1:
            low, high = low.expand(actions.shape[1]), high.expand(actions.shape[1])
        if len(low) != actions.shape[1]:
            raise ValueError(
                f"actions must have D = {len(low)} columns to match the bounds, got shape "
                f"{tuple(actions.shape)}"
            )
        return uniform_negatives(len(actions), n_neg, low, high, generator, device=actions.device)

    def log_prob(self, candidates: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """log q(y) of this sampler at ``candidates`` (B, K, D): −Σ_d log(high_d − low_d) inside the box,
        −inf outside, (B, K). ``actions`` (B, D) (the minibatch's expert actions) only fixes B and D:
        the uniform proposal ignores them."""
        check_tensor("actions", actions, ndim=2)
        b, d = actions.shape
        check_tensor("candidates", candidates, shape=(b, None, d))
        low, high = check_box(self.low, self.high, d)  # (D,), (D,)
        low, high = low.to(candidates), high.to(candidates)
        inside = ((candidates >= low) & (candidates <= high)).all(dim=-1)  # (B, K)
        log_vol = torch.log(high - low).sum()  # log vol(box)
        return torch.where(inside, -log_vol, torch.full_like(log_vol, -math.inf))  # (B, K)

    def __repr__(self) -> str:
        return f"UniformSampler(low={self.low.tolist()}, high={self.high.tolist()})"


class ExpertSampler:
    """DA-IBC: counter-examples drawn from the minibatch's expert actions plus N(0, σ²I)."""

    def __init__(
        self,
        sigma: float,
        low: float | Sequence[float] | None = None,
        high: float | Sequence[float] | None = None,
    ):
        self.sigma = check_positive("sigma", sigma, allow_zero=True)
        if (low is None) != (high is None):
            raise ValueError("low and high must be given together (to clip) or both left None (no clipping)")
        self.low, self.high = low, high

    def __call__(
        self, actions: torch.Tensor, n_neg: int, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        return expert_negatives(
            actions, len(actions), n_neg, self.sigma, generator, low=self.low, high=self.high
        )

    def log_prob(self, candidates: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """log q(y) of the law this sampler draws from, given the minibatch's expert ``actions`` (M, D):
        (B, K) at ``candidates`` (B, K, D) (B = M: the sampler draws B × N from one minibatch of B).

        Unclipped (the default): the Gaussian mixture q(y) = (1/M) Σ_m N(y; a_m, σ² I), exactly. Clipped
        (``low``/``high`` given): per dimension, the Gaussian density strictly inside the box, and on a face
        the log of the mass the clip moves there, log Φ((low − a)/σ) or log Φ((a − high)/σ) (see the module
        docstring: exact for the sampler, an approximation for ranking NCE on the faces); −inf outside the
        box. Needs σ > 0. Computed without gradients (q does not depend on the model).

        q is the law *given the minibatch*: the same for every sample of it (DA-IBC's counter-examples do
        not depend on x), and the expert action y_i is itself one of its M centres, so ranking NCE sees
        q(y_i) ≥ N(0; 0, σ² I) / M at the expert's action.
        """
        if self.sigma == 0:
            raise ValueError("sigma must be > 0 for log_prob: with sigma = 0 the proposal has no density")
        check_tensor("actions", actions, ndim=2)
        m, d = actions.shape
        check_tensor("candidates", candidates, shape=(m, None, d))
        if m == 0:
            raise ValueError("actions must hold at least one action, got shape (0, D)")
        s = self.sigma
        a = actions.to(candidates)  # (M, D)
        with torch.no_grad():
            log_comp = torch.zeros(*candidates.shape[:2], m, dtype=candidates.dtype, device=candidates.device)
            if self.low is not None:
                lo, hi = check_box(self.low, self.high, d)
                lo, hi = lo.to(candidates), hi.to(candidates)  # (D,), (D,)
            for k in range(d):  # (B, K, M) per dimension: D is small, and no (B, K, M, D) temporary
                y, mu = candidates[:, :, k, None], a[None, None, :, k]  # (B, K, 1), (1, 1, M)
                term = -0.5 * ((y - mu) / s).square() - math.log(s) - 0.5 * math.log(2 * math.pi)  # (B, K, M)
                if self.low is not None:
                    at_lo = (y == lo[k]).expand_as(term)
                    at_hi = (y == hi[k]).expand_as(term)
                    term = torch.where(at_lo, torch.special.log_ndtr((lo[k] - mu) / s).expand_as(term), term)
                    term = torch.where(at_hi, torch.special.log_ndtr((mu - hi[k]) / s).expand_as(term), term)
                    out = ((y < lo[k]) | (y > hi[k])).expand_as(term)
                    term = term.masked_fill(out, -math.inf)
                log_comp = log_comp + term
            return torch.logsumexp(log_comp, dim=-1) - math.log(m)  # (B, K): log (1/M) Σ_m q_m(y)

    def boundary_mass(self, actions: torch.Tensor) -> float:
        """The share of counter-examples whose noise takes them out of the box [low, high] (and, when the
        sampler clips, onto its faces): 1 − (1/M) Σ_m Π_d [Φ((high_d − a_md)/σ) − Φ((low_d − a_md)/σ)],
        exactly, for the expert ``actions`` (M, D). The box is [low, high], or [-1, 1] when the sampler
        does not clip."""
        check_tensor("actions", actions, ndim=2)
        d = actions.shape[1]
        dtype = actions.dtype if actions.is_floating_point() else None
        lo, hi = check_box(
            -1.0 if self.low is None else self.low, 1.0 if self.high is None else self.high, d, dtype=dtype
        )
        if self.sigma == 0:
            inside = ((actions >= lo) & (actions <= hi)).all(dim=1).to(lo.dtype)
            return float(1.0 - inside.mean())
        a = actions.to(lo.dtype)
        p_in = torch.special.ndtr((hi - a) / self.sigma) - torch.special.ndtr((lo - a) / self.sigma)  # (M, D)
        return float(1.0 - p_in.prod(dim=1).mean())

    def __repr__(self) -> str:
        clip = "" if self.low is None else f", low={self.low}, high={self.high}"
        return f"ExpertSampler(sigma={self.sigma}{clip})"
