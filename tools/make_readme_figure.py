#!/usr/bin/env python
"""Regenerate book/figures/the_tree.png, the README's figure: chapter 01's closed-loop rollouts.

    python tools/make_readme_figure.py

It repeats chapter 01's steps with the same seeds (expert demonstrations, MSE and MAE regression
policies, 200 rollouts each) and draws them with the same function the chapter uses,
``ibc_tutorial.plotting.multimodality.plot_tree_closed_loop``: the side each episode passes in
the colours of ``TREE_SIDE_COLORS`` (left blue, right orange; y points to the left, so passing
on the right is y < 0).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
os.environ.setdefault("TQDM_DISABLE", "1")  # utils.QUIET_ENV: no progress bars

import torch  # noqa: E402

import ibc_tutorial as ibc  # noqa: E402
from ibc_tutorial.objectives import likelihood_objective  # noqa: E402
from ibc_tutorial.plotting import save  # noqa: E402
from ibc_tutorial.plotting.multimodality import plot_tree_closed_loop  # noqa: E402
from ibc_tutorial.policies.explicit import RegressionPolicy  # noqa: E402
from ibc_tutorial.toy import TreeWorld  # noqa: E402
from ibc_tutorial.training import TrainConfig, train  # noqa: E402

OUT = ROOT / "book" / "figures" / "the_tree.png"


def fit_regression(demos, loss_kind: str, seed: int = 0, steps: int = 600) -> RegressionPolicy:
    """As in chapter 01: a RegressionPolicy (MLP 2 x 64, tanh head) trained by Adam with the MSE or
    the MAE."""
    torch.manual_seed(seed)
    policy = RegressionPolicy.for_vectors(demos.obs.shape[1], 1, hidden=64, layers=2, loss_kind=loss_kind)
    config = TrainConfig(steps=steps, batch_size=128, lr=3e-3, seed=seed)
    train(policy, likelihood_objective(policy), demos.training_data(), config)
    return policy


def main() -> int:
    ibc.seed_everything(0)
    world = TreeWorld()
    demos = world.expert_demonstrations(200, seed=0)
    rollouts = {"experts": world.expert_rollouts(200, seed=2)[0]}
    for kind in ("mse", "mae"):
        policy = fit_regression(demos, kind)
        rollouts[kind.upper() + " regression"] = world.rollout(policy, 200, seed=2)
    title = "Experts pass the tree on both sides; regression policies drive into it"
    fig = plot_tree_closed_loop(world, rollouts, title=title)
    save(fig, OUT)
    rates = ", ".join(f"{k} {world.collision_rate(r):.2f}" for k, r in rollouts.items())
    print(f"wrote {OUT.relative_to(ROOT)} (collision rates: {rates})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
