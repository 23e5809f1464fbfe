"""Checkers for ``exercises/07_car_and_town.ipynb``.

- ``check_yaw_rate(fn)``: the kinematic bicycle's yaw rate, ``fn(speed, steer) -> omega``.
- ``check_pid(fn)``: a discrete PID, ``fn(errors, kp, ki, kd, dt) -> list of outputs``.
- ``check_ran_red_light(fn)``: the red-light rule,
  ``fn(rear_before, rear_after, entry, direction, state) -> bool``.
- ``check_world_to_bev(fn)``: where a world point appears in the 192 x 192 BEV,
  ``fn(x, y, car_x, car_y, car_yaw) -> (row, col)``.
- ``check_expert_stops(fn)``: the chapter's finding about the lights, as a prediction: does the
  expert stop for its light, ``fn(state, gap_m, speed) -> bool``, checked against the library's
  expert (``driving.expert.stops_for_light``) on situations where the binary BEV flag and the
  expert's choice part ways.

Each compares the reader's function with the library's (``ibc_tutorial.driving``) on chosen
cases and, when they differ, tests the usual mistakes one by one to name the one that was
made, without giving the answer away.
"""

from __future__ import annotations

import math

import numpy as np

from ibc_tutorial.exercises.core import Feedback, correct, hint, number_answer, run_check

L = 2.9  # wheelbase (m)
DELTA_MAX = 0.6  # front-wheel angle at steer = 1 (rad)


# --------------------------------------------------------------------------- 1. yaw rate
def _yaw_ref(v, s):
    return -v * math.tan(DELTA_MAX * s) / L


def check_yaw_rate(fn) -> Feedback:
    """Check ``fn(speed, steer)``: omega = -v tan(0.6 steer) / 2.9 (positive steer turns right)."""

    def check() -> Feedback:
        cases = [(4.0, 0.5), (6.0, -1.0), (2.5, 0.2), (10.0, 0.9), (0.0, 0.7), (3.0, 0.0)]
        for v, s in cases:
            out = number_answer(fn(v, s), "yaw_rate")
            if isinstance(out, Feedback):
                return out
            ref = _yaw_ref(v, s)
            if math.isclose(out, ref, rel_tol=1e-6, abs_tol=1e-9):
                continue
            if math.isclose(out, -ref, rel_tol=1e-6, abs_tol=1e-9):
                return hint(
                    "the sign: positive steering turns the car right, i.e. clockwise, and yaw angles count "
                    "counter-clockwise."
                )
            if math.isclose(abs(out), abs(v * math.tan(DELTA_MAX) * s / L), rel_tol=1e-6):
                return hint(
                    "the steering angle: steer = 1 means the front wheels at delta_max; the angle is "
                    "delta_max x steer, and the bicycle needs the tangent of that angle."
                )
            if math.isclose(abs(out), abs(v * DELTA_MAX * s / L), rel_tol=1e-6):
                return hint(
                    "the bicycle's yaw rate uses the tangent of the wheel angle, not the angle itself "
                    "(they differ at large angles)."
                )
            if math.isclose(abs(out), abs(v * math.tan(math.radians(DELTA_MAX * s)) / L), rel_tol=1e-6):
                return hint("angles here are in radians: math.tan expects radians.")
            if math.isclose(abs(out), abs(math.tan(DELTA_MAX * s) / L), rel_tol=1e-6):
                return hint("the yaw rate grows with speed: a car at rest does not turn.")
            return hint(
                f"for speed {v} m/s and steer {s} your yaw rate is {out:.4f} rad/s, which is not the "
                "kinematic "
                "bicycle's: check the formula term by term (speed, wheel angle, wheelbase, sign)."
            )
        return correct(
            "That is the kinematic bicycle: the circle's radius is L / tan(delta), whatever the speed."
        )

    return run_check(check, "`yaw_rate`")


# --------------------------------------------------------------------------- 2. PID
def _pid_ref(errors, kp, ki, kd, dt, integral_dt=True, deriv_dt=True, first_deriv=False, late_sum=False):
    out, integral, prev = [], 0.0, None
    for e in errors:
        before = integral  # the sum up to the step before (late_sum: the current error not yet in it)
        integral += e * (dt if integral_dt else 1.0)
        if prev is None:
            d = (e / (dt if deriv_dt else 1.0)) if first_deriv else 0.0
        else:
            d = (e - prev) / (dt if deriv_dt else 1.0)
        prev = e
        out.append(kp * e + ki * (before if late_sum else integral) + kd * d)
    return out


