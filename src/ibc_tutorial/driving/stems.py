"""The stems of the T-junctions: where a car has two right answers, and whether it keeps both.

Of a T's three approaches, the *stem* has only a left and a right exit, with a building straight
ahead (``docs/design.md``; town02 has 8 stems among its 24 junction approaches). An expert that
roams without a route takes either exit; a policy that averaged them would steer straight into the
building; a policy that kept one of the two would always turn the same way. These pure functions
measure it on per-step records (``EpisodeResult.trace``: ``lane`` (T + 1,), ``pose`` (T + 1, 3),
``speed``, ``red_ahead``, ``entry_dist``, ``actions`` (T, 2)), episode by episode, so that
``stats`` can resample agents and episodes:

- ``stem_crossings``: the junction crossings (``analysis.junction_crossings``) that start from a stem;
- ``stem_exit_counts``: per stem, how often each exit was taken (the Fig. 5 protocol of the DA-IBC
  paper, agent against expert);
- ``circling``: whether the car circles one block (the rule is in its docstring);
- ``episode_measures``: per episode, distinct approaches visited, lanes covered, circling, the stem
  exits, mode coverage (stems visited at least twice, of them those left by both exits), an end at a stem;
- ``decision_window`` and ``steering_onset``: the states of a stem crossing where the choice is made
  (from the entry until the steering passes ±0.3), and where the turn starts (metres from the entry);
- ``red_stops`` and ``kept_states``: the states at rest at a red light, and every state the energy
  analysis looks at.
"""

from __future__ import annotations

import numpy as np

from ibc_tutorial.driving.analysis import _town, exit_counts, junction_crossings, road_coverage
from ibc_tutorial.utils import check_int, check_positive

EXITS = ("left", "right")
"""The exits of a stem (steering: left < 0 < right)."""
STEER_COMMIT = 0.3
"""|steering| from which a turn counts as begun: the end of the decision window."""
MAX_BLOCK = 4
"""Most distinct junction approaches of one loop round a block (``circling``)."""
MIN_LAPS = 2
"""Laps of the same loop in a row that make ``circling``."""
RED_STOPPED = 0.5
"""Speed (m/s) under which a car before a red light counts as stopped."""
RED_RANGE = (0.0, 15.0)
"""Distance (m) before the junction entry within which a stop counts as a stop at the red light."""
LEAD = 10
"""States before a stem crossing's entry that ``kept_states`` keeps (for the steering onset)."""


def stem_approaches(town) -> tuple[int, ...]:
    """Ids of the junction approaches whose only exits are left and right (the stems of the T's)."""
    tw = _town(town)
    return tuple(a.id for a in tw.approaches if a.is_junction and set(a.exits) == set(EXITS))


def stem_crossings(town, lanes: np.ndarray, steer: np.ndarray | None = None) -> list[dict]:
    """``analysis.junction_crossings`` of the record that start from a stem (steering 0 if ``steer`` is
    None)."""
    lanes = np.asarray(lanes).reshape(-1)
    steer = np.zeros(max(len(lanes) - 1, 0)) if steer is None else steer
    stems = set(stem_approaches(town))
    return [c for c in junction_crossings(town, lanes, steer) if c["approach"] in stems]


def stem_exit_counts(crossings: list[dict]) -> dict[int, dict[str, int]]:
    """Per stem approach, ``{"left": n, "right": n}`` over the finished crossings (``stem_crossings``)."""
    taken = [c for c in crossings if c.get("finished", True) and c["turn"] in EXITS]
    return {ap: {t: n[t] for t in EXITS} for ap, n in exit_counts(taken).items()}  # a stem has no straight


def circling(approaches, max_period: int = MAX_BLOCK, min_laps: int = MIN_LAPS) -> int:
    """The period of the loop if the car circles one block, else 0.

    ``approaches`` is the sequence of junction approaches the car passed, in order. The car circles one
    block if some stretch of that sequence repeats one loop of ``L <= max_period`` distinct approaches
    (every pass k of the stretch is at the approach of pass k - L) for at least ``min_laps`` laps
    (``min_laps * L`` passes), and that stretch holds at least half of the episode's passes (most of
    the drive goes round it). The smallest such L is returned. With fewer than ``min_laps`` passes
    (no junction at all, a junction passed once) the car does not circle.
    """
    max_period = check_int("max_period", max_period, minimum=1)
    min_laps = check_int("min_laps", min_laps, minimum=2)
    seq = [int(a) for a in approaches]
    n = len(seq)
    for period in range(1, max_period + 1):
        best = 0
        k = period
        while k < n:  # maximal runs of passes k with seq[k] == seq[k - period]
            if seq[k] != seq[k - period]:
                k += 1
                continue
            a = k
            while k < n and seq[k] == seq[k - period]:
                k += 1
            if len(set(seq[a - period : a])) == period:  # the loop: ``period`` distinct approaches
                best = max(best, k - a + period)  # the stretch a - period .. k - 1
        if best >= min_laps * period and 2 * best >= n:
            return period
    return 0


