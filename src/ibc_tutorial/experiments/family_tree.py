"""Part I side by side at the tree: the seven families of ``family_comparison`` on chapter 01's world.

The tree world with memory (``TreeConfig(obs_prev_action=True)``: the observation is the distance to the
tree and the steering applied at the previous step, chapter 03's last section): half of the experts pass
the tree on the right, half on the left, and nothing in the observation says which before they turn.
Every family is trained on the same 200 expert episodes with the networks, objectives and training of
``family_comparison`` (``train_family``), and measured twice:

- **where it chooses** (``decision_points``): held-out expert observations at the first step of the
  swerve, ``decision_distance`` m before the tree, where every previous steering is still near 0. The
  two modes are the mean steering of the right experts there and of the left experts (about ±0.96);
  the truth is the share of the experts' own actions within ``radius`` of their mode (about 1/2 each).
  A family's masses are measured as at the junction (``family_comparison.masses_near``), and the
  Bhattacharyya coefficient (``family_comparison.bhattacharyya``) compares them with the truth;
- **in closed loop** (``drive``): ``episodes`` episodes from the start distribution, each family acting
  as it does (``controller``): the regression's one action, a draw of the MDN, of the Beta and of the
  flow (one sample, K Euler steps), the energy models' draw from softmax(−E) on a grid of ``grid_n``
  steering values. The shares that hit the tree, pass on the right and pass on the left.

``run_tree`` trains and measures one (family, seed): a job for ``parallel`` (it depends on nothing but
its arguments).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch

from ibc_tutorial.experiments.family_comparison import (
    ENERGY_FAMILIES,
    FAMILIES,
    FamilyConfig,
    bhattacharyya,
    masses_near,
    train_family,
)
from ibc_tutorial.optimizers.grid import action_grid
from ibc_tutorial.policies import GridSamplePolicy
from ibc_tutorial.toy import TreeConfig, TreeWorld
from ibc_tutorial.toy.world import ToyPolicy
from ibc_tutorial.utils import check_choice, check_int, check_positive


@dataclass
class TreeStudyConfig:
    """The tree's data, decision points and closed loop; the networks and training are ``families``'."""

    families: FamilyConfig = field(default_factory=FamilyConfig)
    """The networks, objectives, training and measures shared with the junction's study (its junction
    fields, ``n_train`` and ``n_junctions``, are not used here)."""
    episodes: int = 200
    """Expert episodes of the training set (chapters 01-03: 200)."""
    heldout_episodes: int = 200
    """Expert episodes whose decision points the masses are measured at (drawn from ``data_seed`` + 1)."""
    decision_distance: float = 9.5
    """Distance to the tree (m) of the decision points: the experts' first step of the swerve (a step
    earlier, 10 m before the tree, they still steer straight on)."""
    drive_episodes: int = 200
    """Closed-loop episodes per trained policy."""
    drive_seed: int = 2
    """Seed of the closed loop's start states (chapter 01's)."""

    def __post_init__(self) -> None:
        if not isinstance(self.families, FamilyConfig):
            raise ValueError(f"config.families must be a FamilyConfig, got {type(self.families).__name__}")
        for name in ("episodes", "heldout_episodes", "drive_episodes"):
            check_int(f"config.{name}", getattr(self, name), minimum=1)
        check_int("config.drive_seed", self.drive_seed, minimum=0)
        check_positive("config.decision_distance", self.decision_distance)


@dataclass
class TreeRun:
    """One trained (family, seed) at the tree: its masses where it chooses and its closed loop."""

    family: str
    """One of ``family_comparison.FAMILIES``."""
    seed: int
    """The run's seed (initial weights, minibatches, counter-examples, draws)."""
    masses: list[float]
    """Mass on passing right and passing left at the decision points, averaged over them."""
    truth: list[float]
    """The experts' own mass on passing right and passing left at the decision points."""
    bc: float
    """Bhattacharyya coefficient of ``masses`` (and the mass elsewhere) with ``truth``."""
    collided: float
    """Share of the closed-loop episodes that hit the tree."""
    right: float
    """Share that passed the tree on the right."""
    left: float
    """Share that passed the tree on the left."""