def check_pid(fn) -> Feedback:
    """Check ``fn(errors, kp, ki, kd, dt)`` against ``ibc_tutorial.driving.PID``."""
    from ibc_tutorial.driving.expert import PID

    def check() -> Feedback:
        errors = [1.0, 0.5, 0.5, -0.2, 0.0, 0.3]
        gains = (0.8, 0.3, 0.05, 0.1)
        out = fn(list(errors), *gains)
        try:
            out = [float(u) for u in out]
        except (TypeError, ValueError):
            return hint("pid_outputs must return a list of numbers, one per error.")
        if len(out) != len(errors):
            return hint(
                f"pid_outputs must return one output per error: got {len(out)} for {len(errors)} errors."
            )
        pid = PID(*gains)
        ref = [pid.step(e) for e in errors]
        if np.allclose(out, ref, rtol=1e-6, atol=1e-9):
            # large errors: outputs beyond ±1, which the exercise asks for unclipped
            big = [3.0, -2.5, 0.5, 4.0]
            pid = PID(*gains)
            ref_big = [pid.step(e) for e in big]
            out_big = [float(u) for u in fn(list(big), *gains)]
            if np.allclose(out_big, ref_big, rtol=1e-6, atol=1e-9):
                return correct("Your PID matches the expert's controller step by step.")
            if np.allclose(out_big, np.clip(ref_big, -1.0, 1.0), rtol=1e-6, atol=1e-9):
                return hint(
                    "right while the outputs stay within ±1, but you clip them: the exercise asks for u_t "
                    "itself (the expert clips the steering afterwards, outside the controller)."
                )
            return hint(
                f"right for errors {errors}, wrong for errors {big}: check that nothing in your code depends "
                "on the size of the errors."
            )
        mistakes = [
            (
                dict(integral_dt=False),
                "the integral term: it sums error x dt, an area under the error curve.",
            ),
            (
                dict(deriv_dt=False),
                "the derivative term: it is the change of the error divided by dt, a rate.",
            ),
            (
                dict(late_sum=True),
                "the integral term: the sum runs over k <= t, so the current error e_t is in it already at "
                "step t (add it before computing u_t).",
            ),
            (
                dict(first_deriv=True),
                "the first step: there is no previous error yet, so the derivative term starts at 0.",
            ),
        ]
        for kwargs, message in mistakes:
            if np.allclose(out, _pid_ref(errors, *gains, **kwargs), rtol=1e-6, atol=1e-9):
                return hint(message)
        if np.allclose(out[0], ref[0]):
            return hint(
                "your first output is right but later ones are not: check how the integral accumulates and "
                "how the derivative uses the previous error."
            )
        return hint(
            "your outputs differ from u = kp e + ki sum(e dt) + kd (e - e_prev)/dt from the first step on: "
            "check each term and the gain it goes with."
        )

    return run_check(check, "`pid_outputs`")


# --------------------------------------------------------------------------- 3. red-light rule
RED_LIGHT_LANES = [  # (entry, direction, name): a lane of each heading, the last one diagonal
    (np.array([50.0, 10.0]), np.array([0.0, 1.0]), "north"),
    (np.array([-20.0, 35.0]), np.array([1.0, 0.0]), "east"),
    (np.array([12.0, -8.0]), np.array([0.0, -1.0]), "south"),
    (np.array([7.5, 3.0]), np.array([-0.6, -0.8]), "south-west"),
]


