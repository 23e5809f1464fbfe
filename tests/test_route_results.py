"""Reading route drives (chapter 11): tables per method, junction success, the ends at stems."""

import json

import numpy as np
import pytest

from ibc_tutorial.experiments.agents import route_tables as rr


def _row(route, completion, end="completed", crossings=(), seed=0):
    return {
        "route": route,
        "seed": seed,
        "completion": completion,
        "driving_score": completion * 0.7,
        "end": end,
        "crossings": [{"approach": a, "command": c, "taken": t} for a, c, t in crossings],
    }


STEM = min(rr.ROUTE_TOWN_STEMS)
NOT_STEM = 9  # a town02 approach with a straight exit
DRIVERS = {
    "bc-seed0": [
        _row("r2", 0.5, "wrong_turn", [(STEM, "left", "left"), (NOT_STEM, "left", "straight")]),
        _row("r1", 1.0, crossings=[(NOT_STEM, "straight", "straight")]),
    ],
    "bc-seed1": [
        _row("r1", 0.2, "building", [(STEM, "right", "")]),  # ended inside a junction entered from a stem
        _row("r2", 0.4, "building", [(NOT_STEM, "left", "")]),  # inside a junction, not from a stem
    ],
    "bc-seed2": [
        _row("r1", 0.3, "off_road", [(STEM, "left", "")]),  # off the road inside a stem's junction
        _row("r2", 0.4, "timeout", [(STEM, "left", "")]),  # stopped there: not an end at the stem
    ],
    "expert": [_row("r1", 1.0), _row("r2", 1.0)],
}


def test_method_of_names():
    assert rr.method_of("da-ibc-seed12") == "da-ibc" and rr.method_of("expert") == "expert"
    for bad in ("da-ibc", "mdn-seed0", "bc-seedx"):
        with pytest.raises(ValueError, match="name must be"):
            rr.method_of(bad)


def test_route_table_orders_each_agents_routes_alike():
    bm = rr.by_method(DRIVERS)
    assert list(bm) == ["bc", "expert"]
    t = rr.route_table(bm["bc"], "completion")
    np.testing.assert_array_equal(t, [[1.0, 0.5], [0.2, 0.4], [0.3, 0.4]])  # r1 then r2 for every agent
    with pytest.raises(ValueError, match="same routes"):
        rr.route_table({"a": [_row("r1", 1.0)], "b": [_row("r2", 1.0)]}, "completion")


def test_success_counts_pool_crossings_and_count_unfinished_as_missed():
    taken, crossings = rr.success_counts(rr.by_method(DRIVERS)["bc"], "all")
    np.testing.assert_array_equal(crossings, [[1, 2], [1, 1], [1, 1]])
    np.testing.assert_array_equal(taken, [[1, 1], [0, 0], [0, 0]])
    taken, crossings = rr.success_counts(rr.by_method(DRIVERS)["bc"], "left")
    np.testing.assert_array_equal(crossings, [[0, 2], [0, 1], [1, 1]])
    np.testing.assert_array_equal(taken, [[0, 1], [0, 0], [0, 0]])
    with pytest.raises(ValueError, match="command"):
        rr.success_counts(DRIVERS, "follow")


def test_stem_ends_only_inside_a_junction_entered_from_a_stem():
    assert NOT_STEM not in rr.ROUTE_TOWN_STEMS and len(rr.ROUTE_TOWN_STEMS) == 8
    ends = rr.stem_ends(DRIVERS["bc-seed1"])
    assert [r["route"] for r in ends] == ["r1"]
    assert rr.stem_ends(DRIVERS["bc-seed0"]) == []
    assert [r["route"] for r in rr.stem_ends(DRIVERS["bc-seed2"])] == ["r1"]
    assert rr.count_stem_crossings(DRIVERS["bc-seed0"]) == 1


def test_command_drivers_reads_a_replication_folder(tmp_path):
    for name in ("runs/bc/seed1", "runs/bc/seed0", "runs/expert"):
        (tmp_path / name).mkdir(parents=True)
        (tmp_path / name / "final_eval.json").write_text(json.dumps({"episodes": [_row("r1", 1.0)]}))
    assert list(rr.command_drivers(tmp_path)) == ["bc-seed0", "bc-seed1", "expert"]
    (tmp_path / "runs/bc/seed1/final_eval.json").write_text(json.dumps({"episodes": [{"seed": 0}]}))
    with pytest.raises(ValueError, match="no route drives"):
        rr.command_drivers(tmp_path)
    with pytest.raises(ValueError, match="found none"):
        rr.command_drivers(tmp_path / "empty")


def test_missed_crossings_count_command_and_exit_taken():
    misses = rr.missed_crossings(rr.by_method(DRIVERS)["bc"])
    assert misses == {("left", "straight"): 1, ("right", "none"): 1, ("left", "none"): 3}


def test_group_summary_counts_the_rows_it_is_given():
    from ibc_tutorial import stats
    from ibc_tutorial.experiments.agents.route_tables import format_group_table, group_summary

    def row(route, comp, score, red, end, crossings=()):
        return {"route": route, "seed": 0, "completion": comp, "driving_score": score,
                "red_light_infractions": red, "end": end, "crossings": list(crossings)}  # fmt: skip

    ended = [{"approach": 10**6, "command": "left", "taken": ""}]
    drivers = {
        "ibc-seed0": [row("r1", 1.0, 0.7, 1, "completed"), row("r2", 0.5, 0.5, 0, "wrong_turn")],
        "ibc-seed1": [row("r1", 0.2, 0.2, 0, "building", ended), row("r2", 1.0, 1.0, 0, "completed")],
    }
    g = group_summary(drivers)
    assert g.agents == 2 and g.red == 0.25 and g.stem_ends == 0  # approach 10**6 is no stem
    assert g.ends == {"completed": 2, "wrong_turn": 1, "building": 1, "off_road": 0, "timeout": 0}
    assert g.completion.estimate == np.mean([1.0, 0.5, 0.2, 1.0])
    assert g.score == stats.mean_interval(np.array([[0.7, 0.5], [0.2, 1.0]]))
    text = format_group_table({"IBC": g})
    assert "completed 2 wrong_turn 1 building 1" in text and "timeout" not in text.splitlines()[1]
