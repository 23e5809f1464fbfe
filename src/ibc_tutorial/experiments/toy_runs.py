"""The training runs of chapters 02 and 03 on the tree and side-road worlds, as self-contained jobs.

Each function builds its networks from ``torch.manual_seed(seed)`` (the initial weights) and
trains them with the one loop (``ibc_tutorial.training.train``), the minibatches drawn with
the same ``seed``. A run depends on nothing but its arguments, so ``ibc_tutorial.parallel.
parallel_map`` can run several of them side by side in worker processes, with the same results
as one after another in the notebook's own process:

- ``train_explicit``: chapter 02's explicit policies (MAE regression, Beta, a classifier over
  512 bins, an MDN of 5 Gaussians), built one after another from one seed;
- ``fit_regression`` and ``fit_ebm``: chapter 03's MAE regression and energy model; the energy
  model's objective is an argument (InfoNCE with uniform counter-examples, the steering-EBM
  paper's grid variants), given as a picklable callable, e.g. ``functools.partial`` of
  ``objectives.info_nce_objective``.

Their sweeps over seeds (``train_explicit_stacked``, ``fit_regressions``, ``fit_ebms``) train the
seeds' networks side by side as one stacked model (``ibc_tutorial.stacked_training``): the same
initial weights and minibatches as the runs one by one, the same results up to float64 round-off,
1.3 to 2.2 times as fast for five seeds (``benchmarks/bench_stacked.py``). An energy model trained with
InfoNCE is the exception: with 33 candidates per sample its stacked model is slower than one run per
seed, so chapter 03 trains those one run per seed (``fit_ebm``); the grid objectives gain.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import torch

from ibc_tutorial.objectives import likelihood_objective
from ibc_tutorial.policies import (
    BetaPolicy,
    ClassifierPolicy,
    EnergyModel,
    MDNPolicy,
    MLPEncoder,
    RegressionPolicy,
)
from ibc_tutorial.policies.explicit import ExplicitPolicy
from ibc_tutorial.stacked_training import train_stacked
from ibc_tutorial.toy.world import Demonstrations
from ibc_tutorial.training import Objective, TrainConfig, TrainResult, train
from ibc_tutorial.utils import check_int

EXPLICIT = ("regression", "Beta", "classifier", "MDN")
"""Chapter 02's explicit policies, in the order ``train_explicit`` builds them."""

EXPLICIT_TRAIN = TrainConfig(steps=2000, batch_size=128, lr=3e-3)
"""How chapter 02 trains each explicit policy: 2000 Adam steps on minibatches of 128 (the seed is
``train_explicit``'s)."""


def _check_demos(demos) -> Demonstrations:
    if not isinstance(demos, Demonstrations):
        raise ValueError(
            f"demos must be Demonstrations (world.expert_demonstrations), got {type(demos).__name__}"
        )
    return demos


def make_explicit(name: str, obs_dim: int) -> ExplicitPolicy:
    """One of chapter 02's policies on an MLP encoder of two layers of 64, with one action (steering)."""
    if name == "regression":
        return RegressionPolicy.for_vectors(obs_dim, 1, loss_kind="mae")
    if name == "Beta":
        return BetaPolicy.for_vectors(obs_dim, 1)
    if name == "classifier":
        return ClassifierPolicy.for_vectors(obs_dim, 1, n_bins=512)
    if name == "MDN":
        return MDNPolicy.for_vectors(obs_dim, 1, n_components=5)
    raise ValueError(f"name must be one of {EXPLICIT}, got {name!r}")


