"""Checkers of exercises/07_car_and_town.ipynb: solution -> correct, stub -> not attempted,
typical mistakes -> a hint naming the mistake, code that raises -> a hint (never an exception)."""

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from ibc_tutorial.driving import get_renderer
from ibc_tutorial.driving.lights import RED, YELLOW, RedLightMonitor
from ibc_tutorial.driving.towns import get_town
from ibc_tutorial.exercises import ch07, solutions

CHECKS = [
    (ch07.check_yaw_rate, solutions.ch07_yaw_rate),
    (ch07.check_pid, solutions.ch07_pid_outputs),
    (ch07.check_ran_red_light, solutions.ch07_ran_red_light),
    (ch07.check_world_to_bev, solutions.ch07_world_to_bev),
    (ch07.check_expert_stops, solutions.ch07_expert_stops),
]


@pytest.mark.parametrize("check, solution", CHECKS)
def test_solution_stub_and_crash(check, solution, stub_and_crash):
    assert check(solution).status == "correct"
    stub_and_crash(check)


# ----------------------------------------------------------------------- the solutions agree with the library
def test_yaw_rate_solution_is_the_cars():
    import pymunk

    from ibc_tutorial.driving import Car, CarConfig

    space = pymunk.Space()
    car = Car(space, CarConfig(rolling_drag=0.0, air_drag=0.0))
    car.reset(0.0, 0.0, 0.0, 5.0)
    car.set_controls(0.4, 0.0)
    space.step(0.05)
    assert car.body.angular_velocity == pytest.approx(solutions.ch07_yaw_rate(5.0, 0.4))


def test_red_light_solution_is_the_monitors():
    town = get_town("town02")
    mon = RedLightMonitor(town.stop_lines)
    line = town.stop_lines[3]
    e, d = np.array(line.entry), np.array(line.direction)
    rng = np.random.default_rng(0)
    for _ in range(200):
        a = e + rng.uniform(-3, 3) * d + rng.uniform(-3, 3) * np.array([d[1], -d[0]])
        b = a + rng.uniform(-1, 3) * d
        states = np.full(town.n_lights, RED if rng.random() < 0.7 else YELLOW, dtype=np.uint8)
        mon.reset()
        assert solutions.ch07_ran_red_light(a, b, e, d, int(states[3])) == (3 in mon.update(a, b, states))


def test_world_to_bev_solution_is_the_renderers():
    town = get_town("town02")
    r = get_renderer("town02", 192)
    line = town.stop_lines[5]
    e, d = np.array(line.entry), np.array(line.direction)
    x, y = e - 12 * d + 0.7 * np.array([d[1], -d[0]])
    yaw = math.atan2(d[1], d[0]) + 0.2
    red = np.full((3, town.n_lights), 2, dtype=np.uint8)  # every light red
    bev = r.render(x, y, yaw, red)
    centre = e - 0.6 * d  # the middle of the stop line
    row, col = solutions.ch07_world_to_bev(*centre, x, y, yaw)
    assert bev[4, int(row), int(col)] == 1
    row, col = solutions.ch07_world_to_bev(x, y, x, y, yaw)
    assert (row, col) == (152, 96)


# --------------------------------------------------------------------------- typical mistakes
YAW_MISTAKES = {
    "sign": (lambda v, s: v * math.tan(0.6 * s) / 2.9, "sign"),
    "tan of max times steer": (lambda v, s: -v * math.tan(0.6) * s / 2.9, "tangent of that angle"),
    "no tangent": (lambda v, s: -v * 0.6 * s / 2.9, "tangent"),
    "degrees": (lambda v, s: -v * math.tan(math.radians(0.6 * s)) / 2.9, "radians"),
    "no speed": (lambda v, s: -math.tan(0.6 * s) / 2.9, "speed"),
    "returns a string": (lambda v, s: "fast", "number"),
}


