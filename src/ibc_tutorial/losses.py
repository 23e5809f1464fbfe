"""Losses of the book, each citing the equation it implements.

Explicit policies (chapter 02): Beta negative log-likelihood (eq. 1 of the DA-IBC paper),
mixture-density NLL, classification over bins. Energy models (chapters 03-04): InfoNCE
(eqs. 2-3 of the DA-IBC paper, weighted: its eq. 5), cross-entropy over a fixed grid with
soft targets (eq. 5 of the steering-EBM paper) and temporal smoothing (its eq. 4); ranking NCE
(InfoNCE with the proposal's log-density subtracted: Ma & Collins 2018; Singh, Tu, Sindhwani 2023).
Flow matching: the conditional flow-matching loss on straight paths (Lipman et al. 2023, eq. 23).

Every loss is a mean over the batch, so each refuses an empty batch (B = 0) with a ValueError
rather than returning NaN.
"""

from __future__ import annotations

import math

import torch

from ibc_tutorial.utils import check_choice, check_int, check_positive, check_tensor, value_checks_on


def _check_batch(name: str, x: torch.Tensor) -> None:
    """Refuse an empty batch (B = 0), whose mean loss would be NaN."""
    if len(x) == 0:
        raise ValueError(f"{name} must hold at least one sample (B >= 1), got shape {tuple(x.shape)}")


# =========================================================================== explicit policies (chapter 02)
BETA_EPS = 1e-4
"""``beta_nll`` clamps the rescaled action y' = (y + 1)/2 to [BETA_EPS, 1 - BETA_EPS].

Expert data holds actions exactly at -1 and +1 (full brake, full steering lock), where
y' = 0 or 1 and log y' or log(1 - y') is -inf. Evaluating the Beta density at the nearest
point 1e-4 inside the interval keeps the loss and its gradients finite and changes nothing
for actions further than 2e-4 (in [-1, 1] units) from a bound."""


def _check_actions(name: str, actions: torch.Tensor) -> torch.Tensor:
    check_tensor(name, actions, ndim=2)
    if not actions.is_floating_point():
        raise ValueError(f"{name} must be a floating-point tensor, got dtype {actions.dtype}")
    if value_checks_on() and ((actions < -1).any() or (actions > 1).any()):
        raise ValueError(
            f"{name} must lie in [-1, 1], got values in [{float(actions.min()):.3g}, "
            f"{float(actions.max()):.3g}]"
        )
    return actions


def beta_nll(
    alpha: torch.Tensor, beta: torch.Tensor, actions: torch.Tensor, *, eps: float = BETA_EPS
) -> torch.Tensor:
    """Negative log-likelihood of actions under per-dimension Beta distributions: eq. 1 of the DA-IBC paper.

    The paper rescales each action y in [-1, 1] to y' = (y + 1)/2 in [0, 1] and scores it with
    the Beta density f(y'; α, β) = y'^(α-1) (1 - y')^(β-1) / B(α, β), with no change-of-variables
    term (so the loss is the NLL of y', i.e. that of y plus the constant D·log 2). Eq. 1 sums the
    dimensions (acceleration and steering) and averages over the N samples:

        L = -(1/N) Σ_i Σ_d log f((y_id + 1)/2; α_id, β_id)

    Clamp: y' is clamped to [eps, 1 - eps] (``BETA_EPS`` = 1e-4 by default), so actions exactly
    at -1 or +1 give a finite loss with finite gradients (see ``BETA_EPS``).

    Args:
        alpha, beta: (B, D) concentrations, finite and > 0.
        actions: (B, D) actions in [-1, 1].
        eps: the clamp margin, in (0, 0.5).
    Returns:
        a scalar tensor.
    """
    _check_actions("actions", actions)
    _check_batch("actions", actions)
    check_tensor("alpha", alpha, shape=tuple(actions.shape))
    check_tensor("beta", beta, shape=tuple(actions.shape))
    if value_checks_on() and (alpha <= 0).any():
        raise ValueError(f"alpha must be > 0 everywhere, got minimum {float(alpha.min()):.3g}")
    if value_checks_on() and (beta <= 0).any():
        raise ValueError(f"beta must be > 0 everywhere, got minimum {float(beta.min()):.3g}")
    if not 0.0 < float(eps) < 0.5:
        raise ValueError(f"eps must lie in (0, 0.5), got {eps!r}")
    y = ((actions + 1.0) / 2.0).clamp(eps, 1.0 - eps)  # (B, D), y' of eq. 1
    log_b = torch.lgamma(alpha) + torch.lgamma(beta) - torch.lgamma(alpha + beta)  # log B(α, β)
    log_f = (alpha - 1.0) * torch.log(y) + (beta - 1.0) * torch.log1p(-y) - log_b  # (B, D)
    return -log_f.sum(dim=1).mean()


