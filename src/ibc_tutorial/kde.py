"""Gaussian kernel density estimation and inverse-density weights (section 2.5 of the DA-IBC paper).

The DA-IBC paper estimates how common each expert action is with a kernel density estimate
(its eq. 4) and uses the inverse of that density twice:

- in training, as the weight w_i = 1 / ĝ(y_i) of each sample in the InfoNCE loss (its eq. 5),
  which it applies *by sampling*: each minibatch is drawn with probabilities proportional to
  w_i, so that rare actions (turns, hard braking) are seen more often (the training loop makes
  those draws);
- in inference, to draw the initial samples of its derivative-free optimiser (Algorithm 1;
  see ``ibc_tutorial.optimizers.dfo``).

This module is the only place the weights 1/ĝ are computed:

- ``kde_density(query, data, bandwidth)``: eq. 4 with a Gaussian product kernel, normalised, in
  chunks so that tens of thousands of query and data points fit in memory.
- ``inverse_density_weights(actions, bandwidth)``: w_i ∝ 1 / ĝ(y_i), summing to 1.
- Both take ``bounds=(low, high)``: the reflection-corrected ĝ, which does not lose the kernel
  mass past the edges of the action box (off by default, as the paper's eq. 4; see ``kde_density``).

**Numerical range.** Sums of kernels are taken in float64 and fall back to log space
(log-sum-exp over the kernels) wherever they would underflow, and the normalising constant
M h^D (2π)^(D/2) is handled in log space when it leaves float64's range. So a tiny or huge
bandwidth, or many dimensions, give finite correct densities, or a ValueError naming
``bandwidth`` when the densities themselves cannot be represented in the output's dtype.
"""

from __future__ import annotations

import math

import torch

from ibc_tutorial.utils import check_box, check_int, check_positive, check_tensor

DEFAULT_BANDWIDTH = 0.2
"""h = 0.2, the bandwidth the DA-IBC paper chose "through trial-and-error experimentation" (sec. 4.2)."""

_CHUNK_ELEMENTS = 1 << 22
"""Largest number of (query, data) pairs held at once by ``kde_density`` (about 32 MB in float64)."""


def _kernel_sums(q_all: torch.Tensor, x_all: torch.Tensor, chunk_elements: int) -> torch.Tensor:
    """s(q) = Σ_j exp(−|q − x_j|² / 2) for points in units of h: q_all (Q, D), x_all (M, D) -> (Q,) float64.

    The fast form: |q − x|² = |q|² + |x|² − 2 q·x as one matrix product per block. A row whose
    kernels all underflow comes out 0, and NaN when the coordinates are too large to square;
    ``_log_kernel_sums`` recomputes those rows.
    """
    n_q, m = len(q_all), len(x_all)
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
            sq = torch.addmm(
                q_sq[q0 : q0 + q_chunk, None] + x_sq[None, m0 : m0 + m_chunk], q, x.T, alpha=-2.0
            )  # (Qc, Mc)
            # Π_d K(u_d) = (2π)^(−D/2) exp(−Σ_d u_d² / 2); the constant is applied by the caller
            out[q0 : q0 + q_chunk] += torch.exp_(sq.clamp_min_(0.0).mul_(-0.5)).sum(dim=1)
    return out