def train_explicit(
    demos: Demonstrations, seed: int, names: Sequence[str] = EXPLICIT, *, config: TrainConfig = EXPLICIT_TRAIN
) -> dict[str, tuple[ExplicitPolicy, TrainResult]]:
    """Chapter 02's policies ``names`` trained on ``demos``: ``{name: (policy, loss curve)}``.

    After ``torch.manual_seed(seed)`` the policies are built one after another in the order of
    ``EXPLICIT`` (so a policy's initial weights depend on which policies come before it in
    ``names``), then each is trained with its own loss (``objectives.likelihood_objective``) and
    ``config`` (default ``EXPLICIT_TRAIN``), its minibatches drawn with ``seed``.
    """
    _check_demos(demos)
    seed = check_int("seed", seed, minimum=0)
    names = tuple(names)
    for name in names:
        if name not in EXPLICIT:
            raise ValueError(f"names must be among {EXPLICIT}, got {name!r}")
    if len(set(names)) != len(names) or not names:
        raise ValueError(f"names must name each policy at most once, and at least one, got {names}")
    if not isinstance(config, TrainConfig):
        raise ValueError(f"config must be a TrainConfig, got {type(config).__name__}")
    policies = explicit_policies(demos, seed, names)
    config = replace(config, seed=seed)
    data = demos.training_data()
    return {name: (p, train(p, likelihood_objective(p), data, config)) for name, p in policies.items()}


def explicit_policies(demos: Demonstrations, seed: int, names: Sequence[str] = EXPLICIT) -> dict:
    """The untrained policies ``names`` as ``train_explicit(demos, seed, names)`` starts from them:
    ``{name: policy}``, built one after another in the order of ``EXPLICIT`` after
    ``torch.manual_seed(seed)``."""
    _check_demos(demos)
    check_int("seed", seed, minimum=0)
    torch.manual_seed(seed)  # the initial weights
    return {name: make_explicit(name, demos.obs.shape[1]) for name in EXPLICIT if name in names}


def train_explicit_stacked(
    demos: Demonstrations,
    policies: Sequence[ExplicitPolicy],
    seeds: Sequence[int],
    *,
    config: TrainConfig = EXPLICIT_TRAIN,
) -> list[tuple[ExplicitPolicy, TrainResult]]:
    """One policy family from several seeds, trained side by side as one stacked model
    (``stacked_training.train_stacked``): ``[(policy, loss curve)]`` in the order of ``policies``.

    ``policies[i]`` (untrained, e.g. from ``explicit_policies``) is trained as ``train_explicit`` trains
    it, its minibatches drawn with ``seeds[i]``: the same result up to float64 round-off, 1.3 (the
    classifier) to 2.2 (the regression) times as fast for five seeds (``benchmarks/bench_stacked.py``).
    """
    _check_demos(demos)
    if not isinstance(config, TrainConfig):
        raise ValueError(f"config must be a TrainConfig, got {type(config).__name__}")
    policies = list(policies)
    curves = train_stacked(policies, likelihood_objective, demos.training_data(), config, seeds)
    return list(zip(policies, curves, strict=True))


def fit_regression(demos: Demonstrations, seed: int = 0, *, steps: int = 1000) -> RegressionPolicy:
    """Chapter 03's MAE regression (two layers of 64), trained on ``demos`` by ``steps`` Adam steps
    on minibatches of 64 at learning rate 3e-3."""
    _check_demos(demos)
    seed = check_int("seed", seed, minimum=0)
    torch.manual_seed(seed)  # the initial weights
    policy = _regression(demos)
    config = TrainConfig(steps=steps, batch_size=64, lr=3e-3, seed=seed)
    train(policy, likelihood_objective(policy), demos.training_data(), config)
    return policy


def fit_regressions(
    demos: Demonstrations,
    seeds: Sequence[int],
    *,
    steps: int = 1000,
    batch_size: int = 64,
    loss_kind: str = "mae",
) -> list[RegressionPolicy]:
    """``[fit_regression(demos, seed, steps=steps) for seed in seeds]``, the runs side by side as one
    stacked model (``stacked_training.train_stacked``): the same up to float64 round-off.

    ``batch_size`` and ``loss_kind`` ("mae" or "mse") change what every run does (chapter 01 trains with
    minibatches of 128, MAE and MSE); the defaults are ``fit_regression``'s.
    """
    _check_demos(demos)
    models = []
    for seed in seeds:
        torch.manual_seed(check_int("seed", seed, minimum=0))  # the initial weights, as fit_regression's
        models.append(_regression(demos, loss_kind))
    config = TrainConfig(steps=steps, batch_size=batch_size, lr=3e-3)
    train_stacked(models, likelihood_objective, demos.training_data(), config, seeds)
    return models


