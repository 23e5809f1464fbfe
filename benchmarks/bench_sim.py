#!/usr/bin/env python
"""Steps per second of the driving environment on one core, random actions and the expert, 64 and 192 views.

    python benchmarks/bench_sim.py                 # town02, 5000 steps per cell
    python benchmarks/bench_sim.py --town town01 --steps 20000

Goal (issue 6): at least 1,000 steps/s with the 192 view and 2,000 with the 64 view, so that
closed-loop evaluation (10 episodes x 3000 steps per checkpoint) is never the slow part.
Also printed: the collector's rate (simulation and expert, no BEV) and the Dataset's
rendering rate (samples/s, batches of 128). Numbers depend on the machine and its load:
compare only figures taken side by side.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core: before numpy and torch are imported

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from ibc_tutorial.driving import DrivingSim, Expert, make_env  # noqa: E402
from ibc_tutorial.driving.collect import CollectConfig, collect  # noqa: E402
from ibc_tutorial.driving.dataset import DemoDataset  # noqa: E402


def env_rate(town: str, size: int, policy: str, steps: int, seed: int = 0) -> float:
    env = make_env(town, bev_size=size)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    expert = Expert(env) if policy == "expert" else None
    for _ in range(50):  # warm-up
        env.step(expert.act() if expert else env.action_space.sample())
    env.reset(seed=seed)
    t0 = time.perf_counter()
    for _ in range(steps):
        action = expert.act() if expert else env.action_space.sample()
        obs, r, term, trunc, info = env.step(action)
        if term or trunc:
            env.reset()
    return steps / (time.perf_counter() - t0)


def sim_rate(town: str, steps: int) -> float:
    sim = DrivingSim(town)
    sim.reset(np.random.default_rng(0))
    expert = Expert(sim)
    t0 = time.perf_counter()
    for _ in range(steps):
        a = expert.act()
        sim.step(float(a[0]), float(a[1]))
        if sim.terminated:
            sim.reset(np.random.default_rng(1))
    return steps / (time.perf_counter() - t0)


def dataset_rate(size: int, batches: int) -> float:
    log = collect(CollectConfig(town="town01", routes=1, min_minutes=1, max_minutes=1), show_progress=False)
    ds = DemoDataset(log, bev_size=size)
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    for _ in range(batches):
        ds.batch(rng.integers(0, len(ds), 128))
    return batches * 128 / (time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--town", default="town02", choices=("town01", "town02"))
    parser.add_argument("--steps", type=int, default=5000, help="steps per measurement")
    parser.add_argument("--pin", type=int, default=None, help="pin the process to this CPU core (Linux)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    if args.pin is not None and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {args.pin})
    print(f"driving env, {args.town}, {args.steps} steps per cell, one thread")
    print(f"{'view':>8} | {'random actions':>16} | {'expert':>16} | goal")
    for size, goal in ((64, 2000), (192, 1000)):
        r = env_rate(args.town, size, "random", args.steps)
        e = env_rate(args.town, size, "expert", args.steps)
        ok = "met" if min(r, e) >= goal else "NOT met"
        print(f"{size:>4}x{size:<3} | {r:>10,.0f} st/s | {e:>10,.0f} st/s | {goal:,} ({ok})")
    print(f"collector (simulation + expert, no BEV): {sim_rate(args.town, args.steps):,.0f} steps/s")
    for size in (64, 192):
        print(f"Dataset rendering, {size}x{size}, batches of 128: {dataset_rate(size, 20):,.0f} samples/s")


if __name__ == "__main__":
    main()
