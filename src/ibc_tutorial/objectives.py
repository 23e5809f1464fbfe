"""Training objectives: the losses of the book as ``objective(batch, generator) -> scalar`` for
``training.train``.

Each builder closes over a model (and, for energy models, the way its counter-examples are
chosen), so one loop trains every variant of the book:

- ``likelihood_objective(policy)``: an explicit policy's own negative log-likelihood (or
  regression loss): Beta NLL (eq. 1 of the DA-IBC paper), MDN, classifier, regression;
- ``info_nce_objective(model, sampler, n_neg, weight_key=None, ranking=False)``: InfoNCE (eqs. 2-3,
  eq. 5 with weights) with counter-examples from any sampler of ``ibc_tutorial.negatives``, or with
  ``ranking=True`` ranking NCE (``losses.ranking_nce``: the sampler's log q subtracted from the logits);
- ``flow_matching_objective(policy)``: a ``policies.flow.FlowPolicy``'s conditional flow-matching loss
  (Lipman et al. 2023, eq. 23), its noise and times drawn from the loop's generator;
- ``grid_objective(model, grid, temperature=None, smoothing=0.0)``: the steering-EBM paper's
  cross-entropy over a fixed grid (its eq. 3), with soft targets (eq. 5) and temporal
  smoothing (eq. 4) on pairs of consecutive frames from ``consecutive_pairs``.

A batch is a dict of tensors (``training.TensorData.batch``); the keys default to ``"obs"``
and ``"actions"``.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch

from ibc_tutorial.losses import (
    grid_cross_entropy,
    info_nce,
    ranking_nce,
    soft_targets,
    temporal_smoothing,
)
from ibc_tutorial.negatives import NegativeSampler
from ibc_tutorial.training import DrawnObjective, Objective
from ibc_tutorial.utils import check_int, check_positive, check_tensor


def likelihood_objective(
    policy: torch.nn.Module, *, obs_key: str = "obs", action_key: str = "actions"
) -> Objective:
    """The loss of an explicit policy (regression, Beta, classifier, MDN) as ``train`` wants it.

    Returns ``objective(batch, generator) = policy.loss(batch[obs_key], batch[action_key])``: the
    policy's own negative log-likelihood (or regression loss); the generator is not needed.
    """
    if not callable(getattr(policy, "loss", None)):
        raise ValueError(f"policy must have a loss(obs, actions) method, got {type(policy).__name__}")

    def loss(batch: dict[str, torch.Tensor], drawn: dict) -> torch.Tensor:
        return policy.loss(batch[obs_key], batch[action_key])

    return DrawnObjective(loss)  # no random draws


def info_nce_objective(
    model: torch.nn.Module,
    sampler: NegativeSampler,
    n_neg: int,
    *,
    obs_key: str = "obs",
    action_key: str = "actions",
    weight_key: str | None = None,
    ranking: bool = False,
) -> Objective:
    """InfoNCE with counter-examples from ``sampler``: eqs. 2-3 of the DA-IBC paper (eq. 5 with weights).

    Per minibatch: the sampler draws N counter-examples per sample from the minibatch's expert
    actions (``negatives.UniformSampler`` for IBC, ``negatives.ExpertSampler`` for DA-IBC); the
    model scores the expert action and its counter-examples against one encoding of the
    observation; ``losses.info_nce`` turns the energies into the loss.

    Args:
        model: an ``EnergyModel``.
        sampler: a ``negatives.NegativeSampler``, ``sampler(actions (B, D), n_neg, generator) -> (B, N, D)``.
        n_neg: N_neg, counter-examples per sample (the paper: 1024).
        obs_key, action_key: keys of the observations and expert actions (B, D) in a batch.
        weight_key: key of per-sample weights (B,) for eq. 5, or None for eq. 2. (The DA-IBC
            paper applies its KDE weights by weighted minibatch sampling instead: pass
            ``sample_probs`` to ``train`` for that.)
        ranking: False for InfoNCE, True for ranking NCE (``losses.ranking_nce``: Ma & Collins 2018; Singh,
            Tu, Sindhwani 2023): each logit −E(x, y) − log q(y | x), with log q from ``sampler.log_prob(
            candidates (B, 1 + N, D), actions (B, D))`` at the expert's action and each counter-example.
            InfoNCE learns exp(−E) ∝ p / q, ranking NCE exp(−E) ∝ p; with ``UniformSampler`` both are equal.
    """
    n_neg = check_int("n_neg", n_neg, minimum=1)
    if not isinstance(sampler, NegativeSampler):
        raise ValueError(f"sampler must be a NegativeSampler (a callable), got {type(sampler).__name__}")
    if not isinstance(ranking, bool):
        raise ValueError(f"ranking must be True or False, got {ranking!r}")
    if ranking and not callable(getattr(sampler, "log_prob", None)):
        raise ValueError(
            f"sampler must have a log_prob(candidates, actions) method for ranking=True, got "
            f"{type(sampler).__name__}"
        )

    def draw(batch: dict[str, torch.Tensor], generator: torch.Generator) -> dict[str, torch.Tensor]:
        return {"negatives": sampler(batch[action_key], n_neg, generator)}  # (B, N, D)

    def loss(batch: dict[str, torch.Tensor], drawn: dict[str, torch.Tensor]) -> torch.Tensor:
        actions, negatives = batch[action_key], drawn["negatives"]  # (B, D), (B, N, D)
        candidates = torch.cat([actions[:, None, :], negatives], dim=1)  # (B, 1 + N, D), expert first
        energies = model.energy(batch[obs_key], candidates)  # (B, 1 + N)
        weights = batch[weight_key] if weight_key is not None else None
        if not ranking:
            return info_nce(energies[:, 0], energies[:, 1:], weights)
        log_q = sampler.log_prob(candidates, actions)  # (B, 1 + N): log q of the proposal, expert first
        return ranking_nce(energies[:, 0], energies[:, 1:], log_q[:, 0], log_q[:, 1:], weights)

    return DrawnObjective(loss, draw)


def flow_matching_objective(
    policy: torch.nn.Module, *, obs_key: str = "obs", action_key: str = "actions"
) -> Objective:
    """A ``FlowPolicy``'s conditional flow-matching loss (Lipman et al. 2023, eq. 23, with σ_min = 0).

    Returns ``objective(batch, generator) = policy.loss(batch[obs_key], batch[action_key], generator)``:
    the noise y_0 and the times t of the straight paths are drawn from the loop's generator, so a run is
    reproducible and resumes bit for bit like the others.
    """
    if not callable(getattr(policy, "loss", None)) or not callable(getattr(policy, "sample", None)):
        raise ValueError(
            "policy must be a FlowPolicy (loss(obs, actions, generator) and sample), got "
            f"{type(policy).__name__}"
        )

    def objective(batch: dict[str, torch.Tensor], generator: torch.Generator) -> torch.Tensor:
        return policy.loss(batch[obs_key], batch[action_key], generator)

    return objective


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
) -> Objective:
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
        grid: (G, D) candidate actions, e.g. ``optimizers.grid.action_grid(64)``.
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
        e_grid = model.energy_from_embedding(z, grid.to(z.device))  # (B, G), grid shared by the batch
        return torch.cat([e_gt, e_grid], dim=1)  # (B, 1 + G)

    def cross_entropy(energies: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        if temperature is None:
            targets = torch.zeros_like(energies)
            targets[:, 0] = 1.0  # one-hot on the ground truth
        else:
            g = grid.to(actions.device).expand(len(actions), -1, -1)  # (B, G, D), on the batch's device
            candidates = torch.cat([actions[:, None, :], g], dim=1)  # (B, 1 + G, D)
            targets = soft_targets(candidates, actions, temperature)  # (B, 1 + G), eq. 5
        return grid_cross_entropy(energies, targets)  # eq. 3

    def grid_loss(batch: dict[str, torch.Tensor], drawn: dict) -> torch.Tensor:
        e_t = energies_of(batch[obs_key], batch[action_key])
        loss = cross_entropy(e_t, batch[action_key])
        if smoothing == 0:
            return loss
        e_next = energies_of(batch[next_obs_key], batch[next_action_key])
        loss = 0.5 * (loss + cross_entropy(e_next, batch[next_action_key]))  # mean over both frames
        return loss + temporal_smoothing(e_t[:, 1:], e_next[:, 1:], smoothing)  # eq. 4, ground truth masked

    return DrawnObjective(grid_loss)  # no random draws: the grid is fixed


def consecutive_pairs(
    data: Mapping[str, torch.Tensor], episode_key: str = "episode"
) -> dict[str, torch.Tensor]:
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