def regression_loss(predictions: torch.Tensor, actions: torch.Tensor, kind: str = "mae") -> torch.Tensor:
    """Regression loss of the steering-EBM paper's baseline: mean over the batch of the summed
    absolute ("mae", the paper's choice) or squared ("mse") errors over action dimensions.

    Args:
        predictions, actions: (B, D) tensors.
        kind: "mae" or "mse".
    """
    check_choice("kind", kind, ("mae", "mse"))
    check_tensor("actions", actions, ndim=2)
    _check_batch("actions", actions)
    check_tensor("predictions", predictions, shape=tuple(actions.shape))
    err = predictions - actions  # (B, D)
    per_dim = err.abs() if kind == "mae" else err.square()
    return per_dim.sum(dim=1).mean()


def bin_centers(n_bins: int, low: float = -1.0, high: float = 1.0) -> torch.Tensor:
    """Centres of ``n_bins`` equal bins dividing [low, high]: (n_bins,)."""
    check_int("n_bins", n_bins, minimum=2)
    width = (high - low) / n_bins
    return low + width * (torch.arange(n_bins, dtype=torch.get_default_dtype()) + 0.5)


def action_to_bin(actions: torch.Tensor, n_bins: int) -> torch.Tensor:
    """Index of the bin of [-1, 1] (divided into ``n_bins`` equal bins) holding each action.

    ``actions`` (B, D) in [-1, 1] -> (B, D) int64 in [0, n_bins - 1]; +1 falls in the last bin.
    """
    check_int("n_bins", n_bins, minimum=2)
    _check_actions("actions", actions)
    idx = torch.floor((actions + 1.0) / 2.0 * n_bins).long()
    return idx.clamp(0, n_bins - 1)


