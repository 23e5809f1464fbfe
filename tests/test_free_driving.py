"""The free-driving summary of chapter 09, on constructed episodes."""

from ibc_tutorial.experiments.agents.free_driving import format_free_driving, pooled_visits


def _episode(distance, termination, coverage, visits):
    return {
        "result": {"distance_m": distance, "termination": termination},
        "coverage": coverage,
        "visits": visits,
    }


def visit(approach, turn):
    return {"approach": approach, "turn": turn}


FREE = {
    "bc": {
        "coverage_all": 0.5,
        "episodes": [
            _episode(5.0, "building", 0.1, [visit(1, "left"), visit(1, "left")]),
            _episode(300.0, None, 0.4, [visit(1, "right"), visit(7, "straight")]),
        ],
    }
}


def test_pooled_visits_keeps_every_pass_in_order():
    assert pooled_visits(FREE, ["bc"]) == {
        "bc": [visit(1, "left"), visit(1, "left"), visit(1, "right"), visit(7, "straight")]
    }


def test_format_free_driving_counts_by_hand():
    first, second = format_free_driving(FREE, ["bc"], still_m=10.0).splitlines()
    # 4 passes at 2 approaches; 1 episode under 10 m; approach 1 seen 3 times, once not by its common exit
    assert first == (
        "bc      4 junction passes at 2 approaches; coverage 0.50 (each episode alone 0.10 to 0.40); "
        "episodes standing still: 1; ends: building -"
    )
    assert (
        second.strip()
        == "at approaches visited twice or more: 1 of 3 visits not by the approach's most common exit"
    )
