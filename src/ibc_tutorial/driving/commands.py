"""Route commands: the high-level instruction a goal-directed agent is given (CIL's four commands).

Conditional imitation learning (Codevilla et al. 2018) tells the car, at every step, one of four
commands: **follow the lane**, or **turn left**, **go straight**, **turn right** at the next junction.
The DA-IBC paper leaves its agents routeless on purpose and names a "goal-directed agent ... which can
take high-level commands" as its future work; chapter 11 gives its three agents this input.

**The rule** (the one place it is computed; ``docs/design.md``, "Route commands"):

* on a junction approach lane, within ``COMMAND_DISTANCE_M`` = 20 m (measured along the lane, from the
  car's centre) of the junction's entry, the command is the route's turn at that junction;
* inside the junction (on one of its connector lanes) it stays that turn, until the car is on the exit's
  road lane;
* everywhere else, corners included (a corner has one way out), it is "follow the lane".

20 m is about 3.5 s at the expert's cruise speed (6 m/s): the command is known before the expert
slows for the turn (``ExpertConfig.turn_preview_m`` = 10 m) and before it must stop at the line
(``stop_distance_m`` = 9.5 m); town02's shortest road lane is 31 m, so a command never reaches back
past the previous junction.

The demonstration log already stores the lane the expert followed at every step (``DemoLog.lane``)
and its route's turns (``meta["routes"]``), so every sample's command is computed from the log
(``log_commands``): town01 data collected before commands existed gain them without collecting again.
The turn at a junction is read from the log's own lanes (the connector the expert entered next); for
the last junction of an episode that ended before entering it, from the route's list of turns (the
k-th junction approach of an episode takes the route's k-th turn, as the expert does). A routeless log
whose episode ends on an approach leaves those samples' turn unknown: ``log_commands`` refuses it.
"""

from __future__ import annotations

import numpy as np

from ibc_tutorial.driving.towns import Town, get_town
from ibc_tutorial.utils import check_choice

COMMANDS = ("follow", "left", "straight", "right")
"""The four commands, in the order of their index (the one-hot's columns)."""
N_COMMANDS = len(COMMANDS)
"""4."""
FOLLOW = 0
"""Index of "follow the lane"."""
COMMAND_DISTANCE_M = 20.0
"""On a junction approach lane, the command switches to the route's turn this far (metres, along the lane)
before the junction's entry."""


def _town(town) -> Town:
    return get_town(town) if isinstance(town, str) else town


def command_index(name: str) -> int:
    """Index of a command name in ``COMMANDS``."""
    return COMMANDS.index(check_choice("command", name, COMMANDS))


def distance_to_entry(town, lane: int, xy) -> float:
    """Metres along road lane ``lane`` from ``xy`` to the lane's end (the junction's entry; <= 0 past it)."""
    ln = _town(town).lanes[int(lane)]
    d = (ln.end - ln.start) / ln.length
    return float((ln.end - np.asarray(xy, dtype=float)[:2]) @ d)


def command_at(town, lane: int, xy, next_turn: str | None) -> int:
    """The command (index into ``COMMANDS``) for a car at ``xy`` on ``lane`` whose route takes ``next_turn``
    at the next junction (the module's rule).

    ``next_turn`` is needed only on a junction approach lane within ``COMMAND_DISTANCE_M`` of the entry;
    there ``None`` is a ValueError. On a junction's connector the connector's own turn is the command."""
    tw = _town(town)
    ln = tw.lanes[int(lane)]
    if ln.kind == "connector":
        junction = ln.node in tw.junction_nodes
        return COMMANDS.index(ln.turn) if junction else FOLLOW
    ap = tw.approach_of_lane.get(int(lane))
    if ap is None or not tw.approaches[ap].is_junction:
        return FOLLOW
    if distance_to_entry(tw, lane, xy) > COMMAND_DISTANCE_M:
        return FOLLOW
    if next_turn is None:
        raise ValueError(
            f"next_turn must name the route's turn at approach {ap} (the car is near it), got None"
        )
    exits = sorted(tw.approaches[ap].exits)
    if next_turn not in exits:
        raise ValueError(f"next_turn must be one of {exits} at approach {ap}, got {next_turn!r}")
    return COMMANDS.index(next_turn)