def classification_loss(logits: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """Cross-entropy over bins of the action range, the steering-EBM paper's classification baseline.

    Each action dimension is classified separately into N equal bins of [-1, 1] (the paper
    used N = 512 for steering); the loss is the mean over the batch of the sum over dimensions
    of -log softmax(logits)[bin of the expert action].

    Args:
        logits: (B, D, N) unnormalised scores of the bins of each action dimension.
        actions: (B, D) actions in [-1, 1].
    """
    _check_actions("actions", actions)
    _check_batch("actions", actions)
    b, d = actions.shape
    check_tensor("logits", logits, shape=(b, d, None))
    n = logits.shape[2]
    if n < 2:
        raise ValueError(f"logits must score at least 2 bins per dimension, got {n}")
    target = action_to_bin(actions, n)  # (B, D)
    log_p = torch.log_softmax(logits, dim=-1)  # (B, D, N)
    nll = -log_p.gather(-1, target.unsqueeze(-1)).squeeze(-1)  # (B, D)
    return nll.sum(dim=1).mean()


def mdn_nll(
    logits: torch.Tensor, means: torch.Tensor, stds: torch.Tensor, actions: torch.Tensor
) -> torch.Tensor:
    """Negative log-likelihood under a mixture density network's Gaussian mixture (Bishop 1994).

    The steering-EBM paper's MDN baseline outputs K triplets (mixture weight π_k, mean μ_k,
    standard deviation σ_k); with D action dimensions each component is a diagonal Gaussian:

        p(y | x) = Σ_k π_k Π_d N(y_d; μ_kd, σ_kd²),   π = softmax(logits)

    Returns the mean over the batch of -log p(y | x), computed with log-sum-exp.

    Args:
        logits: (B, K) unnormalised mixture weights.
        means: (B, K, D) component means.
        stds: (B, K, D) component standard deviations, > 0.
        actions: (B, D) target actions.
    """
    check_tensor("actions", actions, ndim=2)
    _check_batch("actions", actions)
    b, d = actions.shape
    check_tensor("logits", logits, shape=(b, None))
    k = logits.shape[1]
    check_tensor("means", means, shape=(b, k, d))
    check_tensor("stds", stds, shape=(b, k, d))
    if value_checks_on() and (stds <= 0).any():
        raise ValueError(f"stds must be > 0 everywhere, got minimum {float(stds.min()):.3g}")
    z = (actions.unsqueeze(1) - means) / stds  # (B, K, D)
    log_normal = -0.5 * z.square() - torch.log(stds) - 0.5 * math.log(2.0 * math.pi)  # (B, K, D)
    log_comp = log_normal.sum(dim=2)  # (B, K): log Π_d N(y_d; μ_kd, σ_kd²)
    log_p = torch.logsumexp(torch.log_softmax(logits, dim=1) + log_comp, dim=1)  # (B,)
    return -log_p.mean()


# =========================================================================== energy models (chapters 03-04)
def _check_energies(pos_energy: torch.Tensor, neg_energy: torch.Tensor, weights: torch.Tensor | None) -> None:
    check_tensor("pos_energy", pos_energy, ndim=1)
    _check_batch("pos_energy", pos_energy)
    b = len(pos_energy)
    check_tensor("neg_energy", neg_energy, shape=(b, None))
    if neg_energy.shape[1] < 1:
        raise ValueError(
            f"neg_energy must hold at least one counter-example per sample, got shape "
            f"{tuple(neg_energy.shape)}"
        )
    if weights is not None:
        check_tensor("weights", weights, shape=(b,))
        if (weights < 0).any():
            raise ValueError(f"weights must be >= 0, got minimum {float(weights.min()):.3g}")


def info_nce(
    pos_energy: torch.Tensor, neg_energy: torch.Tensor, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """InfoNCE over counter-examples: eqs. 2-3 of the DA-IBC paper, weighted as in its eq. 5.

    For sample i with expert action y_i and counter-examples ỹ_i^1..ỹ_i^N (eq. 3):

        p̃_i = exp(-E(x_i, y_i)) / (exp(-E(x_i, y_i)) + Σ_j exp(-E(x_i, ỹ_i^j)))

    i.e. the softmax of the negated energies over the N + 1 candidates, read at the expert's
    action. The loss is the **mean** over the batch of w_i · (−log p̃_i), with w_i = 1 when
    ``weights`` is None. (Eqs. 2 and 5 write a sum over the N samples; the mean divides it by
    the batch size, which changes only the scale of the gradient, so a learning rate does not
    depend on the batch size. The weights are used as given, not renormalised: with KDE
    weights w_i = 1/ĝ(y_i) of eq. 5, the loss scales with their mean.)

    Computed as -log p̃_i = logsumexp_k(-e_ik) + E(x_i, y_i), which stays finite and exact for
    energies in the thousands, where exp(-E) under- or overflows.

    Args:
        pos_energy: (B,) energies of the expert actions, E(x_i, y_i).
        neg_energy: (B, N) energies of the counter-examples, E(x_i, ỹ_i^j).
        weights: optional (B,) non-negative sample weights w_i of eq. 5.
    Returns:
        a scalar tensor.
    """
    _check_energies(pos_energy, neg_energy, weights)
    logits = torch.cat([-pos_energy[:, None], -neg_energy], dim=1)  # (B, 1 + N): -E, expert first
    nll = torch.logsumexp(logits, dim=1) + pos_energy  # (B,): -log p̃_i of eq. 3
    if weights is None:
        return nll.mean()  # eq. 2 (divided by B)
    return (weights * nll).mean()  # eq. 5 (divided by B)


def ranking_nce(
    pos_energy: torch.Tensor,
    neg_energy: torch.Tensor,
    pos_log_q: torch.Tensor,
    neg_log_q: torch.Tensor,
    weights: torch.Tensor | None = None,
) -> torch.Tensor:
    """Ranking noise-contrastive estimation (R-NCE): InfoNCE whose logits subtract log q of the proposal.

    The ranking objective of Ma & Collins 2018 ("Noise Contrastive Estimation and Negative Sampling for
    Conditional Models"), as Singh, Tu, Sindhwani 2023 ("Revisiting Energy Based Models as Policies")
    train energy-based policies with it. With the
    expert action y_i^0 = y_i and counter-examples y_i^j ~ q(· | x_i), the logits are

        l_ij = −E(x_i, y_i^j) − log q(y_i^j | x_i),   j = 0..N (the expert first)

    and the loss is the mean over the batch of −log softmax(l_i)_0 (weighted by w_i if given, as
    ``info_nce``). It is the log-posterior that the expert's action is the one drawn from p among
    N + 1 candidates of which the others come from q: p(y^0) Π_{j≠0} q(y^j) / Σ_k p(y^k) Π_{j≠k} q(y^j),
    with p ∝ exp(−E). Its optimum is exp(−E) ∝ p(y | x) whatever the proposal, where InfoNCE's
    (``info_nce``, the same with log q = 0) is exp(−E) ∝ p / q: InfoNCE learns the expert's density
    *tilted* by the counter-examples' density. For a uniform q, log q is a constant, and R-NCE equals
    InfoNCE exactly (a constant shift of every logit changes no softmax).

    Args:
        pos_energy: (B,) E(x_i, y_i).
        neg_energy: (B, N) E(x_i, ỹ_i^j).
        pos_log_q: (B,) log q(y_i | x_i), the proposal's log-density at the expert's action.
        neg_log_q: (B, N) log q(ỹ_i^j | x_i).
        weights: optional (B,) non-negative sample weights.
    Returns:
        a scalar tensor.
    """
    _check_energies(pos_energy, neg_energy, weights)
    check_tensor("pos_log_q", pos_log_q, shape=tuple(pos_energy.shape))
    check_tensor("neg_log_q", neg_log_q, shape=tuple(neg_energy.shape))
    logits = torch.cat([-pos_energy[:, None], -neg_energy], dim=1) - torch.cat(
        [pos_log_q[:, None], neg_log_q], dim=1
    )  # (B, 1 + N): −E − log q, expert first
    nll = torch.logsumexp(logits, dim=1) - logits[:, 0]  # (B,)
    if weights is None:
        return nll.mean()
    return (weights * nll).mean()


def soft_targets(candidates: torch.Tensor, actions: torch.Tensor, temperature: float) -> torch.Tensor:
    """Target probabilities over candidate actions that fall with distance from the ground truth.

    Eq. 5 of the steering-EBM paper in its intended form:

        p* = softmax(-(a - a_GT)² / T)

    The transcription prints softmax(+(a - a_GT)² / T), which would give the **most** weight to
    the candidate farthest from the ground truth; the paper's text ("assigning some of the
    probability to actions a few degrees away from the ground truth", its Fig. 4, and "99.9% of
    the probability mass was on ±5 degrees around the ground truth") says the weight falls with
    distance, which needs the minus sign. For D > 1, (a - a_GT)² is the squared Euclidean
    distance. The paper used T = 2.5e-3 with angles in radians.

    Args:
        candidates: (B, K, D) candidates per sample, or (K, D) shared by every sample.
        actions: (B, D) ground-truth actions a_GT.
        temperature: T > 0; smaller is sharper (T -> 0 gives the one-hot target).
    Returns:
        (B, K) probabilities, each row summing to 1.
    """
    temperature = check_positive("temperature", temperature)
    check_tensor("actions", actions, ndim=2)
    b, d = actions.shape
    if candidates.ndim == 2:
        check_tensor("candidates", candidates, shape=(None, d))
        diff = candidates[None, :, :] - actions[:, None, :]  # (B, K, D)
    else:
        check_tensor("candidates", candidates, shape=(b, None, d))
        diff = candidates - actions[:, None, :]  # (B, K, D)
    sq = diff.square().sum(dim=-1)  # (B, K): (a - a_GT)²
    return torch.softmax(-sq / temperature, dim=1)  # eq. 5 of the steering-EBM paper, intended sign


def grid_cross_entropy(energies: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
    """Cross-entropy between target probabilities and softmax(-e): eq. 3 of the steering-EBM paper.

        L_EBM = CE(softmax(-e), y) = -Σ_k y_k log softmax(-e)_k

    averaged over the batch. ``energies`` holds e_k = E(o, a_k) for the K = n + 1 candidates
    (n grid actions and the ground truth); ``targets`` is the one-hot vector of the ground truth
    (then this equals ``info_nce`` with the grid as counter-examples) or soft targets
    (``soft_targets``, eq. 5). The checks build their constants on ``targets``' device
    (``ones_like``), so inputs on any device are checked there.

    Args:
        energies: (B, K) energies of the candidates.
        targets: (B, K) non-negative target probabilities, rows summing to 1.
    """
    check_tensor("energies", energies, ndim=2)
    _check_batch("energies", energies)
    if energies.shape[1] < 1:
        raise ValueError(
            f"energies must hold at least one candidate per sample (K >= 1), got shape "
            f"{tuple(energies.shape)}"
        )
    check_tensor("targets", targets, shape=tuple(energies.shape))
    sums = targets.sum(dim=1)  # (B,)
    if value_checks_on() and (
        (targets < 0).any() or not torch.allclose(sums, torch.ones_like(sums), atol=1e-4)
    ):
        raise ValueError("targets must be non-negative with rows summing to 1")
    log_p = torch.log_softmax(-energies, dim=1)  # (B, K)
    return -(targets * log_p).sum(dim=1).mean()


def temporal_smoothing(
    energies_t: torch.Tensor,
    energies_next: torch.Tensor,
    alpha: float = 1.0,
    mask: torch.Tensor | None = None,
) -> torch.Tensor:
    """Temporal smoothing loss, eq. 4 of the steering-EBM paper: L_temp = α ‖e_t − e_{t+1}‖.

    e_t and e_{t+1} are the energies of the **same** candidate actions (a fixed grid) at two
    consecutive frames of one episode. The ground truth's column differs between the frames,
    so the paper masks it from this term: pass ``mask`` (False = masked), or pass only the grid
    columns. ‖·‖ is the Euclidean norm over the unmasked candidates (the paper does not name
    the norm); the result is averaged over the B pairs. The paper used α = 1.

    Args:
        energies_t, energies_next: (B, K) energies at frames t and t + 1.
        alpha: smoothing strength α >= 0.
        mask: optional (K,) or (B, K) bool, True for the columns that enter the loss.
    """
    alpha = check_positive("alpha", alpha, allow_zero=True)
    check_tensor("energies_t", energies_t, ndim=2)
    _check_batch("energies_t", energies_t)
    check_tensor("energies_next", energies_next, shape=tuple(energies_t.shape))
    diff = energies_t - energies_next  # (B, K)
    if mask is not None:
        if (
            not isinstance(mask, torch.Tensor)
            or mask.dtype != torch.bool
            or mask.shape not in (diff.shape[1:], diff.shape)
        ):
            got = (tuple(mask.shape), mask.dtype) if isinstance(mask, torch.Tensor) else type(mask).__name__
            raise ValueError(
                f"mask must be a bool tensor of shape ({diff.shape[1]},) or {tuple(diff.shape)}, got {got}"
            )
        diff = diff * mask
    return alpha * torch.linalg.vector_norm(diff, dim=1).mean()


# =========================================================================== flow matching
def flow_matching_loss(velocity: torch.Tensor, y0: torch.Tensor, y1: torch.Tensor) -> torch.Tensor:
    """The conditional flow-matching loss on straight paths: eq. 23 of Lipman et al. 2023 with σ_min = 0.

        L = mean over samples of ‖v_θ(x, y_t, t) − (y_1 − y_0)‖²,   y_t = (1 − t) y_0 + t y_1

    the squared error between the predicted velocity and the velocity of the straight
    (optimal-transport) path from the noise y_0 to the expert action y_1 (also rectified flow's
    objective, eq. 1 of Liu et al. 2023), summed over the D action dimensions and averaged over
    the samples. The path itself is drawn by ``policies.flow.FlowPolicy.loss``.

    Args:
        velocity: (B, M, D) v_θ at the M points y_t of each of B samples.
        y0: (B, M, D) the noise ends of the paths.
        y1: (B, M, D) the expert ends (an expert action repeated M times).
    Returns:
        a scalar tensor.
    """
    check_tensor("velocity", velocity, ndim=3)
    _check_batch("velocity", velocity)
    check_tensor("y0", y0, shape=tuple(velocity.shape))
    check_tensor("y1", y1, shape=tuple(velocity.shape))
    return (velocity - (y1 - y0)).square().sum(dim=-1).mean()
