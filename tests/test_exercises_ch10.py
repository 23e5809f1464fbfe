"""Checkers of exercises/10_road_following.ipynb: solution -> correct, stub -> not attempted,
typical mistakes -> a hint naming the mistake, code that raises -> a hint (never an exception).

The reference solutions are ``ibc_tutorial.exercises.solutions.ch10_*``."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

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


# --------------------------------------------------------------------------- holes closed (issue 26)
def _rate(peak_of, slight, clear, strict=False):
    peak = np.asarray(peak_of)
    if strict:
        return float(np.where(peak > clear, 1.0, np.where(peak > slight, 0.5, 0.0)).mean())
    return float(np.where(peak >= clear, 1.0, np.where(peak >= slight, 0.5, 0.0)).mean())


def test_swerve_rate_with_strict_thresholds_gets_a_hint():
    def strict(x, s, c):
        x = np.asarray(x, dtype=float)
        return _rate((x - x[:, :1]).max(1), s, c, strict=True)

    fb = ch10.check_swerve_rate(strict)
    assert fb.status == "hint" and "exactly at a threshold" in fb.message, fb.message


@settings(max_examples=25, deadline=None)
@given(slight=st.floats(0.1, 1.5), gap=st.floats(0.05, 1.5))
def test_swerve_rate_with_hard_coded_thresholds_gets_a_hint(slight, gap):
    """Thresholds written into the function instead of read from its arguments: any pair more than
    0.05 m from the checker's last case's (0.7, 1.3) m, whose passes peak every 0.05 m."""
    clear = slight + gap
    assume(abs(slight - 0.7) > 0.05 or abs(clear - 1.3) > 0.05)

    def hard_coded(x, s, c):
        x = np.asarray(x, dtype=float)
        return _rate((x - x[:, :1]).max(1), slight, clear)

    assert ch10.check_swerve_rate(hard_coded).status == "hint"


def test_exercise_text_gives_the_papers_decision_rate():
    """The steering-EBM paper's stack decides at about 12 Hz; 33 ms is its frame spacing."""
    import json
    from pathlib import Path

    nb = json.loads(Path(__file__).parents[1].joinpath("exercises/10_road_following.ipynb").read_text())
    text = "".join("".join(c["source"]) for c in nb["cells"] if c["cell_type"] == "markdown")
    assert "decides every 33 ms" not in text and "12 Hz" in text
