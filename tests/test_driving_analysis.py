"""The one loop over environments (driving.rollout) and the free-driving measures (driving.analysis)."""

import numpy as np
import pytest

from ibc_tutorial.driving import EnvConfig, RolloutRecording, get_town, rollout
from ibc_tutorial.driving.analysis import (
    exit_counts,
    exits_per_approach,
    junction_crossings,
    junction_visits,
    road_coverage,
)


@pytest.fixture(scope="module")
def expert_drive():
    env = EnvConfig("town02", bev_size=32, max_steps=400)
    (r,) = rollout("expert", env, episodes=1, seed=3, record=RolloutRecording(steps=True, obs=True))
    return r


def test_rollout_records_every_step(expert_drive):
    r = expert_drive
    t = r.trace
    n = r.steps + 1
    assert t["pose"].shape == (n, 3) and t["speed"].shape == (n,) and t["lane"].shape == (n,)
    assert t["red_ahead"].dtype == bool and t["entry_dist"].shape == (n,) and t["actions"].shape == (n - 1, 2)
    assert t["bev"].shape == (n, 5, 32, 32) and t["state"].shape == (n, 3)
    np.testing.assert_array_equal(t["pose"][:, :2], r.xy)
    np.testing.assert_allclose(
        t["state"][1:, 1:], t["actions"], atol=1e-6
    )  # the state holds the previous action
    assert np.isinf(t["entry_dist"][~np.isin(t["lane"], list(get_town("town02").approach_of_lane))]).all()


def test_rollout_scores_alone_and_refuses_bad_requests():
    env = EnvConfig("town02", bev_size=32, max_steps=5)
    (r,) = rollout("expert", env, episodes=1, seed=3, record=RolloutRecording(xy=False))
    assert r.xy is None and r.trace is None and r.steps == 5
    with pytest.raises(ValueError, match="obs needs steps"):
        RolloutRecording(obs=True)
    with pytest.raises(ValueError, match="xy"):
        RolloutRecording(xy="yes")
    with pytest.raises(ValueError, match="policy"):
        rollout("pid", env, episodes=1)
    with pytest.raises(ValueError, match="env must be an EnvConfig"):
        rollout("expert", "town02", episodes=1)
    with pytest.raises(ValueError, match="record must be a RolloutRecording"):
        rollout("expert", env, episodes=1, record={"xy": False})


def test_junction_visits_read_the_exit_from_the_lanes(expert_drive):
    tw = get_town("town02")
    ap = next(a for a in tw.approaches if a.is_junction)
    turn, conn = next(iter(ap.exits.items()))
    after = tw.lanes[conn].successors[0]
    lanes = [ap.lane] * 5 + [conn] * 3 + [after] * 4 + [ap.lane] * 2 + [conn, after]
    visits = junction_visits(tw, np.array(lanes))
    assert visits == [
        {"approach": ap.id, "node": ap.node, "turn": turn, "step": 4},
        {"approach": ap.id, "node": ap.node, "turn": turn, "step": 13},
    ]
    assert exits_per_approach(visits) == {ap.id: {"node": ap.node, "visits": 2, "turns": [turn]}}
    assert exit_counts(visits) == {ap.id: {t: 2 * (t == turn) for t in ("left", "straight", "right")}}
    # a record that ends inside the junction: counted only with ended_inside, by the connector entered
    (other_turn, other_conn), *_ = [(t, c) for t, c in ap.exits.items() if t != turn]
    ends_inside = lanes + [ap.lane] * 2 + [other_conn] * 3
    assert junction_visits(tw, np.array(ends_inside)) == visits
    assert junction_visits(tw, np.array(ends_inside), ended_inside=True) == visits + [
        {"approach": ap.id, "node": ap.node, "turn": other_turn, "step": 17}
    ]
    with pytest.raises(ValueError, match="turn"):
        exit_counts([{"approach": 1, "turn": "u-turn"}])
    assert all(
        v["turn"] in ("left", "straight", "right")
        for v in junction_visits("town02", expert_drive.trace["lane"])
    )


