"""Checkers of exercises/07_car_and_town.ipynb: solution -> correct, stub -> not attempted,
typical mistakes -> a hint naming the mistake, code that raises -> a hint (never an exception)."""

import math

import numpy as np
import pytest

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


# --------------------------------------------------------------------------- the solutions agree with the library
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
    "lane too narrow": (_rule(narrow=True), "1.5 m to the side"),
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
