"""Gaussian kernel density estimation and inverse-density weights (section 2.5 of the DA-IBC paper).

The DA-IBC paper estimates how common each expert action is with a kernel density estimate
(its eq. 4) and uses the inverse of that density twice:

- in training, as the weight w_i = 1 / ĝ(y_i) of each sample in the InfoNCE loss (its eq. 5),
  which it applies *by sampling*: each minibatch is drawn with probabilities proportional to
  w_i, so that rare actions (turns, hard braking) are seen more often;
- in inference, to draw the initial samples of its derivative-free optimiser (Algorithm 1;
  see ``ibc_tutorial.inference.dfo``).

Functions:

- ``kde_density(query, data, bandwidth)``: eq. 4 with a Gaussian product kernel, normalised, in
  chunks so that tens of thousands of query and data points fit in memory.
- ``inverse_density_weights(actions, bandwidth)``: w_i ∝ 1 / ĝ(y_i), summing to 1.
- ``sampling_probs(actions, bandwidth, weighting)``: the minibatch probabilities that
  ``ibc_tutorial.training.train`` accepts as ``sample_probs`` (uniform or inverse-density).
- ``sample_indices(probs, batch_size, generator)``: draw one minibatch of indices with those
  probabilities, exactly as ``training.train`` does.
"""

from __future__ import annotations

import math

import torch

from ibc_tutorial.utils import check_choice, check_int, check_positive, check_tensor

DEFAULT_BANDWIDTH = 0.2
"""h = 0.2, the bandwidth the DA-IBC paper chose "through trial-and-error experimentation" (sec. 4.2)."""

_CHUNK_ELEMENTS = 1 << 22
"""Largest number of (query, data) pairs held at once by ``kde_density`` (about 32 MB in float64)."""


