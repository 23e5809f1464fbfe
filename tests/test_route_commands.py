"""Route commands (driving.commands), the town02 routes and their tracker (driving.route_following)."""

from pathlib import Path

import numpy as np
import pytest

from ibc_tutorial.driving.commands import (
    COMMAND_DISTANCE_M,
    COMMANDS,
    FOLLOW,
    command_at,
    distance_to_entry,
    episode_turns,
    log_commands,
    one_hot,
)
from ibc_tutorial.driving.dataset import DemoDataset, DemoLog
from ibc_tutorial.driving.route_following import (
    ROUTES,
    RouteTracker,
    build_route,
    junction_success,
    route_crossings,
    route_length,
)
from ibc_tutorial.driving.routes import Route
from ibc_tutorial.driving.towns import get_town

SHIPPED = Path(__file__).parents[1] / "book" / "results" / "laptop" / "data" / "town01.npz"


def _junction_approach(town, stem: bool):
    return next(ap for ap in town.approaches if ap.is_junction and (("straight" not in ap.exits) == stem))


def test_command_rule_switches_at_the_stated_distance():
    town = get_town("town02")
    ap = _junction_approach(town, stem=True)
    lane = town.lanes[ap.lane]
    d = (lane.end - lane.start) / lane.length
    far = lane.end - d * (COMMAND_DISTANCE_M + 0.5)
    near = lane.end - d * (COMMAND_DISTANCE_M - 0.5)
    assert distance_to_entry(town, ap.lane, near) == pytest.approx(COMMAND_DISTANCE_M - 0.5)
    assert command_at(town, ap.lane, far, "left") == FOLLOW
    assert COMMANDS[command_at(town, ap.lane, near, "left")] == "left"
    assert COMMANDS[command_at(town, ap.lane, near, "right")] == "right"
    # inside the junction: the connector's own turn
    assert COMMANDS[command_at(town, ap.exits["right"], near, None)] == "right"
    with pytest.raises(ValueError, match="next_turn"):
        command_at(town, ap.lane, near, None)
    with pytest.raises(ValueError, match="next_turn must be one of"):
        command_at(town, ap.lane, near, "straight")  # a stem has no straight exit
    # a corner takes no command
    corner = next(a for a in town.approaches if not a.is_junction)
    assert command_at(town, corner.lane, town.lanes[corner.lane].end, None) == FOLLOW


def test_one_hot():
    assert one_hot([0, 3]).tolist() == [[1, 0, 0, 0], [0, 0, 0, 1]]
    with pytest.raises(ValueError, match="commands must be indices"):
        one_hot([4])


@pytest.mark.skipif(not SHIPPED.exists(), reason="the shipped laptop data")
def test_shipped_town01_data_gain_commands_that_match_the_routes():
    log = DemoLog.load(SHIPPED)
    c = log_commands(log)
    counts = np.bincount(c, minlength=4)
    assert counts.sum() == len(log) and (counts > 1000).all()  # every command is frequent
    # the turns read from the lanes (without the routes' lists) agree with the routes' lists, in order
    checked = 0
    for e, sl in enumerate(log.episodes()):
        turns = episode_turns(log.town, log.lane[sl])
        seen = [t for k, t in enumerate(turns) if k == 0 or log.lane[sl][k] != log.lane[sl][k - 1]]
        seen = [t for t in seen if t is not None]
        route = log.meta["routes"][e]["turns"]
        assert seen == route[: len(seen)], e
        checked += len(seen)
    assert checked >= 30
    # a command is the route's turn only near a junction: far from any, "follow"
    town = get_town(log.town)
    for i in np.flatnonzero(c > 0)[::97]:
        lane = town.lanes[int(log.lane[i])]
        if lane.kind == "road":
            assert distance_to_entry(town, lane.id, log.pose[i]) <= COMMAND_DISTANCE_M + 1e-9


def test_dataset_gives_commands_only_when_asked(tmp_path):
    from ibc_tutorial.driving.collect import CollectConfig, collect

    log = collect(CollectConfig(routes=1, min_minutes=0.3, max_minutes=0.3, seed=1), show_progress=False)
    plain = DemoDataset(log, bev_size=32)
    with_cmd = DemoDataset(log, bev_size=32, commands=True)
    obs, _ = plain.batch([0, 1])
    assert "command" not in obs
    obs, _ = with_cmd.batch(np.arange(len(log)))
    assert obs["command"].dtype.is_floating_point is False and obs["command"].shape == (len(log),)
    assert obs["command"].tolist() == log_commands(log).tolist()
    item, _ = with_cmd[0]
    assert item["command"].ndim == 0


def test_routes_have_the_stated_properties():
    town = get_town("town02")
    stems = {ap.id for ap in town.approaches if ap.is_junction and "straight" not in ap.exits}
    assert len(stems) == 8
    taken = set()
    turns = set()
    for name in ROUTES:
        route = build_route(name)
        crossings = route_crossings(route)
        assert route_length(route) >= 1000.0, name
        assert len(crossings) >= 4, name
        taken |= set(crossings)
        turns |= {t for _, t in crossings}
    assert turns == {"left", "straight", "right"}
    stems_both = {s for s in stems if {(s, "left"), (s, "right")} <= taken}
    assert len(stems_both) >= 4
    assert len(stems_both) == 8  # all of them, in fact


