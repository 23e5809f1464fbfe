"""Checkers for ``exercises/10_road_following.ipynb``: the road-following study's three measures.

- ``check_swerve_rate(fn)``: the swerve rate of Table 2 of the steering-EBM paper from lateral
  offsets, ``fn(offsets, slight, clear) -> float``: ``offsets`` is (P, T), one row per pass of a
  side road, the car's lateral offset (m) towards the side road, as measured (not relative).
- ``check_command_whiteness(fn)``: W_cmd (eq. 2 of the paper) of commands driven in stretches
  between restarts, ``fn(segments, dt) -> float`` in 1/s.
- ``check_crashes_per_km(fn)``: crashes per kilometre from a log of runs,
  ``fn(runs) -> float`` with ``runs`` a list of ``{"crashes": n, "distance_m": d}``.

Each compares the reader's function with the library's (``ibc_tutorial.metrics``) on chosen
cases and, when they differ, tests the usual mistakes one by one to name the one made, without
giving the answer away.
"""

from __future__ import annotations

import math

import numpy as np

from ibc_tutorial.exercises.core import Feedback, close, correct, hint, number_answer, run_check
from ibc_tutorial.metrics import crashes_per_km, swerve_rate, whiteness


# --------------------------------------------------------------------------- 1. swerve rate
def _swerve_ref(offsets, slight, clear, *, relative=True, signed=True, peak=True, half=0.5, strict=False):
    x = np.asarray(offsets, dtype=float)
    if relative:
        x = x - x[:, :1]
    if not signed:
        x = np.abs(x)
    m = x.max(axis=1) if peak else x.mean(axis=1)
    if strict:
        return float(np.where(m > clear, 1.0, np.where(m > slight, half, 0.0)).mean())
    return float(np.where(m >= clear, 1.0, np.where(m >= slight, half, 0.0)).mean())


_PEAKS = 0.025 + 0.05 * np.arange(40)
"""(40,) the peaks of the last swerve case's passes (m)."""

SWERVE_CASES = [
    # (offsets (P, T), slight, clear); after the first, each case tells one usual mistake from the others
    (
        np.array(
            [[0.3, 0.4, 0.9, 0.5], [0.0, 0.2, 1.3, 0.1], [-0.2, -0.9, -1.4, -0.6], [0.5, 0.6, 0.6, 0.55]]
        ),
        0.5,
        1.0,
    ),
    (np.array([[0.6, 0.65, 0.7, 0.6], [0.0, 0.1, 0.2, 0.1]]), 0.5, 1.0),  # entered off the centre line
    (np.array([[0.0, -0.7, -1.2, -0.3], [0.0, 0.2, 0.1, 0.0]]), 0.5, 1.0),  # moved away from the side road
    (np.array([[0.0, 1.1, 1.2, 1.1], [0.0, 0.6, 0.6, 0.6]]), 0.5, 1.0),  # peak, not mean
    (np.array([[0.0, 0.6, 0.7, 0.6], [0.0, 0.2, 0.1, 0.0], [0.0, -0.1, -0.2, 0.0]]), 0.5, 1.0),  # half
    # peaks exactly at the thresholds (dyadic numbers: the differences are exact): reaching counts
    (np.array([[0.25, 0.5, 0.75, 0.5], [0.25, 1.25, 0.5, 0.25], [0.0, 0.125, 0.25, 0.125]]), 0.5, 1.0),
    # other thresholds: the function must use its arguments
    (np.array([[0.0, 0.6, 0.1, 0.0], [0.0, 0.9, 0.2, 0.0], [0.0, 0.35, 0.3, 0.3]]), 0.3, 0.8),
    # forty passes peaking every 0.05 m from 0.025 to 1.975 m: thresholds other than the arguments
    # (by more than 0.05 m) change the count
    (_PEAKS[:, None] * np.array([0.0, 1.0, 0.5, 0.0]), 0.7, 1.3),
]


SWERVE_HINTS = {
    "relative": "a car that enters the section already off the centre line has not swerved: measure each "
    "pass's "
    "offsets from where the car was when the section began.",
    "signed": "only movement towards the side road is a swerve: a car that moves away from it has not been "
    "pulled "
    "towards the other option.",
    "peak": "a swerve is judged by how far the car went at its farthest, not on average over the pass.",
    "half": "the paper counts a slight swerve as half a swerve.",
    "strict": "a pass whose peak is exactly at a threshold has reached it: 'reaches' means at or beyond the "
    "threshold.",
    "thresholds": "right for the thresholds 0.5 and 1.0 m, wrong for 0.3 and 0.8 m: use the thresholds "
    "passed as "
    "`slight` and `clear`, not the chapter's numbers.",
}


def check_swerve_rate(fn) -> Feedback:
    """Check ``fn(offsets, slight, clear)`` against ``metrics.swerve_rate`` on offsets made relative."""

    def check() -> Feedback:
        wrong = False
        for offsets, slight, clear in SWERVE_CASES:
            out = number_answer(fn(offsets.copy(), slight, clear), "swerve_rate")
            if isinstance(out, Feedback):
                return out
            ref = swerve_rate(offsets - offsets[:, :1], slight=slight, clear=clear)
            if close(out, ref, rtol=1e-6, atol=1e-9):
                continue
            mistakes = {  # a mistake is named only in a case where no other mistake gives the same answer
                "relative": _swerve_ref(offsets, slight, clear, relative=False),
                "signed": _swerve_ref(offsets, slight, clear, signed=False),
                "peak": _swerve_ref(offsets, slight, clear, peak=False),
                "half": _swerve_ref(offsets, slight, clear, half=1.0),
                "strict": _swerve_ref(offsets, slight, clear, strict=True),
            }
            if (slight, clear) != (0.5, 1.0):
                mistakes["thresholds"] = _swerve_ref(offsets, 0.5, 1.0)
            made = [k for k, v in mistakes.items() if close(out, v, rtol=1e-6, atol=1e-9)]
            if len(made) == 1:
                return hint(SWERVE_HINTS[made[0]])
            if not made:
                return hint(
                    f"for offsets {offsets.tolist()} with thresholds {slight} and {clear} m your rate is "
                    f"{out:.4f}: score each pass 0, 1/2 or 1 from its peak, then average."
                )
            wrong = True
        if wrong:
            return hint(
                "your rates differ from Table 2's measure: score each pass 0, 1/2 or 1 from its peak offset "
                "towards the side road, measured from where the pass began, then average."
            )
        return correct(
            "That is Table 2's measure. Its two thresholds are choices: chapter 10 says why 0.5 m and 1.0 m."
        )

    return run_check(check, "`swerve_rate`")


