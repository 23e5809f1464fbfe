#!/usr/bin/env python
"""Where the hour of ``ibc-tutorial replicate`` goes: each stage timed, then the shares of the whole.

    python benchmarks/bench_replicate.py       # the laptop preset, 1 thread, as one worker runs
    python benchmarks/bench_replicate.py --preset laptop --data book/results/laptop/data/town01.npz
    python benchmarks/bench_replicate.py --train-steps 40 --eval-steps 300
    python benchmarks/bench_replicate.py --limits       # how far each stage is from the CPU's peak
    python benchmarks/bench_replicate.py --set collect.routes=20 --set epochs=4 --set seeds=0,1,2,3,4,5,6,7
                                                                  # what a variant of the preset would cost

With ``--limits`` (``replicate_limits.py`` beside this file, whose docstring says how the shares are
measured), the run prints instead, on a rendered sample of the demonstrations (``--sample``): for every
stage its FLOPs per unit, GFLOP/s and share of the peak of a GEMM and a convolution of its own shapes
measured in the same run. On a shared machine, read the shares, not the times. The candidate speed-ups
once measured against the current path, and not adopted, are in ``RESULTS.md`` beside this file.

Each stage of a replication is timed on a sample of its work in this process, with one torch
thread (as each of ``replicate --workers 2 --threads 1``'s workers), and scaled to the preset:

- collect: the expert driving one town01 route (scaled by the preset's samples);
- render: the dataset's BEV cache (``DemoDataset(cache=True)``) and the KDE weights;
- train: ``--train-steps`` minibatches of each method (scaled by epochs x steps per epoch);
- evaluate: ``--eval-episodes`` batched episodes of ``--eval-steps`` steps of each method's
  freshly built agent, per step driven (an untrained agent's episode may end early), scaled by the
  periodic evaluations, the final table, the held-out episodes and, for BC and DA-IBC, the
  free-driving episodes; a step costs about as much for an untrained agent as for a trained one
  (the cost is the network and the DFO, not the road);
- the expert's own rows (the table's and the held-out starts): ``--eval-episodes`` batched episodes.

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
import sys
import tempfile
import time

import numpy as np
import torch

from ibc_tutorial.driving.collect import CollectConfig, collect
from ibc_tutorial.driving.dataset import DemoDataset, DemoLog
from ibc_tutorial.experiments.agents.agent import Agent, build_network
from ibc_tutorial.experiments.agents.evaluate import evaluate_agent
from ibc_tutorial.experiments.agents.presets import METHODS, get_preset, with_overrides
from ibc_tutorial.experiments.agents.replicate import FIGURE_METHODS
from ibc_tutorial.experiments.agents.train import DemoBatches, objective_for, steps_per_epoch
from ibc_tutorial.experiments.runs import git_commit, machine, now, write_json
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
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="override a preset setting, as replicate's --set (e.g. --set collect.routes=20 --set epochs=4)",
    )
    ap.add_argument(
        "--data", help="demonstrations already collected with the preset (skips timing a collection)"
    )
    ap.add_argument("--train-steps", type=int, default=30, help="minibatches timed per method")
    ap.add_argument(
        "--eval-episodes", type=int, default=10, help="batched episodes timed per method (the table's 10)"
    )
    ap.add_argument("--eval-steps", type=int, default=200, help="steps of each timed episode")
    ap.add_argument("--workers", type=int, default=2, help="worker processes the wall-time estimate assumes")
    ap.add_argument("--limits", action="store_true", help="print each stage's share of the machine's peak")
    ap.add_argument("--sample", type=int, default=4096, help="demonstrations rendered for --limits")
    ap.add_argument("--reps", type=int, default=5, help="timing rounds (minimum or median over them)")
    ap.add_argument(
        "--out",
        help="with --limits: also write the rows, the machine and the load averages to this JSON file",
    )
    args = ap.parse_args()
    torch.set_num_threads(1)
    os.environ.setdefault("TQDM_DISABLE", "1")
    try:
        p = with_overrides(get_preset(args.preset), args.set)
    except ValueError as e:  # a bad --set: one line, before any work
        ap.error(str(e))
    print(
        f"preset {p.name}; {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, torch "
        f"{torch.__version__}, 1 thread; load average before: {os.getloadavg()[0]:.2f}"
    )

    if args.limits:
        return run_limits(p, args)

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
        results, t = timed(
            lambda agent=agent: evaluate_agent(
                agent, "town02", args.eval_episodes, args.eval_steps, show_progress=False
            )
        )
        # seconds per episode-step driven, batched: an untrained agent's episode may end early (in a
        # building), so the steps it drove, not the steps asked for, are the denominator
        per = t / sum(int(r.steps) for r in results)
        # the periodic evaluations, the table's final episodes and the held-out ones
        ep_steps = (
            n_evals * p.eval_episodes * p.eval_steps + (p.final_episodes + p.heldout_episodes) * p.final_steps
        )
        rows.append(
            (f"evaluate {method}", "episode-step", per, ep_steps, per * ep_steps * len(p.seeds), True)
        )
        if method in FIGURE_METHODS:
            fd = p.routeless_episodes * p.routeless_steps
            one, t1 = timed(  # free driving runs one episode at a time: timed so, per step driven
                lambda agent=agent: evaluate_agent(agent, "town02", 1, args.eval_steps, show_progress=False)
            )
            per1 = t1 / int(one[0].steps)
            rows.append((f"free driving {method}", "step", per1, fd, per1 * fd, False))
    results, t = timed(
        lambda: evaluate_agent("expert", "town02", args.eval_episodes, args.eval_steps, show_progress=False)
    )
    per = t / sum(int(r.steps) for r in results)
    expert_steps = (p.final_episodes + p.heldout_episodes) * p.final_steps  # its table and held-out rows
    rows.append(("evaluate expert", "episode-step", per, expert_steps, per * expert_steps, False))

    serial = sum(r[4] for r in rows if not math.isnan(r[4]))
    parallel = sum(r[4] for r in rows if r[5])
    wall = serial - parallel + parallel / max(1, args.workers)
    print(f"\n{'stage':<22}{'per unit (ms)':>14}{'units':>12}{'total (s)':>11}{'share':>8}")
    for stage, unit, per, units, total, _ in rows:
        print(
            f"{stage:<22}{per * 1000:>10.2f} /{unit[:3]}{units:>12,.0f}{total:>11.0f}{total / serial:>8.1%}"
        )
    print(
        f"\nserial total {serial / 60:.1f} min ({len(p.seeds)} seeds x {len(METHODS)} methods, "
        f"{p.epochs} epochs, {n_evals} periodic evaluations); expected wall time with {args.workers} "
        f"workers: {wall / 60:.1f} min"
    )
    print(f"load average after: {os.getloadavg()[0]:.2f}")


def run_limits(p, args) -> None:
    """``--limits``: on ``--sample`` rendered demonstrations of ``--data`` (or a route)."""
    import replicate_limits as rl  # beside this file

    if args.data:
        log = DemoLog.load(args.data)
    else:
        cfg = CollectConfig(
            routes=1, seed=p.collect_seed, min_minutes=p.min_minutes, max_minutes=p.max_minutes
        )
        log = collect(cfg, show_progress=False)
    keep = np.linspace(0, len(log) - 1, min(args.sample, len(log))).astype(int)
    sub = DemoLog(
        log.town,
        **{
            k: getattr(log, k)[keep]
            for k in ("pose", "speed", "prev_action", "action", "executed", "lights", "lane")
        },
        episode=np.zeros(len(keep), dtype=np.int32),
        step=np.arange(len(keep), dtype=np.int32),
        meta=log.meta,
    )  # one long "episode": the light history rows stay inside it
    ds = DemoDataset(sub, bev_size=p.bev_size, cache=True, light_encoding=p.light_encoding)
    probs = inverse_density_weights(ds.actions, p.kde_bandwidth)
    print(f"{len(ds)} demonstrations rendered at {p.bev_size} px (of {len(log)})")
    if args.limits:
        load_before = os.getloadavg()[0]
        rows = rl.limits(p, ds, probs, episodes=p.final_episodes, reps=args.reps)
        rl.print_limits(rows)
        if args.out:
            report = {
                "command": "python benchmarks/bench_replicate.py " + " ".join(sys.argv[1:]),
                "preset": p.name,
                "machine": machine(),
                "load_average": [round(load_before, 2), round(os.getloadavg()[0], 2)],
                "made": now(),
                "commit": git_commit(),
                "rows": rows,
            }
            write_json(args.out, report)
            print(f"written to {args.out}")
    print(
        f"load average after: {os.getloadavg()[0]:.2f} (2 cores; above ~1 the times are inflated, "
        "not the ratios)"
    )


if __name__ == "__main__":
    with tempfile.TemporaryDirectory():
        main()
