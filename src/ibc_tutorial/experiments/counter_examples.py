"""Chapter 04's experiment: uniform (IBC) against expert-perturbed (DA-IBC) counter-examples.

Energy models are trained with InfoNCE on the junction world (``ibc_tutorial.toy.junction``),
each with one counter-example sampler of ``ibc_tutorial.negatives``, and measured on held-out
observations (``evaluate``):

- ``nll``: the NLL of the expert's action under p_θ(y|x) = exp(−E)/Z, with Z summed over a
  fine grid of the whole action box (``metrics.grid_nll``). It does not depend on the
  counter-examples used in training, so it compares the two samplers fairly, which their
  InfoNCE losses do not (each is measured against its own counter-examples). The floor is
  the expert's own NLL (``expert_nll``).
- ``hit``: the share of observations for which the argmin of the energy over that grid lies
  within ``hit_radius`` of one of the expert's valid actions: what an exhaustive optimiser
  would make the car do.

``negatives_histogram`` shows where a sampler's counter-examples land in the action box,
``mode_masses`` how much of p_θ lies near each of the expert's three actions at a junction, and
``valid_mass`` how much of it lies near any valid action: the chance that a policy acting by a draw
from p_θ takes an action the expert could have taken, a measure of behaviour that can still tell two
models apart when both hit rates are 1.
Chapters 05 and 06 reuse the world and these measures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import torch

from ibc_tutorial.metrics import grid_nll
from ibc_tutorial.objectives import info_nce_objective
from ibc_tutorial.optimizers.grid import action_grid, grid_energies
from ibc_tutorial.policies import EnergyModel, MLPEncoder
from ibc_tutorial.toy.junction import JunctionWorld
from ibc_tutorial.training import TrainConfig, train
from ibc_tutorial.utils import check_int, check_positive, check_positive_fields, check_tensor


def train_config(**changes) -> TrainConfig:
    """The training settings of chapter 04's runs, with ``changes`` (any ``TrainConfig`` field).

    600 Adam steps on minibatches of 64 (the paper: 128) at learning rate 3e-3, the held-out
    measures every 50 steps (``log_every``). The seed is ``run``'s own argument.
    """
    return TrainConfig(**{"steps": 600, "batch_size": 64, "lr": 3e-3, "log_every": 50, **changes})


@dataclass
class CounterExampleConfig:
    """Data, model size and measures of one training run (both samplers get the same)."""

    n_train: int = 4000
    """Expert samples in the training set."""
    n_heldout: int = 200
    """Held-out observations for the measures."""
    n_neg: int = 16
    """N_neg, counter-examples per sample (the paper: 1024)."""
    train: TrainConfig = field(default_factory=train_config)
    """How each model is trained (``train_config()``); its ``log_every`` is also how often the
    held-out set is evaluated (the curves' resolution), and ``run`` replaces its ``seed``."""
    width: int = 32
    """Width of the encoder's and the head's hidden layers and of the embedding."""
    grid_n: int = 51
    """Points per axis of the evaluation grid over [-1, 1]² (51: spacing 0.04). A Riemann sum of a
    Gaussian is accurate to about 1 % already at a spacing of twice its standard deviation."""
    hit_radius: float = 0.15
    """An argmin within this distance of a valid expert action counts as a hit."""
    data_seed: int = 12345
    """Seed of the training and held-out data (the same for every run)."""

    def __post_init__(self):
        for name in ("n_train", "n_heldout", "n_neg", "width"):
            check_int(f"config.{name}", getattr(self, name), minimum=1)
        if not isinstance(self.train, TrainConfig):
            raise ValueError(f"config.train must be a TrainConfig, got {type(self.train).__name__}")
        for name in ("steps", "batch_size", "log_every"):
            check_int(f"config.train.{name}", getattr(self.train, name), minimum=1)
        check_positive("config.train.lr", self.train.lr)
        check_int("config.grid_n", self.grid_n, minimum=2)
        check_int("config.data_seed", self.data_seed, minimum=0)
        check_positive_fields(self, ("hit_radius",))


@dataclass
class CounterExampleRun:
    """One training run: the held-out measures at each evaluation step."""

    steps: list[int] = field(default_factory=list)
    """Step of each evaluation."""
    nll: list[float] = field(default_factory=list)
    """Mean held-out grid NLL (nats) at each evaluation."""
    hit: list[float] = field(default_factory=list)
    """Share of held-out observations whose grid argmin is a valid action, at each evaluation."""
    losses: list[float] = field(default_factory=list)
    """Mean training InfoNCE loss over the steps before each evaluation (against its own counter-examples)."""
    model: EnergyModel | None = None
    """The trained model."""


def make_datasets(world: JunctionWorld, config: CounterExampleConfig) -> tuple[dict, dict]:
    """The training set and the held-out set, both drawn with ``config.data_seed``."""
    g = torch.Generator().manual_seed(config.data_seed)
    return world.sample(config.n_train, g), world.sample(config.n_heldout, g)


def make_model(world: JunctionWorld, config: CounterExampleConfig, seed: int) -> EnergyModel:
    """A small EnergyModel (MLP encoder, two-layer head), initialised from ``seed``."""
    torch.manual_seed(check_int("seed", seed, minimum=0))
    w = config.width
    return EnergyModel(
        MLPEncoder(world.obs_dim, embed_dim=w, hidden=w, layers=2), world.action_dim, hidden=w, layers=2
    )


@torch.no_grad()
def evaluate(
    model: EnergyModel, heldout: dict, world: JunctionWorld, config: CounterExampleConfig
) -> dict[str, float]:
    """Held-out ``nll`` (nats, lower is better) and ``hit`` rate (higher is better); see the module
    docstring."""
    grid = action_grid(config.grid_n, 2)  # (G, 2)
    z = model.embed(heldout["obs"])  # (B, E)
    e_grid = grid_energies(model, z, grid)  # (B, G)
    e_pos = model.energy_from_embedding(z, heldout["actions"][:, None, :])[:, 0]  # (B,)
    cell = (2.0 / (config.grid_n - 1)) ** 2
    nll = grid_nll(e_pos, e_grid, cell).mean()
    best = grid[e_grid.argmin(dim=1)]  # (B, 2)
    modes, valid = world.modes(heldout["obs"])  # (B, 3, 2), (B, 3)
    dist = (best[:, None, :] - modes).norm(dim=-1).masked_fill(~valid, math.inf).min(dim=1).values  # (B,)
    return {"nll": float(nll), "hit": float((dist <= config.hit_radius).float().mean())}


def run(
    world: JunctionWorld,
    sampler,
    config: CounterExampleConfig,
    seed: int,
    data: tuple[dict, dict] | None = None,
) -> CounterExampleRun:
    """Train one energy model with InfoNCE and ``sampler``'s counter-examples; evaluate along the way.

    ``seed`` sets the initial weights, the minibatches and the counter-examples (it replaces
    ``config.train.seed``); the data come from ``config.data_seed`` (pass ``data`` =
    ``make_datasets(...)`` to reuse them).
    """
    train_set, heldout = data if data is not None else make_datasets(world, config)
    model = make_model(world, config, seed)
    res = train(
        model,
        info_nce_objective(model, sampler, config.n_neg),
        {"obs": train_set["obs"], "actions": train_set["actions"]},
        replace(config.train, seed=seed),
        evaluate=lambda: evaluate(model, heldout, world, config),
    )
    return CounterExampleRun(
        steps=res.steps,
        nll=[e["nll"] for e in res.evals],
        hit=[e["hit"] for e in res.evals],
        losses=res.losses,
        model=model,
    )


def expert_nll(world: JunctionWorld, heldout: dict) -> float:
    """The best achievable held-out NLL: that of the expert's own density (nats)."""
    return float(-world.log_density(heldout["obs"], heldout["actions"]).mean())


def negatives_histogram(
    sampler,
    actions: torch.Tensor,
    n_neg: int,
    *,
    batches: int = 50,
    batch_size: int = 64,
    bins: int = 40,
    seed: int = 0,
) -> torch.Tensor:
    """Where a sampler's counter-examples land: a (bins, bins) histogram over [-1, 1]², summing to 1.

    Draws ``batches`` minibatches of expert ``actions`` (M, 2), asks the sampler for ``n_neg``
    counter-examples each, and bins those inside the box (rows: steer, columns: acceleration).
    """
    check_tensor("actions", actions, shape=(None, 2))
    batches = check_int("batches", batches, minimum=1)
    batch_size = check_int("batch_size", batch_size, minimum=1)
    bins = check_int("bins", bins, minimum=1)
    g = torch.Generator().manual_seed(check_int("seed", seed, minimum=0))
    counts = torch.zeros(bins, bins)
    for _ in range(batches):
        idx = torch.randint(0, len(actions), (batch_size,), generator=g)
        neg = sampler(actions[idx], n_neg, g).reshape(-1, 2)  # (batch_size * n_neg, 2)
        inside = neg[(neg.abs() <= 1).all(dim=1)]
        ij = ((inside + 1) / 2 * bins).long().clamp(0, bins - 1)
        counts.index_put_((ij[:, 0], ij[:, 1]), torch.ones(len(ij)), accumulate=True)
    return counts / counts.sum()


@torch.no_grad()
def mode_masses(
    model: EnergyModel, obs: torch.Tensor, world: JunctionWorld, *, grid_n: int = 51, radius: float = 0.15
) -> torch.Tensor:
    """Probability p_θ(y|x) puts within ``radius`` of each of the expert's three candidate actions.

    p_θ is normalised over a ``grid_n`` × ``grid_n`` grid of the box. For a junction observation
    the three columns are turning left, going straight and turning right (``world.mode_names``);
    the expert takes each one third of the time. Returns (B, 3) masses (each row sums to at most 1).
    """
    modes, _ = world.modes(obs)  # (B, 3, 2)
    return masses_near(model, obs, modes, grid_n=grid_n, radius=radius)


@torch.no_grad()
def masses_near(
    model: EnergyModel, obs: torch.Tensor, modes: torch.Tensor, *, grid_n: int = 51, radius: float = 0.15
) -> torch.Tensor:
    """Probability p_θ(y|x) = softmax(−E(x, ·)) puts within ``radius`` of each of ``modes`` (B, K, D), with
    p_θ normalised over a grid of ``grid_n`` points per action dimension of the box: (B, K), each row
    summing to at most 1 when the modes lie farther apart than 2 × ``radius`` (any world, any D)."""
    check_positive("radius", radius)
    check_tensor("modes", modes, ndim=3)
    grid = action_grid(check_int("grid_n", grid_n, minimum=2), modes.shape[-1])  # (G, D)
    p = torch.softmax(-grid_energies(model, model.embed(obs), grid), dim=1)  # (B, G)
    near = (grid[None, :, None, :] - modes[:, None, :, :]).norm(dim=-1) <= radius  # (B, G, K)
    return (p[:, :, None] * near).sum(dim=1)  # (B, K)


@torch.no_grad()
def valid_mass(
    model: EnergyModel, obs: torch.Tensor, world: JunctionWorld, *, grid_n: int = 51, radius: float = 0.15
) -> torch.Tensor:
    """Probability p_θ(y|x) puts within ``radius`` of any of the expert's valid actions at ``obs``.

    p_θ is normalised over a ``grid_n`` × ``grid_n`` grid of the box, as in ``evaluate``. This is the
    probability that an action drawn from p_θ (the DA-IBC paper's inference ends with such a draw,
    Algorithm 1) lies within ``radius`` of an action the expert takes there. Returns (B,) in [0, 1].
    """
    check_positive("radius", radius)
    check_tensor("obs", obs, shape=(None, world.obs_dim))
    grid = action_grid(check_int("grid_n", grid_n, minimum=2), 2)  # (G, 2)
    p = torch.softmax(-grid_energies(model, model.embed(obs), grid), dim=1)  # (B, G)
    modes, valid = world.modes(obs)  # (B, 3, 2), (B, 3)
    near = (grid[None, :, None, :] - modes[:, None, :, :]).norm(dim=-1) <= radius  # (B, G, 3)
    near_valid = (near & valid[:, None, :]).any(dim=-1)  # (B, G)
    return (p * near_valid).sum(dim=1)  # (B,)
