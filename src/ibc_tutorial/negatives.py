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
"""

from __future__ import annotations

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

    def __repr__(self) -> str:
        clip = "" if self.low is None else f", low={self.low}, high={self.high}"
        return f"ExpertSampler(sigma={self.sigma}{clip})"