@pytest.mark.parametrize("name", list(YAW_MISTAKES))
def test_yaw_rate_mistakes(name):
    fn, words = YAW_MISTAKES[name]
    fb = ch07.check_yaw_rate(fn)
    assert fb.status == "hint" and words in fb.message


def _pid(integral_dt=True, deriv_dt=True, first=False, length=None):
    def fn(errors, kp, ki, kd, dt):
        out, i, prev = [], 0.0, None
        for e in errors:
            i += e * (dt if integral_dt else 1)
            if prev is None:
                d = e / (dt if deriv_dt else 1) if first else 0.0
            else:
                d = (e - prev) / (dt if deriv_dt else 1)
            prev = e
            out.append(kp * e + ki * i + kd * d)
        return out[:length]

    return fn


PID_MISTAKES = {
    "integral without dt": (_pid(integral_dt=False), "integral"),
    "derivative without dt": (_pid(deriv_dt=False), "derivative"),
    "derivative at the first step": (_pid(first=True), "first step"),
    "too few outputs": (_pid(length=3), "one output per error"),
    "proportional only": (lambda errors, kp, ki, kd, dt: [kp * e for e in errors], "first step"),
}


@pytest.mark.parametrize("name", list(PID_MISTAKES))
def test_pid_mistakes(name):
    fn, words = PID_MISTAKES[name]
    fb = ch07.check_pid(fn)
    assert fb.status == "hint" and words in fb.message


def _rule(yellow=False, no_lateral=False, any_past=False, backwards=False, narrow=False, returns=None):
    def fn(before, after, entry, direction, state):
        if returns is not None:
            return returns
        right = np.array([direction[1], -direction[0]])
        s0, s1 = (before - entry) @ direction, (after - entry) @ direction
        lat = abs((after - entry) @ right)
        red = state == 2 or (yellow and state == 1)
        crossed = (s1 >= 0) if any_past else ((s0 < 0 <= s1) or (backwards and s1 < 0 <= s0))
        within = True if no_lateral else lat <= (1.0 if narrow else 2.0)
        return bool(red and crossed and within)

    return fn


RED_MISTAKES = {
    "yellow counts": (_rule(yellow=True), "only red counts"),
    "any lane": (_rule(no_lateral=True), "another lane"),
    "already past counts": (_rule(any_past=True), "already past"),
    "backwards counts": (_rule(backwards=True), "backwards"),
    "lane too narrow": (_rule(narrow=True), "1.5 m to the right"),
    "always false": (_rule(returns=False), "is an infraction"),
    "returns a number": (_rule(returns=1), "True or False"),
}


@pytest.mark.parametrize("name", list(RED_MISTAKES))
def test_red_light_mistakes(name):
    fn, words = RED_MISTAKES[name]
    fb = ch07.check_ran_red_light(fn)
    assert fb.status == "hint" and words in fb.message


def _bev(swap=False, mirror=False, flip=False, no_turn=False, scale=5.0, row0=152):
    def fn(x, y, cx, cy, yaw):
        if no_turn:
            ahead, right = x - cx, -(y - cy)
        else:
            ahead = (x - cx) * math.cos(yaw) + (y - cy) * math.sin(yaw)
            right = (x - cx) * math.sin(yaw) - (y - cy) * math.cos(yaw)
        row = row0 + scale * ahead if flip else row0 - scale * ahead
        col = 96 - scale * right if mirror else 96 + scale * right
        return (col, row) if swap else (row, col)

    return fn


BEV_MISTAKES = {
    "swapped": (_bev(swap=True), "swapped"),
    "mirrored": (_bev(mirror=True), "mirrored"),
    "ahead is down": (_bev(flip=True), "ahead must be up"),
    "no rotation": (_bev(no_turn=True), "turns with the car"),
    "metres not pixels": (_bev(scale=1.0), "5 pixels per metre"),
    "car in the middle": (_bev(row0=96), "40 px above the bottom"),
    "returns one number": (lambda *a: 3.0, "two numbers"),
}


