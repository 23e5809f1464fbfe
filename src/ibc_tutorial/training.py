"""The training loop shared by the chapters and the command line.

A model is trained by minimising a ``loss_fn(batch, generator) -> scalar tensor`` over
minibatches drawn from a dict of equally long tensors. The loop knows nothing about the
kind of policy: explicit policies pass their negative log-likelihood, energy models pass
InfoNCE with a counter-example sampler. Minibatch indices are drawn uniformly, or with
given probabilities (the DA-IBC paper's way of applying the KDE weights of its eq. 5).

Loss builders for energy models (chapters 03-05):

- ``info_nce_objective(model, sampler, n_neg, weight_key=None)``: InfoNCE (eqs. 2-3, eq. 5 with
  weights) with counter-examples from any sampler of ``ibc_tutorial.negatives``;
- ``grid_objective(model, grid, temperature=None, smoothing=0.0)``: the steering-EBM paper's
  cross-entropy over a fixed grid (its eq. 3), with soft targets (eq. 5) and temporal
  smoothing (eq. 4) on pairs of consecutive frames from ``consecutive_pairs``.

``train(..., evaluate=fn)`` also records a held-out measure at every log point (for curves).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping

import torch

from ibc_tutorial.utils import check_int, check_positive, check_tensor, progress


@dataclass
class TrainConfig:
    """Settings of one training run."""

    steps: int = 2000
    """Number of gradient steps (minibatches)."""
    batch_size: int = 128
    """Samples per minibatch (the DA-IBC paper uses 128)."""
    lr: float = 1e-3
    """Adam learning rate (the paper uses 1e-5 on its much larger dataset)."""
    weight_decay: float = 0.0
    """Adam weight decay."""
    seed: int = 0
    """Seeds the minibatch draws and the generator handed to ``loss_fn``."""
    log_every: int = 50
    """Record the mean loss every this many steps."""
    progress: bool | None = None
    """Show a progress bar: None = yes, unless running under the tests (``utils.quiet``)."""


@dataclass
class TrainResult:
    """What ``train`` returns: the loss curve (one entry per ``log_every`` steps)."""

    steps: list[int] = field(default_factory=list)
    """Step index at which each loss was recorded."""
    losses: list[float] = field(default_factory=list)
    """Mean training loss over the preceding ``log_every`` steps."""
    evals: list = field(default_factory=list)
    """What ``evaluate()`` returned at each log point (empty when no ``evaluate`` was given)."""


def train(
    model: torch.nn.Module,
    loss_fn: Callable[[dict[str, torch.Tensor], torch.Generator], torch.Tensor],
    data: Mapping[str, torch.Tensor],
    config: TrainConfig = TrainConfig(),
    *,
    sample_probs: torch.Tensor | None = None,
    callback: Callable[[int, float], None] | None = None,
    evaluate: Callable[[], object] | None = None,
) -> TrainResult:
    """Train ``model`` in place by Adam on minibatches of ``data``.

    Args:
        model: the parameters to optimise.
        loss_fn: maps a minibatch (a dict with the same keys as ``data``, each of length
            ``batch_size``) and a seeded ``torch.Generator`` to a scalar loss.
        data: tensors with a common first dimension M.
        config: see ``TrainConfig``.
        sample_probs: optional (M,) probabilities of drawing each sample (e.g.
            ``kde.inverse_density_weights``); uniform when None.
        callback: called as ``callback(step, mean_loss)`` at every log point.
        evaluate: called without arguments at every log point, in eval mode and without
            gradients (e.g. a held-out measure); its results are kept in ``TrainResult.evals``.
    """
    check_int("config.steps", config.steps, minimum=1)
    check_int("config.batch_size", config.batch_size, minimum=1)
    check_int("config.log_every", config.log_every, minimum=1)
    check_positive("config.lr", config.lr)
    if not data:
        raise ValueError("data must hold at least one tensor")
    sizes = {k: len(v) for k, v in data.items()}
    m = next(iter(sizes.values()))
    if any(s != m for s in sizes.values()) or m == 0:
        raise ValueError(f"data tensors must share a non-zero first dimension, got lengths {sizes}")
    if sample_probs is not None:
        check_tensor("sample_probs", sample_probs, shape=(m,))
        if (sample_probs < 0).any() or sample_probs.sum() <= 0:
            raise ValueError("sample_probs must be non-negative with a positive sum")

    gen = torch.Generator().manual_seed(config.seed)
    opt = torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    result = TrainResult()
    running, count = 0.0, 0
    model.train()
    for step in progress(range(1, config.steps + 1), desc="training", enabled=config.progress if config.progress is not None else None):
        if sample_probs is None:
            idx = torch.randint(0, m, (config.batch_size,), generator=gen)
        else:
            idx = torch.multinomial(sample_probs, config.batch_size, replacement=True, generator=gen)
        batch = {k: v[idx] for k, v in data.items()}
        loss = loss_fn(batch, gen)
        if loss.ndim != 0 or not torch.isfinite(loss):
            raise ValueError(f"loss_fn must return a finite scalar, got {loss.detach()!r} at step {step}")
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        running += float(loss.detach())
        count += 1
        if step % config.log_every == 0 or step == config.steps:
            mean = running / count
            result.steps.append(step)
            result.losses.append(mean)
            if evaluate is not None:
                model.eval()
                with torch.no_grad():
                    result.evals.append(evaluate())
                model.train()
            if callback is not None:
                callback(step, mean)
            running, count = 0.0, 0
    model.eval()
    return result


# =========================================================================== energy-model objectives (chapters 03-05)
# Builders of ``loss_fn(batch, generator)`` for ``train``: each closes over an EnergyModel and
# the way its counter-examples are chosen, so one loop trains every variant of the book.
from ibc_tutorial.losses import grid_cross_entropy, info_nce, soft_targets, temporal_smoothing  # noqa: E402
from ibc_tutorial.utils import check_positive  # noqa: E402

LossFn = Callable[[dict[str, torch.Tensor], torch.Generator], torch.Tensor]


def likelihood_objective(policy: torch.nn.Module, *, obs_key: str = "obs", action_key: str = "actions") -> LossFn:
    """The loss of an explicit policy (regression, Beta, classifier, MDN) as ``train`` wants it.

    Returns ``loss_fn(batch, generator) = policy.loss(batch[obs_key], batch[action_key])``: the
    policy's own negative log-likelihood (or regression loss); the generator is not needed.
    """
    if not callable(getattr(policy, "loss", None)):
        raise ValueError(f"policy must have a loss(obs, actions) method, got {type(policy).__name__}")

    def loss_fn(batch: dict[str, torch.Tensor], generator: torch.Generator) -> torch.Tensor:
        return policy.loss(batch[obs_key], batch[action_key])

    return loss_fn


def info_nce_objective(
    model: torch.nn.Module,
    sampler: Callable[[torch.Tensor, int, torch.Generator], torch.Tensor],
    n_neg: int,
    *,
    obs_key: str = "obs",
    action_key: str = "actions",
    weight_key: str | None = None,
) -> LossFn:
    """InfoNCE with counter-examples from ``sampler``: eqs. 2-3 of the DA-IBC paper (eq. 5 with weights).

    Per minibatch: the sampler draws N counter-examples per sample from the minibatch's expert
    actions (``negatives.UniformSampler`` for IBC, ``negatives.ExpertSampler`` for DA-IBC); the
    model scores the expert action and its counter-examples against one encoding of the
    observation; ``losses.info_nce`` turns the energies into the loss.

    Args:
        model: an ``EnergyModel``.
        sampler: ``sampler(actions (B, D), n_neg, generator) -> (B, N, D)``.
        n_neg: N_neg, counter-examples per sample (the paper: 1024).
        obs_key, action_key: keys of the observations and expert actions (B, D) in a batch.
        weight_key: key of per-sample weights (B,) for eq. 5, or None for eq. 2. (The DA-IBC
            paper applies its KDE weights by weighted minibatch sampling instead: pass
            ``sample_probs`` to ``train`` for that.)
    """
    n_neg = check_int("n_neg", n_neg, minimum=1)

    def loss_fn(batch: dict[str, torch.Tensor], generator: torch.Generator) -> torch.Tensor:
        actions = batch[action_key]  # (B, D)
        negatives = sampler(actions, n_neg, generator)  # (B, N, D)
        candidates = torch.cat([actions[:, None, :], negatives], dim=1)  # (B, 1 + N, D), expert first
        energies = model.energy(batch[obs_key], candidates)  # (B, 1 + N)
        weights = batch[weight_key] if weight_key is not None else None
        return info_nce(energies[:, 0], energies[:, 1:], weights)

    return loss_fn


def grid_objective(
    model: torch.nn.Module,
    grid: torch.Tensor,
    *,
    temperature: float | None = None,
    smoothing: float = 0.0,
    obs_key: str = "obs",
    action_key: str = "actions",
    next_obs_key: str = "next_obs",
    next_action_key: str = "next_actions",
) -> LossFn:
    """The steering-EBM paper's EBM: cross-entropy over a fixed grid (its eq. 3), with options.

    The candidates of every sample are the ground truth and the G actions of a constant,
    linearly spaced ``grid`` (K = G + 1, ground truth first). The target is one-hot on the
    ground truth, or, with ``temperature``, the soft targets of eq. 5 (intended sign, see
    ``losses.soft_targets``). With ``smoothing`` = α > 0, each batch holds pairs of consecutive
    frames (see ``consecutive_pairs``): the cross-entropy is averaged over both frames (the
    paper flattens the pairs into one minibatch of frames) and α‖e_t − e_{t+1}‖ of eq. 4 is
    added over the grid's columns (the ground-truth column masked).

    Args:
        model: an ``EnergyModel``.
        grid: (G, D) candidate actions, e.g. ``inference.action_grid(64)``.
        temperature: T of eq. 5 for soft targets; None = one-hot targets.
        smoothing: α of eq. 4; 0 = no temporal smoothing.
        obs_key, action_key: keys of the frame-t observations and actions.
        next_obs_key, next_action_key: keys of the frame-t+1 ones (used when smoothing > 0).
    """
    check_tensor("grid", grid, ndim=2)
    if temperature is not None:
        temperature = check_positive("temperature", temperature)
    smoothing = check_positive("smoothing", smoothing, allow_zero=True)

    def energies_of(obs, actions: torch.Tensor) -> torch.Tensor:
        z = model.embed(obs)  # (B, E), once per observation
        e_gt = model.energy_from_embedding(z, actions[:, None, :])  # (B, 1)
        e_grid = model.energy_from_embedding(z, grid)  # (B, G), grid shared by the batch
        return torch.cat([e_gt, e_grid], dim=1)  # (B, 1 + G)

    def cross_entropy(energies: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        if temperature is None:
            targets = torch.zeros_like(energies)
            targets[:, 0] = 1.0  # one-hot on the ground truth
        else:
            candidates = torch.cat([actions[:, None, :], grid.expand(len(actions), -1, -1)], dim=1)  # (B, 1 + G, D)
            targets = soft_targets(candidates, actions, temperature)  # (B, 1 + G), eq. 5
        return grid_cross_entropy(energies, targets)  # eq. 3

    def loss_fn(batch: dict[str, torch.Tensor], generator: torch.Generator) -> torch.Tensor:
        e_t = energies_of(batch[obs_key], batch[action_key])
        loss = cross_entropy(e_t, batch[action_key])
        if smoothing == 0:
            return loss
        e_next = energies_of(batch[next_obs_key], batch[next_action_key])
        loss = 0.5 * (loss + cross_entropy(e_next, batch[next_action_key]))  # mean over both frames
        return loss + temporal_smoothing(e_t[:, 1:], e_next[:, 1:], smoothing)  # eq. 4, ground truth masked

    return loss_fn


def consecutive_pairs(data: Mapping[str, torch.Tensor], episode_key: str = "episode") -> dict[str, torch.Tensor]:
    """Pairs of consecutive frames of the same episode, for temporal smoothing (eq. 4).

    For every frame t whose successor t + 1 belongs to the same episode (frames are stored
    in time order), returns each tensor of ``data`` at t, and, under ``next_<key>``, at t + 1.

    Args:
        data: tensors with a common first dimension M, including ``data[episode_key]`` (M,).
    Returns:
        a dict with the keys of ``data`` and ``next_`` + each key, each of length P < M.
    """
    if episode_key not in data:
        raise ValueError(f"data must hold the episode index under {episode_key!r}, got keys {sorted(data)}")
    ep = data[episode_key]
    same = ep[1:] == ep[:-1]  # (M - 1,): frame t and t + 1 are in one episode
    idx = torch.nonzero(same).squeeze(1)  # (P,)
    if len(idx) == 0:
        raise ValueError("data holds no two consecutive frames of one episode")
    out = {k: v[idx] for k, v in data.items()}
    out.update({f"next_{k}": v[idx + 1] for k, v in data.items()})
    return out