def _red_light_lane(ask, entry, d, name) -> Feedback | None:
    """The rule's cases on one lane, or the hint for the first one answered wrongly. ``ask(before,
    after, state)`` asks the reader's function about this lane."""
    from ibc_tutorial.driving.lights import GREEN, RED, YELLOW

    right = np.array([d[1], -d[0]])
    cross = (entry - 0.3 * d, entry + 0.4 * d)
    if not ask(*cross, RED):
        if name != "north":
            return hint(
                f"right for a lane heading north, wrong for one heading {name}: measure the rear's position "
                "along `direction` (and across it, for the lane's width), not along the y axis."
            )
        return hint(
            "the rear moving from just before the line to just past it while red is an infraction: "
            "compare the position along the lane before and after the step."
        )
    if ask(*cross, YELLOW):
        return hint("only red counts: crossing at yellow is legal (the light has not turned red yet).")
    if ask(*cross, GREEN):
        return hint("crossing at green is not an infraction.")
    wrong_way = {
        "already past": (entry + 0.4 * d, entry + 1.4 * d),
        "still before": (entry - 2.0 * d, entry - 1.0 * d),
        "backwards": (entry + 0.4 * d, entry - 0.3 * d),
    }
    answers = {k: ask(*v, RED) for k, v in wrong_way.items()}
    if any(answers.values()) and name != "north":
        return hint(
            f"right for a lane heading north, wrong for one heading {name}: measure the rear's position "
            "along "
            "`direction`, not along the y axis."
        )
    if answers["already past"]:
        return hint(
            "the rear was already past the line before the step: that crossing was counted (or not) "
            "earlier; count only the step that crosses it."
        )
    if answers["still before"]:
        return hint("the rear is still before the line after the step: no crossing yet.")
    if answers["backwards"]:
        return hint(
            "moving backwards over the line is not running the light: only a forward crossing counts."
        )
    for side in (4.0, -4.0, 2.01, -2.01):
        if ask(cross[0] + side * right, cross[1] + side * right, RED):
            where = "in another lane" if abs(side) > 3 else "just outside the 4 m lane"
            return hint(
                f"a crossing {abs(side)} m to the {'right' if side > 0 else 'left'} of the lane's centre "
                "line is "
                f"{where}: only a crossing within the lane (half a lane width, 2 m, from its centre line) "
                "counts."
                + (
                    ""
                    if name == "north"
                    else f" (This lane heads {name}: across it is perpendicular to `direction`.)"
                )
            )
    for side in (1.5, -1.99, 1.99):
        if not ask(cross[0] + side * right, cross[1] + side * right, RED):
            return hint(
                f"a crossing {abs(side)} m to the {'right' if side > 0 else 'left'} of the centre line is "
                "still "
                "within the 4 m lane and counts."
                + (
                    ""
                    if name == "north"
                    else f" (This lane heads {name}: across the lane is perpendicular to `direction`.)"
                )
            )
    return _red_light_edges(ask, entry, d, right, name)


def _red_light_edges(ask, entry, d, right, name) -> Feedback | None:
    """The rule's edges on one lane: a rear that ends exactly on the line has crossed it, one that starts
    on it had crossed it the step before; a rear exactly 2 m from the centre line is still in the lane
    (axis-aligned lanes only, where that offset is exact in floating point); the lane test is on the
    rear's position after the step."""
    from ibc_tutorial.driving.lights import RED

    if not ask(entry - 0.3 * d, entry.copy(), RED):
        return hint(
            "a rear that ends the step exactly on the stop line has crossed it (after the step it is on the "
            "line or past it): that step counts, with >= where the position after the step is compared."
        )
    if ask(entry.copy(), entry + 0.4 * d, RED):
        return hint(
            "a rear that starts the step exactly on the stop line reached it in the step before, which "
            "counted it: before the step the rear must be strictly before the line."
        )
    if name in ("north", "east", "south"):
        for side in (2.0, -2.0):
            if not ask(entry - 0.3 * d + side * right, entry + 0.4 * d + side * right, RED):
                return hint(
                    "a crossing exactly 2 m from the lane's centre line is on the lane's edge and counts: "
                    "the lane reaches 2 m to each side, edges included (<=, not <)."
                )
    into = (entry - 0.3 * d + 2.5 * right, entry + 0.4 * d + 1.5 * right)  # ends inside the lane
    out_of = (entry - 0.3 * d + 1.5 * right, entry + 0.4 * d + 2.5 * right)  # ends outside it
    if not ask(*into, RED) or ask(*out_of, RED):
        return hint(
            "the lane test is on where the rear is *after* the step: a rear that ends the step within 2 m of "
            "the centre line counts, wherever it came from; one that ends it further out does not."
        )
    return None


