"""Closed-loop evaluation of an agent: the DA-IBC paper's protocol (its Fig. 4 and sec. 4.3).

An agent drives ``episodes`` episodes of ``steps`` steps in a town (town02, unseen in
training), all side by side (``driving.rollout``: the network runs once per step on the batch
of running episodes). Each episode is scored as the paper scores it: distance driven x
0.7 ** (red-light infractions). Episode i starts from ``reset(seed=seed + i)``, so every agent
evaluated with the same ``seed`` meets the same starts and light phases.

    ibc-tutorial evaluate --checkpoint runs/da-ibc/seed0/final.pt

The command's defaults are the book's protocol, the one ``replicate`` uses for the table: town02,
routeless episodes from ``EVAL_SEED``, the checkpoint preset's ``final_episodes`` x
``final_steps``, and the agent's training seed as the policy seed (``--policy-seed`` changes it).
So on the machine that made them it reproduces a run's ``final_eval.json`` episode by episode.
``--crossings`` also writes every junction crossing of every episode to ``--out``, with the steering
applied during it, and, for an energy agent, its energy over steering at each state of the crossings
that ended in a building or off the road (``ended_crossing_energies``: the episodes are driven again to
record them). Chapter 08 reads them to see how the agents end in buildings.
``--device cuda`` runs the network on a GPU (the DFO draws still come from the seeded CPU generator;
the arithmetic, and so the episodes, may differ from a CPU run's in the last bits and then more).
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
import torch

from ibc_tutorial import __version__
from ibc_tutorial.cli import UserError, check_input_file, check_output_file
from ibc_tutorial.driving.analysis import junction_crossings
from ibc_tutorial.driving.env import EnvConfig
from ibc_tutorial.driving.rollout import EpisodeResult, RolloutRecording, rollout
from ibc_tutorial.experiments.agents.agent import Agent
from ibc_tutorial.experiments.agents.checkpoints import load_agent, training_seed
from ibc_tutorial.utils import atomic_write_bytes, check_device, check_int

EVAL_SEED = 1000
"""Seed of the first evaluation episode (the training routes use seeds from 0: kept apart)."""
HELDOUT_SEED = 30000
"""Seed of the first episode of the second, held-out evaluation (``Preset.heldout_episodes``): starts that no
setting of the book was chosen on, to check that the table's numbers are not a property of its ten starts."""

EXPERT_BEV_SIZE = 64
"""BEV size of the environments when the PID expert drives (it does not look at the BEV)."""


def evaluate_agent(
    agent: Agent | str,
    town: str = "town02",
    episodes: int = 10,
    steps: int = 3000,
    *,
    seed: int = EVAL_SEED,
    policy_seed: int = 0,
    routeless: bool = True,
    record_xy: bool = False,
    record_steps: bool = False,
    keep_obs: bool = False,
    show_progress: bool | None = None,
    on_step=None,
) -> list[EpisodeResult]:
    """Drive ``agent`` (an ``Agent``, or "expert") for ``episodes`` batched episodes; one result each.

    ``policy_seed`` seeds the agent's DFO draws; ``record_xy``, ``record_steps``, ``keep_obs`` and
    ``on_step`` are passed to ``driving.rollout``.
    """
    check_int("episodes", episodes, minimum=1)
    check_int("steps", steps, minimum=1)
    if agent == "expert":
        policy, bev_size, encoding = "expert", EXPERT_BEV_SIZE, "intensity"
    else:
        policy, bev_size, encoding = (
            agent.policy(policy_seed),
            agent.preset.bev_size,
            agent.preset.light_encoding,
        )
    env = EnvConfig(town, bev_size, routeless, steps, light_encoding=encoding)
    record = RolloutRecording(xy=record_xy, steps=record_steps, obs=keep_obs, on_step=on_step)
    return rollout(policy, env, episodes, seed, record=record, show_progress=show_progress)


def episode_rows(results: list[EpisodeResult]) -> list[dict]:
    """JSON rows, one per episode: seed, steps, distance, infractions, score, how it ended."""
    return [
        {
            "seed": r.seed,
            "steps": int(r.steps),
            "distance_m": round(float(r.distance_m), 2),
            "red_light_infractions": int(r.red_light_infractions),
            "score": round(float(r.score), 2),
            "termination": r.termination,
        }
        for r in results
    ]


