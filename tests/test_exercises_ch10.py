"""Checkers of exercises/10_road_following.ipynb: solution -> correct, stub -> not attempted,
typical mistakes -> a hint naming the mistake, code that raises -> a hint (never an exception).

The reference solutions are ``ibc_tutorial.exercises.solutions.ch10_*``."""

import math

import numpy as np
import pytest

from ibc_tutorial.exercises import ch10
from ibc_tutorial.exercises.solutions import ch10_command_whiteness, ch10_crashes_per_km, ch10_swerve_rate

CHECKS = [
    (ch10.check_swerve_rate, ch10_swerve_rate),
    (ch10.check_command_whiteness, ch10_command_whiteness),
    (ch10.check_crashes_per_km, ch10_crashes_per_km),
]


@pytest.mark.parametrize("check, solution", CHECKS)
def test_solution_stub_and_crash(check, solution, stub_and_crash):
    assert check(solution).status == "correct"
    stub_and_crash(check)
    assert check(lambda *a: "a lot").status == "hint"


def _score(peak, slight, clear, half=0.5):
    return np.where(peak >= clear, 1.0, np.where(peak >= slight, half, 0.0))


@pytest.mark.parametrize(
    "mistake, words",
    [
        (lambda x, s, c: float(_score(np.asarray(x).max(1), s, c).mean()), "where the car was"),
        (lambda x, s, c: float(_score(np.abs(x - x[:, :1]).max(1), s, c).mean()), "towards the side road"),
        (lambda x, s, c: float(_score((x - x[:, :1]).mean(1), s, c).mean()), "farthest"),
        (lambda x, s, c: float(_score((x - x[:, :1]).max(1), s, c, half=1.0).mean()), "half"),
        (lambda x, s, c: 0.123, "score each pass"),
    ],
)
def test_swerve_rate_mistakes(mistake, words):
    fb = ch10.check_swerve_rate(mistake)
    assert fb.status == "hint" and words in fb.message, fb.message


@pytest.mark.parametrize(
    "mistake, words",
    [
        (lambda segs, dt: float(np.sqrt(np.mean((np.diff(np.concatenate(segs)) / dt) ** 2))), "restart"),
        (
            lambda segs, dt: float(
                np.mean([np.sqrt(np.mean((np.diff(s) / dt) ** 2)) for s in segs if len(s) > 1])
            ),
            "pool",
        ),
        (lambda segs, dt: ch10_command_whiteness(segs, dt) * dt, "δt"),
        (lambda segs, dt: ch10_command_whiteness(segs, dt) ** 2, "square root"),
        (lambda segs, dt: ch10_command_whiteness(segs, dt) * 250.0, "1/s"),
        (lambda segs, dt: 0.5, "square each change"),
    ],
)
def test_whiteness_mistakes(mistake, words):
    fb = ch10.check_command_whiteness(mistake)
    assert fb.status == "hint" and words in fb.message, fb.message


@pytest.mark.parametrize(
    "mistake, words",
    [
        (lambda runs: float(np.mean([r["crashes"] / (r["distance_m"] / 1000) for r in runs])), "pool"),
        (lambda runs: sum(r["crashes"] for r in runs) / sum(r["distance_m"] for r in runs), "per kilometre"),
        (lambda runs: float(sum(r["crashes"] for r in runs)), "divide by the distance"),
        (lambda runs: 7.0, "total crashes"),
    ],
)
def test_crashes_mistakes(mistake, words):
    fb = ch10.check_crashes_per_km(mistake)
    assert fb.status == "hint" and words in fb.message, fb.message


def test_the_checks_agree_with_the_library():
    from ibc_tutorial.metrics import crashes_per_km, swerve_rate, whiteness

    x = np.array([[0.2, 0.9, 0.4], [0.0, 1.5, 0.0]])
    assert ch10_swerve_rate(x, 0.5, 1.0) == swerve_rate(x - x[:, :1], slight=0.5, clear=1.0)
    assert ch10_command_whiteness([np.array([0.0, 0.2, 0.1])], 0.1) == pytest.approx(
        whiteness([0.0, 0.2, 0.1], 0.1)
    )
    assert math.isclose(
        ch10_crashes_per_km([{"crashes": 3, "distance_m": 1500.0}]), crashes_per_km(3, 1500.0)
    )
