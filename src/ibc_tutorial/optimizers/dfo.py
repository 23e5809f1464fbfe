"""Derivative-free optimisation: Algorithm 1 of the DA-IBC paper (chapter 06).

- ``DFOConfig``: the algorithm's settings, with the paper's names and values.
- ``dfo``: one call for one observation (``n_obs=None``) or B observations at once (``n_obs=B``).
- ``dfo_trace``: the same draws for one observation, keeping every iteration's population.
- ``initial_weights`` / ``initial_samples``: the initialisation (Algorithm 1 line 2).
- ``DFOOptimizer`` (an ``ActionOptimizer``) and ``dfo_policy`` (a ``DFOPolicy``): DFO on an energy
  model, for rollouts.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ibc_tutorial.kde import DEFAULT_BANDWIDTH
from ibc_tutorial.optimizers import EnergyPolicy, embedded_energy, eval_mode
from ibc_tutorial.optimizers.common import (  # INITS and the initialisation: importable from here too
    INITS,
    check_call,
    check_expert_actions,
    check_search_settings,
    energies,
    initial_samples,
    initial_weights,
    multinomial,
    prepare_call,
    select_action,
)
from ibc_tutorial.utils import check_positive, draw_device

__all__ = [
    "INITS",
    "DFOConfig",
    "DFOTrace",
    "DFOOptimizer",
    "DFOPolicy",
    "dfo",
    "dfo_policy",
    "dfo_trace",
    "initial_samples",
    "initial_weights",
]


@dataclass(frozen=True)
class DFOConfig:
    """Settings of Algorithm 1 of the DA-IBC paper; the defaults are the paper's (sec. 4.2).

    Validated once, when built. ``low``/``high`` may be numbers or one number per action
    dimension; that their length matches the actions' D is checked when DFO runs.
    """

    n_samples: int = 16384
    """N_samples, the population size N (the paper: 16,384)."""
    n_iters: int = 5
    """N_iters, the number of energy evaluations of the population (the paper: 5)."""
    sigma_init: float = 0.5
    """σ_init, the standard deviation of the first noise, added after the first resampling (the paper: 0.5).
    """
    shrink: float = 0.5
    """K, the factor shrinking σ after each iteration, σ ← K σ (the paper: 0.5)."""
    low: float | tuple[float, ...] = -1.0
    """y_min, the lower bound of the action box (a number, or one per action dimension)."""
    high: float | tuple[float, ...] = 1.0
    """y_max, the upper bound of the action box (a number, or one per action dimension)."""
    bandwidth: float = DEFAULT_BANDWIDTH
    """h, the KDE bandwidth of the "kde" and "inverse-kde" initialisations (the paper: 0.2)."""
    init: str = "inverse-kde"
    """Initialisation (line 2): "inverse-kde" (the paper's text), "kde" (its Algorithm 1 as printed),
    "expert" (plain draws of expert actions, q ≈ ĝ) or "uniform" (IBC)."""
    select: str = "sample"
    """Final choice (line 14): "sample" ŷ ~ Categorical({ỹ_i}, {p̃_i}) (the paper) or "argmax" (IBC)."""

    def __post_init__(self) -> None:
        check_search_settings(self)  # n_samples, n_iters, bandwidth, init, select, low, high
        set_ = object.__setattr__  # frozen: normalise the fields once, here
        set_(self, "sigma_init", check_positive("sigma_init", self.sigma_init, allow_zero=True))
        set_(self, "shrink", check_positive("shrink", self.shrink, allow_zero=True))


@dataclass
class DFOTrace:
    """Algorithm 1 iteration by iteration, for one observation (what ``dfo_trace`` returns)."""

    samples: list[torch.Tensor]
    """Per iteration, the (N, D) population whose energies line 4 computes."""
    energies: list[torch.Tensor]
    """Per iteration, the (N,) energies E_i of that population."""
    probs: list[torch.Tensor]
    """Per iteration, the (N,) softmax probabilities p̃_i (line 5)."""
    sigmas: list[float]
    """Per iteration, the noise scale σ added after resampling (line 9); NaN for the last iteration."""
    action: torch.Tensor
    """(D,) the returned action ŷ."""
    energy_evaluations: int
    """Number of energy evaluations, N × N_iters: the cost of one decision."""
    config: DFOConfig
    """The settings the trace was run with (``config.select`` tells how ``action`` was chosen)."""


# --------------------------------------------------------------------------- lines 3-14
def _dfo_core(energy_fn, y: torch.Tensor, config: DFOConfig, lo, hi, generator, record: bool):
    """Algorithm 1 of the DA-IBC paper from line 3 on, for B observations at once.

    y: (B, N, D) the initial population of line 2. Returns (ŷ (B, D), per-iteration records or None).
    """
    b, n, d = y.shape
    lo, hi, where = lo.to(y.device), hi.to(y.device), draw_device(generator)  # bounds (D,) on y's device
    n_iters = config.n_iters
    sigma = config.sigma_init  # line 2: σ = σ_init
    rec = {"samples": [], "energies": [], "probs": [], "sigmas": []} if record else None
    for it in range(1, n_iters + 1):  # line 3: for iter = 1, 2, ..., N_iters
        e = energies(energy_fn, y)  # line 4: E_i = E_θ(x, ỹ_i)                      (B, N)
        p = torch.softmax(-e, dim=1)  # line 5: p̃_i = exp(−E_i) / Σ_j exp(−E_j)        (B, N)
        if rec is not None:
            rec["samples"].append(y.clone())
            rec["energies"].append(e.clone())
            rec["probs"].append(p.clone())
            rec["sigmas"].append(sigma if it < n_iters else float("nan"))
        if it < n_iters:  # line 6
            # lines 7-8: resample N_samples with replacement, Multinomial(N_samples, {p̃_i}, {ỹ_i})
            idx = multinomial(p, n, generator, replacement=True)  # (B, N)
            y = torch.gather(y, 1, idx[:, :, None].expand(b, n, d))  # (B, N, D)
            # line 9: add noise N(0, σ) (σ is a standard deviation, as in the IBC reference)
            y = y + sigma * torch.randn(y.shape, generator=generator, device=where).to(y.device)
            # line 10: clip to [y_min, y_max]. Samples the noise pushed out of the box are clamped
            # onto its faces, as the IBC reference does (tf.clip_by_value): they are not redrawn.
            y = torch.clamp(y, lo, hi)  # (B, N, D), bounds (D,)
            sigma = config.shrink * sigma  # line 11: σ ← K σ
    return select_action(y, p, config.select, generator), rec  # line 14


def dfo(
    energy_fn,
    expert_actions: torch.Tensor,
    config: DFOConfig = DFOConfig(),
    *,
    n_obs: int | None = None,
    init_weights: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Derivative-free optimisation, Algorithm 1 of the DA-IBC paper.

    Line 2 draws N_samples initial actions; then N_iters times: compute their energies (line 4)
    and softmax probabilities p̃_i ∝ exp(−E_i) (line 5); except in the last iteration, resample
    N_samples of them with replacement by p̃ (lines 7-8), add Gaussian noise of standard
    deviation σ (line 9), clip to [low, high] (line 10) and shrink σ ← K σ (line 11). Finally
    ŷ ~ Categorical({ỹ_i}, {p̃_i}) of the last iteration (line 14; ``select="argmax"`` takes the
    most probable sample instead, as the original IBC does).

    **The initial weights: the paper contradicts itself.** Its text (sec. 2.4.1) draws the
    initial samples from the expert actions with weights w_i = 1 / ĝ(y_i^expert), the inverse
    KDE of sec. 2.5; its Algorithm 1, line 2, prints w_i ∝ KDE(y_i^expert). The two are very
    different priors: expert actions are already distributed like ĝ, so "kde" weights draw
    actions roughly like ĝ², piling the samples onto the most common actions (driving
    straight on), while "inverse-kde" weights draw them roughly uniformly over the region where
    experts acted, rare turns included. Both are here (``init="inverse-kde"`` / ``"kde"``),
    beside the original IBC's ``init="uniform"`` over the box. The default is the text's
    "inverse-kde": in chapter 06 it reaches the valleys of rare actions with few samples where
    "kde" misses them, and it does not bias the choice between modes towards the frequent one.
    On trained DA-IBC models (whose exp(−E) ∝ p/ĝ) chapter 06 measures the initialisations
    nearly tied at the paper's five rounds; with one round, ``init="expert"`` (w_i = 1/M, draws
    distributed like ĝ) undoes the 1/ĝ tilt and reproduces the expert's choices best.

    **Bounds.** Noise can push samples out of [low, high]; they are clamped onto the bounds
    (Algorithm 1 line 10, as the IBC reference's ``tf.clip_by_value``), so the returned action
    always lies inside the box. Expert actions must lie inside it.

    **One observation or B.** With ``n_obs=None``, ``energy_fn`` maps candidate actions (N, D)
    to energies (N,) for the observation at hand and the result is (D,). With ``n_obs=B``,
    ``energy_fn`` maps (B, N, D) to (B, N) (row b scored against observation b) and the result
    is (B, D). The first is the second with B = 1: same core, same draws.

    Args:
        energy_fn: the energies of candidate actions (lower = better), called N_iters times.
        expert_actions: (M, D) expert actions: the support of the initialisation (and D).
        config: the settings (``DFOConfig``; the paper's by default).
        n_obs: None (one observation) or B.
        init_weights: optional precomputed (M,) weights from ``initial_weights`` (skips the KDE).
        generator: a seeded ``torch.Generator`` for reproducible draws.

    Returns:
        (D,) the action ŷ, or (B, D) one per observation.
    """
    fn, y, lo, hi = prepare_call(energy_fn, expert_actions, config, DFOConfig, n_obs, init_weights, generator)
    with torch.no_grad():
        action, _ = _dfo_core(fn, y, config, lo, hi, generator, record=False)  # (B, D)
    return action[0] if n_obs is None else action


def dfo_trace(
    energy_fn,
    expert_actions: torch.Tensor,
    config: DFOConfig = DFOConfig(),
    *,
    init_weights: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> DFOTrace:
    """``dfo`` for one observation (``energy_fn``: (N, D) -> (N,)), also returning every iteration's
    population.

    Same arguments and the same draws as ``dfo``: with equally seeded generators,
    ``dfo_trace(...).action`` equals ``dfo(...)``. For figures and widgets.
    """
    fn, y, lo, hi = prepare_call(energy_fn, expert_actions, config, DFOConfig, None, init_weights, generator)
    with torch.no_grad():
        action, rec = _dfo_core(fn, y, config, lo, hi, generator, record=True)  # y, action: (1, N, D), (1, D)
    return DFOTrace(
        samples=[s[0] for s in rec["samples"]],
        energies=[e[0] for e in rec["energies"]],
        probs=[p[0] for p in rec["probs"]],
        sigmas=rec["sigmas"],
        action=action[0],
        energy_evaluations=config.n_samples * config.n_iters,
        config=config,
    )


# --------------------------------------------------------------------------- on an energy model
class DFOOptimizer:
    """Algorithm 1 on an energy model, an ``ActionOptimizer``: expert actions and weights fixed once.

    Args:
        expert_actions: (M, D) expert actions (the initialisation's support).
        config: the settings.
        init_weights: optional precomputed (M,) initial weights; by default computed here, once
            (``initial_weights``).
    """

    def __init__(
        self,
        expert_actions: torch.Tensor,
        config: DFOConfig = DFOConfig(),
        *,
        init_weights: torch.Tensor | None = None,
    ):
        bounds_ = check_call(expert_actions, config, DFOConfig)
        check_expert_actions(expert_actions, *bounds_)
        self.expert_actions, self.config = expert_actions, config
        self.init_weights = initial_weights(expert_actions, config) if init_weights is None else init_weights

    @torch.no_grad()
    def infer(self, model, obs, *, generator: torch.Generator | None = None) -> torch.Tensor:
        """(B, D) actions for a batch of B observations (a tensor, or a dict of tensors).

        Each observation is embedded once (``model.embed``); only the action part of the head
        runs per candidate (``model.energy_from_embedding``), with the model in eval mode: the
        decision of a ``DFOPolicy``.
        """
        return DFOPolicy(model, self, generator)(obs)  # (B, D)


@torch.no_grad()
def act_with_dfo(
    model,
    obs,
    expert_actions: torch.Tensor,
    config: DFOConfig,
    *,
    init_weights: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Algorithm 1's decisions (B, D) for a batch of B observations of an embedding energy model: each
    observation embedded once (``model.embed``), only the action part of the head run per candidate.

    The decision of a ``DFOPolicy`` and of the driving ``Agent``; the model's mode is the caller's."""
    energy_fn, n_obs = embedded_energy(model, obs)  # (B, N, D) -> (B, N)
    return dfo(  # Algorithm 1 of the DA-IBC paper
        energy_fn, expert_actions, config, n_obs=n_obs, init_weights=init_weights, generator=generator
    )  # (B, D)


class DFOPolicy(EnergyPolicy):
    """``dfo_policy``'s closed-loop policy: ``policy(obs) -> dfo(...)``, (B, D), on a ``DFOOptimizer``'s
    expert actions, settings and initial weights, with the model in eval mode for each decision."""

    optimizer: DFOOptimizer

    @torch.no_grad()
    def __call__(self, obs) -> torch.Tensor:
        opt = self.optimizer
        with eval_mode(self.model):
            return act_with_dfo(
                self.model,
                obs,
                opt.expert_actions,
                opt.config,
                init_weights=opt.init_weights,
                generator=self.generator,
            )  # (B, D)


def dfo_policy(
    model,
    expert_actions: torch.Tensor,
    config: DFOConfig = DFOConfig(),
    *,
    init_weights: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> DFOPolicy:
    """A closed-loop policy ``policy(obs) -> actions (B, D)`` running ``dfo`` on ``model`` in eval mode.

    ``model`` is an energy model with ``embed(obs) -> z`` and ``energy_from_embedding(z, actions
    (B, N, D)) -> (B, N)`` (see ``DFOOptimizer.infer``); ``obs`` is a batch of observations, a
    tensor or a dict of tensors. The initial weights over ``expert_actions`` are computed once,
    here. The model is put in eval mode for each decision and restored after it
    (``DFOPolicy``: an ``optimizers.EnergyPolicy`` with a ``DFOOptimizer`` that calls ``dfo`` itself).
    """
    return DFOPolicy(model, DFOOptimizer(expert_actions, config, init_weights=init_weights), generator)