def test_junction_crossings_span_the_connector_and_keep_the_steering(expert_drive):
    tw = get_town("town02")
    ap = next(a for a in tw.approaches if a.is_junction and "left" in a.exits)
    conn = ap.exits["left"]
    after = tw.lanes[conn].successors[0]
    lanes = np.array([ap.lane] * 3 + [conn] * 4 + [after] * 2 + [ap.lane] * 2 + [conn] * 3)  # (14,) states
    steer = np.array([0, 0, 0, -0.3, -0.5, 0.2, -0.1, 0, 0, 0, 0, 0.4, -0.2, 0.7])  # (14,): after each state
    first, last = junction_crossings(tw, lanes, steer[:13])  # (T + 1,) states, (T,) actions
    assert first == {
        "approach": ap.id,
        "node": ap.node,
        "start": 3,
        "stop": 7,
        "turn": "left",
        "finished": True,
        "steer_min": -0.5,
        "steer_max": 0.2,
    }
    # the record ends inside the junction: the crossing is unfinished, its steering up to the last action
    assert last["start"] == 11 and last["stop"] == 14 and last["turn"] == "" and not last["finished"]
    assert (last["steer_min"], last["steer_max"]) == (-0.2, 0.4)
    assert (
        junction_crossings(tw, lanes, steer)[1]["steer_max"] == 0.7
    )  # one steering per state is accepted too
    assert junction_crossings(tw, np.array([ap.lane] * 4), np.zeros(3)) == []  # never entered the junction
    with pytest.raises(ValueError, match="steer must hold one value per state or per step"):
        junction_crossings(tw, lanes, steer[:5])
    # on a real drive: the crossings are the junction visits, with the same exits
    t = expert_drive.trace
    crossed = [c for c in junction_crossings("town02", t["lane"], t["actions"][:, 0]) if c["finished"]]
    assert [c["turn"] for c in crossed] == [v["turn"] for v in junction_visits("town02", t["lane"])]
    assert all(c["steer_min"] <= c["steer_max"] for c in crossed)


def test_road_coverage_counts_lanes_driven_in_their_direction():
    tw = get_town("town02")
    road = np.isin(tw.wp_lane, tw.road_lanes)
    wp, wh = tw.wp_xy[road], tw.wp_heading[road]
    assert road_coverage(tw, np.c_[wp, wh]) == 1.0  # every waypoint, on it, heading along
    assert road_coverage(tw, np.c_[wp[:1], wh[:1] + np.pi]) == 0.0  # wrong way
    assert road_coverage(tw, np.zeros((0, 3))) == 0.0
    with pytest.raises(ValueError, match="radius"):
        road_coverage(tw, np.c_[wp, wh], radius=0)


def test_road_coverage_agrees_with_a_kd_tree():
    spatial = pytest.importorskip("scipy.spatial")
    tw = get_town("town02")
    road = np.isin(tw.wp_lane, tw.road_lanes)
    wp, wh = tw.wp_xy[road], tw.wp_heading[road]
    rng = np.random.default_rng(0)
    idx = rng.choice(len(wp), 1500)
    poses = np.c_[wp[idx] + rng.normal(0, 2, (1500, 2)), wh[idx] + rng.normal(0, 1.0, 1500)]
    covered = np.zeros(len(wp), dtype=bool)
    for i, near in enumerate(spatial.cKDTree(poses[:, :2]).query_ball_point(wp, r=3.0)):
        if near:
            covered[i] = (np.abs(np.angle(np.exp(1j * (poses[near, 2] - wh[i])))) <= np.pi / 3).any()
    assert road_coverage(tw, poses) == float(covered.mean())


def test_light_label_conflicts_counts_each_encoding():
    from ibc_tutorial.driving.analysis import light_label_conflicts
    from ibc_tutorial.driving.collect import CollectConfig, collect

    log = collect(
        CollectConfig(town="town02", routes=2, seed=0, min_minutes=1.0, max_minutes=1.0), show_progress=False
    )
    r = light_label_conflicts(log)
    c = r["counts"]
    assert sum(c.values()) == r["near"] > 0
    assert r["conflicts"]["binary"] == c[("yellow", "go")] + c[("red", "go")] + c[("green", "stop")]
    assert (
        r["conflicts"]["intensity"]
        <= r["conflicts"]["binary"]
        <= r["conflicts"]["red only"] + c[("yellow", "go")]
    )
    assert (
        c[("red", "stop")] > 0 and r["conflicts"]["intensity"] == 0
    )  # never through red, never stops at green
    with pytest.raises(ValueError):
        light_label_conflicts(log, stop_distance=0.0)


def test_stop_line_gaps_nan_off_approaches():
    from ibc_tutorial.driving.analysis import stop_line_gaps

    town = get_town("town02")
    ap = town.approaches[0]
    lane = town.lanes[ap.lane]
    p = lane.points[-6]
    g, light = stop_line_gaps(
        town, np.array([[p[0], p[1], float(np.arctan2(*lane.end[::-1] - p[::-1]))]]), [ap.lane]
    )
    assert light[0] == town.light_of_approach.get(ap.id, -1)


def test_on_step_sees_what_the_policy_sees_and_must_be_callable():
    seen, given = [], []

    def policy(batch):
        given.append((len(batch["state"]), batch["state"].copy()))
        return np.tile([0.0, 0.3], (len(batch["state"]), 1))

    def hook(t, episodes, batch):
        seen.append((t, episodes, batch["state"].copy()))

    env = EnvConfig("town02", bev_size=32, max_steps=4)
    rollout(policy, env, episodes=2, seed=3, record=RolloutRecording(xy=False, on_step=hook))
    assert [s[0] for s in seen] == [0, 1, 2, 3] and all(s[1] == [0, 1] for s in seen)
    assert all(np.array_equal(s[2], g[1]) for s, g in zip(seen, given, strict=True))
    with pytest.raises(ValueError, match="on_step must be callable"):
        RolloutRecording(on_step="print")
