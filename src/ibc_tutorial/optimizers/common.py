"""What DFO and Langevin share: the action box, the initial population, the two forms of energy
function, the final choice.

- ``INITS``, ``initial_weights``, ``initial_samples``: the initialisation, Algorithm 1 line 2 of
  the DA-IBC paper (Langevin starts its chains the same way).
- ``check_search_settings``: the settings both configs share (population, iterations, bandwidth,
  initialisation, final choice, action box), checked in one place.

Energy functions come in two forms:

- single observation: ``energy_fn(actions (N, D)) -> (N,)``, what ``dfo(..., n_obs=None)`` takes;
- B observations: ``energy_fn(actions (B, N, D)) -> (B, N)``, row b scored against observation b.

For an ``EnergyModel``: ``z = model.embed(obs)`` once, then
``energy_fn = lambda a: model.energy_from_embedding(z, a)`` (the batched form). The single form
is the batched one with B = 1 (``single_observation``): both run the same core.

**Devices.** A population lives on the device of the expert actions it starts from (and the
energy function must return energies there). Random draws are made on the generator's device
(the CPU for a ``torch.Generator()``; ``utils.draw_device``) and moved: on a GPU, Algorithm 1
draws the same indices and noise from the same seeded generator as on the CPU.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from ibc_tutorial.kde import inverse_density_weights, kde_density
from ibc_tutorial.utils import check_box, check_choice, check_int, check_positive, check_tensor, draw_device

SELECTIONS = ("sample", "argmax")
"""Final choice: "sample" ŷ ~ Categorical({ỹ_i}, {p̃_i}) (Algorithm 1 line 14 of the DA-IBC paper)
or "argmax", the lowest energy (the original IBC)."""

INITS = ("uniform", "kde", "inverse-kde", "expert")
"""Initialisations of Algorithm 1: "uniform" (original IBC), "kde" (Algorithm 1 line 2 as printed:
w_i ∝ KDE(y_i)), "inverse-kde" (the DA-IBC paper's text, sec. 2.4.1: w_i = 1 / ĝ(y_i)) and
"expert" (every expert action equally likely, w_i = 1 / M: initial samples distributed like ĝ)."""


def config_box(low, high) -> tuple[float | tuple[float, ...], float | tuple[float, ...]]:
    """Validate the action box [low, high] of a config (``utils.check_box``): numbers, or one per dimension.

    Returns ``(low, high)`` as floats or tuples of floats, as given. Whether a tuple's length
    matches the actions' D is checked when the actions are known (``bounds``).
    """
    lo, hi = check_box(low, high, dtype=torch.float64)  # (D,), (D,)

    def as_given(v, t: torch.Tensor):
        v = v.tolist() if hasattr(v, "tolist") else v  # a tensor or an array: a number (0-d) or a list
        return tuple(float(x) for x in t) if isinstance(v, Sequence) else float(t[0])

    return as_given(low, lo), as_given(high, hi)


def check_search_settings(config) -> None:
    """Validate and normalise, in place, the fields every search's frozen config shares (``DFOConfig``,
    ``LangevinConfig``): the population ``n_samples`` and the iterations ``n_iters`` (integers >= 1), the
    KDE ``bandwidth`` (> 0), ``init`` (``INITS``), ``select`` (``SELECTIONS``) and the box ``low``,
    ``high`` (``config_box``)."""
    set_ = object.__setattr__  # frozen: the fields are normalised once, when the config is built
    set_(config, "n_samples", check_int("n_samples", config.n_samples, minimum=1))
    set_(config, "n_iters", check_int("n_iters", config.n_iters, minimum=1))
    set_(config, "bandwidth", check_positive("bandwidth", config.bandwidth))
    check_choice("init", config.init, INITS)
    check_choice("select", config.select, SELECTIONS)
    low, high = config_box(config.low, config.high)
    set_(config, "low", low)
    set_(config, "high", high)


def bounds(low, high, d: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``low``/``high`` (numbers, or sequences of length D) as (D,) tensors with low < high
    (``utils.check_box``).

    In torch's default dtype (float32 unless a chapter sets float64), like the populations.
    """
    return check_box(low, high, d)