def crossing_rows(town: str, result: EpisodeResult) -> list[dict]:
    """JSON rows, one per junction crossing of an episode recorded with ``record_steps``
    (``driving.analysis.junction_crossings``: approach, node, states, exit, steering extremes)."""
    if result.trace is None:
        raise ValueError("result must be recorded with record_steps=True to list its junction crossings")
    rows = junction_crossings(town, result.trace["lane"], result.trace["actions"][:, 0])
    for c in rows:
        c["steer_min"], c["steer_max"] = round(c["steer_min"], 4), round(c["steer_max"], 4)
    return rows


ENERGY_GRID = 41
"""Values per action dimension of the (steer, acceleration) grid of ``ended_crossing_energies``."""


def ended_crossing_energies(
    agent: Agent,
    town: str,
    rows: list[dict],
    *,
    steps: int,
    seed: int,
    policy_seed: int,
    routeless: bool = True,
    n_grid: int = ENERGY_GRID,
) -> np.ndarray | None:
    """The energy over steering at every state of each crossing that ended in a building or off the road.

    ``rows`` are the episode rows of one evaluation (``episode_rows``) with their ``junction_crossings``
    (``crossing_rows``), in episode order. The episodes are driven again, up to the last of those
    crossings, with the same starts and policy seed, and at each state of each such crossing the agent's
    energy is computed on an ``n_grid`` x ``n_grid`` grid of (steer, acceleration) in [-1, 1]². Each
    ended crossing gets ``energy_by_steer``: per state, the lowest energy over the accelerations at each
    steering value, minus its minimum over the steering values (so 0 at the preferred steering), in
    nats. Returns the steering grid (n_grid,), or None when no crossing ended.

    Raises ValueError for a BC agent (it has no energy), or if the replay does not end those episodes
    as ``rows`` say (e.g. evaluated on another machine, whose arithmetic sent the car elsewhere).
    """
    if agent.method == "bc":
        raise ValueError("ended_crossing_energies needs an energy agent (ibc or da-ibc), got bc")
    check_int("n_grid", n_grid, minimum=2)
    check_int("steps", steps, minimum=1)
    wanted = {
        i: r["junction_crossings"][-1]
        for i, r in enumerate(rows)
        if r["termination"] and r.get("junction_crossings") and not r["junction_crossings"][-1]["finished"]
    }
    if not wanted:
        return None
    captured: dict[int, list] = {i: [] for i in wanted}

    def keep(t: int, episodes: list[int], batch: dict) -> None:
        for k, i in enumerate(episodes):
            c = wanted.get(i)
            if c is not None and c["start"] <= t < c["stop"]:
                captured[i].append({"bev": batch["bev"][k : k + 1], "state": batch["state"][k : k + 1]})

    horizon = min(steps, max(c["stop"] for c in wanted.values()))
    replay = evaluate_agent(
        agent,
        town,
        len(rows),
        horizon,
        seed=seed,
        policy_seed=policy_seed,
        routeless=routeless,
        record_xy=False,
        show_progress=False,
        on_step=keep,
    )
    for i in wanted:
        if (
            replay[i].termination != rows[i]["termination"]
            or round(float(replay[i].distance_m), 2) != rows[i]["distance_m"]
        ):
            raise ValueError(
                f"the replay of episode {i} ended {replay[i].termination or 'later'} after "
                f"{replay[i].distance_m:.2f} m, not as evaluated ({rows[i]['termination']} after "
                f"{rows[i]['distance_m']} m): the energies would not be those of the crossing"
            )
    steer = None
    for i, c in wanted.items():
        profiles = []
        for obs in captured[i]:
            steer, _accel, e = agent.energy_grid(obs, n_grid)  # e: (G accel, G steer)
            profile = e.min(axis=0)  # (G,) lowest energy over the accelerations at each steering value
            profiles.append([round(float(v), 3) for v in profile - profile.min()])
        c["energy_by_steer"] = profiles  # (states, G)
    return steer


