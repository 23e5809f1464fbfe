"""Forks: where a demonstration's stem choice first shows, found by replaying the episode with the other turn.

At the stem of a T (``driving.stems``) the expert goes left or right. Whether the data hold *two answers at
one observation* is a question about the labels: the simulator and the expert are deterministic, so an
episode of a collection (``driving.collect``) can be driven again from its plan with one stem's turn
flipped. This *twin* is identical to the recorded episode, state for state and label for label, up to its
**fork**: the first state at which the expert's two labels differ. At the fork the observation is the same
in both (it was made by the same actions), and the two labels are the two right answers; from the next state
on the previous action gives the branch away. How far apart the two labels are at the fork (the **label
gap**, in steering) says how much of a two-answer state the stem is.

- ``replay``: an episode of a collection driven again, with chosen junction turns flipped;
- ``stem_forks``: every stem crossing of a log with its fork, the distance of the fork before the
  junction entry and the label gap there;
- ``forks_per_stem``: crossings per stem and way.

A collection's stem twins (``CollectConfig.stem_twins``) are such pairs by construction; ``stem_forks``
measures them the same way, by replay.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ibc_tutorial.driving.analysis import junction_visits
from ibc_tutorial.driving.collect import CollectConfig, drive_episode, episode_plan, make_expert
from ibc_tutorial.driving.expert import ExpertConfig
from ibc_tutorial.driving.sim import DrivingSim
from ibc_tutorial.driving.stems import EXITS, stem_approaches
from ibc_tutorial.utils import check_int, progress

__all__ = ["collection_config", "fork_traces", "forks_per_stem", "replay", "stem_forks"]


def collection_config(log) -> CollectConfig:
    """The ``CollectConfig`` a log was collected with (its meta), checked: routes, not routeless, with the
    default expert apart from the settings the collection sets."""
    meta = log.meta
    if "config" not in meta or "routes" not in meta:
        raise ValueError(
            "log must be a collection's log (driving.collect), with 'config' and 'routes' in meta"
        )
    fields = {k: tuple(v) if isinstance(v, list) else v for k, v in meta["config"].items()}
    config = CollectConfig(**fields)
    if config.routeless:
        raise ValueError(
            "log must be collected on routes (routeless=False): a routeless episode cannot be replayed"
        )
    stored = ExpertConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in meta["expert"].items()})
    if stored != make_expert(DrivingSim(config.town), config).config:
        raise ValueError("log's expert settings differ from those its collection config makes: cannot replay")
    return config


def replay(log, episode: int, flip: tuple[int, ...] = (), steps: int | None = None, sim=None) -> dict:
    """Drive episode ``episode`` of ``log``'s collection again, with the route's junction turns at the indices
    ``flip`` changed to the stem's other exit (each must be a stem's turn: "left" <-> "right").

    ``steps`` (default: the recorded episode's length) bounds the drive. Returns ``action`` (T, 2) (the
    expert's labels), ``lane`` (T,) and ``pose`` (T, 3) of each state, and the route's ``turns``.
    The expert's one memory across episodes (the acceleration label of the last state, which tells it that
    the car leaves from rest) is restored from the log, so an unflipped replay is the recorded episode bit for
    bit (tested)."""
    config = collection_config(log)
    rows = np.flatnonzero(log.episode == episode)
    if not len(rows):
        raise ValueError(f"episode must be one of the log's episodes, got {episode}")
    sim = DrivingSim(config.town) if sim is None else sim
    expert = make_expert(sim, config)
    plan = episode_plan(sim, config, int(episode))
    turns = list(plan.route.turns)
    for j in flip:
        check_int("flip index", j, minimum=0, maximum=len(turns) - 1)
        if turns[j] not in EXITS:
            raise ValueError(f"flip must index stem turns (left or right), turn {j} is {turns[j]!r}")
        turns[j] = EXITS[1 - EXITS.index(turns[j])]
    if rows[0] > 0:  # the label the expert last saw, in the episode before (driving.expert.Expert.perturb)
        expert._last_label_acc = float(log.action[rows[0] - 1, 1])
    twin = episode >= config.routes
    out = {k: [] for k in ("action", "lane", "pose")}

    def record(action, executed):
        out["action"].append(np.asarray(action, dtype=np.float32))
        out["lane"].append(expert.current_lane)
        out["pose"].append(sim.car.pose)

    drive_episode(
        sim,
        expert,
        plan.rng,
        replace(plan.route, turns=tuple(turns)),
        len(rows) if steps is None else check_int("steps", steps, minimum=1),
        offsets=plan.offsets,
        speed=expert.config.cruise_speed if twin else 0.0,
        after_stem=config.twin_after_steps if twin and steps is None else None,
        on_step=record,
    )
    return {
        "action": np.array(out["action"]).reshape(-1, 2),
        "lane": np.array(out["lane"]),
        "pose": np.array(out["pose"]).reshape(-1, 3),
        "turns": tuple(turns),
    }


def stem_forks(log, show_progress: bool | None = None, episodes=None) -> list[dict]:
    """Every stem crossing of ``log`` (a route collection of ``driving.collect``) and its fork.

    Each crossing is replayed with its stem's turn flipped (``replay``) up to the state after it entered the
    junction (of the log's ``episodes`` only, if given: a list of episode indices). Returns one dict per
    crossing: ``episode``, ``approach`` (the stem), ``turn`` (the exit taken), ``turn_index`` (which of the
    route's turns it is), ``twin`` (True for the collection's stem twins), ``fork`` (the step of the episode
    at which the labels first differ), ``fork_row`` (its row in the log), ``entry_m`` (how far the car's
    centre is before the junction entry at the fork, along the approach), ``labels`` ((2, 2): the action
    recorded and the twin's at the fork) and ``gap`` (their difference in steering, ``|recorded - twin|``).
    """
    config = collection_config(log)
    town = DrivingSim(config.town).town
    stems = set(stem_approaches(town))
    jobs = []
    known = np.unique(log.episode).tolist()
    if episodes is not None:
        wanted = [int(e) for e in episodes]
        unknown = sorted(set(wanted) - set(known))
        if unknown:
            raise ValueError(f"episodes must be episodes of the log, got {unknown}")
        known = [e for e in known if e in set(wanted)]
    for ep in known:
        rows = np.flatnonzero(log.episode == ep)
        visits = junction_visits(town, log.lane[rows], ended_inside=True)
        for j, v in enumerate(visits):  # the route's turn j is taken at the episode's j-th junction
            if v["approach"] in stems and v["turn"] in EXITS:
                jobs.append((ep, rows, j, v))
    sim = DrivingSim(config.town)
    out = []
    for ep, rows, j, v in progress(jobs, desc="replaying stem crossings", enabled=show_progress):
        upto = min(v["step"] + 2, len(rows))  # the state after the last one on the stem's lane
        twin = replay(log, ep, flip=(j,), steps=upto, sim=sim)
        recorded = log.action[rows[: len(twin["action"])]]
        differ = np.flatnonzero(np.any(recorded != twin["action"], axis=1))
        if not len(differ):
            raise ValueError(f"episode {ep}: the twin of its stem crossing at step {v['step']} never forks")
        f = int(differ[0])
        ap = town.approaches[v["approach"]]
        x, y, _ = log.pose[rows[f]]
        entry_m = float(np.dot(ap.entry - np.array([x, y]), ap.direction))
        out.append(
            {
                "episode": int(ep),
                "approach": int(v["approach"]),
                "turn": v["turn"],
                "turn_index": j,
                "twin": bool(ep >= config.routes),
                "fork": f,
                "fork_row": int(rows[f]),
                "entry_m": round(entry_m, 3),
                "labels": np.stack([recorded[f], twin["action"][f]]),
                "gap": float(abs(recorded[f, 0] - twin["action"][f, 0])),
            }
        )
    return out


def forks_per_stem(forks: list[dict], town) -> dict[int, dict[str, int]]:
    """Per stem approach of ``town`` (every one, crossed or not): ``{"left": n, "right": n}`` crossings."""
    counts = {ap: {e: 0 for e in EXITS} for ap in stem_approaches(town)}
    for f in forks:
        counts[f["approach"]][f["turn"]] += 1
    return counts


def fork_traces(log, fork: dict, before: int = 20, after: int = 8) -> dict:
    """The steering of a stem crossing and of its twin around the fork (``fork``: one of ``stem_forks``),
    from ``before`` states before it to ``after`` states after: ``entry_m`` (how far before the junction
    entry the recorded car is at each state), ``recorded`` and ``twin`` (their steering labels) and
    ``fork`` (the position of the fork in these arrays)."""
    before = check_int("before", before, minimum=0)
    after = check_int("after", after, minimum=0)
    rows = np.flatnonzero(log.episode == fork["episode"])
    f = int(fork["fork"])
    lo, hi = max(f - before, 0), min(f + after + 1, len(rows))
    twin = replay(log, fork["episode"], flip=(fork["turn_index"],), steps=hi)
    town = DrivingSim(collection_config(log).town).town
    ap = town.approaches[fork["approach"]]
    xy = log.pose[rows[lo:hi], :2]
    return {
        "entry_m": (ap.entry[None, :] - xy) @ ap.direction,
        "recorded": log.action[rows[lo:hi], 0],
        "twin": twin["action"][lo:hi, 0],
        "fork": f - lo,
    }
