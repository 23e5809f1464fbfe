"""Part I side by side: seven policy families on the junction world's three-way choice.

Every family is trained on the same junction-world demonstrations (``toy.junction``; the data of
chapter 04, ``counter_examples.make_datasets``) with the one loop, on the same ``MLPEncoder``, and
measured where the expert is multimodal: at a T-junction it turns left, goes straight or turns
right, one third each. Measured per family (``mode_masses``) on held-out junction observations:

- the **mass on each mode**: the probability the policy's action lands within ``radius`` of the
  expert's left, straight and right actions. For the energy models, the mass of p_θ = softmax(−E)
  over a fine grid of the box (``counter_examples.mode_masses``: the distribution a draw from the
  energy acts by); for the others, the share of ``samples`` draws of the policy's action (the
  MDN's and the Beta's "sample" mode, the flow's samples; the regression's single action);
- the **Bhattacharyya coefficient** BC = Σ_k √(m_k t_k) between the policy's masses and the truth
  t (``true_mode_masses``), over the three modes and the mass elsewhere (whose truth is ~0):
  1 for the expert's own distribution, lower for any misplaced or misweighted mass.

The families (``FAMILIES``): "mae" (regression, the steering-EBM paper's baseline), "mdn" (5
Gaussians), "beta" (the DA-IBC paper's BC, eq. 1), "ibc" (InfoNCE, uniform counter-examples),
"da-ibc" (InfoNCE, expert + N(0, σ²) counter-examples: learns exp(−E) ∝ p / q), "da-ibc r-nce" (the
same counter-examples with ranking NCE: exp(−E) ∝ p) and "flow" (conditional flow matching).
``run_family`` trains and measures one (family, seed); ``compare`` maps it over families and seeds
in worker processes (``parallel.parallel_map``); ``summarize`` reduces the runs per family.

What does not depend on the world is shared with the tree's study (``experiments.family_tree``): the
networks (``make_policy``, on any world with ``obs_dim`` and ``action_dim``), their objectives and training
(``train_family``), their draws (``draw_actions``), the mass near given modes (``masses_near``) and the
Bhattacharyya coefficient over any number of modes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from ibc_tutorial.experiments.counter_examples import CounterExampleConfig, make_datasets, train_config
from ibc_tutorial.experiments.counter_examples import masses_near as energy_masses_near
from ibc_tutorial.negatives import ExpertSampler, UniformSampler
from ibc_tutorial.objectives import flow_matching_objective, info_nce_objective, likelihood_objective
from ibc_tutorial.parallel import parallel_map
from ibc_tutorial.policies import (
    BetaPolicy,
    EnergyModel,
    FlowConfig,
    FlowPolicy,
    MDNPolicy,
    MLPEncoder,
    RegressionPolicy,
)
from ibc_tutorial.toy.junction import JunctionWorld
from ibc_tutorial.training import TrainConfig, train
from ibc_tutorial.utils import check_choice, check_int, check_positive, check_tensor

FAMILIES = ("mae", "mdn", "beta", "ibc", "da-ibc", "da-ibc r-nce", "flow")
"""The policy families compared, in the order of the table."""

ENERGY_FAMILIES = ("ibc", "da-ibc", "da-ibc r-nce")
"""The families that are energy models (measured on the grid's softmax(−E))."""


@dataclass
class FamilyConfig:
    """Data, model sizes, training and measures shared by every family."""

    n_train: int = 4000
    """Expert samples in the training set (chapter 04's)."""
    n_junctions: int = 64
    """Held-out junction observations the masses are averaged over."""
    width: int = 64
    """Width of every encoder's and head's hidden layers and of the embedding (chapter 04: 32)."""
    train: TrainConfig = field(default_factory=lambda: train_config(steps=2000, lr=2e-3, progress=False))
    """How every family is trained (chapter 04's minibatches of 64, 2000 steps at 2e-3); ``run_family``
    sets the seed."""
    n_neg: int = 16
    """Counter-examples per sample of the energy models."""
    neg_sigma: float = 0.1
    """σ of DA-IBC's counter-example noise (chapter 04's)."""
    flow_layers: int = 4
    """Hidden layers of the flow's velocity head (the other heads have 2): at 2 its samples blur between
    the modes (mass on each 0.14-0.29 over 5 seeds); the field that splits them near t = 1 needs depth."""
    flow: FlowConfig = field(default_factory=lambda: FlowConfig(n_steps=10))
    """The flow policy's settings (its ``n_samples`` is replaced by ``samples`` when measuring)."""
    samples: int = 500
    """Draws per observation for the families measured by sampling (MDN, Beta, flow)."""
    radius: float = 0.15
    """An action within this distance of a mode counts as that mode (as in chapter 04)."""
    grid_n: int = 51
    """Points per axis of the grid of the energy models' softmax."""
    data_seed: int = 12345
    """Seed of the training data and the held-out observations (the same for every run)."""

    def __post_init__(self) -> None:
        for name in ("n_train", "n_junctions", "width", "n_neg", "samples", "flow_layers"):
            check_int(f"config.{name}", getattr(self, name), minimum=1)
        check_int("config.grid_n", self.grid_n, minimum=2)
        check_int("config.data_seed", self.data_seed, minimum=0)
        check_positive("config.neg_sigma", self.neg_sigma)
        check_positive("config.radius", self.radius)
        if not isinstance(self.train, TrainConfig):
            raise ValueError(f"config.train must be a TrainConfig, got {type(self.train).__name__}")
        if not isinstance(self.flow, FlowConfig):
            raise ValueError(f"config.flow must be a FlowConfig, got {type(self.flow).__name__}")


@dataclass
class FamilyRun:
    """One trained (family, seed) and its measures on the held-out junction observations."""

    family: str
    """One of ``FAMILIES``."""
    seed: int
    """The run's seed (initial weights, minibatches, counter-examples, noise)."""
    masses: list[float]
    """Mass on the left, straight and right modes, averaged over the observations."""
    bc: float
    """Bhattacharyya coefficient of ``masses`` (and the mass elsewhere) with the truth."""


def true_mode_masses(world: JunctionWorld, radius: float) -> torch.Tensor:
    """The expert's own mass on each mode at a junction, (3,): 1/3 × P(‖N(0, s² I₂)‖ ≤ radius), s =
    ``expert_noise`` (the Rayleigh distribution's CDF; the modes lie farther apart than 2 × radius)."""
    s = world.config.expert_noise
    inside = 1.0 - math.exp(-(check_positive("radius", radius) ** 2) / (2 * s**2))
    return torch.full((3,), inside / 3.0)


def bhattacharyya(masses: torch.Tensor, truth: torch.Tensor) -> float:
    """BC = Σ_k √(m_k t_k) over the K modes and the rest (1 − Σ m, 1 − Σ t): in [0, 1], 1 when equal.
    ``masses`` and ``truth`` are (K,), K >= 1 (three at the junction, two at the tree)."""
    check_tensor("truth", truth, ndim=1)
    check_tensor("masses", masses, shape=tuple(truth.shape))
    m = torch.cat([masses, (1 - masses.sum()).clamp_min(0)[None]])
    t = torch.cat([truth, (1 - truth.sum()).clamp_min(0)[None]])
    return float((m * t).sqrt().sum())


def make_policy(family: str, world, config: FamilyConfig, seed: int) -> torch.nn.Module:
    """The untrained network of ``family`` on an ``MLPEncoder``, its weights drawn from ``seed``; ``world``
    gives the sizes (``obs_dim``, ``action_dim``: the junction world or a toy world)."""
    check_choice("family", family, FAMILIES)
    torch.manual_seed(check_int("seed", seed, minimum=0))
    w = config.width
    encoder = MLPEncoder(world.obs_dim, embed_dim=w, hidden=w, layers=2)
    d = world.action_dim
    if family == "mae":
        return RegressionPolicy(encoder, d, loss_kind="mae")
    if family == "mdn":
        return MDNPolicy(encoder, d, n_components=5)
    if family == "beta":
        return BetaPolicy(encoder, d)
    if family == "flow":
        return FlowPolicy(encoder, d, hidden=w, layers=config.flow_layers, config=config.flow)
    return EnergyModel(encoder, d, hidden=w, layers=2)


def objective_for(family: str, policy: torch.nn.Module, config: FamilyConfig):
    """The training objective of ``family`` (see the module docstring)."""
    check_choice("family", family, FAMILIES)
    if family in ("mae", "mdn", "beta"):
        return likelihood_objective(policy)
    if family == "flow":
        return flow_matching_objective(policy)
    if family == "ibc":
        return info_nce_objective(policy, UniformSampler(-1.0, 1.0), config.n_neg)
    sampler = ExpertSampler(config.neg_sigma)
    return info_nce_objective(policy, sampler, config.n_neg, ranking=family == "da-ibc r-nce")


def junction_observations(world: JunctionWorld, config: FamilyConfig) -> torch.Tensor:
    """``config.n_junctions`` held-out junction observations (n, 4), drawn from ``config.data_seed`` + 1."""
    g = torch.Generator().manual_seed(config.data_seed + 1)
    obs = []
    while sum(len(o) for o in obs) < config.n_junctions:
        d = world.sample(4 * config.n_junctions, g)
        obs.append(d["obs"][d["situation"] == 1])
    return torch.cat(obs)[: config.n_junctions]


def train_family(family: str, world, data: dict, config: FamilyConfig, seed: int) -> torch.nn.Module:
    """``family``'s network (``make_policy``) trained on ``data`` ({"obs": (M, obs_dim), "actions": (M, D)})
    by its objective with ``config.train`` and ``seed`` (initial weights and minibatches alike)."""
    policy = make_policy(family, world, config, seed)
    train_cfg = TrainConfig(**{**config.train.__dict__, "seed": seed})
    train(policy, objective_for(family, policy, config), data, train_cfg)
    return policy


@torch.no_grad()
def draw_actions(
    family: str, policy, obs: torch.Tensor, n: int, generator: torch.Generator, n_steps: int | None = None
) -> torch.Tensor:
    """(B, N, D): ``n`` actions of a non-energy family per observation, as it acts: the MDN's and the
    Beta's "sample" mode, the flow's samples (``n_steps`` Euler steps, default its config's K), the
    regression's one action repeated."""
    check_choice("family", family, tuple(f for f in FAMILIES if f not in ENERGY_FAMILIES))
    n = check_int("n", n, minimum=1)
    policy.eval()
    b = len(obs)
    if family == "flow":
        return policy.sample(obs, n, n_steps, generator=generator)  # (B, N, D)
    if family == "mae":
        return policy.act(obs)[:, None, :].expand(b, n, -1)  # (B, N, D): one action
    y = policy.act(obs.repeat_interleave(n, dim=0), mode="sample", generator=generator)  # (B N, D)
    return y.reshape(b, n, -1)


@torch.no_grad()
def masses_near(
    family: str, policy, obs: torch.Tensor, modes: torch.Tensor, config: FamilyConfig, seed: int, **draw
) -> torch.Tensor:
    """(B, K): each observation's mass within ``config.radius`` of each of ``modes`` (B, K, D): the energy
    models' softmax(−E) on a grid (``counter_examples.masses_near``), the others' share of
    ``config.samples`` draws (``draw_actions``, seeded by ``seed``; ``draw``: its ``n_steps``)."""
    check_choice("family", family, FAMILIES)
    policy.eval()
    if family in ENERGY_FAMILIES:
        return energy_masses_near(policy, obs, modes, grid_n=config.grid_n, radius=config.radius)
    y = draw_actions(family, policy, obs, config.samples, torch.Generator().manual_seed(seed), **draw)
    near = (y[:, :, None, :] - modes[:, None, :, :]).norm(dim=-1) <= config.radius  # (B, S, K)
    return near.float().mean(dim=1)  # (B, K)


def mode_masses(
    family: str, policy, obs: torch.Tensor, world: JunctionWorld, config: FamilyConfig, seed: int, **draw
) -> torch.Tensor:
    """(B, 3): each junction observation's mass on the left, straight and right modes (module docstring)."""
    modes, _ = world.modes(obs)  # (B, 3, 2)
    return masses_near(family, policy, obs, modes, config, seed, **draw)


def junction_data(world: JunctionWorld, config: FamilyConfig) -> dict:
    """The training set every family learns from: {"obs": (M, 4), "actions": (M, 2)} (chapter 04's data)."""
    data_config = CounterExampleConfig(n_train=config.n_train, data_seed=config.data_seed)
    train_set, _ = make_datasets(world, data_config)
    return {"obs": train_set["obs"], "actions": train_set["actions"]}


def run_family(family: str, seed: int, config: FamilyConfig | None = None) -> FamilyRun:
    """Train ``family`` from ``seed`` on the junction world and measure its mode masses (a job for
    ``parallel_map``: depends on nothing but its arguments)."""
    config = FamilyConfig() if config is None else config
    world = JunctionWorld()
    policy = train_family(family, world, junction_data(world, config), config, seed)
    masses = mode_masses(family, policy, junction_observations(world, config), world, config, seed).mean(0)
    truth = true_mode_masses(world, config.radius)
    return FamilyRun(family, seed, [float(m) for m in masses], bhattacharyya(masses, truth))


def compare(
    families=FAMILIES,
    seeds=(0, 1, 2, 3, 4),
    config: FamilyConfig | None = None,
    *,
    workers: int | None = None,
) -> list[FamilyRun]:
    """``run_family`` for every family and seed (family-major order), in up to ``workers`` processes."""
    for f in families:
        check_choice("families", f, FAMILIES)
    seeds = [check_int("seeds", s, minimum=0) for s in seeds]
    calls = [(f, s) for f in families for s in seeds]
    return parallel_map(run_family, calls, workers=workers, config=config or FamilyConfig())


def summarize(runs: list[FamilyRun], world: JunctionWorld | None = None, radius: float = 0.15) -> dict:
    """Per family: ``masses`` (mean over seeds, (3,)), ``max_error`` (the largest |mass − truth| over
    seeds and modes), ``bc`` (mean over seeds), ``within_0.1`` (every mode of every seed within 0.1 of the
    truth), ``seeds``."""
    truth = true_mode_masses(JunctionWorld() if world is None else world, radius)
    out: dict[str, dict] = {}
    for family in dict.fromkeys(r.family for r in runs):
        m = torch.tensor([r.masses for r in runs if r.family == family])  # (S, 3)
        err = float((m - truth).abs().max())
        out[family] = {
            "masses": m.mean(0).tolist(),
            "max_error": err,
            "bc": sum(r.bc for r in runs if r.family == family) / len(m),
            "within_0.1": err <= 0.1,
            "seeds": len(m),
        }
    return out