def _regression(demos: Demonstrations, loss_kind: str = "mae") -> RegressionPolicy:
    return RegressionPolicy.for_vectors(demos.obs.shape[1], 1, hidden=64, layers=2, loss_kind=loss_kind)


def fit_ebm(
    data: dict[str, torch.Tensor],
    obs_dim: int,
    objective: Callable[[EnergyModel], Objective],
    seed: int = 0,
    *,
    steps: int = 1000,
    batch_size: int = 64,
    width: int = 64,
) -> tuple[EnergyModel, TrainResult]:
    """Chapter 03's energy model for one steering action, trained on ``data`` by ``objective(model)``.

    The model: an MLP encoder of two layers of ``width`` and a head of two layers of ``width``
    (``EnergyModel``, late fusion). Adam at learning rate 3e-3, ``steps`` steps on minibatches of
    ``batch_size``. ``objective`` builds the training objective for the model, e.g.
    ``functools.partial(objectives.info_nce_objective, sampler=negatives.UniformSampler(-1.0, 1.0),
    n_neg=32)``; it must be picklable to run in a worker process (a partial of a library function
    is, a lambda is not). Returns the model and its loss curve.
    """
    obs_dim = check_int("obs_dim", obs_dim, minimum=1)
    seed = check_int("seed", seed, minimum=0)
    width = check_int("width", width, minimum=1)
    if not callable(objective):
        raise ValueError(f"objective must be callable as objective(model), got {type(objective).__name__}")
    torch.manual_seed(seed)  # the initial weights
    model = _ebm(obs_dim, width)
    config = TrainConfig(steps=steps, batch_size=batch_size, lr=3e-3, seed=seed)
    curve = train(model, objective(model), data, config)
    return model, curve


def _ebm(obs_dim: int, width: int) -> EnergyModel:
    return EnergyModel(
        MLPEncoder(obs_dim, embed_dim=width, hidden=width), action_dim=1, hidden=width, layers=2
    )


def fit_ebms(
    data: dict[str, torch.Tensor],
    obs_dim: int,
    objective: Callable[[EnergyModel], Objective],
    seeds: Sequence[int],
    *,
    steps: int = 1000,
    batch_size: int = 64,
    width: int = 64,
) -> list[tuple[EnergyModel, TrainResult]]:
    """``[fit_ebm(data, obs_dim, objective, seed, ...) for seed in seeds]``, the runs side by side as one
    stacked model (``stacked_training.train_stacked``): the same up to float64 round-off. ``objective``
    must build a ``training.DrawnObjective`` (InfoNCE and the grid objectives of ``objectives`` do). The grid
    objectives gain (1.3 times as fast for five seeds); InfoNCE with many counter-examples loses (0.7 times
    at 32: ``benchmarks/bench_stacked.py``), so chapter 03 trains those with ``fit_ebm``."""
    obs_dim = check_int("obs_dim", obs_dim, minimum=1)
    width = check_int("width", width, minimum=1)
    if not callable(objective):
        raise ValueError(f"objective must be callable as objective(model), got {type(objective).__name__}")
    models = []
    for seed in seeds:
        torch.manual_seed(check_int("seed", seed, minimum=0))  # the initial weights, as fit_ebm's
        models.append(_ebm(obs_dim, width))
    config = TrainConfig(steps=steps, batch_size=batch_size, lr=3e-3)
    curves = train_stacked(models, objective, data, config, seeds)
    return list(zip(models, curves, strict=True))
