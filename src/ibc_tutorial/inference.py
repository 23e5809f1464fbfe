"""Inference for energy models: the action an implicit policy takes is argmin_y E(x, y).

- ``grid_argmin``: exhaustive search over a grid of candidate actions (1-D or 2-D actions).
- ``dfo``: derivative-free optimisation, Algorithm 1 of the DA-IBC paper (chapter 06), for one
  observation; ``dfo_batch`` for B observations at once (closed loop), ``dfo_trace`` keeping every
  iteration's population, ``dfo_policy`` wrapping an energy model for rollouts,
  ``dfo_init_weights``/``initial_samples`` for its initialisation (line 2).
- ``langevin``: gradient-based MCMC of the original IBC paper (chapter 06), with ``langevin_batch``,
  ``langevin_trace`` and its step-size schedule ``polynomial_schedule``.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ibc_tutorial.kde import kde_density
from ibc_tutorial.utils import check_choice, check_int, check_positive, check_tensor


def action_grid(n_per_dim: int, action_dim: int = 1, low: float = -1.0, high: float = 1.0) -> torch.Tensor:
    """A regular grid of candidate actions: (n_per_dim ** action_dim, action_dim)."""
    check_int("n_per_dim", n_per_dim, minimum=2)
    check_int("action_dim", action_dim, minimum=1, maximum=2)
    if not low < high:
        raise ValueError(f"low must be < high, got low={low}, high={high}")
    axis = torch.linspace(low, high, n_per_dim)
    if action_dim == 1:
        return axis[:, None]  # (G, 1)
    gx, gy = torch.meshgrid(axis, axis, indexing="ij")
    return torch.stack([gx.reshape(-1), gy.reshape(-1)], dim=-1)  # (G, 2)


# =========================================================================== grid argmin (chapter 03)
CHUNK_ELEMENTS = 1 << 20
"""``grid_energies`` scores at most about this many (observation, candidate, hidden unit)
activations at once: small blocks stay in the CPU's cache and run several times faster
than one huge (B, G, H) tensor, which is bound by memory bandwidth."""


def grid_energies(model, z: torch.Tensor, grid: torch.Tensor, *, chunk_elements: int = CHUNK_ELEMENTS) -> torch.Tensor:
    """Energies of a shared grid of candidates for embeddings ``z`` (B, E), in blocks of observations.

    Same result as ``model.energy_from_embedding(z, grid)`` (B, G), computed over blocks of
    observations so that each block holds about ``chunk_elements`` hidden activations.
    """
    check_int("chunk_elements", chunk_elements, minimum=1)
    hidden = int(getattr(model, "hidden", 1))
    rows = max(1, chunk_elements // max(1, len(grid) * hidden))
    return torch.cat([model.energy_from_embedding(block, grid) for block in z.split(rows)], dim=0)  # (B, G)


@torch.no_grad()
def grid_argmin(model, obs, grid: torch.Tensor, *, return_energies: bool = False):
    """ŷ = argmin over a fixed grid of E(x, y): exhaustive inference for 1-D or 2-D actions.

    The steering-EBM paper's inference (its sec. 3 and Fig. 3, right): every candidate of a
    constant, linearly spaced grid is scored and the lowest energy wins (eq. 1 of that paper).
    The observation is encoded once (``model.embed``) and the grid, shared by every
    observation, is scored against the embedding (``model.energy_from_embedding``), so the
    cost per candidate is only the energy model's action head.

    Args:
        model: an ``EnergyModel`` (anything with ``embed`` and ``energy_from_embedding``).
        obs: a batch of B observations (tensor, or dict of tensors).
        grid: (G, D) candidate actions, e.g. ``action_grid(201)``.
        return_energies: also return the (B, G) energies.
    Returns:
        (B, D) actions, or ``(actions, energies)``.
    """
    check_tensor("grid", grid, ndim=2)
    if len(grid) < 1:
        raise ValueError("grid must hold at least one candidate action")
    z = model.embed(obs)  # (B, E), once per observation
    energies = grid_energies(model, z, grid)  # (B, G), in cache-sized blocks
    best = energies.argmin(dim=1)  # (B,)
    actions = grid[best]  # (B, D)
    return (actions, energies) if return_energies else actions


# =========================================================================== DFO and Langevin (chapter 06)
# Energy functions come in two forms:
#   single observation: energy_fn(actions (N, D)) -> (N,)      used by dfo, dfo_trace, langevin
#   B observations:     energy_fn(actions (B, N, D)) -> (B, N)  used by dfo_batch, langevin_batch
# For an EnergyModel: z = model.embed(obs) once, then energy_fn = lambda a: model.energy_from_embedding(z, a).
# The single form is the batched one with B = 1: both run the same core.

DFO_INITS = ("uniform", "kde", "inverse-kde")
"""Initialisations of Algorithm 1: "uniform" (original IBC), "kde" (Algorithm 1 line 2 as printed:
w_i ∝ KDE(y_i)) and "inverse-kde" (the DA-IBC paper's text, sec. 2.4.1: w_i = 1 / ĝ(y_i))."""

SELECTIONS = ("sample", "argmax")
"""Final choice: "sample" ŷ ~ Categorical({ỹ_i}, {p̃_i}) (Algorithm 1 line 14) or "argmax" (original IBC)."""


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


@dataclass
class LangevinTrace:
    """Langevin MCMC step by step, for one observation (what ``langevin_trace`` returns)."""

    samples: list[torch.Tensor]
    """(N, D) populations: the initial one, then the one after each step."""
    step_sizes: list[float]
    """The step size ε of each step (the polynomial schedule)."""
    action: torch.Tensor
    """(D,) the returned action ŷ."""
    energy_evaluations: int
    """Energy evaluations: N per step (each with a backward pass for the gradient) plus N for the final choice."""
    gradient_evaluations: int
    """Gradient evaluations dE/dy: N per step."""


def _bounds(low, high, d: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``low``/``high`` (floats, or sequences of length D) as (D,) float32 tensors with low < high."""
    lo = torch.as_tensor(low, dtype=torch.float32).reshape(-1)
    hi = torch.as_tensor(high, dtype=torch.float32).reshape(-1)
    for name, t in (("low", lo), ("high", hi)):
        if t.numel() not in (1, d):
            raise ValueError(f"{name} must be a number or have one entry per action dimension (D = {d}), got {t.numel()} entries")
        if not torch.isfinite(t).all():
            raise ValueError(f"{name} must be finite, got {t.tolist()}")
    lo, hi = lo.expand(d).clone(), hi.expand(d).clone()
    if not (lo < hi).all():
        raise ValueError(f"low must be < high in every action dimension, got low={lo.tolist()}, high={hi.tolist()}")
    return lo, hi


def _check_expert_actions(expert_actions: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    if ((expert_actions < lo) | (expert_actions > hi)).any():
        raise ValueError(f"expert_actions must lie inside [low, high] = [{lo.tolist()}, {hi.tolist()}]")
    return expert_actions.detach().to(torch.float32)


def dfo_init_weights(expert_actions: torch.Tensor, init: str = "inverse-kde", bandwidth: float = 0.2) -> torch.Tensor | None:
    """The Categorical weights over expert actions of Algorithm 1 line 2; None for ``init="uniform"``.

    "kde": w_i ∝ ĝ(y_i) (the algorithm as printed); "inverse-kde": w_i ∝ 1 / ĝ(y_i) (the text).
    Computing them costs a KDE over the M expert actions (M² kernel evaluations): closed-loop
    code computes them once and passes them to ``dfo``/``dfo_batch`` as ``init_weights``.

    Returns:
        (M,) weights summing to 1, or None.
    """
    check_tensor("expert_actions", expert_actions, ndim=2)
    check_choice("init", init, DFO_INITS)
    if init == "uniform":
        return None
    g = kde_density(expert_actions, expert_actions, bandwidth).to(torch.float64)  # (M,) ĝ(y_i), eq. 4
    w = g if init == "kde" else 1.0 / g
    return (w / w.sum()).to(torch.float32)


def initial_samples(
    expert_actions: torch.Tensor,
    n_obs: int,
    n_samples: int,
    *,
    init: str = "inverse-kde",
    low=-1.0,
    high=1.0,
    bandwidth: float = 0.2,
    init_weights: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """The initial population {ỹ_i} of Algorithm 1 line 2, for ``n_obs`` observations: (B, N, D).

    "uniform": ỹ_i ~ U(low, high) (original IBC). "kde"/"inverse-kde": ỹ_i ~ Categorical({y_i^expert},
    {w_i}) with the weights of ``dfo_init_weights`` (or the given ``init_weights``): copies of
    expert actions, no noise yet (the first noise comes after the first resampling, line 9).
    """
    check_tensor("expert_actions", expert_actions, ndim=2)
    check_int("n_obs", n_obs, minimum=1)
    check_int("n_samples", n_samples, minimum=1)
    check_choice("init", init, DFO_INITS)
    m, d = expert_actions.shape
    if m == 0:
        raise ValueError("expert_actions must hold at least one action (M >= 1)")
    lo, hi = _bounds(low, high, d)
    experts = _check_expert_actions(expert_actions, lo, hi)
    if init == "uniform":
        u = torch.rand(n_obs, n_samples, d, generator=generator)  # (B, N, D)
        return lo + (hi - lo) * u
    if init_weights is None:
        init_weights = dfo_init_weights(experts, init, bandwidth)
    else:
        check_tensor("init_weights", init_weights, shape=(m,))
        if (init_weights < 0).any() or init_weights.sum() <= 0:
            raise ValueError("init_weights must be non-negative with a positive sum")
    idx = torch.multinomial(init_weights, n_obs * n_samples, replacement=True, generator=generator)  # (B·N,)
    return experts[idx].reshape(n_obs, n_samples, d)  # (B, N, D)


def _energies(energy_fn, y: torch.Tensor) -> torch.Tensor:
    """Call a batched ``energy_fn`` on (B, N, D) candidates and check it returns finite (B, N)."""
    e = energy_fn(y)
    if not isinstance(e, torch.Tensor) or tuple(e.shape) != tuple(y.shape[:2]):
        got = tuple(e.shape) if isinstance(e, torch.Tensor) else type(e).__name__
        raise ValueError(f"energy_fn must return one energy per candidate action, shape {tuple(y.shape[:2])}, got {got}")
    if not torch.isfinite(e).all():
        raise ValueError("energy_fn returned NaN or inf energies")
    return e.to(torch.float32)


def _select(y: torch.Tensor, p: torch.Tensor, select: str, generator) -> torch.Tensor:
    """Line 14 of Algorithm 1 ("sample") or the original argmax: y (B, N, D), p (B, N) -> (B, D)."""
    if select == "sample":
        j = torch.multinomial(p, 1, generator=generator)[:, 0]  # (B,) ŷ ~ Categorical({ỹ_i}, {p̃_i})
    else:
        j = p.argmax(dim=1)  # (B,) the lowest energy
    return y[torch.arange(len(y)), j]  # (B, D)


def _dfo_core(energy_fn, y, *, n_iters, sigma_init, shrink, lo, hi, select, generator, record):
    """Algorithm 1 of the DA-IBC paper from line 3 on, for B observations at once.

    y: (B, N, D) the initial population of line 2. Returns (ŷ (B, D), per-iteration records or None).
    """
    b, n, d = y.shape
    sigma = sigma_init  # line 2: σ = σ_init
    rec = {"samples": [], "energies": [], "probs": [], "sigmas": []} if record else None
    for it in range(1, n_iters + 1):  # line 3: for iter = 1, 2, ..., N_iters
        e = _energies(energy_fn, y)  # line 4: E_i = E_θ(x, ỹ_i)                      (B, N)
        p = torch.softmax(-e, dim=1)  # line 5: p̃_i = exp(−E_i) / Σ_j exp(−E_j)        (B, N)
        if rec is not None:
            rec["samples"].append(y.clone())
            rec["energies"].append(e.clone())
            rec["probs"].append(p.clone())
            rec["sigmas"].append(sigma if it < n_iters else float("nan"))
        if it < n_iters:  # line 6
            # lines 7-8: resample N_samples with replacement, Multinomial(N_samples, {p̃_i}, {ỹ_i})
            idx = torch.multinomial(p, n, replacement=True, generator=generator)  # (B, N)
            y = torch.gather(y, 1, idx[:, :, None].expand(b, n, d))  # (B, N, D)
            # line 9: add noise N(0, σ) (σ is a standard deviation, as in the IBC reference)
            y = y + sigma * torch.randn(y.shape, generator=generator)
            # line 10: clip to [y_min, y_max]. Samples the noise pushed out of the box are clamped
            # onto its faces, as the IBC reference does (tf.clip_by_value): they are not redrawn.
            y = torch.maximum(torch.minimum(y, hi), lo)
            sigma = shrink * sigma  # line 11: σ ← K σ
    return _select(y, p, select, generator), rec  # line 14


def _check_dfo_args(expert_actions, n_samples, n_iters, sigma_init, shrink, low, high, init, select):
    check_tensor("expert_actions", expert_actions, ndim=2)
    check_int("n_samples", n_samples, minimum=1)
    check_int("n_iters", n_iters, minimum=1)
    check_positive("sigma_init", sigma_init, allow_zero=True)
    check_positive("shrink", shrink, allow_zero=True)
    check_choice("init", init, DFO_INITS)
    check_choice("select", select, SELECTIONS)
    return _bounds(low, high, expert_actions.shape[1])


def dfo_batch(
    energy_fn,
    expert_actions: torch.Tensor,
    n_obs: int,
    *,
    n_samples: int = 16384,
    n_iters: int = 5,
    sigma_init: float = 0.5,
    shrink: float = 0.5,
    low=-1.0,
    high=1.0,
    bandwidth: float = 0.2,
    init: str = "inverse-kde",
    select: str = "sample",
    init_weights: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Algorithm 1 of the DA-IBC paper for B observations at once (closed-loop rollouts).

    Same arguments as ``dfo``, except that ``energy_fn`` maps candidates (B, N, D) to energies
    (B, N) (row b scored against observation b) and ``n_obs`` = B.

    Returns:
        (B, D) one action per observation.
    """
    lo, hi = _check_dfo_args(expert_actions, n_samples, n_iters, sigma_init, shrink, low, high, init, select)
    with torch.no_grad():
        y = initial_samples(expert_actions, n_obs, n_samples, init=init, low=lo, high=hi, bandwidth=bandwidth, init_weights=init_weights, generator=generator)
        action, _ = _dfo_core(energy_fn, y, n_iters=n_iters, sigma_init=float(sigma_init), shrink=float(shrink), lo=lo, hi=hi, select=select, generator=generator, record=False)
    return action  # (B, D)


def _single(energy_fn):
    """Turn a single-observation energy_fn ((N, D) -> (N,)) into the batched form with B = 1."""

    def batched(y):  # (1, N, D) -> (1, N)
        e = energy_fn(y[0])
        if not isinstance(e, torch.Tensor) or tuple(e.shape) != (y.shape[1],):
            got = tuple(e.shape) if isinstance(e, torch.Tensor) else type(e).__name__
            raise ValueError(f"energy_fn must map actions (N, D) to energies (N,) = ({y.shape[1]},), got {got}")
        return e[None]

    return batched


def dfo(
    energy_fn,
    expert_actions: torch.Tensor,
    *,
    n_samples: int = 16384,
    n_iters: int = 5,
    sigma_init: float = 0.5,
    shrink: float = 0.5,
    low=-1.0,
    high=1.0,
    bandwidth: float = 0.2,
    init: str = "inverse-kde",
    select: str = "sample",
    init_weights: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Derivative-free optimisation, Algorithm 1 of the DA-IBC paper, for one observation.

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

    **Bounds.** Noise can push samples out of [low, high]; they are clamped onto the bounds
    (Algorithm 1 line 10, as the IBC reference's ``tf.clip_by_value``), so the returned action
    always lies inside the box. Expert actions must lie inside it.

    Args:
        energy_fn: maps candidate actions (N, D) to energies (N,) for the observation at hand
            (lower = better); called N_iters times on N candidates.
        expert_actions: (M, D) expert actions: the support of the initialisation (and D).
        n_samples: N_samples (the paper: 16,384).
        n_iters: N_iters (the paper: 5).
        sigma_init: σ_init, the standard deviation of the first noise (the paper: 0.5).
        shrink: K, the factor shrinking σ after each iteration (the paper: 0.5).
        low, high: y_min, y_max: numbers, or one per action dimension.
        bandwidth: h of the KDE for the "kde"/"inverse-kde" initialisations (the paper: 0.2).
        init: "inverse-kde" (the paper's text), "kde" (its Algorithm 1 line 2) or "uniform" (IBC).
        select: "sample" (the paper) or "argmax" (IBC).
        init_weights: optional precomputed (M,) weights from ``dfo_init_weights`` (skips the KDE).
        generator: a seeded ``torch.Generator`` for reproducible draws.

    Returns:
        (D,) the action ŷ.
    """
    return dfo_batch(
        _single(energy_fn), expert_actions, 1, n_samples=n_samples, n_iters=n_iters, sigma_init=sigma_init, shrink=shrink,
        low=low, high=high, bandwidth=bandwidth, init=init, select=select, init_weights=init_weights, generator=generator,
    )[0]


def dfo_trace(
    energy_fn,
    expert_actions: torch.Tensor,
    *,
    n_samples: int = 16384,
    n_iters: int = 5,
    sigma_init: float = 0.5,
    shrink: float = 0.5,
    low=-1.0,
    high=1.0,
    bandwidth: float = 0.2,
    init: str = "inverse-kde",
    select: str = "sample",
    init_weights: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> DFOTrace:
    """``dfo`` for one observation, also returning every iteration's population (for figures and widgets).

    Same arguments and the same draws as ``dfo``: with equally seeded generators,
    ``dfo_trace(...).action`` equals ``dfo(...)``.
    """
    lo, hi = _check_dfo_args(expert_actions, n_samples, n_iters, sigma_init, shrink, low, high, init, select)
    with torch.no_grad():
        y = initial_samples(expert_actions, 1, n_samples, init=init, low=lo, high=hi, bandwidth=bandwidth, init_weights=init_weights, generator=generator)
        action, rec = _dfo_core(_single(energy_fn), y, n_iters=n_iters, sigma_init=float(sigma_init), shrink=float(shrink), lo=lo, hi=hi, select=select, generator=generator, record=True)
    return DFOTrace(
        samples=[s[0] for s in rec["samples"]],
        energies=[e[0] for e in rec["energies"]],
        probs=[p[0] for p in rec["probs"]],
        sigmas=rec["sigmas"],
        action=action[0],
        energy_evaluations=n_samples * n_iters,
    )


def dfo_policy(model, expert_actions: torch.Tensor, *, generator: torch.Generator | None = None, **dfo_kwargs):
    """A closed-loop policy ``policy(obs (B, obs_dim)) -> actions (B, D)`` that runs ``dfo_batch`` on ``model``.

    ``model`` is an energy model with ``embed(obs) -> z`` and ``energy_from_embedding(z, actions
    (B, N, D)) -> (B, N)``: each observation is embedded once per decision and only the action
    part of the head runs per candidate. The initial weights over ``expert_actions`` are computed
    once, here. ``dfo_kwargs`` are those of ``dfo`` (n_samples, n_iters, init, select, ...).
    """
    check_tensor("expert_actions", expert_actions, ndim=2)
    init = dfo_kwargs.get("init", "inverse-kde")
    if dfo_kwargs.get("init_weights") is None:
        dfo_kwargs["init_weights"] = dfo_init_weights(expert_actions, init, dfo_kwargs.get("bandwidth", 0.2))

    def policy(obs: torch.Tensor) -> torch.Tensor:
        was_training = getattr(model, "training", False)
        if was_training:
            model.eval()
        try:
            with torch.no_grad():
                z = model.embed(obs)  # (B, embed) once per observation
                return dfo_batch(lambda a: model.energy_from_embedding(z, a), expert_actions, len(z), generator=generator, **dfo_kwargs)
        finally:
            if was_training:
                model.train()

    return policy


# --------------------------------------------------------------------------- Langevin MCMC (the original IBC)
def polynomial_schedule(step: int, n_steps: int, init: float = 1e-1, final: float = 1e-5, power: float = 2.0) -> float:
    """Step size ε of Langevin step ``step`` (0-based) of ``n_steps``: the IBC paper's polynomial decay.

    ε_k = (ε_init − ε_final) · (1 − k / (n_steps − 1))^power + ε_final, from ε_init at the first step
    to ε_final at the last (the IBC reference's ``PolynomialSchedule``: 1e-1 to 1e-5, power 2).
    """
    check_int("n_steps", n_steps, minimum=1)
    check_int("step", step, minimum=0, maximum=n_steps - 1)
    if n_steps == 1:
        return float(init)
    return float((init - final) * (1.0 - step / (n_steps - 1)) ** power + final)


def _langevin_core(energy_fn, y, *, n_iters, step_init, step_final, power, noise_scale, delta_clip, lo, hi, select, generator, record):
    """Langevin MCMC of the IBC reference for B observations: y (B, N, D) -> (ŷ (B, D), records)."""
    max_delta = delta_clip * 0.5 * (hi - lo)  # (D,) the reference scales the clip as if actions were in [-1, 1]
    rec = {"samples": [y.detach().clone()], "steps": []} if record else None
    for k in range(n_iters):
        eps = polynomial_schedule(k, n_iters, step_init, step_final, power)
        with torch.enable_grad():
            yk = y.detach().requires_grad_(True)
            e = _energies(energy_fn, yk)  # (B, N)
            (grad,) = torch.autograd.grad(e.sum(), yk)  # (B, N, D) dE/dy for each candidate
        # y ← y − ε (½ ∂E/∂y + noise_scale · n),  n ~ N(0, I): the reference's langevin_step
        delta = eps * (0.5 * grad + noise_scale * torch.randn(y.shape, generator=generator))
        delta = torch.maximum(torch.minimum(delta, max_delta), -max_delta)  # clip each move to ±delta_clip
        y = torch.maximum(torch.minimum(y.detach() - delta, hi), lo)  # stay inside the box
        if rec is not None:
            rec["samples"].append(y.clone())
            rec["steps"].append(eps)
    with torch.no_grad():
        p = torch.softmax(-_energies(energy_fn, y), dim=1)  # (B, N) the final probabilities
        return _select(y, p, select, generator), rec


def _check_langevin_args(expert_actions, n_samples, n_iters, step_init, step_final, power, noise_scale, delta_clip, low, high, init, select):
    check_tensor("expert_actions", expert_actions, ndim=2)
    check_int("n_samples", n_samples, minimum=1)
    check_int("n_iters", n_iters, minimum=1)
    check_positive("step_init", step_init)
    check_positive("step_final", step_final)
    check_positive("power", power, allow_zero=True)
    check_positive("noise_scale", noise_scale, allow_zero=True)
    check_positive("delta_clip", delta_clip)
    check_choice("init", init, DFO_INITS)
    check_choice("select", select, SELECTIONS)
    return _bounds(low, high, expert_actions.shape[1])


def langevin_batch(
    energy_fn,
    expert_actions: torch.Tensor,
    n_obs: int,
    *,
    n_samples: int = 1024,
    n_iters: int = 25,
    step_init: float = 1e-1,
    step_final: float = 1e-5,
    power: float = 2.0,
    noise_scale: float = 1.0,
    delta_clip: float = 0.1,
    low=-1.0,
    high=1.0,
    bandwidth: float = 0.2,
    init: str = "uniform",
    select: str = "argmax",
    init_weights: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Langevin MCMC for B observations at once; ``energy_fn`` maps (B, N, D) to (B, N) and must be differentiable.

    See ``langevin``. Returns (B, D).
    """
    lo, hi = _check_langevin_args(expert_actions, n_samples, n_iters, step_init, step_final, power, noise_scale, delta_clip, low, high, init, select)
    y = initial_samples(expert_actions, n_obs, n_samples, init=init, low=lo, high=hi, bandwidth=bandwidth, init_weights=init_weights, generator=generator)
    action, _ = _langevin_core(energy_fn, y, n_iters=n_iters, step_init=step_init, step_final=step_final, power=power, noise_scale=noise_scale,
                               delta_clip=delta_clip, lo=lo, hi=hi, select=select, generator=generator, record=False)
    return action.detach()


def langevin(
    energy_fn,
    expert_actions: torch.Tensor,
    *,
    n_samples: int = 1024,
    n_iters: int = 25,
    step_init: float = 1e-1,
    step_final: float = 1e-5,
    power: float = 2.0,
    noise_scale: float = 1.0,
    delta_clip: float = 0.1,
    low=-1.0,
    high=1.0,
    bandwidth: float = 0.2,
    init: str = "uniform",
    select: str = "argmax",
    init_weights: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Gradient-based inference by Langevin MCMC, as in the original IBC paper (Florence et al. 2022).

    N samples (uniform in the box by default, as in IBC) each take ``n_iters`` steps

        y ← clip(y − clip(ε_k (½ ∂E/∂y + noise_scale · n), ±delta_clip), low, high),  n ~ N(0, I),

    with the step size ε_k decaying polynomially from ``step_init`` to ``step_final``
    (``polynomial_schedule``; the IBC reference's defaults 1e-1, 1e-5, power 2, 25 steps, moves
    clipped to 0.1 of the half-range). This is the IBC reference's form: the noise is scaled by ε,
    not by √(2ε) as in textbook Langevin dynamics, so it anneals faster than it samples. Then the
    final energies give softmax probabilities and ``select`` picks the action ("argmax": IBC's
    greedy evaluation; "sample": as Algorithm 1 line 14).

    Args:
        energy_fn: maps (N, D) candidates to (N,) energies, differentiably in the actions.
        expert_actions: (M, D) expert actions: D, and the support of "kde"/"inverse-kde" inits.
        n_samples: N, the number of chains (each step costs a forward and a backward pass).
        n_iters: number of Langevin steps.
        step_init, step_final, power: the polynomial step-size schedule.
        noise_scale: scale of the Gaussian noise inside the step (1.0 in IBC).
        delta_clip: largest move per step and dimension, as a fraction of the half-range.
        low, high, bandwidth, init, select, init_weights, generator: as in ``dfo``.

    Returns:
        (D,) the action ŷ.
    """
    return langevin_batch(
        _single(energy_fn), expert_actions, 1, n_samples=n_samples, n_iters=n_iters, step_init=step_init, step_final=step_final,
        power=power, noise_scale=noise_scale, delta_clip=delta_clip, low=low, high=high, bandwidth=bandwidth, init=init,
        select=select, init_weights=init_weights, generator=generator,
    )[0]


def langevin_trace(
    energy_fn,
    expert_actions: torch.Tensor,
    *,
    n_samples: int = 1024,
    n_iters: int = 25,
    step_init: float = 1e-1,
    step_final: float = 1e-5,
    power: float = 2.0,
    noise_scale: float = 1.0,
    delta_clip: float = 0.1,
    low=-1.0,
    high=1.0,
    bandwidth: float = 0.2,
    init: str = "uniform",
    select: str = "argmax",
    init_weights: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> LangevinTrace:
    """``langevin`` for one observation, also returning the population after every step (same draws)."""
    lo, hi = _check_langevin_args(expert_actions, n_samples, n_iters, step_init, step_final, power, noise_scale, delta_clip, low, high, init, select)
    y = initial_samples(expert_actions, 1, n_samples, init=init, low=lo, high=hi, bandwidth=bandwidth, init_weights=init_weights, generator=generator)
    action, rec = _langevin_core(_single(energy_fn), y, n_iters=n_iters, step_init=step_init, step_final=step_final, power=power,
                                 noise_scale=noise_scale, delta_clip=delta_clip, lo=lo, hi=hi, select=select, generator=generator, record=True)
    return LangevinTrace(
        samples=[s[0] for s in rec["samples"]],
        step_sizes=rec["steps"],
        action=action[0].detach(),
        energy_evaluations=n_samples * (n_iters + 1),
        gradient_evaluations=n_samples * n_iters,
    )
