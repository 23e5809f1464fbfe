"""Checkers of exercises/11_route_commands.ipynb: solution -> correct, stub -> not attempted,
typical mistakes -> a hint naming the mistake, code that raises -> a hint (never an exception).

The reference solutions are ``ibc_tutorial.exercises.solutions.ch11_*``."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ibc_tutorial.driving.route_following import chance_crossings
from ibc_tutorial.exercises import ch11
from ibc_tutorial.exercises.solutions import ch11_chance_crossings, ch11_command, ch11_junction_success

CHECKS = [
    (ch11.check_command, ch11_command),
    (ch11.check_junction_success, ch11_junction_success),
    (ch11.check_chance_crossings, ch11_chance_crossings),
]


@pytest.mark.parametrize("check, solution", CHECKS)
def test_solution_stub_and_crash(check, solution, stub_and_crash):
    assert check(solution).status == "correct"
    stub_and_crash(check)
    assert check(lambda *a: "a lot").status == "hint"


def _command(strict=False, limit=20.0, connector=True, corner=True):
    def fn(kind, d, next_turn, connector_turn):
        if kind == "junction connector":
            return connector_turn if connector else next_turn
        if kind == "corner connector":
            return "follow" if corner else connector_turn
        if kind == "road":
            return "follow"
        return "follow" if (d >= limit if strict else d > limit) else next_turn

    return fn


@pytest.mark.parametrize(
    "mistake, words",
    [
        (_command(strict=True), "exactly 20 m"),
        (_command(limit=10.0), "20 m"),
        (_command(limit=25.0), "20 m"),  # another distance
        (_command(connector=False), "inside a junction"),
        (_command(corner=False), "corner"),
        (lambda kind, d, t, c: "follow", "route's turn"),
        (lambda kind, d, t, c: t, "no turn to give"),
        (lambda kind, d, t, c: "left", "no turn to give"),  # the turn hard-coded
        (lambda kind, d, t, c: "north", "one of"),
    ],
)
def test_command_mistakes(mistake, words):
    fb = ch11.check_command(mistake)
    assert fb.status == "hint" and words in fb.message, fb.message


def _success(per_route=False, skip_unfinished=False, zero=False):
    def fn(rows):
        return ch11._rates(rows, per_route=per_route, skip_unfinished=skip_unfinished, zero_if_none=zero)

    return fn


@pytest.mark.parametrize(
    "mistake, words",
    [
        (_success(zero=True), "no rate"),
        (_success(per_route=True), "pool the crossings"),
        (_success(skip_unfinished=True), "keep it"),
        (lambda rows: {"left": 1.0, "right": 1.0, "straight": 1.0, "all": 1.0}, "your rates differ"),
        (lambda rows: [0.5, 0.5], "keys"),
        (lambda rows: {k: v for k, v in ch11_junction_success(rows).items() if k != "all"}, "keys"),
    ],
)
def test_junction_success_mistakes(mistake, words):
    fb = ch11.check_junction_success(mistake)
    assert fb.status == "hint" and words in fb.message, fb.message


@pytest.mark.parametrize(
    "mistake, words",
    [
        (lambda exits: sum(1.0 / e for e in exits), "multiply"),
        (lambda exits: math.prod(1.0 / e for e in exits), "on average"),
        (lambda exits: ch11_chance_crossings(exits) + 1.0, "first term"),
        (lambda exits: 1.0, "your expectation"),
        (lambda exits: "one", "number"),
    ],
)
def test_chance_crossings_mistakes(mistake, words):
    fb = ch11.check_chance_crossings(mistake)
    assert fb.status == "hint" and words in fb.message, fb.message


@given(st.lists(st.integers(1, 4), min_size=1, max_size=12))
def test_chance_crossings_solution_matches_the_library_and_its_bounds(exits):
    v = chance_crossings(exits)
    assert math.isclose(ch11_chance_crossings(exits), v, rel_tol=1e-12)
    assert 0 < v <= len(exits)  # at most every crossing passed
    assert math.isclose(v, len(exits)) == all(e == 1 for e in exits)


def test_chance_crossings_refuses_bad_exits():
    for bad in ([0, 2], [2.5]):
        with pytest.raises(ValueError, match="exits must be whole numbers"):
            chance_crossings(bad)


@given(
    st.lists(
        st.lists(
            st.tuples(
                st.sampled_from(["left", "straight", "right"]),
                st.sampled_from(["left", "straight", "right", ""]),
            ),
            max_size=6,
        ),
        min_size=1,
        max_size=5,
    )
)
def test_junction_success_solution_matches_the_library(routes):
    from ibc_tutorial.driving.route_following import junction_success

    rows = [{"crossings": [{"approach": 0, "command": c, "taken": t} for c, t in r]} for r in routes]
    lib = junction_success(rows)
    mine = ch11_junction_success(rows)
    for k in ("left", "straight", "right", "all"):
        assert (mine[k] is None) == (lib[k]["rate"] is None)
        if mine[k] is not None:
            assert math.isclose(mine[k], lib[k]["rate"], abs_tol=1e-4)
