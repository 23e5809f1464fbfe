#!/usr/bin/env python
"""Seeds trained as one stacked model against one run per seed: the time of each, and their ratio.

    OMP_NUM_THREADS=1 python benchmarks/bench_stacked.py             # chapter 02/03's networks, 5 seeds
    OMP_NUM_THREADS=1 python benchmarks/bench_stacked.py --steps 200 --seeds 3

For each network of the toy chapters (chapter 02's four explicit policies, chapter 03's regression and
energy model with InfoNCE, and a small grid-objective energy model), in one process and float64 as the
chapters train: S seeds trained one after another with ``training.train`` and the same S seeds with
``stacked_training.train_stacked``, the two timed in alternation over ``--rounds`` rounds; it prints
the median times, their ratio (> 1: stacking is faster) and the largest difference of the trained
weights between the two ways (round-off, amplified by training; chapter 02's MDN amplifies it most).
"""

from __future__ import annotations

import argparse
import statistics
import time
from functools import partial

import torch

from ibc_tutorial.experiments.toy_runs import make_explicit
from ibc_tutorial.negatives import UniformSampler
from ibc_tutorial.objectives import grid_objective, info_nce_objective, likelihood_objective
from ibc_tutorial.optimizers.grid import action_grid
from ibc_tutorial.policies import EnergyModel, MLPEncoder
from ibc_tutorial.stacked_training import train_stacked
from ibc_tutorial.toy import TreeWorld
from ibc_tutorial.training import TrainConfig, train


def networks(obs_dim: int) -> dict:
    """name: (build(), objective(model), batch size), as the chapters train them."""

    def ebm(width):
        return lambda: EnergyModel(
            MLPEncoder(obs_dim, embed_dim=width, hidden=width), action_dim=1, hidden=width, layers=2
        )

    explicit = {
        name: (partial(make_explicit, name, obs_dim), likelihood_objective, 128)
        for name in ("regression", "Beta", "classifier", "MDN")
    }
    return {
        **explicit,
        "EBM, InfoNCE (ch. 03)": (
            ebm(64),
            partial(info_nce_objective, sampler=UniformSampler(), n_neg=32),
            64,
        ),
        "EBM, grid, width 32 (ch. 03)": (ebm(32), partial(grid_objective, grid=action_grid(32)), 32),
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--steps", type=int, default=300, help="training steps of each run")
    parser.add_argument("--seeds", type=int, default=5, help="seeds per sweep (S)")
    parser.add_argument(
        "--rounds", type=int, default=3, help="alternating rounds timed (the median is shown)"
    )
    args = parser.parse_args()
    torch.set_default_dtype(torch.float64)
    demos = TreeWorld().expert_demonstrations(200, seed=0)
    data = demos.training_data()
    seeds = list(range(args.seeds))
    print(f"{args.seeds} seeds x {args.steps} steps, float64, {torch.get_num_threads()} torch thread(s)")
    print(
        f"{'network':30s} {'one by one (s)':>14s} {'stacked (s)':>12s} {'ratio':>6s} {'weights apart':>14s}"
    )
    for name, (build, objective, batch) in networks(demos.obs.shape[1]).items():
        config = TrainConfig(steps=args.steps, batch_size=batch, lr=3e-3, progress=False)
        times = {"separate": [], "stacked": []}
        for _ in range(args.rounds):
            separate, stacked = [], []
            for s in seeds:
                torch.manual_seed(s)
                separate.append(build())
                torch.manual_seed(s)
                stacked.append(build())
            t = time.perf_counter()
            for s, model in zip(seeds, separate, strict=True):
                train(model, objective(model), data, TrainConfig(**{**config.__dict__, "seed": s}))
            times["separate"].append(time.perf_counter() - t)
            t = time.perf_counter()
            train_stacked(stacked, objective, data, config, seeds)
            times["stacked"].append(time.perf_counter() - t)
        a, b = statistics.median(times["separate"]), statistics.median(times["stacked"])
        with torch.no_grad():
            apart = max(
                float((p - q).abs().max())
                for m, n in zip(separate, stacked, strict=True)
                for p, q in zip(m.parameters(), n.parameters(), strict=True)
            )
        print(f"{name:30s} {a:14.2f} {b:12.2f} {a / b:6.2f} {apart:14.1e}")


if __name__ == "__main__":
    main()