def episode_measures(
    town, lanes: np.ndarray, poses: np.ndarray, steer: np.ndarray, *, terminated: bool
) -> dict:
    """What one episode shows of the stems and of the town (one record's ``lane``, ``pose``, steering;
    ``terminated``: the episode ended in a building or off the road, not at its last step).

    Returns a dict:
        ``approaches`` (the junction approaches passed, in order, unfinished crossings included),
        ``distinct_approaches``, ``lanes_covered`` (``analysis.road_coverage``: the share of the town's
        lane waypoints passed), ``circling`` (``circling``'s period, 0 if none),
        ``stem_exits`` (``stem_exit_counts``), ``stem_crossings`` (finished ones), ``left`` and ``right``
        (their exits), ``stems_twice`` (stems crossed at least twice to the end),
        ``stems_both`` (of those, the ones left by both exits), ``ended_at_stem`` (the episode was
        terminated inside a crossing from a stem: in a building or off the road).
    """
    crossings = junction_crossings(town, lanes, steer)
    stems = set(stem_approaches(town))
    from_stems = [c for c in crossings if c["approach"] in stems]
    exits = stem_exit_counts(from_stems)
    approaches = [c["approach"] for c in crossings]
    twice = [a for a, d in exits.items() if sum(d.values()) >= 2]
    return {
        "approaches": approaches,
        "distinct_approaches": len(set(approaches)),
        "lanes_covered": road_coverage(town, poses),
        "circling": circling(approaches),
        "stem_exits": exits,
        "stem_crossings": sum(sum(d.values()) for d in exits.values()),
        "left": sum(d["left"] for d in exits.values()),
        "right": sum(d["right"] for d in exits.values()),
        "stems_twice": len(twice),
        "stems_both": sum(all(exits[a][e] > 0 for e in EXITS) for a in twice),
        "ended_at_stem": bool(
            terminated and crossings and not crossings[-1]["finished"] and crossings[-1]["approach"] in stems
        ),
    }


def decision_window(crossing: dict, steer: np.ndarray, threshold: float = STEER_COMMIT) -> np.ndarray:
    """States of a crossing from its entry until the steering passes ±``threshold`` (that state included).

    ``crossing`` from ``junction_crossings`` (``start``, ``stop``); ``steer`` (T,) the steering applied
    after each state. If the steering never passes the threshold in the crossing, the window is the
    whole crossing. The indices are states of the record (``start``, ``start + 1``, ...).
    """
    threshold = check_positive("threshold", threshold)
    steer = np.asarray(steer, dtype=float).reshape(-1)
    stop = min(int(crossing["stop"]), len(steer))
    start = int(crossing["start"])
    if stop <= start:
        return np.arange(start, start, dtype=int)
    past = np.flatnonzero(np.abs(steer[start:stop]) >= threshold)
    end = start + int(past[0]) + 1 if len(past) else stop
    return np.arange(start, end, dtype=int)


def steering_onset(
    crossing: dict, poses: np.ndarray, steer: np.ndarray, threshold: float = STEER_COMMIT, lead: int = LEAD
) -> float:
    """Where the turn of a finished left or right crossing begins: metres from the entry (negative before).

    The onset is the first state, from ``lead`` states before the entry (``crossing["start"]``) to the
    exit, whose steering is at least ``threshold`` toward the exit taken (>= +threshold for right,
    <= -threshold for left). The distance is the path length between the entry and that state. NaN if
    the crossing is not a finished left or right turn or the steering never gets there.
    """
    if crossing.get("turn") not in EXITS or not crossing.get("finished", True):
        return float("nan")
    threshold = check_positive("threshold", threshold)
    lead = check_int("lead", lead, minimum=0)
    steer = np.asarray(steer, dtype=float).reshape(-1)
    xy = np.asarray(poses, dtype=float).reshape(-1, 3)[:, :2]
    start, stop = int(crossing["start"]), min(int(crossing["stop"]), len(steer))
    lo = max(0, start - lead)
    sign = 1.0 if crossing["turn"] == "right" else -1.0
    hit = np.flatnonzero(sign * steer[lo:stop] >= threshold)
    if not len(hit):
        return float("nan")
    k = lo + int(hit[0])
    step = np.r_[0.0, np.hypot(*np.diff(xy, axis=0).T)]  # (T + 1,) metres driven into each state
    path = np.cumsum(step)
    return float(path[k] - path[start])


def red_stops(
    red_ahead: np.ndarray,
    speed: np.ndarray,
    entry_dist: np.ndarray,
    stopped: float = RED_STOPPED,
    within: tuple[float, float] = RED_RANGE,
) -> np.ndarray:
    """One state per stop at a red light: the first state of each red spell at which the car is at rest.

    A red spell is a run of consecutive states with ``red_ahead`` (the light of the approach shows red
    or yellow); its stop is the first state with speed < ``stopped`` m/s and the entry ``within`` metres
    ahead. Spells in which the car never stops (it ran the light, or the light turned) give none.
    """
    stopped = check_positive("stopped", stopped)
    red = np.asarray(red_ahead, dtype=bool).reshape(-1)
    speed = np.asarray(speed, dtype=float).reshape(-1)
    dist = np.asarray(entry_dist, dtype=float).reshape(-1)
    if not (len(red) == len(speed) == len(dist)):
        raise ValueError(
            "red_ahead, speed and entry_dist must have one value per state, "
            f"got {len(red)}, {len(speed)}, {len(dist)}"
        )
    ok = red & (speed < stopped) & (dist >= within[0]) & (dist <= within[1])
    out = []
    edges = np.flatnonzero(np.diff(np.r_[0, red.astype(int), 0]))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        hit = np.flatnonzero(ok[a:b])
        if len(hit):
            out.append(int(a + hit[0]))
    return np.array(out, dtype=int)


def kept_states(
    town,
    lanes: np.ndarray,
    speed: np.ndarray,
    red_ahead: np.ndarray,
    entry_dist: np.ndarray,
    lead: int = LEAD,
) -> np.ndarray:
    """States whose observations the energy analysis needs: each stem crossing from ``lead`` states before
    its entry to its exit, and ``red_stops``. Sorted, without repeats."""
    lead = check_int("lead", lead, minimum=0)
    keep: set[int] = set()
    for c in stem_crossings(town, lanes):
        keep.update(range(max(0, c["start"] - lead), c["stop"]))
    keep.update(red_stops(red_ahead, speed, entry_dist).tolist())
    return np.array(sorted(keep), dtype=int)