def check_ran_red_light(fn) -> Feedback:
    """Check ``fn(rear_before, rear_after, entry, direction, state)`` against the red-light rule, on
    lanes heading north, east, south and south-west."""

    def check() -> Feedback:
        for entry, d, name in RED_LIGHT_LANES:

            def ask(before, after, state, entry=entry, d=d):
                out = fn(np.array(before, float), np.array(after, float), entry.copy(), d.copy(), state)
                if not isinstance(out, (bool, np.bool_)):
                    raise TypeError(f"ran_red_light must return True or False, got {type(out).__name__}")
                return bool(out)

            fb = _red_light_lane(ask, entry, d, name)
            if fb is not None:
                return fb
        return correct("That is the rule the environment applies (``lights.RedLightMonitor``).")

    return run_check(check, "`ran_red_light`")


# --------------------------------------------------------------------------- 4. BEV geometry
def _bev_ref(x, y, cx, cy, yaw):
    f = (x - cx) * math.cos(yaw) + (y - cy) * math.sin(yaw)  # metres ahead
    r = (x - cx) * math.sin(yaw) - (y - cy) * math.cos(yaw)  # metres to the right
    return 152 - 5 * f, 96 + 5 * r


def check_world_to_bev(fn) -> Feedback:
    """Check ``fn(x, y, car_x, car_y, car_yaw) -> (row, col)`` against the 192 view's geometry."""

    def check() -> Feedback:
        cases = [
            (10.0, 5.0, 10.0, 5.0, 0.3),
            (20.0, 0.0, 10.0, 0.0, 0.0),
            (10.0, -3.0, 10.0, 0.0, 0.0),
            (3.0, 12.0, 3.0, 2.0, math.pi / 2),
            (14.0, 9.0, 10.0, 5.0, 0.7),
            (-4.0, 2.0, 1.0, -1.0, -2.2),
        ]
        for x, y, cx, cy, yaw in cases:
            out = fn(x, y, cx, cy, yaw)
            try:
                row, col = (float(v) for v in out)
            except (TypeError, ValueError):
                return hint("world_to_bev must return two numbers: (row, col).")
            ref = _bev_ref(x, y, cx, cy, yaw)
            if np.allclose((row, col), ref, atol=1e-6):
                continue
            if np.allclose((col, row), ref, atol=1e-6):
                return hint("rows and columns are swapped: return (row, col), row counted down from the top.")
            mirrored = (ref[0], 192 - ref[1])
            if np.allclose((row, col), mirrored, atol=1e-6):
                return hint(
                    "left and right are mirrored: a point to the car's right must appear right of the car "
                    "in the image (a larger column)."
                )
            if np.allclose((row, col), (304 - ref[0], ref[1]), atol=1e-6):
                return hint(
                    "ahead must be up: image rows grow downwards, so a point ahead of the car has a "
                    "smaller row."
                )
            noturn = (152 - 5 * (x - cx), 96 - 5 * (y - cy))
            if np.allclose((row, col), noturn, atol=1e-6) and yaw != 0:
                return hint(
                    "the view turns with the car: project the offset onto the car's heading (cos, sin) and "
                    "onto its right (sin, -cos)."
                )
            if np.allclose((row, col), ((ref[0] - 152) / 5 + 152, (ref[1] - 96) / 5 + 96), atol=1e-6):
                return hint("the scale: the view has 5 pixels per metre.")
            if np.isclose(col, ref[1], atol=1e-6):
                return hint(
                    "the column is right but not the row: the car sits 40 px above the bottom edge of the "
                    "192 px view."
                )
            return hint(
                f"the point ({x}, {y}) seen from a car at ({cx}, {cy}) heading {yaw:.2f} rad lands at "
                f"({row:.1f}, {col:.1f}) in your view: check the offset's projection, the scale and the "
                "car's pixel."
            )
        return correct("That is the BEV's geometry: the renderer applies it to all 36,864 pixels at once.")

    return run_check(check, "`world_to_bev`")


