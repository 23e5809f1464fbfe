"""The Fig. 5 and Fig. 6 analogues of the DA-IBC paper: free driving, and energy landscapes at chosen moments.

- ``free_driving``: each agent drives town02 without a route (``driving.rollout`` with its
  per-step record); the trajectories go to ``free_driving.npz``, road coverage and the exits
  taken per junction approach (``driving.analysis``) to ``results.json`` (the Fig. 5 analogue);
- ``pick_junction`` / ``pick_red``: the moments of those drives at which the Fig. 6 analogue
  looks at the energy: a junction approach (left and right both taken, if any was) and a red
  light ahead;
- ``landscapes``: the DA-IBC agent's energy over (steer, acceleration) at those moments and ten
  DFO inferences each, written to ``landscapes.npz``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from ibc_tutorial.driving.analysis import exits_per_approach, junction_visits, road_coverage
from ibc_tutorial.driving.rollout import RolloutRecording
from ibc_tutorial.experiments.agents.agent import Agent
from ibc_tutorial.experiments.agents.evaluate import EVAL_SEED, EVAL_TOWN, episode_rows, evaluate_agent
from ibc_tutorial.experiments.agents.presets import Preset
from ibc_tutorial.experiments.agents.replication_folder import FREE_DRIVING, LANDSCAPES
from ibc_tutorial.experiments.runs import write_npz

JUNCTION_DISTANCE = 8.0
"""The junction observation is taken where the car is closest to this distance (m) before the entry."""
JUNCTION_RANGE = (4.0, 15.0)
"""Distances (m) before the entry at which a junction observation is taken (a green light preferred)."""
RED_DISTANCE = (2.0, 15.0)
"""A red-light observation: on an approach whose light is red, this far (m) from the entry."""
RED_TARGET = 6.0
"""Of the red-light moments, the one closest to this distance (m) before the entry is taken."""


def record_drive(agent: Agent, steps: int, seed: int, policy_seed: int = 0) -> dict:
    """One free-driving episode (no route) with its per-step record and observations.

    Returns ``EpisodeResult.trace`` (pose, speed, lane, red_ahead, entry_dist, actions, bev, state)
    plus the episode's ``result`` row (``evaluate.episode_rows``).
    """
    (r,) = evaluate_agent(
        agent,
        EVAL_TOWN,
        1,
        steps,
        seed=seed,
        policy_seed=policy_seed,
        record=RolloutRecording(xy=False, steps=True, obs=True),
    )
    return dict(r.trace, result=episode_rows([r])[0])


def free_driving(out, preset: Preset, agents: dict[str, Agent], log=print) -> tuple[dict, dict]:
    """Free driving in town02 for each agent in ``agents`` ({method: Agent}); writes ``free_driving.npz``.

    Returns ``{method: {"episodes", "coverage_all", "exits_all"}}`` and the recordings
    ``{(method, episode): record_drive(...)}`` for ``landscapes``.
    """
    summary, arrays, recordings = {}, {}, {}
    for method, agent in agents.items():
        eps = []
        for i in range(preset.routeless_episodes):
            rec = record_drive(agent, preset.routeless_steps, seed=EVAL_SEED + i)
            visits = junction_visits(EVAL_TOWN, rec["lane"])
            eps.append(
                {
                    "result": rec["result"],
                    "coverage": round(road_coverage(EVAL_TOWN, rec["pose"]), 4),
                    "visits": visits,
                    "exits": {str(k): v for k, v in exits_per_approach(visits).items()},
                }
            )
            arrays[f"{method}_{i}_xy"] = rec["pose"][:, :2].astype(np.float32)
            recordings[(method, i)] = rec
        all_poses = np.concatenate(
            [recordings[(method, i)]["pose"] for i in range(preset.routeless_episodes)]
        )
        all_visits = [v for e in eps for v in e["visits"]]
        summary[method] = {
            "episodes": eps,
            "coverage_all": round(road_coverage(EVAL_TOWN, all_poses), 4),
            "exits_all": {str(k): v for k, v in exits_per_approach(all_visits).items()},
        }
        if log:
            log(
                f"free driving {method}: coverage {summary[method]['coverage_all']:.3f}, "
                f"{len(all_visits)} junction passes"
            )
    write_npz(Path(out) / FREE_DRIVING, arrays)
    return summary, recordings


def pick_junction(recordings: list[dict]) -> tuple | None:
    """(recording, step, approach, exits) of the junction observation, or None without junction passes.

    Among the approaches where the car met a green light 4-15 m before the entry (all approaches
    if none), one taken with different exits if there is one (left and right preferred), else the
    most visited one; the moment is the one 4-15 m before the entry closest to 8 m, with a green
    light if there is one.
    """
    all_visits = [(rec, v) for rec in recordings for v in junction_visits(EVAL_TOWN, rec["lane"])]
    if not all_visits:
        return None
    summary = exits_per_approach([v for _, v in all_visits])

    def green_in_range(a) -> bool:  # a moment 4-15 m before the entry with a green light, on some visit
        for rec, v in all_visits:
            if v["approach"] != a:
                continue
            j, lane = v["step"], rec["lane"][v["step"]]
            while j >= 0 and rec["lane"][j] == lane:
                if JUNCTION_RANGE[0] <= rec["entry_dist"][j] <= JUNCTION_RANGE[1] and not rec["red_ahead"][j]:
                    return True
                j -= 1
        return False

    # a moving decision first (green light), then different exits (left and right best), then visits
    ap = max(
        summary,
        key=lambda a: (
            green_in_range(a),
            ("left" in summary[a]["turns"]) and ("right" in summary[a]["turns"]),
            len(summary[a]["turns"]),
            summary[a]["visits"],
            -a,
        ),
    )
    candidates = []  # (out of range, red, |distance - 8 m|, order, step, rec)
    for order, (rec, v) in enumerate(x for x in all_visits if x[1]["approach"] == ap):
        k = v["step"]
        lane = rec["lane"][k]
        j = k
        while j >= 0 and rec["lane"][j] == lane:  # back along the stretch on the approach lane
            d = float(rec["entry_dist"][j])
            off = not JUNCTION_RANGE[0] <= d <= JUNCTION_RANGE[1]
            candidates.append((off, bool(rec["red_ahead"][j]), abs(d - JUNCTION_DISTANCE), order, j, rec))
            j -= 1
    *_, step, rec = min(candidates, key=lambda c: c[:5])
    return rec, step, ap, summary[ap]


def pick_red(recordings: list[dict]) -> tuple | None:
    """(recording, step) of the red-light observation: the first drive with a red light 2-15 m ahead, closest
    to 6 m."""
    for rec in recordings:
        ok = np.flatnonzero(
            rec["red_ahead"] & (rec["entry_dist"] >= RED_DISTANCE[0]) & (rec["entry_dist"] <= RED_DISTANCE[1])
        )
        if len(ok):
            return rec, int(ok[np.argmin(np.abs(rec["entry_dist"][ok] - RED_TARGET))])
    return None


def landscapes(
    out, agent: Agent, recordings: dict, n_grid: int = 41, n_inferences: int = 10, log=print
) -> dict:
    """Energy over (steer, acceleration) and ten DFO inferences at a junction and at a red light; writes
    ``landscapes.npz``.

    The moments are picked from ``agent``'s own drives first, then from the other agents'.
    Returns the moments' descriptions (``results.json``'s ``landscapes``).
    """
    own = [r for (m, _), r in sorted(recordings.items()) if m == agent.method]
    others = [r for (m, _), r in sorted(recordings.items()) if m != agent.method]
    found = {
        "junction": pick_junction(own) or pick_junction(others),
        "red_light": pick_red(own) or pick_red(others),
    }
    arrays, meta = {}, {}
    gen = torch.Generator().manual_seed(0)
    for name, pick in found.items():
        if pick is None:
            meta[name] = None
            continue
        rec, step = pick[0], pick[1]
        obs = {"bev": rec["bev"][step][None], "state": rec["state"][step][None]}
        steer, accel, e = agent.energy_grid(obs, n_grid)
        points = np.stack([agent.act(obs, gen).numpy()[0] for _ in range(n_inferences)])  # (10, 2)
        arrays.update(
            {
                f"{name}_energy": e.astype(np.float32),
                f"{name}_points": points.astype(np.float32),
                f"{name}_bev": rec["bev"][step],
                f"{name}_state": rec["state"][step],
            }
        )
        arrays["steer"], arrays["accel"] = steer.astype(np.float32), accel.astype(np.float32)
        meta[name] = {
            "pose": [round(float(x), 3) for x in rec["pose"][step]],
            "speed": round(float(rec["speed"][step]), 3),
            "entry_dist_m": round(float(rec["entry_dist"][step]), 2),
            "red_ahead": bool(rec["red_ahead"][step]),
            "episode_seed": rec["result"]["seed"],
        }
        if name == "junction":
            meta[name].update(
                approach=pick[2], node=pick[3]["node"], visits=pick[3]["visits"], turns=pick[3]["turns"]
            )
    write_npz(Path(out) / LANDSCAPES, arrays)
    if log:
        log(f"energy landscapes: {', '.join(k for k, v in meta.items() if v is not None) or 'none found'}")
    return meta
