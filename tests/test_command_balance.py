"""driving.command_balance: town01 demonstration routes on which every command, "straight" included, is
commanded about equally often (for a retraining of chapter 11's agents; not run at scale here)."""

import numpy as np
import pytest

from ibc_tutorial.driving.collect import CollectConfig, collect, episode_plan, episode_steps
from ibc_tutorial.driving.command_balance import (
    TURNS,
    balanced_routes,
    planned_counts,
    reach_m,
    turns_within,
)
from ibc_tutorial.driving.commands import command_runs, log_commands
from ibc_tutorial.driving.routes import Route
from ibc_tutorial.driving.sim import DrivingSim
from ibc_tutorial.driving.towns import get_town

TOWN01 = get_town("town01")
CONFIG = CollectConfig(town="town01", routes=10, seed=0, brake_noise=1.0)  # the ten-routes collection


def test_turns_within_grow_with_the_distance_and_stop_at_the_route():
    route = balanced_routes(TOWN01, [3000], seed=3)[0]
    counts = [len(turns_within(TOWN01, route, d)) for d in (0.0, 100.0, 400.0, 1600.0, 1e6)]
    assert counts == sorted(counts) and counts[0] == 0 and counts[-1] <= len(route.turns)
    assert (
        turns_within(TOWN01, route, 1600.0) == route.turns[: counts[3]]
    )  # the route's first turns, in order
    assert reach_m(600) == pytest.approx(180.0)  # 60 s at 3 m/s


def test_balanced_routes_spread_the_commands_where_random_ones_do_not():
    """On the ten-routes collection's budgets: random routes plan "straight" about half as often as
    each turn; the balanced ones within two of each other."""
    steps = episode_steps(CONFIG)
    sim = DrivingSim("town01")
    random = [episode_plan(sim, CONFIG, k).route for k in range(CONFIG.routes)]
    balanced = balanced_routes(TOWN01, steps, seed=0)
    r, b = planned_counts(TOWN01, random, steps), planned_counts(TOWN01, balanced, steps)
    assert r["straight"] < 0.6 * min(r["left"], r["right"])
    assert max(b.values()) - min(b.values()) <= 2 and sum(b.values()) >= sum(r.values()) - 3
    assert balanced == balanced_routes(TOWN01, steps, seed=0)  # seeded: the same routes again
    for route in balanced:  # every turn legal at its junction: expanding the route raises on an illegal one
        assert all(t in TURNS for t in route.turns) and len(route.lanes(TOWN01, max_lanes=1000)) > 64


def test_collect_drives_the_given_routes_and_commands_straight_as_often_as_the_turns():
    """Measured by driving the expert (2 s): the balanced routes command left, straight and right 14, 15
    and 14 times in town01, where the collection's random routes command them 16, 9 and 16 times."""
    routes = balanced_routes(TOWN01, episode_steps(CONFIG), seed=0)
    log = collect(CONFIG, show_progress=False, routes=routes)
    assert [r["turns"] for r in log.meta["routes"]] == [list(r.turns) for r in routes]
    runs = command_runs(log, log_commands(log))
    assert runs == {"left": 14, "straight": 15, "right": 14}
    assert max(runs.values()) - min(runs.values()) <= 2


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="routes must be a list of 10 Route"):
        collect(CONFIG, show_progress=False, routes=[Route(0, 0.0, ())])
    with pytest.raises(ValueError, match="distance_m"):
        turns_within(TOWN01, Route(0, 0.0, ()), -1.0)
    with pytest.raises(ValueError, match="steps"):
        balanced_routes(TOWN01, [0])
    with pytest.raises(ValueError, match="seed"):
        balanced_routes(TOWN01, [100], seed=-1)
    assert np.isfinite(reach_m(1))


def test_a_replication_with_balanced_routes_collects_on_them():
    """``replicate --set balanced_routes=true``: the demonstrations are driven on ``balanced_routes`` of the
    preset's collection; without it, on the collection's own random routes."""
    from dataclasses import replace

    from ibc_tutorial.experiments.agents.presets import PRESETS
    from ibc_tutorial.experiments.agents.replicate import collect_demonstrations

    tiny = replace(PRESETS["tiny"], commands=True)
    config = tiny.collect_config()
    balanced = balanced_routes(get_town(config.town), episode_steps(config), seed=config.seed)
    log = collect_demonstrations(replace(tiny, balanced_routes=True), show_progress=False)
    assert [r["turns"] for r in log.meta["routes"][: config.routes]] == [list(r.turns) for r in balanced]
    plain = collect_demonstrations(tiny, show_progress=False)
    sim = DrivingSim(config.town)
    drawn = [list(episode_plan(sim, config, k).route.turns) for k in range(config.routes)]
    assert [r["turns"] for r in plain.meta["routes"][: config.routes]] == drawn
    with pytest.raises(ValueError, match="balanced_routes must be True or False"):
        replace(tiny, balanced_routes=1)
