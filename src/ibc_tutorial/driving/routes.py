"""Routes: a start point and a fixed list of junction choices, as in the paper's ten town01 routes.

The DA-IBC paper's expert follows predefined routes of the CARLA leaderboard (its sec. 4.1);
here a route is a start on a road lane and the turn ("left", "straight" or "right") to take
at each T-junction met in turn (corners have one way out and take no choice). Expanded over
the lane graph it gives the dense path the expert follows.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ibc_tutorial.driving.towns import Town
from ibc_tutorial.utils import check_int


@dataclass(frozen=True)
class Route:
    """A start on a road lane and the turns to take at successive T-junctions."""

    start_lane: int
    """Id of the road lane the car starts on."""
    start_s: float
    """Arc length along that lane where it starts (metres)."""
    turns: tuple[str, ...]
    """Turn at each T-junction met, in order; after the last one the choice is random."""

    def lanes(self, town: Town, max_lanes: int = 200) -> list[int]:
        """The lane ids the route follows, as far as its turns go (at most ``max_lanes``)."""
        check_int("max_lanes", max_lanes, minimum=1)
        if not (0 <= self.start_lane < len(town.lanes)) or town.lanes[self.start_lane].kind != "road":
            raise ValueError(f"start_lane must be a road lane of {town.name}, got {self.start_lane}")
        out = [self.start_lane]
        k = 0
        while len(out) < max_lanes:
            lane = out[-1]
            ap = town.approach_of_lane.get(lane)
            if ap is not None and town.approaches[ap].is_junction:
                if k == len(self.turns):
                    break
                turn = self.turns[k]
                k += 1
                out.append(town.next_lane(lane, turn))
            else:
                out.append(town.next_lane(lane))
        return out


def random_start(town: Town, rng: np.random.Generator) -> tuple[int, float]:
    """A random (road lane, arc length), uniform over the road lanes' length, at least 3 m after a
    lane's start and 12 m before its stop line."""
    lanes = [town.lanes[i] for i in town.road_lanes]
    usable = np.array([ln.length - 15.0 for ln in lanes])
    k = int(rng.choice(len(lanes), p=usable / usable.sum()))
    return lanes[k].id, 3.0 + float(rng.random()) * usable[k]


def uniform_exit(exits: list[str], rng: np.random.Generator) -> str:
    """One of a junction approach's legal ``exits`` (sorted), each equally likely."""
    return exits[int(rng.integers(len(exits)))]


def random_route(
    town: Town,
    rng: np.random.Generator,
    n_turns: int = 64,
    start: tuple[int, float] | None = None,
    choose: Callable[[list[str], np.random.Generator], str] = uniform_exit,
) -> Route:
    """A route with ``n_turns`` legal turns from a random start (or ``start`` = (lane, s)).

    At each junction approach met, ``choose(exits, rng)`` picks the turn among the sorted legal exits
    (``uniform_exit``: each equally likely; chapter 10's demonstrations keep straight past side roads).
    A ``choose`` that is not callable is refused before anything is drawn, one that returns no legal
    exit when called; both with a ValueError naming ``choose``."""
    check_int("n_turns", n_turns, minimum=0)
    if not callable(choose):
        raise ValueError(f"choose must be a callable choose(exits, rng) -> one of the exits, got {choose!r}")
    if start is None:
        start = random_start(town, rng)
    lane = start[0]
    turns: list[str] = []
    while len(turns) < n_turns:
        ap = town.approach_of_lane.get(lane)
        if ap is not None and town.approaches[ap].is_junction:
            exits = sorted(town.approaches[ap].exits)
            turn = choose(exits, rng)
            if turn not in exits:
                raise ValueError(f"choose must return one of the exits it is given, {exits}, got {turn!r}")
            turns.append(turn)
            lane = town.next_lane(lane, turn)
        else:
            lane = town.next_lane(lane)
    return Route(int(start[0]), float(start[1]), tuple(turns))
