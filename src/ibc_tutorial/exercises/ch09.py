"""Checkers for ``exercises/09_replication.ipynb``.

- ``check_bootstrap_difference(fn)``: a 95 % interval for the difference of two methods' mean
  scores by the two-level bootstrap (agents, then episodes within each drawn agent),
  ``fn(scores_a (A, E), scores_b (B, E), n_resamples, rng) -> (low, high)``, compared with
  ``stats.difference_interval``.
- ``check_exit_shares(fn)``: the share of a junction approach's visits by exit,
  ``fn(visits, approach) -> {"left": s, "straight": s, "right": s}``, on visits as
  ``driving.analysis.junction_visits`` records them.
- ``check_verdict(fn)``: the rule that decides a claim "the quantity is above a threshold" from its
  interval, ``fn(estimate, low, high, threshold) -> "holds" | "does not hold" | "cannot tell at this
  scale"``, compared with ``stats.verdict``.

The bootstrap is random, so its check is statistical: with 20,000 resamples the ends of the
interval vary by about 0.5 % of its width (standard deviation, measured) from one seed to another;
an answer within 4 % of the reference's width passes, and the usual mistakes (resampling pooled
episodes or agent means only, another level, the wrong sign, shared draws for both methods) land
7 % or more away on at least one of the two cases chosen.
"""

from __future__ import annotations

import math

import numpy as np

from ibc_tutorial.exercises.core import Feedback, correct, hint, run_check
from ibc_tutorial.stats import (
    CANNOT_TELL,
    DOES_NOT_HOLD,
    HOLDS,
    TURNS,
    Interval,
    difference_interval,
    verdict,
)

RESAMPLES = 20_000
"""Resamples the checker asks for."""
TOLERANCE = 0.04
"""An end of the interval passes within this share of the reference interval's width."""


# --------------------------------------------------------------------------- 1. a bootstrap interval
def _cases() -> list[tuple[np.ndarray, np.ndarray]]:
    """Two pairs of methods: agents that differ a lot (pooling fails), agents alike with noisy episodes
    (agent means alone fail)."""
    rng = np.random.default_rng(0)
    a = np.array([100.0, 500.0, 900.0])[:, None] + rng.normal(0, 60, (3, 10))  # (3, 10)
    b = np.array([300.0, 350.0, 400.0])[:, None] + rng.normal(0, 60, (3, 10))
    c = 500 + rng.normal(0, 400, (4, 8))
    c -= c.mean(1, keepdims=True) - 500  # (4, 8) every agent's mean exactly 500
    d = 450 + rng.normal(0, 100, (4, 8))
    # one agent far above its two siblings: the resampled differences are skewed, so an interval drawn
    # symmetrically about them (mean ± 1.96 sd, or the "basic" bootstrap's reflection) misses the percentiles
    rng = np.random.default_rng(5)
    e = np.array([150.0, 200.0, 1000.0])[:, None] + rng.normal(0, 50, (3, 10))
    f = np.array([300.0, 320.0, 340.0])[:, None] + rng.normal(0, 50, (3, 10))
    return [(a, b), (c, d), (e, f)]


def _q(reps: np.ndarray, level: float = 0.95) -> tuple[float, float]:
    lo, hi = np.percentile(reps, [50 * (1 - level), 50 * (1 + level)])
    return float(lo), float(hi)


def _boot(
    x: np.ndarray, r: int, rng: np.random.Generator, agents=True, episodes=True, pooled=False, idx=None
) -> np.ndarray:
    """(R,) resampled means of x (A, E) with a level switched off, or pooled; ``idx`` reuses draws."""
    a, e = x.shape
    if pooled:
        return rng.choice(x.ravel(), size=(r, x.size)).mean(1)
    if idx is None:
        ag = rng.integers(a, size=(r, a)) if agents else np.broadcast_to(np.arange(a), (r, a))
        ep = rng.integers(e, size=(r, a, e)) if episodes else np.broadcast_to(np.arange(e), (r, a, e))
        idx = (ag, ep)
    ag, ep = idx
    return x[ag[..., None], ep].mean((1, 2))


