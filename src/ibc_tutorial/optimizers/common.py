"""What DFO and Langevin share: the action box, the two forms of energy function, the final choice.

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

import math
from collections.abc import Sequence

import torch

from ibc_tutorial.utils import check_choice, check_tensor, draw_device

SELECTIONS = ("sample", "argmax")
"""Final choice: "sample" ŷ ~ Categorical({ỹ_i}, {p̃_i}) (Algorithm 1 line 14 of the DA-IBC paper)
or "argmax", the lowest energy (the original IBC)."""


def check_box(low, high) -> tuple[float | tuple[float, ...], float | tuple[float, ...]]:
    """Validate the action box [low, high] of a config: numbers, or one number per action dimension.

    Returns ``(low, high)`` as floats or tuples of floats. Whether a tuple's length matches the
    actions' D is checked when the actions are known (``bounds``).
    """
    out = []
    for name, v in (("low", low), ("high", high)):
        if hasattr(v, "tolist"):  # a tensor or an array: a number (0-d) or a list
            v = v.tolist()
        try:
            v = tuple(float(x) for x in v) if isinstance(v, Sequence) else float(v)
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be a number or a sequence of numbers, got {v!r}") from None
        values = v if isinstance(v, tuple) else (v,)
        if not values or not all(math.isfinite(x) for x in values):
            raise ValueError(f"{name} must be finite numbers, got {v!r}")
        out.append(v)
    lo, hi = out
    lo_t, hi_t = (t if isinstance(t, tuple) else (t,) for t in (lo, hi))
    if len(lo_t) == len(hi_t) or 1 in (len(lo_t), len(hi_t)):
        n = max(len(lo_t), len(hi_t))
        pairs = zip(lo_t * n if len(lo_t) == 1 else lo_t, hi_t * n if len(hi_t) == 1 else hi_t)
        if not all(a < b for a, b in pairs):
            raise ValueError(f"low must be < high in every action dimension, got low={lo}, high={hi}")
    return lo, hi


def bounds(low, high, d: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``low``/``high`` (numbers, or sequences of length D) as (D,) tensors with low < high.

    In torch's default dtype (float32 unless a chapter sets float64), like the populations.
    """
    lo = torch.as_tensor(low, dtype=torch.get_default_dtype()).reshape(-1)
    hi = torch.as_tensor(high, dtype=torch.get_default_dtype()).reshape(-1)
    for name, t in (("low", lo), ("high", hi)):
        if t.numel() not in (1, d):
            raise ValueError(
                f"{name} must be a number or have one entry per action dimension (D = {d}), got {t.numel()} entries"
            )
        if not torch.isfinite(t).all():
            raise ValueError(f"{name} must be finite, got {t.tolist()}")
    lo, hi = lo.expand(d).clone(), hi.expand(d).clone()  # (D,), (D,)
    if not (lo < hi).all():
        raise ValueError(
            f"low must be < high in every action dimension, got low={lo.tolist()}, high={hi.tolist()}"
        )
    return lo, hi


def check_expert_actions(expert_actions: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """(M, D) expert actions inside [lo, hi], M >= 1, in the default dtype, without gradient (on their device)."""
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
    """Check the arguments every optimizer call shares; return the action box ``bounds`` (lo, hi), each (D,)."""
    check_tensor("expert_actions", expert_actions, ndim=2)
    if not isinstance(config, config_type):
        raise ValueError(f"config must be a {config_type.__name__}, got {type(config).__name__}")
    return bounds(config.low, config.high, expert_actions.shape[1])