def check_expert_actions(expert_actions: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """(M, D) expert actions inside [lo, hi], M >= 1, in the default dtype, without gradient (on their
    device)."""
    if len(expert_actions) == 0:
        raise ValueError("expert_actions must hold at least one action (M >= 1)")
    lo, hi = lo.to(expert_actions.device), hi.to(expert_actions.device)  # (D,), (D,)
    if ((expert_actions < lo) | (expert_actions > hi)).any():
        raise ValueError(f"expert_actions must lie inside [low, high] = [{lo.tolist()}, {hi.tolist()}]")
    return expert_actions.detach().to(torch.get_default_dtype())


def energies(energy_fn, y: torch.Tensor) -> torch.Tensor:
    """Call a batched ``energy_fn`` on (B, N, D) candidates and check it returns finite (B, N)."""
    e = energy_fn(y)
    if not isinstance(e, torch.Tensor) or tuple(e.shape) != tuple(y.shape[:2]):
        got = tuple(e.shape) if isinstance(e, torch.Tensor) else type(e).__name__
        raise ValueError(
            f"energy_fn must return one energy per candidate action, shape {tuple(y.shape[:2])}, got {got}"
        )
    if not torch.isfinite(e).all():
        raise ValueError("energy_fn returned NaN or inf energies")
    return e.to(y.dtype)  # (B, N), in the populations' dtype


def multinomial(
    p: torch.Tensor, n: int, generator: torch.Generator | None, replacement: bool = False
) -> torch.Tensor:
    """``torch.multinomial(p, n, replacement)``, drawn on the generator's device and returned on p's."""
    where = draw_device(generator)
    return torch.multinomial(p.to(where), n, replacement=replacement, generator=generator).to(p.device)


def select_action(
    y: torch.Tensor, p: torch.Tensor, select: str, generator: torch.Generator | None
) -> torch.Tensor:
    """Line 14 of Algorithm 1 ("sample") or the original argmax: y (B, N, D), p (B, N) -> (B, D)."""
    check_choice("select", select, SELECTIONS)
    if select == "sample":
        j = multinomial(p, 1, generator)[:, 0]  # (B,) ŷ ~ Categorical({ỹ_i}, {p̃_i})
    else:
        j = p.argmax(dim=1)  # (B,) the lowest energy
    return y[torch.arange(len(y), device=y.device), j.to(y.device)]  # (B, D)


def single_observation(energy_fn):
    """Turn a single-observation energy_fn ((N, D) -> (N,)) into the batched form with B = 1."""

    def batched(y: torch.Tensor) -> torch.Tensor:  # (1, N, D) -> (1, N)
        e = energy_fn(y[0])
        if not isinstance(e, torch.Tensor) or tuple(e.shape) != (y.shape[1],):
            got = tuple(e.shape) if isinstance(e, torch.Tensor) else type(e).__name__
            raise ValueError(
                f"energy_fn must map actions (N, D) to energies (N,) = ({y.shape[1]},), got {got}"
            )
        return e[None]

    return batched


def check_call(expert_actions: torch.Tensor, config, config_type: type) -> tuple[torch.Tensor, torch.Tensor]:
    """Check the arguments every optimizer call shares; return the action box ``bounds`` (lo,
    hi), each (D,)."""
    check_tensor("expert_actions", expert_actions, ndim=2)
    if not isinstance(config, config_type):
        raise ValueError(f"config must be a {config_type.__name__}, got {type(config).__name__}")
    return bounds(config.low, config.high, expert_actions.shape[1])


# --------------------------------------------------------------------------- line 2: the initial population
def initial_weights(expert_actions: torch.Tensor, config) -> torch.Tensor | None:
    """The Categorical weights over expert actions of Algorithm 1 line 2; None for ``init="uniform"``.

    "kde": w_i ∝ ĝ(y_i) (the algorithm as printed), from ``kde.kde_density``; "inverse-kde":
    w_i ∝ 1 / ĝ(y_i) (the text), ``kde.inverse_density_weights``; "expert": w_i = 1 / M. Computing them costs
    a KDE over the M expert actions (M² kernel evaluations): closed-loop code computes them once and passes
    them to ``dfo`` as ``init_weights``.

    Args:
        expert_actions: (M, D) expert actions.
        config: a ``DFOConfig`` or ``LangevinConfig`` (its ``init`` and ``bandwidth`` are used).
    Returns:
        (M,) weights summing to 1 in the default dtype, on the expert actions' device, or None.
    """
    check_tensor("expert_actions", expert_actions, ndim=2)
    if config.init == "uniform":
        return None
    if config.init == "expert":  # each expert action equally likely: draws distributed like ĝ
        m = len(expert_actions)
        return torch.full((m,), 1.0 / m, dtype=torch.get_default_dtype(), device=expert_actions.device)
    device, experts = expert_actions.device, expert_actions.cpu()  # the KDE is computed on the CPU
    if config.init == "inverse-kde":
        w = inverse_density_weights(experts, config.bandwidth)  # (M,) eqs. 4-5
        return w.to(torch.get_default_dtype()).to(device)
    g = kde_density(experts, experts, config.bandwidth).to(torch.float64)  # (M,) ĝ(y_i), eq. 4
    return (g / g.sum()).to(torch.get_default_dtype()).to(device)


def initial_samples(
    expert_actions: torch.Tensor,
    n_obs: int,
    config,
    *,
    init_weights: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """The initial population {ỹ_i} of Algorithm 1 line 2, for ``n_obs`` observations: (B, N, D).

    "uniform": ỹ_i ~ U(low, high) (original IBC). "kde"/"inverse-kde": ỹ_i ~ Categorical({y_i^expert},
    {w_i}) with the weights of ``initial_weights`` (or the given ``init_weights``): copies of
    expert actions, no noise yet (the first noise comes after the first resampling, line 9).

    Args:
        expert_actions: (M, D) expert actions inside the box, M >= 1.
        n_obs: B, the number of observations.
        config: a ``DFOConfig`` or ``LangevinConfig`` (``n_samples``, ``init``, ``low``, ``high``,
            ``bandwidth``).
        init_weights: optional precomputed (M,) weights (skips the KDE).
        generator: a seeded ``torch.Generator`` for reproducible draws (made on its device, the
            CPU for a ``torch.Generator()``, then moved).

    Returns the population on the expert actions' device.
    """
    check_tensor("expert_actions", expert_actions, ndim=2)
    check_int("n_obs", n_obs, minimum=1)
    m, d = expert_actions.shape
    lo, hi = bounds(config.low, config.high, d)  # (D,), (D,)
    experts = check_expert_actions(expert_actions, lo, hi)  # (M, D), default dtype
    n = config.n_samples
    if config.init == "uniform":
        u = torch.rand(n_obs, n, d, generator=generator, device=draw_device(generator))  # (B, N, D)
        lo, hi, u = lo.to(experts.device), hi.to(experts.device), u.to(experts.device)
        return lo + (hi - lo) * u
    if init_weights is None:
        init_weights = initial_weights(experts, config)
    else:
        check_tensor("init_weights", init_weights, shape=(m,))
        if (init_weights < 0).any() or init_weights.sum() <= 0:
            raise ValueError("init_weights must be non-negative with a positive sum")
    idx = multinomial(init_weights, n_obs * n, generator, replacement=True)  # (B·N,)
    return experts[idx.to(experts.device)].reshape(n_obs, n, d)  # (B, N, D)


def prepare_call(
    energy_fn, expert_actions: torch.Tensor, config, config_type: type, n_obs, init_weights, generator
):
    """What every DFO and Langevin call begins with: the checks, the batched energy function and
    the initial population of Algorithm 1 line 2.

    ``n_obs`` None (one observation: ``energy_fn`` maps (N, D) to (N,)) or B. Returns
    ``(fn, y, lo, hi)``: the batched energy function ((B, N, D) -> (B, N)), the population
    y (B, N, D) and the action box (D,), (D,).
    """
    lo, hi = check_call(expert_actions, config, config_type)
    if n_obs is None:
        b, fn = 1, single_observation(energy_fn)
    else:
        b, fn = check_int("n_obs", n_obs, minimum=1), energy_fn
    with torch.no_grad():
        y = initial_samples(expert_actions, b, config, init_weights=init_weights, generator=generator)
    return fn, y, lo, hi  # y: (B, N, D)