@pytest.mark.parametrize("name", list(BEV_MISTAKES))
def test_world_to_bev_mistakes(name):
    fn, words = BEV_MISTAKES[name]
    fb = ch07.check_world_to_bev(fn)
    assert fb.status == "hint" and words in fb.message


# --------------------------------------------------------------------------- 5. will the expert stop?
def test_expert_stops_solution_is_the_experts_rule():
    from ibc_tutorial.driving.expert import stops_for_light

    for state in (0, 1, 2):
        for gap in np.linspace(0.2, 12.0, 25):
            for speed in (0.0, 2.0, 4.5, 6.0, 8.0):
                assert solutions.ch07_expert_stops(state, gap, speed) == stops_for_light(state, gap, speed)


STOP_MISTAKES = {
    "yellow as red": (lambda st, g, v: g <= 9.5 and st != 0, "yellow is not red"),
    "yellow as green": (lambda st, g, v: g <= 9.5 and st == 2, "yellow is not green"),
    "no distance limit": (lambda st, g, v: st == 2 or (st == 1 and v * v / (2 * g) <= 4.0), "distance"),
    "full brake at yellow": (
        lambda st, g, v: g <= 9.5 and (st == 2 or (st == 1 and v * v / (2 * g) <= 8.0)),
        "compare the deceleration",
    ),
    "stops at green": (
        lambda st, g, v: g <= 9.5 and (st != 1 or v * v / (2 * g) <= 4.0),
        "red stops, green goes",
    ),
    "returns a string": (lambda st, g, v: "stop", "True or False"),
}


@pytest.mark.parametrize("name", list(STOP_MISTAKES))
def test_expert_stops_mistakes(name):
    fn, words = STOP_MISTAKES[name]
    fb = ch07.check_expert_stops(fn)
    assert fb.status == "hint" and words in fb.message, fb.message


# --------------------------------------------------------------------------- holes closed (issue 26)
def _ignores_direction(before, after, entry, direction, state):
    """Every lane taken as northbound: y along the lane, x across it."""
    return bool(state == 2 and before[1] < entry[1] <= after[1] and abs(after[0] - entry[0]) <= 2.0)


def test_red_light_ignoring_direction_gets_a_hint():
    fb = ch07.check_ran_red_light(_ignores_direction)
    assert fb.status == "hint" and "`direction`" in fb.message, fb.message


@settings(max_examples=25, deadline=None)
@given(half_width=st.one_of(st.floats(0.2, 1.98), st.floats(2.02, 6.0)))
def test_red_light_with_another_lateral_tolerance_gets_a_hint(half_width):
    """Any tolerance across the lane other than 2 m (± 0.02): 3.9 m used to pass."""

    def fn(before, after, entry, direction, state):
        right = np.array([direction[1], -direction[0]])
        s0, s1 = (before - entry) @ direction, (after - entry) @ direction
        return bool(state == 2 and s0 < 0 <= s1 and abs((after - entry) @ right) <= half_width)

    fb = ch07.check_ran_red_light(fn)
    assert fb.status == "hint" and "m to the" in fb.message, fb.message


@settings(max_examples=20, deadline=None)
@given(
    angle=st.floats(0.0, 2 * math.pi),
    ex=st.floats(-100, 100),
    ey=st.floats(-100, 100),
    along=st.tuples(st.floats(-3, 3), st.floats(-3, 3)).filter(lambda p: min(map(abs, p)) > 1e-6),
    across=st.floats(-5, 5).filter(lambda a: abs(abs(a) - 2.0) > 1e-6),
    state=st.sampled_from([0, 1, 2]),
)
def test_red_light_solution_is_the_monitor_on_any_lane(angle, ex, ey, along, across, state):
    """The reference the checker's lanes come from agrees with ``RedLightMonitor`` for a lane of any
    heading: the checker's four headings are samples of a rule that holds for all."""
    from types import SimpleNamespace

    d = np.array([math.cos(angle), math.sin(angle)])
    right = np.array([d[1], -d[0]])
    entry = np.array([ex, ey])
    before = entry + along[0] * d + across * right
    after = entry + along[1] * d + across * right
    monitor = RedLightMonitor([SimpleNamespace(entry=tuple(entry), direction=tuple(d))])
    expected = state == 2 and 0 in monitor.crossed(before, after)
    assert solutions.ch07_ran_red_light(before, after, entry, d, state) == expected