def tree_world() -> TreeWorld:
    """The tree world with the previous steering in the observation: (distance / 10 m, previous steering)."""
    return TreeWorld(TreeConfig(obs_prev_action=True))


def decision_points(
    world: TreeWorld, config: TreeStudyConfig
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The held-out experts' decision points: observations (B, 2), the two modes at each (B, 2, 1) (passing
    right: the right experts' mean steering there; passing left: the left experts'), and the truth (2,):
    the share of the experts' actions there within ``families.radius`` of their own mode."""
    demos = world.expert_demonstrations(config.heldout_episodes, config.families.data_seed + 1)
    distance = world.physical(demos.obs)[:, 0]  # (M,) m
    at = (distance - config.decision_distance).abs() < 0.25  # one step (0.5 m) of each expert
    if not at.any():
        raise ValueError(
            f"config.decision_distance: no expert step within 0.25 m of {config.decision_distance}"
        )
    obs, actions, mode = demos.obs[at], demos.actions[at, 0], demos.mode[at]  # (B, 2), (B,), (B,)
    if not ((mode == 0).any() and (mode == 1).any()):
        raise ValueError("config.heldout_episodes: the decision points need experts of both sides")
    centres = torch.stack([actions[mode == 0].mean(), actions[mode == 1].mean()])  # (2,): right, left
    near_own = (actions - centres[mode]).abs() <= config.families.radius  # (B,)
    truth = torch.stack([(near_own & (mode == k)).float().mean() for k in (0, 1)])  # (2,)
    modes = centres[None, :, None].expand(len(obs), 2, 1)  # (B, 2, 1)
    return obs, modes, truth


def controller(family: str, policy, config: FamilyConfig, generator: torch.Generator) -> ToyPolicy:
    """How ``family`` acts in closed loop: ``obs (B, obs_dim) -> steering (B, 1)`` (module docstring)."""
    check_choice("family", family, FAMILIES)
    policy.eval()
    if family in ENERGY_FAMILIES:
        return GridSamplePolicy(policy, action_grid(config.grid_n, 1), generator)
    if family == "flow":
        return lambda obs: policy.sample(obs, 1, generator=generator)[:, 0]  # (B, 1): one sample
    if family == "mae":
        return policy.controller()
    return policy.controller("sample", generator)


def drive(world: TreeWorld, policy: ToyPolicy, config: TreeStudyConfig) -> dict[str, float]:
    """``config.drive_episodes`` closed-loop episodes: the shares that ``collided``, passed ``right`` and
    ``left``."""
    r = world.rollout(policy, config.drive_episodes, seed=config.drive_seed)
    side = world.pass_side(r)  # (E,): +1 right, -1 left, 0 collided
    return {
        "collided": world.collision_rate(r),
        "right": float((side == 1).float().mean()),
        "left": float((side == -1).float().mean()),
    }


def run_tree(family: str, seed: int, config: TreeStudyConfig | None = None) -> TreeRun:
    """Train ``family`` from ``seed`` on the tree's demonstrations; its masses at the decision points and
    its closed loop (a job for ``parallel``)."""
    config = TreeStudyConfig() if config is None else config
    check_choice("family", family, FAMILIES)
    seed = check_int("seed", seed, minimum=0)
    world = tree_world()
    data = world.expert_demonstrations(config.episodes, config.families.data_seed).training_data()
    policy = train_family(family, world, data, config.families, seed)
    obs, modes, truth = decision_points(world, config)
    masses = masses_near(family, policy, obs, modes, config.families, seed).mean(0)  # (2,)
    loop = drive(
        world, controller(family, policy, config.families, torch.Generator().manual_seed(seed)), config
    )
    return TreeRun(family, seed, masses.tolist(), truth.tolist(), bhattacharyya(masses, truth), **loop)