def episode_turns(town, lanes: np.ndarray, route_turns=None) -> list[str | None]:
    """For each step of one episode's lane record (the lane followed at each step), the turn taken at the
    next junction: the connector entered after the approach lane; for an approach the episode ended on, the
    route's turn of that junction (``route_turns``: the k-th junction approach takes the k-th), else None.
    Off junction approach lanes the entry is None (no turn is needed there)."""
    tw = _town(town)
    lanes = np.asarray(lanes).reshape(-1)
    out: list[str | None] = [None] * len(lanes)
    k = -1  # index of the junction choice being approached
    prev = None
    runs: list[tuple[int, int, int]] = []  # (first step, last step, choice index) of each approach run
    for i, lane in enumerate(lanes.tolist()):
        ap = tw.approach_of_lane.get(lane)
        on_approach = ap is not None and tw.approaches[ap].is_junction
        if on_approach and lane != prev:
            k += 1
            runs.append((i, i, k))
        elif on_approach:
            runs[-1] = (runs[-1][0], i, runs[-1][2])
        prev = lane
    for a, b, choice in runs:
        ap = tw.approaches[tw.approach_of_lane[int(lanes[a])]]
        turn = None
        after = lanes[b + 1 :].tolist()
        for lane in after:  # the first of this junction's connectors entered next
            conn = tw.lanes[lane]
            if conn.kind == "connector" and conn.node == ap.node:
                turn = conn.turn
                break
            if conn.kind == "road":
                break
        if turn is None and route_turns is not None and choice < len(route_turns):
            turn = route_turns[choice]
        for i in range(a, b + 1):
            out[i] = turn
    return out


def log_commands(log) -> np.ndarray:
    """(N,) int64 the command of every sample of a demonstration log (``driving.dataset.DemoLog``): the
    module's rule, from the lanes the expert followed and its routes' turns (``meta["routes"]``).

    ValueError if a sample near a junction has no known turn (a routeless episode ending on an approach)."""
    tw = _town(log.town)
    routes = log.meta.get("routes") or []
    out = np.zeros(len(log), dtype=np.int64)
    for e, sl in enumerate(log.episodes()):
        route_turns = routes[e].get("turns") if e < len(routes) and isinstance(routes[e], dict) else None
        turns = episode_turns(tw, log.lane[sl], route_turns)
        for j, i in enumerate(range(sl.start, sl.stop)):
            try:
                out[i] = command_at(tw, int(log.lane[i]), log.pose[i], turns[j])
            except ValueError:
                raise ValueError(
                    f"sample {i} (episode {e}) is {COMMAND_DISTANCE_M:.0f} m or less before a junction whose "
                    "turn the log does not record (a routeless episode that ended there): no command"
                ) from None
    return out


def one_hot(commands, n: int = N_COMMANDS) -> np.ndarray:
    """(B, n) float32 one-hot rows of command indices (B,)."""
    c = np.asarray(commands, dtype=np.int64).reshape(-1)
    if len(c) and (c.min() < 0 or c.max() >= n):
        raise ValueError(f"commands must be indices in [0, {n}), got {int(c.min())}..{int(c.max())}")
    return np.eye(n, dtype=np.float32)[c]


def command_runs(log, commands=None) -> dict[str, int]:
    """How many times each turn ("left", "straight", "right") is commanded in a demonstration log: the runs
    of that command within each episode (``commands``: ``log_commands(log)``, computed if None)."""
    c_all = log_commands(log) if commands is None else np.asarray(commands).reshape(-1)
    if len(c_all) != len(log):
        raise ValueError(f"commands must hold one command per sample ({len(log)}), got {len(c_all)}")
    runs = dict.fromkeys(COMMANDS[1:], 0)
    for episode in log.episodes():
        c = c_all[episode]
        for k in np.flatnonzero(np.diff(np.r_[-1, c]) != 0):  # the first step of each run
            if c[k] != FOLLOW:
                runs[COMMANDS[c[k]]] += 1
    return runs