# --------------------------------------------------------------------------- 2. W_cmd
SEGMENTS = [
    [np.array([0.0, 0.1, 0.1, -0.1]), np.array([0.5, 0.5, 0.4])],
    [np.array([0.2, 0.0, 0.3, 0.3, 0.1, 0.0]), np.array([-0.4, 0.4]), np.array([0.9])],
]


def _w_pooled(segments, dt):
    segs = [np.asarray(s, dtype=float) for s in segments if len(s) >= 2]
    n = sum(len(s) - 1 for s in segs)
    return math.sqrt(sum((len(s) - 1) * whiteness(s, dt) ** 2 for s in segs) / n)


def check_command_whiteness(fn) -> Feedback:
    """Check ``fn(segments, dt)``: eq. 2 over every change within a segment, pooled, in 1/s."""

    def check() -> Feedback:
        for segments, dt in ((SEGMENTS[0], 0.1), (SEGMENTS[1], 0.1), (SEGMENTS[1], 0.05)):
            out = number_answer(fn([s.copy() for s in segments], dt), "command_whiteness")
            if isinstance(out, Feedback):
                return out
            ref = _w_pooled(segments, dt)
            if close(out, ref, rtol=1e-6, atol=1e-9):
                continue
            joined = np.concatenate(segments)
            if close(out, whiteness(joined, dt), rtol=1e-6, atol=1e-9):
                return hint(
                    "a restart puts the car somewhere else: the change of command across it is not a change "
                    "the model made. Take differences within each stretch only."
                )
            per = [whiteness(s, dt) for s in segments if len(s) >= 2]
            if close(out, float(np.mean(per)), rtol=1e-6, atol=1e-9):
                return hint(
                    "the stretches have different lengths: pool their squared rates of change over all the "
                    "changes (eq. 2's D) instead of averaging one W per stretch."
                )
            if close(out, ref * dt, rtol=1e-6, atol=1e-9) or close(out, ref * dt * dt, rtol=1e-6, atol=1e-9):
                return hint("eq. 2 divides each change by the time between decisions, δt.")
            if close(out, ref * ref, rtol=1e-6, atol=1e-9):
                return hint("eq. 2 is a root mean square: take the square root.")
            if close(out, ref * 250.0, rtol=1e-6, atol=1e-9) or close(
                out, ref * math.degrees(0.6), rtol=1e-6, atol=1e-9
            ):
                return hint(
                    "the exercise asks for the book's unit, steer per second (1/s), not degrees per second."
                )
            return hint(
                f"for these stretches at δt = {dt} s your W is {out:.5f}: square each change's rate δP/δt, "
                "average over all changes of all stretches, take the root."
            )
        return correct("That is W_cmd in 1/s; multiplied by 250 it is in the paper's steering-wheel °/s.")

    return run_check(check, "`command_whiteness`")


# --------------------------------------------------------------------------- 3. crashes per km
RUNS = [
    [{"crashes": 2, "distance_m": 400.0}, {"crashes": 1, "distance_m": 1600.0}],
    [
        {"crashes": 0, "distance_m": 900.0},
        {"crashes": 3, "distance_m": 300.0},
        {"crashes": 1, "distance_m": 800.0},
    ],
]


def check_crashes_per_km(fn) -> Feedback:
    """Check ``fn(runs)``: the runs' crashes summed over their distance summed, per km."""

    def check() -> Feedback:
        for runs in RUNS:
            out = number_answer(fn([dict(r) for r in runs]), "crashes_per_km")
            if isinstance(out, Feedback):
                return out
            c = [r["crashes"] for r in runs]
            d = [r["distance_m"] for r in runs]
            ref = crashes_per_km(c, d)
            if close(out, ref, rtol=1e-6, atol=1e-9):
                continue
            if close(
                out,
                float(np.mean([ci / (di / 1000) for ci, di in zip(c, d, strict=False)])),
                rtol=1e-6,
                atol=1e-9,
            ):
                return hint(
                    "a short run would weigh as much as a long one: pool the crashes and the distances of "
                    "all runs first, then divide."
                )
            if close(out, ref / 1000, rtol=1e-6, atol=1e-9) or close(out, ref * 1000, rtol=1e-6, atol=1e-9):
                return hint("the distances are in metres; the rate is per kilometre.")
            if close(out, float(sum(c)), rtol=1e-6, atol=1e-9):
                return hint(
                    "a count alone does not compare routes of different lengths: divide by the distance."
                )
            return hint(f"for these runs your rate is {out:.4f}: total crashes over total kilometres.")
        return correct(
            "Pooled crashes per km: the table of chapter 10 reports it per seed, then its mean and spread."
        )

    return run_check(check, "`crashes_per_km`")