def _mistakes(a: np.ndarray, b: np.ndarray) -> list[tuple[tuple[float, float], str]]:
    rng = np.random.default_rng(1)
    r = RESAMPLES
    full_a, full_b = _boot(a, r, rng), _boot(b, r, rng)
    shared = (rng.integers(a.shape[0], size=(r, a.shape[0])), rng.integers(a.shape[1], size=(r, *a.shape)))
    diffs = full_a - full_b  # (R,)
    lo, hi = _q(diffs)
    estimate = float(a.mean() - b.mean())
    spread = 1.96 * float(diffs.std())
    return [
        ((-hi, -lo), "the sign: the interval is for mean(A) - mean(B)."),
        (
            (float(diffs.mean()) - spread, float(diffs.mean()) + spread),
            "the percentiles: a percentile interval reads the 2.5th and 97.5th percentiles of the "
            "resampled differences themselves, not their mean ± 1.96 standard deviations (with one agent far "
            "from the others the differences are skewed, and the interval is not symmetric).",
        ),
        (
            (2 * estimate - hi, 2 * estimate - lo),
            "the percentiles: the percentile interval is [2.5th, 97.5th percentile] of the resampled "
            "differences as they are, not reflected about the estimate (that is the 'basic' bootstrap).",
        ),
        (
            _q(_boot(a, r, rng, pooled=True) - _boot(b, r, rng, pooled=True)),
            "you resampled all episodes of a method as one pool: that treats the episodes of one agent as if "
            "each came from another agent. Draw agents first, then episodes within each drawn agent.",
        ),
        (
            _q(_boot(a, r, rng, episodes=False) - _boot(b, r, rng, episodes=False)),
            "you resampled agents but kept each drawn agent's episodes as they are: the episodes vary too "
            "(other "
            "starts), so draw them with replacement within each drawn agent.",
        ),
        (
            _q(_boot(a, r, rng, agents=False) - _boot(b, r, rng, agents=False)),
            "you resampled episodes but kept every agent once: another run of the method would give other "
            "agents, "
            "so draw the agents with replacement too.",
        ),
        (
            _q(full_a - full_b, 0.90),
            "the level: a 95 % interval runs from the 2.5th to the 97.5th percentile.",
        ),
        (_q(full_a), "that is an interval for mean(A) alone: the claim is about mean(A) - mean(B)."),
        (
            _q(_boot(a, r, rng, idx=shared) - _boot(b, r, rng, idx=shared)),
            "the two methods share the same agent and episode draws in your resamples: their agents are "
            "different "
            "networks, so draw each method's resample independently.",
        ),
    ]


def check_bootstrap_difference(fn) -> Feedback:
    """Check ``fn(scores_a, scores_b, n_resamples, rng) -> (low, high)`` against
    ``stats.difference_interval``."""

    def ask(a, b, seed):
        out = fn(a.copy(), b.copy(), RESAMPLES, np.random.default_rng(seed))
        try:
            lo, hi = (float(v) for v in out)
        except (TypeError, ValueError):
            raise TypeError("bootstrap_difference must return two numbers, (low, high)") from None
        return lo, hi

    def check() -> Feedback:
        for k, (a, b) in enumerate(_cases()):
            out = ask(a, b, 123)
            if not all(math.isfinite(v) for v in out):
                return hint("bootstrap_difference returned NaN or inf.")
            if out[0] > out[1]:
                return hint("return (low, high) with low <= high.")
            ref = difference_interval(a, b, n_resamples=4 * RESAMPLES, seed=2)
            tol = TOLERANCE * (ref.high - ref.low)
            if abs(out[0] - ref.low) <= tol and abs(out[1] - ref.high) <= tol:
                if k == 0 and ask(a, b, 123) != out:
                    return hint(
                        "called twice with generators of the same seed, your function gave two intervals: "
                        "draw every random number from the generator `rng` it is given."
                    )
                continue
            for value, message in _mistakes(a, b):
                if abs(out[0] - value[0]) <= tol and abs(out[1] - value[1]) <= tol:
                    return hint(message)
            return hint(
                f"for these methods (mean difference {a.mean() - b.mean():.1f}) your interval is "
                f"[{out[0]:.1f}, {out[1]:.1f}]: check the two levels of the resampling (agents with "
                "replacement, then E episodes of each drawn agent) and the percentiles."
            )
        return correct(
            "That is the two-level bootstrap (``stats.difference_interval``): with three agents per "
            "method, the spread between agents dominates the interval however many episodes each drives."
        )

    return run_check(check, "`bootstrap_difference`")


# --------------------------------------------------------------------------- 2. shares of exits
def _visits() -> list[dict]:
    """Visits of a few approaches; approaches 4 and 5 lead into the same junction (node 2)."""
    rows = [
        (4, 2, "left"),
        (5, 2, "straight"),
        (4, 2, "left"),
        (9, 3, "right"),
        (4, 2, "straight"),
        (5, 2, "right"),
        (4, 2, "left"),
        (9, 3, "right"),
        (5, 2, "straight"),
        (4, 2, "right"),
        (7, 1, "straight"),
    ]
    return [
        {"approach": ap, "node": node, "turn": turn, "step": 10 * k}
        for k, (ap, node, turn) in enumerate(rows)
    ]


def _shares_ref(visits, approach, *, key="approach", node=None, counts=False, all_visits=False):
    want = node if key == "node" else approach
    turns = [v["turn"] for v in visits if v[key] == want]
    total = len(visits) if all_visits else len(turns)
    return {t: turns.count(t) / (1 if counts else total) for t in TURNS}


