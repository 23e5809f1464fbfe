"""The one training loop of the book: the toy chapters and the driving agents alike.

A model is trained by Adam, minimising an *objective* ``objective(batch, generator) -> scalar``
over minibatches of the training data. The loop knows nothing about the kind of policy: an
explicit policy's objective is its negative log-likelihood, an energy model's is InfoNCE with
a counter-example sampler (``ibc_tutorial.objectives`` builds both).

The data is anything with a length M and a ``batch(indices) -> batch`` method (``Minibatches``):
a dict of equally long tensors is wrapped as ``TensorData`` (the toy chapters), and a dataset
that renders its samples on demand (the driving demonstrations) provides ``batch`` itself.

Minibatch indices are drawn uniformly, or with given probabilities (the DA-IBC paper's way of
applying the KDE weights of its eq. 5): ``draw_minibatch`` is the only place they are drawn.

``Trainer`` holds everything a run needs to continue: the model, Adam's state, the generator of
the minibatch draws (also handed to the objective for its counter-examples), the step and the
running loss. ``Trainer.state_dict`` / ``load_state_dict`` save and restore all of it, so an
interrupted run resumes bit for bit as if it had not stopped. ``train`` is the one-call form.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import torch

from ibc_tutorial.utils import check_choice, check_int, check_positive, check_tensor, progress

Objective = Callable[[Any, torch.Generator], torch.Tensor]
"""``objective(batch, generator) -> scalar loss``: what ``train`` minimises (see ``ibc_tutorial.objectives``).
"""


class DrawnObjective:
    """An objective in two parts: ``objective(batch, generator) = loss(batch, draw(batch, generator))``.

    ``draw(batch, generator) -> dict of tensors`` makes the objective's random draws (an energy model's
    counter-examples), ``loss(batch, drawn) -> scalar`` is deterministic. Called whole, it is an
    ``Objective`` like any other; split, ``stacked_training.train_stacked`` draws each seed's with that
    seed's generator and computes the loss of every seed in one ``torch.vmap`` call.

    Args:
        loss: ``loss(batch, drawn) -> scalar``, no random draw inside.
        draw: ``draw(batch, generator) -> dict``, or None for an objective without random draws.
    """

    def __init__(
        self,
        loss: Callable[[Any, dict[str, torch.Tensor]], torch.Tensor],
        draw: Callable[[Any, torch.Generator], dict[str, torch.Tensor]] | None = None,
    ):
        if not callable(loss) or (draw is not None and not callable(draw)):
            raise ValueError("loss must be callable, and draw callable or None")
        self.loss, self.draw = loss, draw

    def draws(self, batch, generator: torch.Generator) -> dict[str, torch.Tensor]:
        """The random draws for ``batch`` ({} without ``draw``)."""
        return {} if self.draw is None else self.draw(batch, generator)

    def __call__(self, batch, generator: torch.Generator) -> torch.Tensor:
        return self.loss(batch, self.draws(batch, generator))


@runtime_checkable
class Minibatches(Protocol):
    """Training data as the loop sees it: M samples, fetched a minibatch at a time."""

    def __len__(self) -> int: ...

    def batch(self, indices: torch.Tensor) -> Any:
        """The samples at ``indices`` (B,) as one minibatch (what the objective receives)."""
        ...


class TensorData:
    """A dict of tensors with a common first dimension M as ``Minibatches``: ``batch`` indexes each."""

    def __init__(self, data: Mapping[str, torch.Tensor]):
        if not data:
            raise ValueError("data must hold at least one tensor")
        sizes = {k: len(v) for k, v in data.items()}
        m = next(iter(sizes.values()))
        if any(s != m for s in sizes.values()) or m == 0:
            raise ValueError(f"data tensors must share a non-zero first dimension, got lengths {sizes}")
        self.data = dict(data)
        self.m = m

    def __len__(self) -> int:
        return self.m

    def batch(self, indices: torch.Tensor) -> dict[str, torch.Tensor]:
        return {k: v[indices] for k, v in self.data.items()}  # each (B, ...)


LR_SCHEDULES = ("constant", "cosine")
"""Learning-rate schedules ``TrainConfig.lr_schedule`` accepts."""


@dataclass
class TrainConfig:
    """Settings of one training run."""

    steps: int = 2000
    """Number of gradient steps (minibatches) of the whole run (a resumed run stops here too)."""
    batch_size: int = 128
    """Samples per minibatch (the DA-IBC paper uses 128)."""
    lr: float = 1e-3
    """Adam learning rate (the paper uses 1e-5 on its much larger dataset)."""
    lr_schedule: str = "constant"
    """"constant", or "cosine": the rate at step t is lr * (1 + cos(pi t / steps)) / 2, from lr down to 0."""
    weight_decay: float = 0.0
    """Adam weight decay."""
    seed: int = 0
    """Seeds the minibatch draws and the generator handed to the objective."""
    log_every: int = 50
    """Record the mean loss every this many steps (and at the last step)."""
    progress: bool | None = None
    """Show a progress bar: None = yes, unless running under the tests (``utils.quiet``)."""
    desc: str = "training"
    """Label of the progress bar."""


@dataclass
class TrainResult:
    """What ``train`` / ``Trainer.run`` returns: the loss curve (one entry per log point)."""

    steps: list[int] = field(default_factory=list)
    """Step index at which each loss was recorded."""
    losses: list[float] = field(default_factory=list)
    """Mean training loss over the steps since the previous log point."""
    evals: list = field(default_factory=list)
    """What ``evaluate()`` returned at each log point (empty when no ``evaluate`` was given)."""


def draw_minibatch(
    probs: torch.Tensor | None, m: int, batch_size: int, generator: torch.Generator
) -> torch.Tensor:
    """Indices (batch_size,) of one minibatch among M samples: uniform, or with probabilities ``probs`` (M,).

    Drawn with replacement, as the DA-IBC paper applies its eq. 5 weights by sampling (sec. 2.5).
    """
    if probs is None:
        return torch.randint(0, m, (batch_size,), generator=generator)  # (B,)
    return torch.multinomial(probs, batch_size, replacement=True, generator=generator)  # (B,)


def learning_rate(config: TrainConfig, step: int) -> float:
    """The step size of gradient step ``step`` (0-based) of a run with ``config`` (its ``lr_schedule``)."""
    if config.lr_schedule == "cosine":
        return config.lr * 0.5 * (1.0 + math.cos(math.pi * step / config.steps))
    return config.lr


def check_config(config: TrainConfig) -> TrainConfig:
    """ValueError naming the field unless ``config`` is a ``TrainConfig`` a run can start from."""
    if not isinstance(config, TrainConfig):
        raise ValueError(f"config must be a TrainConfig, got {type(config).__name__}")
    check_int("config.steps", config.steps, minimum=1)
    check_int("config.batch_size", config.batch_size, minimum=1)
    check_int("config.log_every", config.log_every, minimum=1)
    check_positive("config.lr", config.lr)
    check_choice("config.lr_schedule", config.lr_schedule, LR_SCHEDULES)
    return config


def as_minibatches(data) -> Minibatches:
    """``data`` as ``Minibatches``: a dict of tensors is wrapped in ``TensorData``, anything else must have
    ``batch``."""
    if isinstance(data, Mapping):
        return TensorData(data)
    if not isinstance(data, Minibatches):
        raise ValueError(
            f"data must be a dict of tensors or have __len__ and batch(indices), got {type(data).__name__}"
        )
    if len(data) == 0:
        raise ValueError("data must hold at least one sample")
    return data


class Trainer:
    """A resumable training run: ``run`` trains up to ``config.steps``; ``state_dict`` captures it all.

    Args:
        model: the parameters to optimise (trained in place).
        objective: ``objective(batch, generator) -> scalar`` (see ``ibc_tutorial.objectives``).
        data: a dict of tensors with a common first dimension M, or any ``Minibatches``.
        config: see ``TrainConfig`` (its defaults if None).
        sample_probs: optional (M,) probabilities of drawing each sample (e.g.
            ``kde.inverse_density_weights``); uniform when None.
    """

    def __init__(
        self,
        model: torch.nn.Module,
        objective: Objective,
        data,
        config: TrainConfig | None = None,
        *,
        sample_probs: torch.Tensor | None = None,
    ):
        config = check_config(TrainConfig() if config is None else config)  # a fresh one each run: mutable
        if not callable(objective):
            raise ValueError(f"objective must be callable, got {type(objective).__name__}")
        self.data = as_minibatches(data)
        m = len(self.data)
        if sample_probs is not None:
            check_tensor("sample_probs", sample_probs, shape=(m,))
            if (sample_probs < 0).any() or sample_probs.sum() <= 0:
                raise ValueError("sample_probs must be non-negative with a positive sum")
        self.model, self.objective, self.config, self.sample_probs = model, objective, config, sample_probs
        self.generator = torch.Generator().manual_seed(config.seed)
        self.optimizer = torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
        self.step = 0
        """Gradient steps taken so far (over every call to ``run``)."""
        self._running, self._count = 0.0, 0  # loss sum and steps since the last log point

    def learning_rate(self, step: int) -> float:
        """The step size of gradient step ``step`` (0-based) under ``config.lr_schedule``."""
        return learning_rate(self.config, step)

    def state_dict(self) -> dict:
        """Everything needed to continue exactly: model, Adam, generator, step, running loss (plain data)."""
        return {
            "model": {k: v.detach().clone() for k, v in self.model.state_dict().items()},
            "optimizer": self.optimizer.state_dict(),
            "generator": self.generator.get_state(),
            "step": self.step,
            "running_loss": self._running,
            "running_count": self._count,
        }

    def load_state_dict(self, state: Mapping) -> None:
        """Restore a ``state_dict`` (e.g. read back from a checkpoint)."""
        missing = {"model", "optimizer", "generator", "step"} - set(state)
        if missing:
            raise ValueError(f"state must hold {sorted(missing)} (a Trainer.state_dict())")
        self.step = check_int("state['step']", state["step"], minimum=0)
        if self.step > self.config.steps:
            raise ValueError(f"state['step'] must be <= config.steps = {self.config.steps}, got {self.step}")
        self.model.load_state_dict(state["model"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.generator.set_state(state["generator"])
        self._running, self._count = float(state.get("running_loss", 0.0)), int(state.get("running_count", 0))

    def run(
        self,
        *,
        evaluate: Callable[[], object] | None = None,
        callback: Callable[[int, float], None] | None = None,
    ) -> TrainResult:
        """Train from ``self.step`` to ``config.steps``; record the mean loss every ``log_every`` steps.

        Args:
            evaluate: called without arguments at every log point, in eval mode and without
                gradients (e.g. a held-out measure); its results are kept in ``TrainResult.evals``.
            callback: called as ``callback(step, mean_loss)`` at every log point, after
                ``evaluate`` (e.g. to write a checkpoint from ``state_dict()``).
        """
        c, model = self.config, self.model
        m = len(self.data)
        result = TrainResult()
        model.train()
        for step in progress(range(self.step + 1, c.steps + 1), desc=c.desc, enabled=c.progress):
            idx = draw_minibatch(self.sample_probs, m, c.batch_size, self.generator)  # (B,)
            loss = self.objective(self.data.batch(idx), self.generator)
            if loss.ndim != 0 or not torch.isfinite(loss):
                raise ValueError(
                    f"the objective must return a finite scalar, got {loss.detach()!r} at step {step}"
                )
            self.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            for group in self.optimizer.param_groups:
                group["lr"] = self.learning_rate(step - 1)
            self.optimizer.step()
            self.step = step
            self._running += float(loss.detach())
            self._count += 1
            if step % c.log_every == 0 or step == c.steps:
                mean = self._running / self._count
                self._running, self._count = 0.0, 0
                result.steps.append(step)
                result.losses.append(mean)
                if evaluate is not None:
                    model.eval()
                    with torch.no_grad():
                        result.evals.append(evaluate())
                if callback is not None:
                    callback(step, mean)
                model.train()
        model.eval()
        return result


def train(
    model: torch.nn.Module,
    objective: Objective,
    data,
    config: TrainConfig | None = None,
    *,
    sample_probs: torch.Tensor | None = None,
    evaluate: Callable[[], object] | None = None,
    callback: Callable[[int, float], None] | None = None,
    state: Mapping | None = None,
) -> TrainResult:
    """Train ``model`` in place by Adam on minibatches of ``data`` (see ``Trainer`` for the arguments).

    With ``state`` (a ``Trainer.state_dict()``), the run continues from it up to ``config.steps``.
    """
    trainer = Trainer(model, objective, data, config, sample_probs=sample_probs)
    if state is not None:
        trainer.load_state_dict(state)
    return trainer.run(evaluate=evaluate, callback=callback)
