"""Demonstration routes chosen so that every route command is well represented (for chapter 11's agents).

A route's turns are drawn at random among each junction approach's legal exits (``routes.random_route``).
In a T-junction town "straight" is legal only on the through road, never from a stem, so random routes
command it least: the ten town01 routes of the ``ten-routes`` collection command "straight" 9 times
against 16 lefts and 16 rights, and an agent learns "go straight at the junction" from nine examples.

``balanced_routes`` draws the same kind of routes (a random start, a legal turn at every junction) but
chooses each turn, among the legal exits, as the one least often commanded so far (ties at random): in
the routes before it, counting only the junctions the expert will reach in its time (``turns_within``),
and in the route itself. ``collect(config, routes=balanced_routes(...))`` drives the expert on them.
"""

from __future__ import annotations

import numpy as np

from ibc_tutorial.driving.routes import Route, random_route, random_start
from ibc_tutorial.driving.towns import Town
from ibc_tutorial.utils import check_int, check_positive

TURNS = ("left", "straight", "right")
"""The turns a route command names at a junction."""
EXPERT_SPEED_MPS = 3.0
"""The expert's mean speed over a route, stops included, to estimate how far it gets: 3.08 m/s over the ten
town01 routes of ``book/results/ten-routes/data`` (6477.5 m in 2105.2 s), rounded down."""
STEPS_PER_SECOND = 10
"""Simulation steps per second."""


def turns_within(town: Town, route: Route, distance_m: float) -> tuple[str, ...]:
    """The turns of ``route`` at the junctions whose entry lies within ``distance_m`` of its start, along
    its lanes (the junctions a car that drives that far reaches and is commanded at)."""
    distance_m = check_positive("distance_m", distance_m, allow_zero=True)
    out, travelled, k = [], -route.start_s, 0
    for lane in route.lanes(town):
        travelled += town.lanes[lane].length
        ap = town.approach_of_lane.get(lane)
        if ap is not None and town.approaches[ap].is_junction:
            if travelled > distance_m or k == len(route.turns):
                break
            out.append(route.turns[k])
            k += 1
    return tuple(out)


def reach_m(steps: int, speed_mps: float = EXPERT_SPEED_MPS) -> float:
    """How far the expert gets in ``steps`` simulation steps at its mean speed ``speed_mps``."""
    return check_int("steps", steps, minimum=0) / STEPS_PER_SECOND * check_positive("speed_mps", speed_mps)


class _LeastCommanded:
    """``choose(exits, rng)`` for ``random_route``: the legal exit commanded least so far, in the counts
    committed by earlier routes plus this route's own turns (ties broken by ``rng``)."""

    def __init__(self, committed: dict[str, int]):
        self.counts = dict(committed)

    def __call__(self, exits: list[str], rng: np.random.Generator) -> str:
        low = min(self.counts[e] for e in exits)
        fewest = [e for e in exits if self.counts[e] == low]
        turn = fewest[int(rng.integers(len(fewest)))]
        self.counts[turn] += 1
        return turn


def balanced_routes(town: Town, steps, seed: int = 0, *, n_turns: int = 64) -> list[Route]:
    """One route per entry of ``steps`` (each route's step budget, e.g. ``collect.episode_steps``), drawn
    from ``np.random.default_rng([seed, k])`` like the collection's: a random start, then at each junction
    the legal exit commanded least so far. Only the turns the expert reaches in its budget
    (``turns_within(route, reach_m(steps[k]))``) count for the routes after it."""
    seed = check_int("seed", seed, minimum=0)
    budgets = [check_int("steps", s, minimum=1) for s in np.asarray(steps).ravel().tolist()]
    committed = dict.fromkeys(TURNS, 0)
    out = []
    for k, budget in enumerate(budgets):
        rng = np.random.default_rng([seed, k])
        choose = _LeastCommanded(committed)
        route = random_route(town, rng, n_turns=n_turns, start=random_start(town, rng), choose=choose)
        for turn in turns_within(town, route, reach_m(budget)):
            committed[turn] += 1
        out.append(route)
    return out


def planned_counts(town: Town, routes, steps) -> dict[str, int]:
    """How many times each turn is reached within each route's budget: the commands the plan expects."""
    counts = dict.fromkeys(TURNS, 0)
    for route, budget in zip(routes, np.asarray(steps).ravel().tolist(), strict=True):
        for turn in turns_within(town, route, reach_m(int(budget))):
            counts[turn] += 1
    return counts