@settings(max_examples=20, deadline=None)
@given(horizon=st.one_of(st.floats(5.0, 9.25), st.floats(9.75, 20.0)))
def test_expert_stops_with_another_horizon_gets_a_hint(horizon):
    """Any horizon other than 9.5 m (± 0.25): 10 m used to pass."""

    def fn(state, gap, speed):
        if gap > horizon or state == 0:
            return False
        return state == 2 or (gap > 0 and speed * speed / (2 * gap) <= 4.0)

    fb = ch07.check_expert_stops(fn)
    assert fb.status == "hint" and "distance" in fb.message, fb.message


def test_exercise_5_text_matches_the_chapter():
    """The BEV's default encoding draws yellow at its own level; only the one-bit flag draws it like red."""
    import json
    from pathlib import Path

    from ibc_tutorial.driving.bev import LIGHT_LEVELS

    nb = json.loads(Path(__file__).parents[1].joinpath("exercises/07_car_and_town.ipynb").read_text())
    text = next("".join(c["source"]) for c in nb["cells"] if "".join(c["source"]).startswith("## Exercise 5"))
    assert "flag, which draws a yellow line exactly like a red one" in text
    assert "yellow 0.6" in text and abs(float(LIGHT_LEVELS[1]) - 0.6) < 1e-9


def _red_light_rule(s0_ok, s1_ok, lateral_ok, at="after"):
    """The red-light rule with its three comparisons and the point the lane test reads made pluggable."""

    def fn(before, after, entry, direction, state):
        right = np.array([direction[1], -direction[0]])
        s0, s1 = (before - entry) @ direction, (after - entry) @ direction
        point = {"after": after, "before": before, "middle": (before + after) / 2}[at]
        return bool(state == 2 and s0_ok(s0) and s1_ok(s1) and lateral_ok(abs((point - entry) @ right)))

    return fn


@pytest.mark.parametrize(
    "wrong, words",
    [
        (_red_light_rule(lambda s: s < 0, lambda s: s > 0, lambda x: x <= 2.0), "ends the step exactly on"),
        (_red_light_rule(lambda s: s <= 0, lambda s: s >= 0, lambda x: x <= 2.0), "starts the step exactly"),
        (_red_light_rule(lambda s: s < 0, lambda s: s >= 0, lambda x: x < 2.0), "edges included"),
        (_red_light_rule(lambda s: s < 0, lambda s: s >= 0, lambda x: x <= 2.0, at="before"), "*after*"),
        (_red_light_rule(lambda s: s < 0, lambda s: s >= 0, lambda x: x <= 2.0, at="middle"), "*after*"),
    ],
)
def test_red_light_edges_of_the_rule_get_a_hint(wrong, words):
    """Strict where the rule is not (and the converse), and the lane tested at another point: each passed
    before the edges were asked about."""
    fb = ch07.check_ran_red_light(wrong)
    assert fb.status == "hint" and words in fb.message, fb.message


def test_red_light_edges_are_the_monitors():
    """The edge cases the checker asks about are decided as ``RedLightMonitor`` decides them."""
    from types import SimpleNamespace

    for entry, d, _ in ch07.RED_LIGHT_LANES:
        right = np.array([d[1], -d[0]])
        monitor = RedLightMonitor([SimpleNamespace(entry=tuple(entry), direction=tuple(d))])
        cases = [
            (entry - 0.3 * d, entry.copy()),
            (entry.copy(), entry + 0.4 * d),
            (entry - 0.3 * d + 2.5 * right, entry + 0.4 * d + 1.5 * right),
            (entry - 0.3 * d + 1.5 * right, entry + 0.4 * d + 2.5 * right),
            (entry - 0.3 * d + 2.0 * right, entry + 0.4 * d + 2.0 * right),
        ]
        for before, after in cases:
            expected = 0 in monitor.crossed(before, after)
            assert solutions.ch07_ran_red_light(before, after, entry, d, RED) == expected


