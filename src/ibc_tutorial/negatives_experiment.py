"""Chapter 04's experiment: uniform (IBC) against expert-perturbed (DA-IBC) counter-examples.

The problem (``ApproachProblem``) is a 2-D action problem shaped like urban driving, small
enough to train dozens of energy models on a laptop CPU in a minute. An observation
x = (κ, j, r, v) describes the road ahead: curvature κ, a T-junction ahead (j = 1), a red
light ahead (r = 1), and the speed v. The action is y = (steer, acceleration) in [-1, 1]²
(negative acceleration = braking, as in sec. 3.2 of the DA-IBC paper). The expert:

- *cruise* (most samples): steer = 0.8 κ with κ mostly near 0, acceleration 0.5 − 0.5 v
  (moderate): the expert's actions crowd into a small region of the action box;
- *junction* (rarer): turn left, go straight or turn right, one third each: **three valid
  actions for the same observation** (steer −0.7, 0 or +0.7; slower in the turns);
- *red light* (rarer): brake, the harder the faster: acceleration −0.5 − 0.45 v.

Every expert action carries Gaussian noise of standard deviation ``expert_noise`` per
dimension, so the expert's conditional density p(y|x) is a known mixture of Gaussians and the
ideal held-out NLL is known.

Measures on held-out observations (``evaluate``):

- ``nll``: the NLL of the expert's action under p_θ(y|x) = exp(−E)/Z, with Z summed over a
  fine grid of the whole action box (``metrics.grid_nll``). It does not depend on the
  counter-examples used in training, so it compares the two samplers fairly, which their
  InfoNCE losses do not (each is measured against its own counter-examples).
- ``hit``: the share of observations for which the argmin of the energy over that grid lies
  within ``hit_radius`` of one of the expert's valid actions: what an exhaustive optimiser
  would make the car do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from ibc_tutorial.inference import action_grid, grid_energies
from ibc_tutorial.metrics import grid_nll
from ibc_tutorial.policies import EnergyModel, MLPEncoder
from ibc_tutorial.training import TrainConfig, info_nce_objective, train
from ibc_tutorial.utils import check_int, check_positive

SITUATIONS = ("cruise", "junction", "red light")
"""Names of the situations, indexed by ``sample(...)["situation"]``."""


@dataclass
class ApproachConfig:
    """The driving-shaped 2-D action problem of chapter 04."""

    p_junction: float = 0.15
    """Share of observations with a T-junction ahead (three valid actions)."""
    p_red: float = 0.15
    """Share of observations with a red light ahead (braking)."""
    curvature_std: float = 0.2
    """Standard deviation of the road curvature κ while cruising (clipped to ±0.6)."""
    turn_steer: float = 0.7
    """|steer| of a turn at a junction."""
    turn_accel: float = 0.1
    """Acceleration while turning at a junction."""
    straight_accel: float = 0.35
    """Acceleration while going straight over a junction."""
    expert_noise: float = 0.02
    """Standard deviation of the expert's Gaussian noise on each action dimension (sharp modes)."""


