"""The training loop shared by the chapters and the command line.

A model is trained by minimising a ``loss_fn(batch, generator) -> scalar tensor`` over
minibatches drawn from a dict of equally long tensors. The loop knows nothing about the
kind of policy: explicit policies pass their negative log-likelihood, energy models pass
InfoNCE with a counter-example sampler. Minibatch indices are drawn uniformly, or with
given probabilities (the DA-IBC paper's way of applying the KDE weights of its eq. 5).
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


def train(
    model: torch.nn.Module,
    loss_fn: Callable[[dict[str, torch.Tensor], torch.Generator], torch.Tensor],
    data: Mapping[str, torch.Tensor],
    config: TrainConfig = TrainConfig(),
    *,
    sample_probs: torch.Tensor | None = None,
    callback: Callable[[int, float], None] | None = None,
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
            if callback is not None:
                callback(step, mean)
            running, count = 0.0, 0
    model.eval()
    return result
