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

import numpy as np

from ibc_tutorial.driving.env import EnvConfig
from ibc_tutorial.driving.rollout import EpisodeResult, RolloutRecording, rollout
from ibc_tutorial.experiments.agents.agent import Agent
from ibc_tutorial.utils import check_int

EVAL_TOWN = "town02"
"""The town of every evaluation, unseen in training (the DA-IBC paper trains in Town01, tests in Town02)."""
EVAL_SEED = 1000
"""Seed of the first evaluation episode (the training routes use seeds from 0: kept apart)."""
HELDOUT_SEED = 30000
"""Seed of the first episode of the second, held-out evaluation (``Preset.heldout_episodes``): starts that no
setting of the book was chosen on, to check that the table's numbers are not a property of its ten starts."""

SCORES_ONLY = RolloutRecording(xy=False)
"""``evaluate_agent``'s default recording: the scores alone (no positions unless asked)."""

EXPERT_BEV_SIZE = 64
"""BEV size of the environments when the PID expert drives (it does not look at the BEV)."""


def evaluate_agent(
    agent: Agent | str,
    town: str = EVAL_TOWN,
    episodes: int = 10,
    steps: int = 3000,
    *,
    seed: int = EVAL_SEED,
    policy_seed: int = 0,
    routeless: bool = True,
    record: RolloutRecording = SCORES_ONLY,
    show_progress: bool | None = False,
) -> list[EpisodeResult]:
    """Drive ``agent`` (an ``Agent``, or "expert") for ``episodes`` batched episodes; one result each.

    ``policy_seed`` seeds the agent's DFO draws; ``record`` is what ``driving.rollout`` keeps of each
    episode besides its score (``RolloutRecording``; by default nothing, not even the positions);
    ``show_progress``: a progress bar over the steps.
    """
    if not isinstance(record, RolloutRecording):
        raise ValueError(f"record must be a RolloutRecording, got {type(record).__name__}")
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


def summarize_episodes(rows: list[dict]) -> dict:
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