@pytest.mark.parametrize(
    "wrong, words",
    [
        (  # the horizon exclusive: "less than 9.5 m"
            lambda s, g, v: False if (g >= 9.5 or s == 0) else (s == 2 or (g > 0 and v * v / (2 * g) <= 4.0)),
            "9.5 m included",
        ),
        (  # yellow stops only strictly below the expert's deceleration
            lambda s, g, v: False if (g > 9.5 or s == 0) else (s == 2 or (g > 0 and v * v / (2 * g) < 4.0)),
            "<=, not <",
        ),
    ],
)
def test_expert_stops_strict_where_the_rule_is_not_gets_a_hint(wrong, words):
    fb = ch07.check_expert_stops(wrong)
    assert fb.status == "hint" and words in fb.message, fb.message


def test_exercise_3_text_states_the_edges_the_checker_asks_about():
    """The checker asks about a rear ending or starting exactly on the line, a crossing exactly 2 m from
    the centre line and the lane tested after the step: the exercise says how each is decided."""
    import json
    from pathlib import Path

    nb = json.loads(Path(__file__).parents[1].joinpath("exercises/07_car_and_town.ipynb").read_text())
    text = next("".join(c["source"]) for c in nb["cells"] if "".join(c["source"]).startswith("## Exercise 3"))
    for words in (
        "strictly before it before the step",
        "on it or past it after the step",
        "after the step must",
    ):
        assert words in text, words
    assert "at most 2 m, edge included" in text


def test_chapter_07_states_the_experts_horizon_as_the_library_applies_it():
    """Exercise 5 sends the reader to the chapter's item 4: the horizon is inclusive, as in
    ``stops_for_light``."""
    import json
    from pathlib import Path

    from ibc_tutorial.driving.expert import ExpertConfig, stops_for_light

    nb = json.loads(Path(__file__).parents[1].joinpath("book/07_car_and_town.ipynb").read_text())
    text = "".join("".join(c["source"]) for c in nb["cells"] if c["cell_type"] == "markdown")
    horizon = ExpertConfig().stop_distance_m
    assert f"A red or yellow stop line of its lane {horizon} m ahead or closer makes it stop" in text
    assert stops_for_light(2, horizon, 6.0) and not stops_for_light(2, horizon + 1e-9, 6.0)


@settings(max_examples=15, deadline=None)
@given(limit=st.floats(0.9, 3.0))
@example(limit=1.0)
def test_pid_that_clips_its_output_gets_a_hint(limit):
    """The exercise asks for u_t unclipped; the first case's outputs stay within ±0.9, so only a case with
    large errors tells a clip apart."""

    def fn(errors, kp, ki, kd, dt):
        return [max(-limit, min(limit, u)) for u in solutions.ch07_pid_outputs(errors, kp, ki, kd, dt)]

    fb = ch07.check_pid(fn)
    assert fb.status == "hint", fb.message
    if limit == 1.0:
        assert "you clip them" in fb.message, fb.message


def test_pid_whose_sum_lags_one_step_gets_a_hint():
    def fn(errors, kp, ki, kd, dt):
        out, integral, prev = [], 0.0, None
        for e in errors:
            d = 0.0 if prev is None else (e - prev) / dt
            out.append(kp * e + ki * integral + kd * d)
            integral += e * dt
            prev = e
        return out

    fb = ch07.check_pid(fn)
    assert fb.status == "hint" and "k <= t" in fb.message, fb.message
