"""Several seeds of one small network trained side by side as one stacked model: ``train_stacked``.

The toy chapters train the same small network from several initial seeds. Each training step of
such a network is a few dozen tiny tensor operations, and most of its time is Python's and
autograd's overhead per operation, not arithmetic. ``train_stacked`` trains S networks of the same
architecture at once: their parameters stacked along a new first dimension (S, ...) with
``torch.func.stack_module_state``, the loss of all S computed by one ``torch.vmap`` of the
objective over the stacked parameters (each operation runs once for all seeds, as a batched
matrix product), one backward pass, and Adam on the stacked parameters.

**The same training as one run per seed, up to float64 round-off.** Each network keeps the initial
weights it was built with; each seed draws its minibatches and its random draws (counter-examples)
from its own generator, in the order ``training.Trainer`` draws them (``training.DrawnObjective``
separates an objective's draws from its loss for this); Adam works element by element, so a seed's
update depends only on its own gradients; the loss of the S seeds is their sum, whose gradient with
respect to one seed's parameters is that seed's gradient. What differs is the order of the sums
inside a batched matrix product: the weights of the two ways agree to about 1e-13 after a few
steps (``tests/test_stacked_training.py``). A network whose training amplifies the last bits of
the arithmetic (chapter 02's MDN) ends elsewhere either way, as it does on another CPU.

Inside ``torch.vmap`` no code may branch on a tensor's values, so the losses' checks of their
inputs' values (finite, inside [-1, 1]) are switched off there (``utils.without_value_checks``);
``train_stacked`` runs the objective once, with the checks, on the whole training data first.
``benchmarks/bench_stacked.py`` measures the time against one run per seed: for five seeds, 1.3 to 2.2
times as fast for chapter 02's policies and chapter 03's grid energy models, where a step is mostly
overhead, but 0.7 times for an energy model trained with InfoNCE at 32 counter-examples, where a step is
arithmetic on (B, 33, H) tensors that the batched form does no faster.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch
from torch import nn
from torch.func import functional_call, stack_module_state, vmap

from ibc_tutorial.training import (
    DrawnObjective,
    TrainConfig,
    TrainResult,
    as_minibatches,
    check_config,
    draw_minibatch,
    learning_rate,
)
from ibc_tutorial.utils import check_int, without_value_checks


class _LossOf(nn.Module):
    """The objective's loss as a module's forward, for ``functional_call``: ``model`` is the module whose
    parameters the stacked ones stand in for (the objective was built on it)."""

    def __init__(self, model: nn.Module, loss: Callable):
        super().__init__()
        self.model, self.loss = model, loss

    def forward(self, batch, drawn):
        return self.loss(batch, drawn)


def _stack(items: list[dict[str, torch.Tensor]]) -> dict[str, torch.Tensor]:
    return {k: torch.stack([item[k] for item in items]) for k in items[0]}  # each (S, ...)


def _check_models(models) -> list[nn.Module]:
    models = list(models)
    if not models or not all(isinstance(m, nn.Module) for m in models):
        raise ValueError("models must be a non-empty sequence of torch.nn.Module")
    shapes = [{k: tuple(v.shape) for k, v in m.state_dict().items()} for m in models]
    if any(type(m) is not type(models[0]) or s != shapes[0] for m, s in zip(models, shapes, strict=True)):
        raise ValueError("models must share one architecture: the same class and parameter shapes")
    if len({id(m) for m in models}) != len(models):
        raise ValueError("models must be distinct modules (each seed its own)")
    return models


def train_stacked(
    models: Sequence[nn.Module],
    objective: Callable[[nn.Module], DrawnObjective],
    data,
    config: TrainConfig,
    seeds: Sequence[int],
) -> list[TrainResult]:
    """Train ``models`` (S networks of one architecture) in place, seed s as ``training.train(models[s],
    objective(models[s]), data, replace(config, seed=seeds[s]))`` would, all S in one stacked model.

    Args:
        models: the S networks, each with the initial weights it would start a separate run from.
        objective: builds the training objective of a model, e.g. ``objectives.likelihood_objective`` or a
            ``functools.partial`` of ``objectives.info_nce_objective``; it must return a
            ``training.DrawnObjective`` (the book's objectives do, except the flow policy's).
        data: a dict of tensors with a common first dimension M, or any ``training.Minibatches``.
        config: the settings of every run (steps, batch size, learning rate and its schedule, weight
            decay, log_every); its ``seed`` is replaced by each run's.
        seeds: the S seeds of the minibatch draws (and of the objective's draws), one per model.

    Returns:
        Each model's loss curve (``TrainResult``, no ``evals``), in the order of ``models``. The models
        are left in eval mode, as ``train`` leaves them.
    """
    models = _check_models(models)
    seeds = [check_int("seeds[i]", s, minimum=0) for s in seeds]
    if len(seeds) != len(models):
        raise ValueError(f"seeds must give one seed per model ({len(models)}), got {len(seeds)}")
    check_config(config)
    template = models[0]
    built = objective(template)
    if not isinstance(built, DrawnObjective):
        raise ValueError(
            f"objective(model) must return a training.DrawnObjective (its draws apart from its loss), got "
            f"{type(built).__name__}"
        )
    data = as_minibatches(data)
    m = len(data)
    everything = data.batch(torch.arange(m))
    with torch.no_grad():  # the loss's value checks, once, on every sample (and a finite loss)
        first = built(everything, torch.Generator().manual_seed(seeds[0]))
    if first.ndim != 0 or not torch.isfinite(first):
        raise ValueError(f"the objective must return a finite scalar, got {first!r} on the whole data")

    params, buffers = stack_module_state(models)  # {name: (S, ...)}; params are new leaves
    call = _LossOf(template, built.loss)
    stacked = {f"model.{k}": v for k, v in {**params, **buffers}.items()}

    def loss_of_one(weights, batch, drawn):  # one seed's weights, batch and draws -> scalar
        return functional_call(call, weights, (batch, drawn))

    losses_of_all = vmap(loss_of_one)  # (S, ...) each -> (S,)
    optimizer = torch.optim.Adam(params.values(), lr=config.lr, weight_decay=config.weight_decay)
    generators = [torch.Generator().manual_seed(s) for s in seeds]
    results = [TrainResult() for _ in seeds]
    running, count = [0.0] * len(seeds), 0
    for model in models:
        model.train()
    for step in range(1, config.steps + 1):
        batches, drawn = [], []
        for g in generators:  # as Trainer.run: the minibatch first, then the objective's draws
            batch = data.batch(draw_minibatch(None, m, config.batch_size, g))
            batches.append(batch)
            drawn.append(built.draws(batch, g))
        with without_value_checks():
            losses = losses_of_all(stacked, _stack(batches), _stack(drawn))  # (S,)
        if losses.shape != (len(seeds),) or not torch.isfinite(losses).all():
            raise ValueError(f"the objective must return a finite scalar per seed, got {losses.detach()!r}")
        optimizer.zero_grad(set_to_none=True)
        losses.sum().backward()  # d(sum)/d(seed s's weights) = seed s's own gradient
        for group in optimizer.param_groups:
            group["lr"] = learning_rate(config, step - 1)  # the same schedule for every seed
        optimizer.step()
        running = [r + v for r, v in zip(running, losses.detach().tolist(), strict=True)]
        count += 1
        if step % config.log_every == 0 or step == config.steps:
            for result, total in zip(results, running, strict=True):
                result.steps.append(step)
                result.losses.append(total / count)
            running, count = [0.0] * len(seeds), 0
    with torch.no_grad():
        for s, model in enumerate(models):
            for name, p in model.named_parameters():
                p.copy_(params[name][s])
            model.eval()
    return results