def kde_density(
    query: torch.Tensor,
    data: torch.Tensor,
    bandwidth: float = DEFAULT_BANDWIDTH,
    *,
    chunk_elements: int = _CHUNK_ELEMENTS,
) -> torch.Tensor:
    """Gaussian kernel density estimate ĝ at each query point: eq. 4 of the DA-IBC paper.

    ĝ(q) = 1 / (M h^D) · Σ_j Π_d K((q_d − x_jd) / h),   K(u) = exp(−u²/2) / √(2π),

    the paper's eq. 4 (written there for D = 1) with the product of one Gaussian kernel per
    action dimension, the usual multivariate form with the same bandwidth h on every axis.
    It integrates to 1 over R^D (not over the action box: mass near the bounds spills out).

    Args:
        query: (Q, D) points at which to evaluate the density.
        data: (M, D) the samples x_j (e.g. expert actions).
        bandwidth: h > 0, in the units of the data.
        chunk_elements: at most this many (query, data) pairs are processed at once, so Q and M
            in the tens of thousands need only a few tens of MB.

    Returns:
        (Q,) densities, in query's dtype (accumulated in float64).
    """
    check_tensor("query", query, ndim=2)
    check_tensor("data", data, ndim=2)
    if query.shape[1] != data.shape[1]:
        raise ValueError(f"query and data must have the same number of dimensions D, got query {tuple(query.shape)} and data {tuple(data.shape)}")
    if len(data) == 0:
        raise ValueError("data must hold at least one point, got shape " + str(tuple(data.shape)))
    h = check_positive("bandwidth", bandwidth)
    check_int("chunk_elements", chunk_elements, minimum=1)
    # Work in units of h, centred on the data's mean (keeps the squared distances below exact
    # enough in float64 even for data far from the origin).
    centre = data.detach().to(torch.float64).mean(dim=0)  # (D,)
    q_all = (query.detach().to(torch.float64) - centre) / h  # (Q, D)
    x_all = (data.detach().to(torch.float64) - centre) / h  # (M, D)
    n_q, d = q_all.shape
    m = len(x_all)
    q_sq = (q_all * q_all).sum(dim=1)  # (Q,) |q|²
    x_sq = (x_all * x_all).sum(dim=1)  # (M,) |x|²
    # Split the M data points into chunks, then the queries so that each block holds at most
    # chunk_elements (query, data) pairs.
    m_chunk = min(m, chunk_elements)
    q_chunk = max(1, chunk_elements // m_chunk)
    out = torch.zeros(n_q, dtype=torch.float64)
    for q0 in range(0, n_q, q_chunk):
        q = q_all[q0 : q0 + q_chunk]  # (Qc, D)
        for m0 in range(0, m, m_chunk):
            x = x_all[m0 : m0 + m_chunk]  # (Mc, D)
            # Σ_d u_d² = |q|² + |x|² − 2 q·x with u = (q − x_j) / h; clamp rounding below 0
            sq = torch.addmm(q_sq[q0 : q0 + q_chunk, None] + x_sq[None, m0 : m0 + m_chunk], q, x.T, alpha=-2.0)  # (Qc, Mc)
            # Π_d K(u_d) = (2π)^(−D/2) exp(−Σ_d u_d² / 2); the constant is applied once below
            out[q0 : q0 + q_chunk] += torch.exp_(sq.clamp_min_(0.0).mul_(-0.5)).sum(dim=1)
    norm = m * h**d * (2.0 * math.pi) ** (d / 2)  # 1 / (M h^D) and the kernels' (2π)^(−D/2)
    return (out / norm).to(query.dtype if query.is_floating_point() else torch.float32)


def inverse_density_weights(actions: torch.Tensor, bandwidth: float = DEFAULT_BANDWIDTH) -> torch.Tensor:
    """Weights w_i ∝ 1 / ĝ(y_i) of eq. 5 of the DA-IBC paper, normalised to sum to 1.

    ĝ is the KDE of eq. 4 over the same actions (each action counts itself, so ĝ(y_i) > 0).
    Rare actions get large weights, common ones small: drawn with these probabilities, a
    minibatch covers the actions roughly uniformly over the region where experts acted.

    Args:
        actions: (M, D) expert actions.
        bandwidth: the KDE bandwidth h.

    Returns:
        (M,) non-negative weights summing to 1 (float32 for float32 actions).
    """
    check_tensor("actions", actions, ndim=2)
    g = kde_density(actions, actions, bandwidth).to(torch.float64)  # (M,)
    w = 1.0 / g
    return (w / w.sum()).to(actions.dtype)


def sampling_probs(actions: torch.Tensor, bandwidth: float = DEFAULT_BANDWIDTH, weighting: str = "inverse-kde") -> torch.Tensor:
    """Minibatch probabilities for ``training.train(..., sample_probs=...)``: the paper's way of applying eq. 5.

    Args:
        actions: (M, D) expert actions of the training set.
        bandwidth: the KDE bandwidth h.
        weighting: "inverse-kde" (p_i ∝ 1 / ĝ(y_i), the DA-IBC paper) or "uniform" (p_i = 1 / M,
            plain minibatches; ``train`` does the same when given ``sample_probs=None``).

    Returns:
        (M,) probabilities summing to 1.
    """
    check_tensor("actions", actions, ndim=2)
    check_choice("weighting", weighting, ("inverse-kde", "uniform"))
    if weighting == "uniform":
        return torch.full((len(actions),), 1.0 / len(actions), dtype=actions.dtype)
    return inverse_density_weights(actions, bandwidth)


def sample_indices(probs: torch.Tensor, batch_size: int, *, generator: torch.Generator | None = None) -> torch.Tensor:
    """Draw one minibatch of sample indices with replacement, with the given probabilities.

    This is the draw ``training.train`` makes at every step when given ``sample_probs``
    (``torch.multinomial`` with replacement), so with the same generator state it returns the
    same indices; chapters use it to look at what weighted minibatches contain.

    Args:
        probs: (M,) non-negative probabilities (need not be normalised).
        batch_size: number of indices to draw.
        generator: a seeded ``torch.Generator`` (or None for torch's global one).

    Returns:
        (batch_size,) int64 indices into the M samples.
    """
    check_tensor("probs", probs, ndim=1)
    check_int("batch_size", batch_size, minimum=1)
    if (probs < 0).any() or probs.sum() <= 0:
        raise ValueError("probs must be non-negative with a positive sum")
    return torch.multinomial(probs, batch_size, replacement=True, generator=generator)