def _log_kernel_sums(q: torch.Tensor, x: torch.Tensor, h: float, chunk_elements: int) -> torch.Tensor:
    """log Σ_j exp(−|q − x_j|² / (2h²)) for points in data units: q (Q, D), x (M, D) -> (Q,) float64.

    The safe form, for the rows the fast one cannot give: direct differences (an exact 0 for a
    point and itself), divided by h (inf when h is tiny: that kernel is 0), and log-sum-exp.
    """
    n_q, (m, d) = len(q), x.shape
    m_chunk = max(1, min(m, chunk_elements // max(1, d)))
    q_chunk = max(1, chunk_elements // (m_chunk * max(1, d)))
    out = torch.full((n_q,), -math.inf, dtype=torch.float64)
    for q0 in range(0, n_q, q_chunk):
        for m0 in range(0, m, m_chunk):
            u = (q[q0 : q0 + q_chunk, None, :] - x[None, m0 : m0 + m_chunk, :]) / h  # (Qc, Mc, D)
            log_k = -0.5 * (u * u).sum(dim=2)  # (Qc, Mc) log of the unnormalised product kernel
            out[q0 : q0 + q_chunk] = torch.logaddexp(out[q0 : q0 + q_chunk], torch.logsumexp(log_k, dim=1))
    return out


def _check_bounds(bounds, d: int) -> tuple[torch.Tensor, torch.Tensor] | None:
    """``bounds`` = None or (low, high), numbers or length-D sequences -> two (D,) float64 tensors."""
    if bounds is None:
        return None
    if not isinstance(bounds, (tuple, list)) or len(bounds) != 2:
        raise ValueError(f"bounds must be None or a pair (low, high), got {bounds!r}")
    lo, hi = check_box(*bounds, d, name="bounds", dtype=torch.float64)  # (D,), (D,)
    return lo, hi


def _reflect(data: torch.Tensor, bounds: tuple[torch.Tensor, torch.Tensor]) -> torch.Tensor:
    """The data and their mirror images in every face of the box: (M, D) -> (3^D · M, D) float64.

    Per dimension each point x_d has three images, x_d, 2 low_d − x_d and 2 high_d − x_d; the
    product over dimensions gives 3^D images per point (the first block is the data itself).
    """
    x = data.detach().to(torch.float64)  # (M, D)
    lo, hi = bounds
    images = [x]
    for d in range(x.shape[1]):
        new = []
        for img in images:
            for edge in (lo[d], hi[d]):
                mirrored = img.clone()
                mirrored[:, d] = 2 * edge - img[:, d]
                new.append(mirrored)
        images += new
    return torch.cat(images)  # (3^D M, D)


def _density64(
    query: torch.Tensor,
    data: torch.Tensor,
    h: float,
    chunk_elements: int,
    bounds: tuple[torch.Tensor, torch.Tensor] | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """(ĝ, log ĝ) at each query point, both (Q,) float64; see ``kde_density``."""
    # Work in units of h, centred on the data's mean (keeps the squared distances below exact
    # enough in float64 even for data far from the origin).
    centre = data.detach().to(torch.float64).mean(dim=0)  # (D,)
    q_c = query.detach().to(torch.float64) - centre  # (Q, D)
    m, d = data.shape  # M counts the data, not their mirror images
    points = data.detach().to(torch.float64) if bounds is None else _reflect(data, bounds)  # (M or 3^D M, D)
    x_c = points - centre
    s = _kernel_sums(q_c / h, x_c / h, chunk_elements)  # (Q,)
    log_s = torch.log(s)  # (Q,)
    bad = ~(s > 0)  # every kernel underflowed, or coordinates too large to square (NaN)
    if bad.any():
        log_s[bad] = _log_kernel_sums(q_c[bad], x_c, h, chunk_elements)
    # 1 / (M h^D) and the kernels' (2π)^(−D/2): directly when it is a normal float64, else in logs
    log_norm = math.log(m) + d * math.log(h) + 0.5 * d * math.log(2.0 * math.pi)
    try:
        norm = m * h**d * (2.0 * math.pi) ** (d / 2)
    except OverflowError:  # Python floats raise instead of returning inf
        norm = math.inf
    if math.isfinite(norm) and norm > 0:
        dens = s / norm  # (Q,) the common case, exactly as eq. 4 reads
        dens[bad] = torch.exp(log_s[bad] - log_norm)
    else:
        dens = torch.exp(log_s - log_norm)  # (Q,) 0 only where the true density is below ~1e-308
    return dens, log_s - log_norm


def _check_kde_args(
    name: str, query: torch.Tensor, data: torch.Tensor, bandwidth, chunk_elements: int
) -> float:
    check_tensor(name, query, ndim=2)
    check_tensor("data", data, ndim=2)
    if query.shape[1] != data.shape[1]:
        raise ValueError(
            f"{name} and data must have the same number of dimensions D, got {name} {tuple(query.shape)} and "
            f"data {tuple(data.shape)}"
        )
    if len(query) == 0:
        raise ValueError(f"{name} must hold at least one point, got shape {tuple(query.shape)}")
    if len(data) == 0:
        raise ValueError("data must hold at least one point, got shape " + str(tuple(data.shape)))
    if query.shape[1] == 0:
        raise ValueError(
            f"{name} and data must have at least one dimension (D >= 1), got shape {tuple(query.shape)}"
        )
    check_int("chunk_elements", chunk_elements, minimum=1)
    return check_positive("bandwidth", bandwidth)


def kde_density(
    query: torch.Tensor,
    data: torch.Tensor,
    bandwidth: float = DEFAULT_BANDWIDTH,
    *,
    bounds=None,
    chunk_elements: int = _CHUNK_ELEMENTS,
) -> torch.Tensor:
    """Gaussian kernel density estimate ĝ at each query point: eq. 4 of the DA-IBC paper.

    ĝ(q) = 1 / (M h^D) · Σ_j Π_d K((q_d − x_jd) / h),   K(u) = exp(−u²/2) / √(2π),

    the paper's eq. 4 (written there for D = 1) with the product of one Gaussian kernel per
    action dimension, the usual multivariate form with the same bandwidth h on every axis.
    It integrates to 1 over R^D (not over the action box: mass near the bounds spills out).

    **Boundary correction** (``bounds`` = (low, high), off by default). Near an edge of the
    action box part of each kernel lies outside the box, and no data beyond the edge make up
    for it: where the density reaches the edge, ĝ there is about half the true density (a
    quarter in a corner), and 1/ĝ twice the weight it should be. With ``bounds`` the estimate
    uses the reflection method (Schuster 1985, "Incorporating support constraints into
    nonparametric estimators of densities", Communications in Statistics A 14): every data
    point is mirrored in each face of the box, and ĝ_r(q) = 1 / (M h^D) Σ over the data and
    their images of Π_d K((q_d − x_d) / h), for q inside the box. The spilled mass comes back
    as the mirror image's mass inside; a density that is flat at an edge is estimated without
    bias there, and ĝ_r integrates to 1 over the box up to the (tiny, for h much smaller than
    the box) mass that images carry past the opposite face.

    Args:
        query: (Q, D) points at which to evaluate the density, Q >= 1.
        data: (M, D) the samples x_j (e.g. expert actions), M >= 1.
        bandwidth: h > 0, in the units of the data.
        bounds: None (eq. 4 as written) or (low, high), numbers or (D,) sequences: the box of
            the reflection correction above (the data should lie inside it).
        chunk_elements: at most this many (query, data) pairs are processed at once, so Q and M
            in the tens of thousands need only a few tens of MB.

    Returns:
        (Q,) densities, in query's dtype (accumulated in float64; float32 for integer queries).

    Raises:
        ValueError naming ``bandwidth`` when a density is too large for the output dtype
        (a tiny h, or many dimensions: ĝ ~ 1 / (h^D (2π)^(D/2)) at the data points).
    """
    h = _check_kde_args("query", query, data, bandwidth, chunk_elements)
    box = _check_bounds(bounds, data.shape[1])
    dens, _ = _density64(query, data, h, chunk_elements, box)  # (Q,) float64
    dtype = query.dtype if query.is_floating_point() else torch.float32
    out = dens.to(dtype)
    if not torch.isfinite(out).all():
        raise ValueError(
            f"bandwidth h = {h:g} is too small for D = {data.shape[1]}: densities reach "
            f"{float(dens.max()):.3g}, "
            f"beyond {dtype}; use a larger bandwidth, or float64 inputs"
        )
    return out


def inverse_density_weights(
    actions: torch.Tensor, bandwidth: float = DEFAULT_BANDWIDTH, *, bounds=None
) -> torch.Tensor:
    """Weights w_i ∝ 1 / ĝ(y_i) of eq. 5 of the DA-IBC paper, normalised to sum to 1.

    ĝ is the KDE of eq. 4 over the same actions (each action counts itself, so ĝ(y_i) > 0).
    Rare actions get large weights, common ones small: drawn with these probabilities, a
    minibatch covers the actions roughly uniformly over the region where experts acted.
    When ĝ leaves the range of ``actions``' dtype (a tiny bandwidth, many dimensions), the
    weights are computed from log ĝ instead, w = softmax(−log ĝ), which is the same quantity.

    Args:
        actions: (M, D) expert actions, M >= 1.
        bandwidth: the KDE bandwidth h.
        bounds: None (the paper's eq. 4, the default) or (low, high) of the action box, e.g.
            (-1.0, 1.0): ĝ with the reflection correction (see ``kde_density``), so that
            actions on and near the box's edges do not get inflated weights.

    Returns:
        (M,) non-negative weights summing to 1 (float32 for float32 actions).
    """
    h = _check_kde_args("actions", actions, actions, bandwidth, _CHUNK_ELEMENTS)
    box = _check_bounds(bounds, actions.shape[1])
    dens, log_dens = _density64(actions, actions, h, _CHUNK_ELEMENTS, box)  # (M,) float64
    dtype = actions.dtype if actions.is_floating_point() else torch.float32
    g = dens.to(dtype).to(torch.float64)  # (M,) ĝ(y_i) as kde_density returns it
    w = 1.0 / g
    total = w.sum()
    if bool(torch.isfinite(total)) and float(total) > 0:
        return (w / total).to(dtype)
    return torch.softmax(-log_dens, dim=0).to(dtype)  # (M,) the same weights, from log ĝ