def _poses_along(route: Route, town, n_lanes: int):
    """Poses every metre along the first ``n_lanes`` lanes of ``route``, from its start."""
    poses = []
    for k, lane in enumerate(route.lanes(town)[:n_lanes]):
        ln = town.lanes[lane]
        pts, hs = ln.points, ln.headings
        if k == 0:
            keep = np.arange(len(pts)) * ln.length / len(pts) >= route.start_s
            pts, hs = pts[keep], hs[keep]
        poses += [(float(p[0]), float(p[1]), float(h)) for p, h in zip(pts, hs, strict=True)]
    return poses


def test_tracker_follows_a_route_and_gives_its_commands():
    town = get_town("town02")
    route = build_route("r4")
    tracker = RouteTracker(route)
    cmds = [tracker.update(*pose) for pose in _poses_along(route, town, len(route.lanes(town)))]
    assert not tracker.wrong_turn
    assert tracker.completed and tracker.completion == 1.0
    assert [c["taken"] for c in tracker.crossings] == [c["command"] for c in tracker.crossings]
    assert [c["command"] for c in tracker.crossings] == list(route.turns)
    # the commands given: every turn of the route, in order, each as one run, "follow" in between
    runs = [c for k, c in enumerate(cmds) if c != FOLLOW and (k == 0 or cmds[k - 1] != c)]
    assert [COMMANDS[c] for c in runs] == list(route.turns)
    assert cmds[0] == FOLLOW


def test_tracker_notices_a_wrong_turn():
    town = get_town("town02")
    route = build_route("r4")
    first = route_crossings(route)[0]
    other = next(t for t in town.approaches[first[0]].exits if t != first[1])
    detour = Route(route.start_lane, route.start_s, (other,))
    tracker = RouteTracker(route)
    for pose in _poses_along(detour, town, len(detour.lanes(town))):
        tracker.update(*pose)
    assert tracker.wrong_turn and not tracker.completed
    assert tracker.crossings[0]["command"] == first[1] and tracker.crossings[0]["taken"] == other
    s = junction_success([{"crossings": tracker.crossings}])
    assert s[first[1]] == {"crossings": 1, "taken": 0, "rate": 0.0}


def test_observation_before_crossing_is_the_first_state_within_the_distance():
    from ibc_tutorial.driving.commands import COMMANDS
    from ibc_tutorial.driving.route_following import observation_before_crossing, route_crossings

    obs, where = observation_before_crossing("r2", 0, 2.0, bev_size=32, light_encoding="flag")
    approach, turn = route_crossings(build_route("r2"))[0]
    assert where["approach"] == approach and where["turn"] == turn
    assert 0.0 < where["distance_m"] <= 2.0  # the first state within 2 m: not yet past the entry
    assert COMMANDS[int(obs["command"])] == turn  # within 20 m of the entry: the route's turn
    assert obs["bev"].shape == (5, 32, 32) and obs["state"].shape == (3,)
    far, where_far = observation_before_crossing("r2", 0, 40.0, bev_size=32)
    assert where_far["step"] < where["step"] and COMMANDS[int(far["command"])] == "follow"
    with pytest.raises(ValueError, match="crossing must be below 14"):
        observation_before_crossing("r2", 14, 2.0)


@pytest.mark.parametrize("name", ["r4", "r5", "r6"])
def test_a_wrong_exit_is_a_failed_crossing_whichever_connector_the_car_is_seen_on(name):
    town = get_town("town02")
    route = build_route(name)
    first = route_crossings(route)[0]
    for other in (t for t in town.approaches[first[0]].exits if t != first[1]):
        detour = Route(route.start_lane, route.start_s, (other,))
        lanes = detour.lanes(town)
        # the car seen on the approach lane, then straight on the wrong exit's road lane (its connector's
        # points skipped): the crossing must still be recorded, as missed
        poses = [p for p in _poses_along(detour, town, len(lanes))]
        conn = next(k for k in lanes if town.lanes[k].kind == "connector" and town.lanes[k].node is not None)
        skip = {(float(x), float(y)) for x, y in town.lanes[conn].points}
        tracker = RouteTracker(route)
        for x, y, h in poses:
            if (x, y) not in skip:
                tracker.update(x, y, h)
        assert tracker.wrong_turn, (name, other)
        assert [(c["command"], c["taken"]) for c in tracker.crossings] == [(first[1], other)], (name, other)


@pytest.mark.parametrize("name", ["r1", "r4"])
def test_route_path_gives_every_turn_once_in_order(name):
    from ibc_tutorial.driving.route_following import route_length, route_path

    xy, cmds = route_path(name)
    route = build_route(name)
    assert xy.shape == (len(cmds), 2)
    steps = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    assert abs(steps.sum() - route_length(route)) < 0.05 * route_length(route)  # the route's length
    runs = [COMMANDS[c] for k, c in enumerate(cmds) if c != FOLLOW and (k == 0 or cmds[k - 1] != c)]

    def merged(seq):  # two equal turns with no "follow" between them are one run of that command
        return [t for k, t in enumerate(seq) if k == 0 or seq[k - 1] != t]

    assert merged(runs) == merged(list(route.turns))


def test_command_runs_count_each_turn_once_per_approach():
    from ibc_tutorial.driving.commands import command_runs

    class Log:  # two episodes: a left, then a straight after "follow"; a right that the episode starts in
        def __len__(self):
            return 9

        def episodes(self):
            return [slice(0, 6), slice(6, 9)]

    cmds = np.array([0, 1, 1, 0, 2, 2, 3, 3, 0])
    assert command_runs(Log(), cmds) == {"left": 1, "straight": 1, "right": 1}
    with pytest.raises(ValueError, match="one command per sample"):
        command_runs(Log(), cmds[:-1])