# --------------------------------------------------------------------------- 5. will the expert stop?
STOP_CASES = [  # (state, gap_m, speed): 0 green, 1 yellow, 2 red
    (2, 5.0, 6.0),
    (0, 5.0, 6.0),
    (1, 8.0, 6.0),
    (1, 3.0, 6.0),
    (2, 12.0, 6.0),
    (1, 6.0, 4.5),
    (1, 4.0, 6.0),
    (2, 0.5, 0.0),
    (1, 9.0, 3.0),
    (1, 12.0, 6.0),
    (0, 1.0, 0.5),
    (1, 4.5, 6.0),
    (1, 1.5, 6.0),
    (2, 9.7, 6.0),  # just beyond the horizon (9.5 m): a horizon of 10 m stops here
    (2, 9.3, 6.0),  # just within it: a horizon of 9 m drives on here
    (2, 9.5, 6.0),  # exactly at it: within (<=), so red stops here
    (1, 9.4, 3.0),  # yellow, within it, slow enough to stop
    (1, 9.8, 2.0),  # yellow, beyond it
]


def check_expert_stops(fn) -> Feedback:
    """Check ``fn(state, gap_m, speed) -> bool``: does the expert stop for its lane's light?"""
    from ibc_tutorial.driving.expert import ExpertConfig, stops_for_light

    config = ExpertConfig()

    def check() -> Feedback:
        answers = []
        for state, gap, speed in STOP_CASES:
            out = fn(state, gap, speed)
            if not isinstance(out, (bool, np.bool_)):
                return hint(f"expert_stops must return True or False, got {type(out).__name__}.")
            answers.append(bool(out))
        truth = [stops_for_light(*c, config) for c in STOP_CASES]
        wrong = [c for c, a, t in zip(STOP_CASES, answers, truth, strict=False) if a != t]
        if not wrong:
            return correct(
                "That is the expert's rule. A one-bit 'must stop' flag draws a yellow line like a red one, "
                "yet "
                "at (yellow, 3 m, 6 m/s) the expert drives on: there the flag contradicts the expert's "
                "label. "
                "The intensity encoding draws yellow at its own level, 0.6, and lets distance and speed "
                "decide."
            )
        if any(s == 2 and g > config.stop_distance_m for s, g, _ in wrong):
            return hint(
                f"distance: the expert considers its light only within {config.stop_distance_m} m of the "
                "line; "
                "a red light further away does not stop it yet."
            )
        if any(s == 2 and g <= config.stop_distance_m for s, g, _ in wrong):
            return hint(
                f"distance: the expert considers its light within {config.stop_distance_m} m of the line "
                f"({config.stop_distance_m} m included), and a red light within that distance always stops "
                "it."
            )
        yellow = [c for c in wrong if c[0] == 1]
        if yellow and all(c[0] == 1 and c[2] ** 2 / (2 * c[1]) == config.yellow_brake for c in wrong):
            return hint(
                f"at yellow, a stop that needs exactly the expert's {config.yellow_brake} m/s^2 is one it "
                "makes: it stops when v^2 / (2 gap) is at or below that deceleration (<=, not <)."
            )
        near_yellow = [k for k, c in enumerate(STOP_CASES) if c[0] == 1 and c[1] <= config.stop_distance_m]
        if yellow and all(answers[k] for k in near_yellow) and all(c[0] == 1 for c in wrong):
            return hint(
                "yellow is not red: close to the line and fast, stopping would need more braking than the "
                f"expert allows at yellow ({config.yellow_brake} m/s^2, the deceleration v^2 / (2 gap)), "
                "so it drives on."
            )
        if yellow and not any(answers[STOP_CASES.index(c)] for c in yellow):
            return hint(
                "yellow is not green either: when a firm brake still stops the car before the line, the "
                "expert stops."
            )
        if any(c[0] == 1 for c in wrong):
            return hint(
                "at yellow, compare the deceleration needed to stop at the line, v^2 / (2 gap), with the "
                f"expert's {config.yellow_brake} m/s^2: at or below it, it stops."
            )
        state, gap, speed = wrong[0]
        yours = answers[STOP_CASES.index(wrong[0])]
        return hint(
            f"for light state {state} at {gap} m and {speed} m/s your answer is {yours}: "
            "red stops, green goes; chapter 07's section *The expert* gives the rule."
        )

    return run_check(check, "`expert_stops`")
