"""Towns and lanes: layout facts, lane and waypoint continuity, legal exits of every approach."""

import math

import numpy as np
import pytest

from ibc_tutorial.driving.lanes import LANE_WIDTH, WAYPOINT_SPACING
from ibc_tutorial.driving.routes import Route, random_route
from ibc_tutorial.driving.towns import TOWNS, get_town


@pytest.mark.parametrize("name, size, junctions", [("town01", (400, 335), 12), ("town02", (200, 200), 8)])
def test_layout_matches_carla(name, size, junctions):
    town = get_town(name)
    w, h = town.size
    assert abs(w - size[0]) < 10 and abs(h - size[1]) < 10
    assert town.n_junctions == junctions
    assert town.n_lights == 3 * junctions  # one head per approach of a T-junction
    assert len(town.buildings) == len(town.layout.blocks)


@pytest.mark.parametrize("name", TOWNS)
def test_lanes_join_and_waypoints_are_dense(name):
    town = get_town(name)
    for lane in town.lanes:
        assert lane.successors, f"lane {lane.id} is a dead end"
        for nxt in lane.successors:
            other = town.lanes[nxt]
            assert np.allclose(lane.end, other.start, atol=1e-9)  # positions join
            assert (
                abs(math.remainder(lane.heading_out - other.heading_in, 2 * math.pi)) < 1e-9
            )  # so do headings
        steps = np.linalg.norm(np.diff(np.vstack([lane.points, lane.end]), axis=0), axis=1)
        assert steps.max() <= WAYPOINT_SPACING + 1e-9 and steps.min() > 0.5
        # every waypoint lies on the lane's centre line
        assert np.abs(lane.distance_to(lane.points)).max() < 1e-9


@pytest.mark.parametrize("name", TOWNS)
def test_right_hand_traffic(name):
    town = get_town(name)
    for lane in town.lanes:
        if lane.kind != "road":
            continue
        centre = (town.nodes[lane.from_node] + town.nodes[lane.to_node]) / 2
        d = (lane.end - lane.start) / lane.length
        mid = (lane.start + lane.end) / 2
        right = np.array([d[1], -d[0]])
        assert np.isclose((mid - centre) @ right, LANE_WIDTH / 2)  # 2 m right of the road's centre line


@pytest.mark.parametrize("name", TOWNS)
def test_every_approach_has_its_legal_exits(name):
    town = get_town(name)
    for ap in town.approaches:
        arms = {a.arm for a in town.approaches if a.node == ap.node}
        assert len(ap.exits) == len(arms) - 1  # every other arm, no U-turn
        assert ap.is_junction == (len(arms) == 3)
        for turn, lane_id in ap.exits.items():
            conn = town.lanes[lane_id]
            assert conn.turn == turn and conn.node == ap.node
            road = town.lanes[conn.successors[0]]
            assert road.from_node == ap.node and road.to_node != town.lanes[ap.lane].from_node
        if (
            ap.is_junction
        ):  # a T-junction: the stem approach turns left or right, the others go straight or turn
            assert set(ap.exits) in ({"left", "right"}, {"straight", "left"}, {"straight", "right"})
    for lane in town.lanes:
        if lane.kind == "road":
            assert lane.id in town.approach_of_lane


@pytest.mark.parametrize("name", TOWNS)
def test_route_path_is_continuous(name):
    town = get_town(name)
    route = random_route(town, np.random.default_rng(0), n_turns=20)
    lanes = route.lanes(town)
    assert (
        sum(
            town.approaches[town.approach_of_lane[i]].is_junction for i in lanes if i in town.approach_of_lane
        )
        >= 20
    )
    pts = np.vstack([town.lanes[i].points for i in lanes])
    steps = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    assert steps.max() <= WAYPOINT_SPACING + 1e-9


def test_bad_town_and_bad_route_are_refused():
    with pytest.raises(ValueError, match="town"):
        get_town("town03")
    town = get_town("town02")
    connector = next(ln.id for ln in town.lanes if ln.kind == "connector")
    with pytest.raises(ValueError, match="start_lane"):
        Route(connector, 0.0, ()).lanes(town)
    stem = next(ap for ap in town.approaches if ap.is_junction and "straight" not in ap.exits)
    start_lane = stem.lane
    with pytest.raises(ValueError, match="turn must be one of"):
        Route(start_lane, 0.0, ("straight",)).lanes(town)


def test_a_bad_chooser_is_refused_naming_choose():
    town = get_town("town01")
    rng = np.random.default_rng(0)
    before = rng.bit_generator.state
    for bad in ("left", None, 3):  # not callable: refused up front, before the start is drawn
        with pytest.raises(ValueError, match="choose must be a callable"):
            random_route(town, rng, n_turns=3, choose=bad)
    assert rng.bit_generator.state == before
    with pytest.raises(
        ValueError, match=r"choose must return one of the exits it is given, \[.*\], got 'up'"
    ):
        random_route(town, rng, n_turns=3, choose=lambda exits, r: "up")


def test_localize_finds_the_lane():
    town = get_town("town01")
    lane = town.lanes[5]
    p, h = lane.points[7], lane.headings[7]
    assert town.localize(p[0] + 0.3, p[1] - 0.2, h + 0.1)[:2] == (5, 7)
