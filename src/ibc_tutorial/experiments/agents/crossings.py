"""Junction crossings of an evaluation, and an energy agent's energies in the crossings that ended badly.

``ibc-tutorial evaluate --crossings`` writes every junction crossing of every episode
(``crossing_rows``: ``driving.analysis.junction_crossings``, with the steering applied during it) and,
for an energy agent, its energy over steering at each state of the crossings that ended in a building
or off the road (``ended_crossing_energies``: the episodes are driven again to record them). Chapter 08
reads them to see how the agents end in buildings.
"""

from __future__ import annotations

import numpy as np

from ibc_tutorial.driving.analysis import junction_crossings
from ibc_tutorial.driving.energy_profiles import read_grid
from ibc_tutorial.driving.rollout import EpisodeResult, RolloutRecording
from ibc_tutorial.experiments.agents.agent import Agent
from ibc_tutorial.experiments.agents.evaluate import evaluate_agent
from ibc_tutorial.utils import check_int


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
    energy is computed on an ``n_grid`` x ``n_grid`` grid of (steer, acceleration) in [-1, 1]² and read as
    every chapter reads an energy at a state (``driving.energy_profiles.read_grid``). Each ended crossing
    gets, per state, ``energy_by_steer``: the lowest energy over the accelerations at each steering value,
    minus its minimum over the steering values (so 0 at the preferred steering), in nats;
    ``valleys_by_state``: its valleys within 3 nats; ``argmin_steer_by_state``: the preferred steering.
    Returns the steering grid (n_grid,), or None when no crossing ended.

    Raises ValueError for a BC or flow agent (it has no energy), or if the replay does not end those episodes
    as ``rows`` say (e.g. evaluated on another machine, whose arithmetic sent the car elsewhere).
    """
    if not agent.has_energy:
        raise ValueError(
            f"ended_crossing_energies needs an energy agent (ibc, da-ibc or da-ibc-rnce), got {agent.method}"
        )
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
        record=RolloutRecording(xy=False, on_step=keep),
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
        readings = []
        for obs in captured[i]:
            steer, _accel, e = agent.energy_grid(obs, n_grid)  # e: (G accel, G steer)
            readings.append(read_grid(steer, e))  # the one reading of an energy at a state
        c["energy_by_steer"] = [[round(float(v), 3) for v in r["profile"]] for r in readings]  # (states, G)
        c["valleys_by_state"] = [r["valleys"] for r in readings]
        c["argmin_steer_by_state"] = [round(r["argmin_steer"], 3) for r in readings]
    return steer