class ApproachProblem:
    """Observations (κ, j, r, v) and expert actions (steer, acceleration); see the module docstring."""

    obs_dim = 4
    action_dim = 2

    def __init__(self, config: ApproachConfig = ApproachConfig()):
        check_positive("config.expert_noise", config.expert_noise)
        if not (0 <= config.p_junction and 0 <= config.p_red and config.p_junction + config.p_red < 1):
            raise ValueError(f"config.p_junction and config.p_red must be >= 0 with a sum < 1, got {config.p_junction}, {config.p_red}")
        self.config = config

    # ------------------------------------------------------------------ the expert
    def modes(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The expert's noise-free valid actions: obs (B, 4) -> modes (B, 3, 2) and valid (B, 3) bool.

        A cruise or red-light observation has one valid action (in column 0); a junction three.
        """
        c = self.config
        kappa, junction, red, v = obs[:, 0], obs[:, 1] > 0.5, obs[:, 2] > 0.5, obs[:, 3]
        b = len(obs)
        steer = (0.8 * kappa)[:, None].repeat(1, 3)  # (B, 3)
        accel = (0.5 - 0.5 * v)[:, None].repeat(1, 3)
        accel = torch.where(red[:, None], (-0.5 - 0.45 * v)[:, None].expand(b, 3), accel)
        turn = torch.tensor([-c.turn_steer, 0.0, c.turn_steer])
        turn_acc = torch.tensor([c.turn_accel, c.straight_accel, c.turn_accel])
        steer = torch.where(junction[:, None], turn.expand(b, 3), steer)
        accel = torch.where(junction[:, None], turn_acc.expand(b, 3), accel)
        valid = torch.zeros(b, 3, dtype=torch.bool)
        valid[:, 0] = True
        valid[junction] = True
        return torch.stack([steer, accel], dim=-1), valid  # (B, 3, 2), (B, 3)

    def log_density(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """log p(y|x) of the expert (a mixture of Gaussians over its valid actions): (B,)."""
        s = self.config.expert_noise
        modes, valid = self.modes(obs)
        sq = (actions[:, None, :] - modes).square().sum(-1)  # (B, 3)
        log_n = -0.5 * sq / s**2 - math.log(2 * math.pi * s**2)  # (B, 3)
        log_w = torch.where(valid, -torch.log(valid.sum(1, keepdim=True).float()), torch.tensor(-math.inf))
        return torch.logsumexp(log_n + log_w, dim=1)

    def sample(self, n: int, generator: torch.Generator) -> dict[str, torch.Tensor]:
        """n observations with expert actions: {obs (n, 4), actions (n, 2), situation (n,) int64}."""
        n = check_int("n", n, minimum=1)
        c = self.config
        u = torch.rand(n, generator=generator)
        situation = torch.zeros(n, dtype=torch.long)
        situation[u < c.p_junction + c.p_red] = 2
        situation[u < c.p_junction] = 1
        kappa = (c.curvature_std * torch.randn(n, generator=generator)).clamp(-0.6, 0.6)
        kappa = torch.where(situation == 1, torch.zeros(n), kappa)  # junctions on straight roads
        v = 0.2 + 0.7 * torch.rand(n, generator=generator)
        obs = torch.stack([kappa, (situation == 1).float(), (situation == 2).float(), v], dim=1)  # (n, 4)
        modes, valid = self.modes(obs)
        pick = torch.multinomial(valid.float(), 1, generator=generator)[:, 0]  # uniform over valid modes
        actions = modes[torch.arange(n), pick] + c.expert_noise * torch.randn(n, 2, generator=generator)
        return {"obs": obs, "actions": actions.clamp(-1.0, 1.0), "situation": situation}


# =========================================================================== the experiment
@dataclass
class ExperimentConfig:
    """Budget and model size of one training run (both samplers get the same)."""

    n_train: int = 4000
    """Expert samples in the training set."""
    n_heldout: int = 200
    """Held-out observations for the measures."""
    n_neg: int = 16
    """N_neg, counter-examples per sample (the paper: 1024)."""
    steps: int = 600
    """Gradient steps."""
    batch_size: int = 64
    """Minibatch size (the paper: 128)."""
    lr: float = 3e-3
    """Adam learning rate."""
    width: int = 32
    """Width of the encoder's and the head's hidden layers and of the embedding."""
    eval_every: int = 50
    """Evaluate on the held-out set every this many steps (the curves' resolution)."""
    grid_n: int = 51
    """Points per axis of the evaluation grid over [-1, 1]² (51: spacing 0.04). A Riemann sum of a
    Gaussian is accurate to about 1 % already at a spacing of twice its standard deviation."""
    hit_radius: float = 0.15
    """An argmin within this distance of a valid expert action counts as a hit."""
    data_seed: int = 12345
    """Seed of the training and held-out data (the same for every run)."""


@dataclass
class RunResult:
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


def make_datasets(problem: ApproachProblem, config: ExperimentConfig) -> tuple[dict, dict]:
    """The training set and the held-out set, both drawn with ``config.data_seed``."""
    g = torch.Generator().manual_seed(config.data_seed)
    return problem.sample(config.n_train, g), problem.sample(config.n_heldout, g)


def make_model(problem: ApproachProblem, config: ExperimentConfig, seed: int) -> EnergyModel:
    """A small EnergyModel (MLP encoder, two-layer head), initialised from ``seed``."""
    torch.manual_seed(check_int("seed", seed, minimum=0))
    w = config.width
    return EnergyModel(MLPEncoder(problem.obs_dim, embed_dim=w, hidden=w, layers=2), problem.action_dim, hidden=w, layers=2)


@torch.no_grad()
def evaluate(model: EnergyModel, heldout: dict, problem: ApproachProblem, config: ExperimentConfig) -> dict[str, float]:
    """Held-out ``nll`` (nats, lower is better) and ``hit`` rate (higher is better); see the module docstring."""
    grid = action_grid(config.grid_n, 2)  # (G, 2)
    z = model.embed(heldout["obs"])  # (B, E)
    e_grid = grid_energies(model, z, grid)  # (B, G)
    e_pos = model.energy_from_embedding(z, heldout["actions"][:, None, :])[:, 0]  # (B,)
    cell = (2.0 / (config.grid_n - 1)) ** 2
    nll = grid_nll(e_pos, e_grid, cell).mean()
    best = grid[e_grid.argmin(dim=1)]  # (B, 2)
    modes, valid = problem.modes(heldout["obs"])
    dist = (best[:, None, :] - modes).norm(dim=-1).masked_fill(~valid, math.inf).min(dim=1).values  # (B,)
    return {"nll": float(nll), "hit": float((dist <= config.hit_radius).float().mean())}


def run(problem: ApproachProblem, sampler, config: ExperimentConfig, seed: int, data: tuple[dict, dict] | None = None) -> RunResult:
    """Train one energy model with InfoNCE and ``sampler``'s counter-examples; evaluate along the way.

    ``seed`` sets the initial weights, the minibatches and the counter-examples; the data come
    from ``config.data_seed`` (pass ``data`` = ``make_datasets(...)`` to reuse them).
    """
    train_set, heldout = data if data is not None else make_datasets(problem, config)
    model = make_model(problem, config, seed)
    tc = TrainConfig(steps=config.steps, batch_size=config.batch_size, lr=config.lr, seed=seed, log_every=config.eval_every)
    res = train(
        model,
        info_nce_objective(model, sampler, config.n_neg),
        {"obs": train_set["obs"], "actions": train_set["actions"]},
        tc,
        evaluate=lambda: evaluate(model, heldout, problem, config),
    )
    return RunResult(
        steps=res.steps, nll=[e["nll"] for e in res.evals], hit=[e["hit"] for e in res.evals], losses=res.losses, model=model
    )


def expert_nll(problem: ApproachProblem, heldout: dict) -> float:
    """The best achievable held-out NLL: that of the expert's own density (nats)."""
    return float(-problem.log_density(heldout["obs"], heldout["actions"]).mean())


def negatives_histogram(
    sampler, actions: torch.Tensor, n_neg: int, *, batches: int = 50, batch_size: int = 64, bins: int = 40, seed: int = 0
) -> torch.Tensor:
    """Where a sampler's counter-examples land: a (bins, bins) histogram over [-1, 1]², summing to 1.

    Draws ``batches`` minibatches of expert ``actions`` (M, 2), asks the sampler for ``n_neg``
    counter-examples each, and bins those inside the box (rows: steer, columns: acceleration).
    """
    g = torch.Generator().manual_seed(seed)
    counts = torch.zeros(bins, bins)
    for _ in range(check_int("batches", batches, minimum=1)):
        idx = torch.randint(0, len(actions), (batch_size,), generator=g)
        neg = sampler(actions[idx], n_neg, g).reshape(-1, 2)
        inside = neg[(neg.abs() <= 1).all(dim=1)]
        ij = ((inside + 1) / 2 * bins).long().clamp(0, bins - 1)
        counts.index_put_((ij[:, 0], ij[:, 1]), torch.ones(len(ij)), accumulate=True)
    return counts / counts.sum()


@torch.no_grad()
def mode_masses(model: EnergyModel, obs: torch.Tensor, problem: ApproachProblem, *, grid_n: int = 51, radius: float = 0.15) -> torch.Tensor:
    """Probability p_θ(y|x) puts within ``radius`` of each of the expert's three candidate actions.

    p_θ is normalised over a ``grid_n`` × ``grid_n`` grid of the box. For a junction observation
    the three columns are turning left, going straight and turning right; the expert takes each
    one third of the time. Returns (B, 3) masses (each row sums to at most 1).
    """
    grid = action_grid(check_int("grid_n", grid_n, minimum=2), 2)  # (G, 2)
    p = torch.softmax(-grid_energies(model, model.embed(obs), grid), dim=1)  # (B, G)
    modes, _ = problem.modes(obs)  # (B, 3, 2)
    near = (grid[None, :, None, :] - modes[:, None, :, :]).norm(dim=-1) <= radius  # (B, G, 3)
    return (p[:, :, None] * near).sum(dim=1)  # (B, 3)
