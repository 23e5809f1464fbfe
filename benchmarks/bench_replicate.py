#!/usr/bin/env python
"""Where the hour of ``ibc-tutorial replicate`` goes: each stage timed, then the shares of the whole.

    python benchmarks/bench_replicate.py                         # the laptop preset, 1 thread, as one worker runs
    python benchmarks/bench_replicate.py --preset laptop --data book/results/laptop/data/town01.npz
    python benchmarks/bench_replicate.py --train-steps 40 --eval-steps 300

Each stage of a replication is timed on a sample of its work in this process, with one torch
thread (as each of ``replicate --workers 2 --threads 1``'s workers), and scaled to the preset:

- collect: the expert driving one town01 route (scaled by the preset's samples);
- render: the dataset's BEV cache (``DemoDataset(cache=True)``) and the KDE weights;
- train: ``--train-steps`` minibatches of each method (scaled by epochs x steps per epoch);
- evaluate: ``--eval-episodes`` batched episodes of ``--eval-steps`` steps of each method's
  freshly built agent (scaled by the periodic evaluations, the final table and, for BC and
  DA-IBC, the free-driving episodes); an untrained agent drives about as long per step as a
  trained one (the cost is the network and the DFO, not the road);
- the expert's own row: ``--eval-episodes`` batched episodes of the expert.

Printed: seconds per unit of work, the scaled total of each stage, its share of the serial
total, and the wall time expected with ``--workers`` processes (runs in parallel, the shared
stages not). The load average is printed beside: timings taken while the machine does other
work are inflated. Measured figures belong in the chapter that quotes them, with this command.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import tempfile
import time

import torch

from ibc_tutorial.driving.collect import CollectConfig, collect
from ibc_tutorial.driving.dataset import DemoDataset, DemoLog
from ibc_tutorial.experiments.agents.agent import Agent, build_network
from ibc_tutorial.experiments.agents.evaluate import evaluate_agent
from ibc_tutorial.experiments.agents.presets import METHODS, get_preset
from ibc_tutorial.experiments.agents.replicate import FIGURE_METHODS
from ibc_tutorial.experiments.agents.train import DemoBatches, objective_for, steps_per_epoch
from ibc_tutorial.kde import inverse_density_weights
from ibc_tutorial.training import TrainConfig, Trainer


def timed(fn):
    t = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--preset", default="laptop")
    ap.add_argument(
        "--data", help="demonstrations already collected with the preset (skips timing a collection)"
    )
    ap.add_argument("--train-steps", type=int, default=30, help="minibatches timed per method")
    ap.add_argument("--eval-episodes", type=int, default=4, help="batched episodes timed per method")
    ap.add_argument("--eval-steps", type=int, default=200, help="steps of each timed episode")
    ap.add_argument("--workers", type=int, default=2, help="worker processes the wall-time estimate assumes")
    args = ap.parse_args()
    torch.set_num_threads(1)
    os.environ.setdefault("TQDM_DISABLE", "1")
    p = get_preset(args.preset)
    print(
        f"preset {p.name}; {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, torch "
        f"{torch.__version__}, 1 thread; load average before: {os.getloadavg()[0]:.2f}"
    )

    rows = []  # (stage, unit, seconds per unit, units, total seconds, parallel)
    if args.data:
        log = DemoLog.load(args.data)
    else:
        one = CollectConfig(
            routes=1, seed=p.collect_seed, min_minutes=p.min_minutes, max_minutes=p.max_minutes
        )
        log1, t = timed(lambda: collect(one, show_progress=False))
        samples = p.routes * 600 * (p.min_minutes + p.max_minutes) / 2
        rows.append(("collect", "sample", t / len(log1), samples, t / len(log1) * samples, False))
        log = log1
    ds, t_render = timed(lambda: DemoDataset(log, bev_size=p.bev_size, cache=True))
    probs, t_kde = timed(lambda: inverse_density_weights(ds.actions, p.kde_bandwidth))
    m_full = p.routes * 600 * (p.min_minutes + p.max_minutes) / 2 if not args.data else len(log)
    rows.append(("render BEVs", "sample", t_render / len(log), m_full, t_render / len(log) * m_full, False))
    rows.append(
        ("KDE weights", "run", t_kde * (m_full / len(log)) ** 2, 1, t_kde * (m_full / len(log)) ** 2, False)
    )

    n_steps = steps_per_epoch(int(m_full), p.batch_size) * p.epochs
    n_evals = p.epochs // p.eval_every
    for method in METHODS:
        torch.manual_seed(0)
        net = build_network(method, p)
        trainer = Trainer(
            net,
            objective_for(method, net, p),
            DemoBatches(ds),
            TrainConfig(steps=args.train_steps + 3, batch_size=p.batch_size, lr=p.lr, progress=False),
            sample_probs=probs,
        )
        trainer.config.steps = 3
        trainer.run()  # warm-up: first calls allocate
        trainer.config.steps = args.train_steps + 3
        _, t = timed(trainer.run)
        per = t / args.train_steps
        rows.append((f"train {method}", "minibatch", per, n_steps, per * n_steps * len(p.seeds), True))
        agent = Agent(method, net.eval(), p, ds.actions, init_weights=probs if method == "da-ibc" else None)
        _, t = timed(
            lambda: evaluate_agent(agent, "town02", args.eval_episodes, args.eval_steps, show_progress=False)
        )
        per = t / (args.eval_episodes * args.eval_steps)  # seconds per episode-step, batched
        ep_steps = n_evals * p.eval_episodes * p.eval_steps + p.final_episodes * p.final_steps
        rows.append(
            (f"evaluate {method}", "episode-step", per, ep_steps, per * ep_steps * len(p.seeds), True)
        )
        if method in FIGURE_METHODS:
            fd = p.routeless_episodes * p.routeless_steps
            per1 = per * args.eval_episodes  # free driving runs one episode at a time
            rows.append((f"free driving {method}", "step", per1, fd, per1 * fd, False))
    _, t = timed(
        lambda: evaluate_agent("expert", "town02", args.eval_episodes, args.eval_steps, show_progress=False)
    )
    per = t / (args.eval_episodes * args.eval_steps)
    rows.append(
        (
            "evaluate expert",
            "episode-step",
            per,
            p.final_episodes * p.final_steps,
            per * p.final_episodes * p.final_steps,
            False,
        )
    )

    serial = sum(r[4] for r in rows if not math.isnan(r[4]))
    parallel = sum(r[4] for r in rows if r[5])
    wall = serial - parallel + parallel / max(1, args.workers)
    print(f"\n{'stage':<22}{'per unit (ms)':>14}{'units':>12}{'total (s)':>11}{'share':>8}")
    for stage, unit, per, units, total, _ in rows:
        print(
            f"{stage:<22}{per * 1000:>10.2f} /{unit[:3]}{units:>12,.0f}{total:>11.0f}{total / serial:>8.1%}"
        )
    print(
        f"\nserial total {serial / 60:.1f} min ({len(p.seeds)} seeds x {len(METHODS)} methods, {p.epochs} epochs, "
        f"{n_evals} periodic evaluations); expected wall time with {args.workers} workers: {wall / 60:.1f} min"
    )
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    with tempfile.TemporaryDirectory():
        main()