def summarize(rows: list[dict]) -> dict:
    """Mean and (population) standard deviation of score, distance and infractions over episodes."""
    if not rows:
        raise ValueError("rows must hold at least one episode")
    out = {"episodes": len(rows)}
    for key in ("score", "distance_m", "red_light_infractions"):
        v = np.array([r[key] for r in rows], dtype=float)
        out[f"{key}_mean"] = round(float(v.mean()), 3)
        out[f"{key}_std"] = round(float(v.std()), 3)
    out["terminated"] = int(sum(bool(r["termination"]) for r in rows))
    return out


def run(args: argparse.Namespace) -> int:
    """``ibc-tutorial evaluate`` (arguments in ``ibc_tutorial.cli``): check the checkpoint and ``--out``, drive,
    print, write. Errors are raised for ``cli.main`` to print on one line."""
    seed = check_int("--seed", args.seed, minimum=0)
    threads = check_int("--threads", args.threads, minimum=0)
    device = check_device("--device", getattr(args, "device", "cpu"))
    if args.episodes is not None:
        check_int("--episodes", args.episodes, minimum=1)
    if args.steps is not None:
        check_int("--steps", args.steps, minimum=1)
    if args.policy_seed is not None:
        check_int("--policy-seed", args.policy_seed, minimum=0)
    crossings = getattr(args, "crossings", False)
    if crossings and not args.out:
        raise UserError("--crossings needs --out (the crossings are written there, not printed)")
    if args.out:
        check_output_file("--out", args.out, force=getattr(args, "force", False))
    agent, ckpt = load_agent(check_input_file("--checkpoint", args.checkpoint, "agent checkpoint (.pt)"))
    agent.to(device)  # loaded onto the CPU (map_location="cpu"), then moved
    episodes = args.episodes or agent.preset.final_episodes
    steps = args.steps or agent.preset.final_steps
    policy_seed = args.policy_seed if args.policy_seed is not None else training_seed(ckpt)
    if policy_seed is None:
        raise UserError(f"{args.checkpoint} does not record its training seed: pass --policy-seed")
    routeless = not getattr(args, "routed", False)
    if threads:
        torch.set_num_threads(threads)
    results = evaluate_agent(
        agent,
        args.town,
        episodes,
        steps,
        seed=seed,
        policy_seed=policy_seed,
        routeless=routeless,
        record_steps=crossings,
    )
    rows = episode_rows(results)
    energy_steer = None
    if crossings:
        for row, r in zip(rows, results):
            row["junction_crossings"] = crossing_rows(args.town, r)
        if agent.method != "bc":
            energy_steer = ended_crossing_energies(
                agent, args.town, rows, steps=steps, seed=seed, policy_seed=policy_seed, routeless=routeless
            )
    print(
        f"{ckpt['method']} agent (epoch {ckpt['epoch']}) in {args.town}, {episodes} {'routeless' if routeless else 'routed'} "
        f"episodes of {steps} steps from seed {seed}, policy seed {policy_seed}:"
    )
    print(f"{'episode':>8} {'seed':>6} {'steps':>6} {'distance m':>11} {'infractions':>12} {'score':>8}  end")
    for k, r in enumerate(rows):
        print(
            f"{k:>8} {r['seed']:>6} {r['steps']:>6} {r['distance_m']:>11.1f} {r['red_light_infractions']:>12} "
            f"{r['score']:>8.1f}  {r['termination'] or '-'}"
        )
    s = summarize(rows)
    print(
        f"mean score {s['score_mean']:.1f} ± {s['score_std']:.1f}, distance {s['distance_m_mean']:.1f} m, "
        f"infractions {s['red_light_infractions_mean']:.2f}"
    )
    if args.out:
        from ibc_tutorial.experiments.agents.results import (
            git_commit,
            machine,
        )  # deferred: results imports this module

        payload = {
            "checkpoint": str(args.checkpoint),
            "method": ckpt["method"],
            "town": args.town,
            "steps": steps,
            "seed": seed,
            "policy_seed": policy_seed,
            "routeless": routeless,
            "package_version": __version__,
            "commit": git_commit(),
            "machine": machine(),
            "summary": s,
            "episodes": rows,
        }
        if energy_steer is not None:  # the steering values of the ended crossings' energy_by_steer
            payload["energy_steer_grid"] = [round(float(v), 4) for v in energy_steer]
        atomic_write_bytes(args.out, json.dumps(payload, indent=1).encode())
    return 0 if all(math.isfinite(r["score"]) for r in rows) else 1
