"""What one decision costs each family of ``family_comparison``, measured in one process.

Every family's network is built on the junction world (2-D actions) from the same seed, so every one has
the same ``MLPEncoder`` with the same weights; the networks are untrained (a decision's cost does not
depend on the weights). Each way of acting (``WAYS``) is timed on the same batch of observations:

- "mae": the regression's one action (one encoder pass, one head pass);
- "mdn", "beta": one draw from the mixture or the Beta (one encoder pass, one head pass, a draw);
- "energy, grid": one draw from softmax(−E) on a grid of ``grid_n`` points per action dimension (the
  measure of the energy models' masses, and how they act at the tree): grid_n^D head passes;
- "energy, DFO": Algorithm 1 of the DA-IBC paper at the town's laptop settings (``dfo_samples`` ×
  ``dfo_iters`` head passes, uniform initialisation over the box);
- "flow, K=k": one flow sample by k Euler steps (k head passes), for each k of ``flow_steps``.

The three energy families (IBC, DA-IBC, DA-IBC with R-NCE) share one network and so one cost. Reported
per way (``decision_cost``): the network evaluations per decision (encoder and head passes per
observation) and the CPU seconds per decision (the median over ``repeats`` timed calls on the batch,
divided by its size), and both as ratios to the regression's.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass

import torch

from ibc_tutorial.experiments.family_comparison import FamilyConfig, make_policy
from ibc_tutorial.optimizers.dfo import DFOConfig, act_with_dfo
from ibc_tutorial.optimizers.grid import action_grid
from ibc_tutorial.policies import GridSamplePolicy
from ibc_tutorial.policies.flow import network_evaluations
from ibc_tutorial.toy.junction import JunctionWorld
from ibc_tutorial.utils import check_int


@dataclass
class CostConfig:
    """The batch, the timing and the ways of acting that are timed."""

    batch: int = 64
    """Observations per timed call (one decision each)."""
    repeats: int = 30
    """Timed calls per way of acting (the median is kept), after ``warmup`` untimed ones."""
    warmup: int = 3
    """Untimed calls first."""
    flow_steps: tuple[int, ...] = (1, 4, 10, 20)
    """K of the flow rows."""
    dfo_samples: int = 512
    """DFO's N_samples (the laptop preset's)."""
    dfo_iters: int = 3
    """DFO's N_iters (the laptop preset's)."""
    seed: int = 0
    """Seed of the networks' weights, the observations and the draws."""

    def __post_init__(self) -> None:
        for name in ("batch", "repeats", "dfo_samples", "dfo_iters"):
            check_int(f"config.{name}", getattr(self, name), minimum=1)
        check_int("config.warmup", self.warmup, minimum=0)
        check_int("config.seed", self.seed, minimum=0)
        self.flow_steps = tuple(check_int("config.flow_steps", k, minimum=1) for k in self.flow_steps)


def ways_of_acting(family_config: FamilyConfig, config: CostConfig) -> dict[str, tuple]:
    """{way: (decide(obs) -> (B, D), evaluations per observation {"encoder", "head"})} on the junction
    world, every network from ``config.seed`` (the same encoder weights)."""
    world = JunctionWorld()
    g = torch.Generator().manual_seed(config.seed)
    nets = {
        f: make_policy(f, world, family_config, config.seed) for f in ("mae", "mdn", "beta", "ibc", "flow")
    }
    for net in nets.values():
        net.eval()
    one = {"encoder": 1, "head": 1}
    grid = action_grid(family_config.grid_n, world.action_dim)  # (G, 2)
    grid_policy = GridSamplePolicy(nets["ibc"], grid, g)
    dfo = DFOConfig(n_samples=config.dfo_samples, n_iters=config.dfo_iters, init="uniform")
    box = torch.zeros(1, world.action_dim)  # uniform initialisation: the expert actions are not used
    ways = {
        "mae": (lambda obs: nets["mae"].act(obs), one),
        "mdn": (lambda obs: nets["mdn"].act(obs, mode="sample", generator=g), one),
        "beta": (lambda obs: nets["beta"].act(obs, mode="sample", generator=g), one),
        "energy, grid": (grid_policy, {"encoder": 1, "head": len(grid)}),
        "energy, DFO": (
            lambda obs: act_with_dfo(nets["ibc"], obs, box, dfo, generator=g),
            {"encoder": 1, "head": config.dfo_samples * config.dfo_iters},
        ),
    }
    for k in config.flow_steps:
        ways[f"flow, K={k}"] = (
            lambda obs, k=k: nets["flow"].sample(obs, 1, k, generator=g)[:, 0],
            network_evaluations(1, k),
        )
    return ways


@torch.no_grad()
def decision_cost(family_config: FamilyConfig | None = None, config: CostConfig | None = None) -> dict:
    """Per way of acting (module docstring): ``encoder`` and ``head`` passes per decision, ``cpu_us`` (CPU
    microseconds per decision), and ``evaluations_ratio`` (head passes) and ``cpu_ratio`` to "mae"."""
    family_config = FamilyConfig() if family_config is None else family_config
    config = CostConfig() if config is None else config
    world = JunctionWorld()
    obs = world.sample(config.batch, torch.Generator().manual_seed(config.seed))["obs"]  # (B, 4)
    rows = {}
    for way, (decide, evaluations) in ways_of_acting(family_config, config).items():
        for _ in range(config.warmup):
            decide(obs)
        times = []
        for _ in range(config.repeats):
            t0 = time.process_time()
            decide(obs)
            times.append(time.process_time() - t0)
        rows[way] = {**evaluations, "cpu_us": 1e6 * statistics.median(times) / config.batch}
    base = rows["mae"]
    for row in rows.values():
        row["evaluations_ratio"] = row["head"] / base["head"]
        row["cpu_ratio"] = row["cpu_us"] / base["cpu_us"] if base["cpu_us"] > 0 else float("nan")
    return rows