def check_exit_shares(fn) -> Feedback:
    """Check ``fn(visits, approach) -> {"left", "straight", "right"}`` (shares of the approach's visits)."""

    def check() -> Feedback:
        visits = _visits()
        for approach in (4, 5, 9, 7):
            out = fn([dict(v) for v in visits], approach)
            if not isinstance(out, dict):
                return hint(f"exit_shares must return a dict {{exit: share}}, got {type(out).__name__}.")
            if set(out) != set(TURNS):
                missing = sorted(set(TURNS) - set(out))
                if missing and set(out) <= set(TURNS):
                    return hint(
                        f"for approach {approach} your dict has no {', '.join(map(repr, missing))}: give "
                        "every "
                        "exit a share, 0 for one that was never taken."
                    )
                return hint(
                    f"the keys must be exactly {', '.join(map(repr, TURNS))}, got {sorted(map(str, out))}."
                )
            try:
                got = {t: float(out[t]) for t in TURNS}
            except (TypeError, ValueError):
                return hint("each share must be a number.")
            ref = _shares_ref(visits, approach)
            if all(math.isclose(got[t], ref[t], abs_tol=1e-9) for t in TURNS):
                continue
            node = next(v["node"] for v in visits if v["approach"] == approach)
            mistakes = [
                (
                    _shares_ref(visits, approach, counts=True),
                    "those are counts: divide by the approach's visits, so that the shares sum to 1.",
                ),
                (
                    _shares_ref(visits, approach, all_visits=True),
                    "divide by the visits of *this approach*, not by all the junction passes of the drive.",
                ),
                (
                    _shares_ref(visits, approach, key="node", node=node),
                    "you took every visit of the junction (its node): an approach is one direction into "
                    "it, and the "
                    "visits from other directions have other exits. Keep the visits whose 'approach' is "
                    "the one asked.",
                ),
            ]
            for value, message in mistakes:
                if all(math.isclose(got[t], value[t], abs_tol=1e-9) for t in TURNS):
                    return hint(message)
            return hint(
                f"for approach {approach} your shares are {got}: count its visits by 'turn' and divide by "
                "its number of visits."
            )
        return correct(
            "Those are the exit shares. An agent that spreads its visits over two exits at one approach, "
            "visit after visit, is what the paper's Fig. 5 calls making different decisions there."
        )

    return run_check(check, "`exit_shares`")


# --------------------------------------------------------------------------- 3. the verdict
VERDICT_CASES = [  # (estimate, low, high, threshold)
    (120.0, 15.0, 230.0, 0.0),
    (-80.0, -150.0, -12.0, 0.0),
    (60.0, -40.0, 170.0, 0.0),
    (-30.0, -95.0, 20.0, 0.0),
    (0.93, 0.88, 0.97, 0.85),
    (0.90, 0.81, 0.99, 0.85),
    (0.70, 0.55, 0.83, 0.85),
    (40.0, 0.0, 90.0, 0.0),
    (0.62, 0.60, 0.66, 0.60),
    (30.0, 2.0, 150.0, 0.0),  # asymmetric about the estimate: "wide, so cannot tell" is wrong here
    (-25.0, -60.0, 0.0, 0.0),  # the upper end on the threshold: not below it
    (0.80, 0.52, 0.84, 0.85),
]


def check_verdict(fn) -> Feedback:
    """Check ``fn(estimate, low, high, threshold) -> str`` against ``stats.verdict``."""

    def check() -> Feedback:
        for est, lo, hi, t in VERDICT_CASES:
            out = fn(est, lo, hi, t)
            if not isinstance(out, str):
                return hint(f"verdict must return one of the three strings, got {type(out).__name__}.")
            if out not in (HOLDS, DOES_NOT_HOLD, CANNOT_TELL):
                return hint(
                    f"verdict must return {HOLDS!r}, {DOES_NOT_HOLD!r} or {CANNOT_TELL!r}, got {out!r}."
                )
            ref = verdict(Interval(est, lo, hi), t)
            if out == ref:
                continue
            case = (
                f"for the interval [{lo:g}, {hi:g}] (estimate {est:g}) and the threshold {t:g} you "
                f"answered {out!r}"
            )
            if t in (lo, hi):
                return hint(
                    f"{case}: an interval that ends exactly on the threshold does not lie above (or below) "
                    "it."
                )
            if lo <= t <= hi and out == (HOLDS if est > t else DOES_NOT_HOLD):
                return hint(
                    f"{case}: the estimate is on one side, but the interval reaches the other side, so a "
                    "replication with other agents could well land there. The ordering does not decide."
                )
            if ref == CANNOT_TELL:
                return hint(f"{case}: the interval contains the threshold, so it cannot decide either way.")
            return hint(
                f"{case}: the whole interval lies {'above' if ref == HOLDS else 'below'} the threshold."
            )
        return correct(
            "That is the rule the chapter applies to every claim (``stats.verdict``): the interval "
            'decides, and "cannot tell at this scale" is an honest third answer.'
        )

    return run_check(check, "`verdict`")
