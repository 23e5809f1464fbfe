"""Gradient-based inference of the original IBC paper (Florence et al. 2022), chapter 06.

- ``LangevinConfig``: the settings of the IBC reference's "Langevin MCMC" (its defaults).
- ``langevin``: one call for one observation (``n_obs=None``) or B observations (``n_obs=B``).
- ``langevin_trace``: the same draws for one observation, keeping the population after every step.
- ``polynomial_schedule``: the step size ε_k of each step.

**What it is.** The IBC reference's update is annealed noisy gradient descent,

    y ← clip(y − clip(ε_k (½ ∂E/∂y + noise_scale · n), ±delta_clip), low, high),  n ~ N(0, I),

whose noise is scaled by ε_k, not by √(2 η) for its gradient step η = ε_k / 2 as in the
unadjusted Langevin algorithm (ULA). With ε_k ≪ 1 the noise is far smaller than ULA's, so the
chains descend into the minima and stay there: it anneals rather than samples, and its
population is *not* a sample of p(y | x) ∝ exp(−E(x, y)). ``LangevinConfig.noise="ula"`` swaps
in ULA's noise, √(2 · ε_k/2) · n = √ε_k · n, for which the chains (with small steps and no clip
binding) do sample exp(−E).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from ibc_tutorial.kde import DEFAULT_BANDWIDTH
from ibc_tutorial.optimizers.common import (
    check_search_settings,
    energies,
    prepare_call,
    select_action,
)
from ibc_tutorial.utils import check_choice, check_int, check_positive, draw_device

NOISES = ("ibc", "ula")
"""The noise of a step: "ibc" ε_k · n (the IBC reference) or "ula" √ε_k · n (unadjusted Langevin)."""


@dataclass(frozen=True)
class LangevinConfig:
    """Settings of the IBC reference's Langevin MCMC; the defaults are the reference's.

    Validated once, when built. ``low``, ``high``, ``bandwidth``, ``init`` and ``select`` mean
    what they mean in ``DFOConfig``.
    """

    n_samples: int = 1024
    """N, the number of chains (each step costs a forward and a backward pass per chain)."""
    n_iters: int = 25
    """Number of Langevin steps (the reference: 25)."""
    step_init: float = 1e-1
    """ε of the first step (the reference's polynomial schedule: 1e-1)."""
    step_final: float = 1e-5
    """ε of the last step (the reference: 1e-5)."""
    power: float = 2.0
    """Power of the polynomial decay of ε (the reference: 2)."""
    noise_scale: float = 1.0
    """Scale of the Gaussian noise inside the step (the reference: 1.0)."""
    delta_clip: float = 0.1
    """Largest move per step and dimension, as a fraction of the half-range (the reference: 0.1)."""
    low: float | tuple[float, ...] = -1.0
    """Lower bound of the action box (a number, or one per action dimension)."""
    high: float | tuple[float, ...] = 1.0
    """Upper bound of the action box (a number, or one per action dimension)."""
    bandwidth: float = DEFAULT_BANDWIDTH
    """h, the KDE bandwidth of the "kde" and "inverse-kde" initialisations."""
    init: str = "uniform"
    """Initial chains: "uniform" in the box (IBC), or "kde"/"inverse-kde" draws of expert actions as in DFO.
    """
    select: str = "argmax"
    """Final choice from the last energies: "argmax" (IBC's greedy evaluation) or "sample" (as Algorithm 1
    line 14)."""
    noise: str = "ibc"
    """"ibc": noise ε_k · n (the reference: annealing, not sampling); "ula": √ε_k · n (samples exp(−E))."""

    def __post_init__(self) -> None:
        check_search_settings(self)  # n_samples, n_iters, bandwidth, init, select, low, high: as DFOConfig's
        set_ = object.__setattr__  # frozen: normalise the fields once, here
        for name in ("step_init", "step_final", "delta_clip"):
            set_(self, name, check_positive(name, getattr(self, name)))
        for name in ("power", "noise_scale"):
            set_(self, name, check_positive(name, getattr(self, name), allow_zero=True))
        check_choice("noise", self.noise, NOISES)


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
    """Energy evaluations: N per step (each with a backward pass for the gradient) plus N for the final
    choice."""
    gradient_evaluations: int
    """Gradient evaluations dE/dy: N per step."""
    config: LangevinConfig
    """The settings the trace was run with."""


def polynomial_schedule(
    step: int, n_steps: int, init: float = 1e-1, final: float = 1e-5, power: float = 2.0
) -> float:
    """Step size ε of Langevin step ``step`` (0-based) of ``n_steps``: the IBC paper's polynomial decay.

    ε_k = (ε_init − ε_final) · (1 − k / (n_steps − 1))^power + ε_final, from ε_init at the first step
    to ε_final at the last (the IBC reference's ``PolynomialSchedule``: 1e-1 to 1e-5, power 2).
    """
    check_int("n_steps", n_steps, minimum=1)
    check_int("step", step, minimum=0, maximum=n_steps - 1)
    if n_steps == 1:
        return float(init)
    return float((init - final) * (1.0 - step / (n_steps - 1)) ** power + final)


def _langevin_core(energy_fn, y: torch.Tensor, config: LangevinConfig, lo, hi, generator, record: bool):
    """Langevin MCMC of the IBC reference for B observations: y (B, N, D) -> (ŷ (B, D), records).

    The noise is drawn with ``generator`` on its own device (``utils.draw_device``) and moved to y's, as
    DFO's is: a run on a GPU draws the same numbers from the same seeded CPU generator as on the CPU."""
    c = config
    lo, hi, where = lo.to(y.device), hi.to(y.device), draw_device(generator)  # bounds (D,) on y's device
    max_delta = (
        c.delta_clip * 0.5 * (hi - lo)
    )  # (D,) the reference scales the clip as if actions were in [-1, 1]
    rec = {"samples": [y.detach().clone()], "steps": []} if record else None
    for k in range(c.n_iters):
        eps = polynomial_schedule(k, c.n_iters, c.step_init, c.step_final, c.power)
        with torch.enable_grad():
            yk = y.detach().requires_grad_(True)
            e = energies(energy_fn, yk)  # (B, N)
            (grad,) = torch.autograd.grad(e.sum(), yk)  # (B, N, D) dE/dy for each candidate
        n = torch.randn(y.shape, generator=generator, device=where).to(y.device)  # (B, N, D) n ~ N(0, I)
        if c.noise == "ibc":
            delta = eps * (0.5 * grad + c.noise_scale * n)  # the reference's langevin_step
        else:
            delta = (
                eps * 0.5 * grad + math.sqrt(eps) * c.noise_scale * n
            )  # ULA: gradient step η = ε/2, noise √(2η)
        delta = torch.clamp(delta, -max_delta, max_delta)  # clip each move to ±delta_clip of the half-range
        y = torch.clamp(y.detach() - delta, lo, hi)  # stay inside the box
        if rec is not None:
            rec["samples"].append(y.clone())
            rec["steps"].append(eps)
    with torch.no_grad():
        p = torch.softmax(-energies(energy_fn, y), dim=1)  # (B, N) the final probabilities
        return select_action(y, p, c.select, generator), rec


def langevin(
    energy_fn,
    expert_actions: torch.Tensor,
    config: LangevinConfig = LangevinConfig(),
    *,
    n_obs: int | None = None,
    init_weights: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Gradient-based inference by the IBC reference's "Langevin MCMC" (see the module docstring).

    N chains (uniform in the box by default, as in IBC) each take ``n_iters`` steps of the
    update above, with ε_k decaying polynomially from ``step_init`` to ``step_final``
    (``polynomial_schedule``; the reference's 1e-1, 1e-5, power 2, 25 steps, moves clipped to
    0.1 of the half-range). Then the final energies give softmax probabilities and ``select``
    picks the action. With the default ``noise="ibc"`` this is annealed noisy gradient descent,
    not a sampler of exp(−E); ``noise="ula"`` makes it the unadjusted Langevin algorithm.

    Args:
        energy_fn: differentiable in the actions; with ``n_obs=None`` maps (N, D) to (N,), with
            ``n_obs=B`` maps (B, N, D) to (B, N), as in ``dfo``.
        expert_actions: (M, D) expert actions: D, and the support of "kde"/"inverse-kde" inits.
        config: the settings (``LangevinConfig``; the reference's by default).
        n_obs: None (one observation) or B.
        init_weights, generator: as in ``dfo``.

    Returns:
        (D,) the action ŷ, or (B, D) one per observation.
    """
    fn, y, lo, hi = prepare_call(
        energy_fn, expert_actions, config, LangevinConfig, n_obs, init_weights, generator
    )
    action, _ = _langevin_core(fn, y, config, lo, hi, generator, record=False)
    action = action.detach()  # (B, D)
    return action[0] if n_obs is None else action


def langevin_trace(
    energy_fn,
    expert_actions: torch.Tensor,
    config: LangevinConfig = LangevinConfig(),
    *,
    init_weights: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> LangevinTrace:
    """``langevin`` for one observation, also returning the population after every step (same draws)."""
    fn, y, lo, hi = prepare_call(
        energy_fn, expert_actions, config, LangevinConfig, None, init_weights, generator
    )
    action, rec = _langevin_core(fn, y, config, lo, hi, generator, record=True)  # y: (1, N, D)
    return LangevinTrace(
        samples=[s[0] for s in rec["samples"]],
        step_sizes=rec["steps"],
        action=action[0].detach(),
        energy_evaluations=config.n_samples * (config.n_iters + 1),
        gradient_evaluations=config.n_samples * config.n_iters,
        config=config,
    )
