"""Closed-loop evaluation of an agent: the DA-IBC paper's protocol (its Fig. 4 and sec. 4.3).

An agent drives ``episodes`` episodes of ``steps`` steps in a town (town02, unseen in
training), all side by side (``driving.rollout``: the network runs once per step on the batch
of running episodes). Each episode is scored as the paper scores it: distance driven x
0.7 ** (red-light infractions). Episode i starts from ``reset(seed=seed + i)``, so every agent
evaluated with the same ``seed`` meets the same starts and light phases.

    ibc-tutorial evaluate --checkpoint runs/da-ibc/seed0/final.pt --town town02 --episodes 10 --steps 3000
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from ibc_tutorial.driving.rollout import EpisodeResult, rollout
from ibc_tutorial.driving.towns import TOWNS
from ibc_tutorial.utils import check_int

EVAL_SEED = 1000
"""Seed of the first evaluation episode (the training routes use seeds from 0: kept apart)."""


def evaluate_agent(agent, town: str = "town02", episodes: int = 10, steps: int = 3000, *, seed: int = EVAL_SEED,
                   policy_seed: int = 0, routeless: bool = True, record_xy: bool = False,
                   show_progress: bool | None = None) -> list[EpisodeResult]:
    """Drive ``agent`` (an ``agents.Agent``, or "expert") for ``episodes`` batched episodes; one result each."""
    check_int("episodes", episodes, minimum=1)
    check_int("steps", steps, minimum=1)
    policy = agent if agent == "expert" else agent.policy(policy_seed)
    return rollout(policy, town=town, episodes=episodes, steps=steps, bev_size=_bev_size(agent), seed=seed,
                   routeless=routeless, record_xy=record_xy, show_progress=show_progress)


def _bev_size(agent) -> int:
    return 64 if agent == "expert" else agent.preset.bev_size


def episode_rows(results: list[EpisodeResult]) -> list[dict]:
    """JSON rows, one per episode: seed, steps, distance, infractions, score, how it ended."""
    return [{"seed": r.seed, "steps": int(r.steps), "distance_m": round(float(r.distance_m), 2),
             "red_light_infractions": int(r.red_light_infractions), "score": round(float(r.score), 2),
             "termination": r.termination} for r in results]


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


# ---------------------------------------------------------------------- command line
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--checkpoint", required=True, help="an agent checkpoint written by 'ibc-tutorial train'")
    parser.add_argument("--town", default="town02", choices=TOWNS, help="town to drive (default: %(default)s)")
    parser.add_argument("--episodes", type=int, default=10, help="episodes, run side by side (default: %(default)s)")
    parser.add_argument("--steps", type=int, default=3000, help="steps per episode, 0.1 s each (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=EVAL_SEED, help="seed of the first episode (default: %(default)s)")
    parser.add_argument("--routeless", action="store_true", help="free driving: no route drawn for the episodes")
    parser.add_argument("--out", default=None, help="optional JSON file for the per-episode results")
    parser.add_argument("--threads", type=int, default=0,
                        help="torch CPU threads (default 0: torch's choice; 1 is fastest on a busy machine)")


def run(args: argparse.Namespace) -> int:
    from ibc_tutorial.checkpoints import load_agent

    try:
        check_int("--episodes", args.episodes, minimum=1)
        check_int("--steps", args.steps, minimum=1)
        check_int("--seed", args.seed, minimum=0)
        if check_int("--threads", args.threads, minimum=0):
            import torch

            torch.set_num_threads(args.threads)
        agent, ckpt = load_agent(args.checkpoint)
    except ValueError as exc:
        raise SystemExit(f"ibc-tutorial evaluate: {exc}") from None
    results = evaluate_agent(agent, args.town, args.episodes, args.steps, seed=args.seed, routeless=args.routeless)
    rows = episode_rows(results)
    print(f"{ckpt['method']} agent (epoch {ckpt['epoch']}) in {args.town}, {args.episodes} episodes of {args.steps} steps:")
    print(f"{'episode':>8} {'seed':>6} {'steps':>6} {'distance m':>11} {'infractions':>12} {'score':>8}  end")
    for k, r in enumerate(rows):
        print(f"{k:>8} {r['seed']:>6} {r['steps']:>6} {r['distance_m']:>11.1f} {r['red_light_infractions']:>12} "
              f"{r['score']:>8.1f}  {r['termination'] or '-'}")
    s = summarize(rows)
    print(f"mean score {s['score_mean']:.1f} ± {s['score_std']:.1f}, distance {s['distance_m_mean']:.1f} m, "
          f"infractions {s['red_light_infractions_mean']:.2f}")
    if args.out:
        from ibc_tutorial.utils import atomic_write_bytes

        payload = {"checkpoint": str(args.checkpoint), "method": ckpt["method"], "town": args.town,
                   "steps": args.steps, "summary": s, "episodes": rows}
        atomic_write_bytes(args.out, json.dumps(payload, indent=1).encode())
    return 0 if all(math.isfinite(r["score"]) for r in rows) else 1


# ---------------------------------------------------------------------- free driving (the paper's Fig. 5)
def drive_recording(agent, town: str = "town02", steps: int = 1500, *, seed: int = EVAL_SEED, policy_seed: int = 0,
                    keep_obs: bool = False) -> dict:
    """One free-driving episode (no route) of ``agent``, recording every step.

    Returns a dict of arrays over the T + 1 recorded states (the start included): ``pose``
    (T+1, 3), ``speed`` (T+1,), ``lane`` (T+1,) (the lane whose waypoint is nearest, heading
    aligned), ``red_ahead`` (T+1,) (the light of the approach the car is on shows red or
    yellow), ``entry_dist`` (T+1,) (metres to that approach's junction entry, inf off
    approaches), ``actions`` (T, 2); with ``keep_obs`` also ``bev`` (T+1, 5, S, S) and
    ``state`` (T+1, 3); and the episode's ``result`` row (see ``episode_rows``).
    """
    from ibc_tutorial.driving.env import make_env
    from ibc_tutorial.driving.rollout import EpisodeResult

    check_int("steps", steps, minimum=1)
    env = make_env(town, bev_size=agent.preset.bev_size, routeless=True, max_steps=steps)
    tw = env.town
    obs, info = env.reset(seed=seed)
    policy = agent.policy(policy_seed)
    rec: dict[str, list] = {k: [] for k in ("pose", "speed", "lane", "red_ahead", "entry_dist", "actions", "bev", "state")}

    def note(obs, info):
        x, y, yaw = info["x"], info["y"], info["yaw"]
        lane, _, _ = tw.localize(x, y, yaw)
        ap = tw.approach_of_lane.get(lane)
        red, dist = False, float("inf")
        if ap is not None and ap in tw.light_of_approach:
            light = tw.light_of_approach[ap]
            red = bool(env.sim.stop_flags()[2, light])
            entry = np.asarray(tw.stop_lines[light].entry)
            dist = float(np.hypot(*(entry - (x, y))))
        rec["pose"].append((x, y, yaw))
        rec["speed"].append(info["speed"])
        rec["lane"].append(lane)
        rec["red_ahead"].append(red)
        rec["entry_dist"].append(dist)
        if keep_obs:
            rec["bev"].append(obs["bev"])
            rec["state"].append(obs["state"])

    note(obs, info)
    done = False
    while not done:
        batch = {"bev": obs["bev"][None], "state": obs["state"][None]}
        action = np.clip(np.asarray(policy(batch), dtype=np.float64).reshape(2), -1.0, 1.0)
        obs, _, terminated, truncated, info = env.step(action)
        rec["actions"].append(action)
        note(obs, info)
        done = terminated or truncated
    out = {k: np.asarray(v) for k, v in rec.items() if k not in ("bev", "state")}
    out["pose"] = out["pose"].astype(np.float64)
    if keep_obs:
        out["bev"] = np.stack(rec["bev"])
        out["state"] = np.stack(rec["state"])
    r = EpisodeResult(seed, info["step"], info["distance_m"], info["red_light_infractions"], info["score"],
                      bool(info["termination"]), info["termination"])
    out["result"] = episode_rows([r])[0]
    return out


def junction_visits(town, lanes: np.ndarray) -> list[dict]:
    """Every pass through a junction in a sequence of lanes: ``{"approach", "node", "turn", "step"}``.

    The exit is read from the first road lane after the approach lane: the turn whose connector
    leads onto it (robust to the overlapping connectors at a junction's entry).
    """
    from ibc_tutorial.driving.towns import get_town

    tw = get_town(town) if isinstance(town, str) else town
    road = set(tw.road_lanes)
    visits = []
    prev, prev_step = None, None
    for k, lane in enumerate(np.asarray(lanes).tolist()):
        if lane not in road:
            continue
        if prev is not None and lane != prev:
            ap_id = tw.approach_of_lane.get(prev)
            if ap_id is not None and tw.approaches[ap_id].is_junction:
                ap = tw.approaches[ap_id]
                for turn, conn in ap.exits.items():
                    if lane in tw.lanes[conn].successors:
                        visits.append({"approach": int(ap_id), "node": int(ap.node), "turn": turn, "step": int(prev_step)})
                        break
        prev, prev_step = lane, k
    return visits


def exits_per_approach(visits: list[dict]) -> dict[int, dict]:
    """Per junction approach: visits and the different exits taken, ``{approach: {"visits", "turns"}}``."""
    out: dict[int, dict] = {}
    for v in visits:
        d = out.setdefault(v["approach"], {"node": v["node"], "visits": 0, "turns": []})
        d["visits"] += 1
        if v["turn"] not in d["turns"]:
            d["turns"].append(v["turn"])
    return out


def road_coverage(town, poses: np.ndarray, radius: float = 3.0) -> float:
    """Share of the town's road-lane waypoints (1 m apart, both directions) that the car passed.

    A waypoint counts as passed if some recorded pose lies within ``radius`` metres of it with a
    heading within 60 degrees of the lane's (so driving one direction covers one lane).
    """
    from scipy.spatial import cKDTree

    from ibc_tutorial.driving.towns import get_town

    tw = get_town(town) if isinstance(town, str) else town
    road = np.isin(tw.wp_lane, tw.road_lanes)
    wp, wh = tw.wp_xy[road], tw.wp_heading[road]
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    covered = np.zeros(len(wp), dtype=bool)
    tree = cKDTree(poses[:, :2])
    for i, near in enumerate(tree.query_ball_point(wp, r=radius)):
        if near:
            dh = np.abs(np.angle(np.exp(1j * (poses[near, 2] - wh[i]))))
            covered[i] = bool((dh <= np.pi / 3).any())
    return float(covered.mean())
