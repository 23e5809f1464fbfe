"""Checkers for ``exercises/08_training_agents.ipynb``.

- ``check_episode_score(fn)``: the DA-IBC paper's episode score from an episode's log,
  ``fn(xy (T+1, 2), crossed (T,)) -> float``: the length of the path driven x 0.7 ** (stop lines
  crossed at red).
- ``check_unseen_share(fn)``: the training protocol's weighted minibatches, ``fn(probs (M,),
  batch_size) -> float``: the expected share of the M samples that one epoch (ceil(M / B)
  minibatches of B, drawn with replacement with probabilities ``probs``) never draws.
- ``check_recipe(fn)``: the three agents as the paper defines them, ``fn(method) -> dict`` with the
  loss, the counter-examples and the DFO's start and final choice (``RECIPES``, the chapter's table,
  which the tests check against the library's agents).

Each compares the reader's function with the library's definition (``driving.sim.score``,
``training.draw_minibatch``'s protocol, ``experiments.agents``) on chosen cases and, when they
differ, tries the usual mistakes one by one to name the one that was made.
"""

from __future__ import annotations

import math

import numpy as np

from ibc_tutorial.exercises.core import Feedback, correct, hint, number_answer, run_check

PENALTY = 0.7
"""The score's factor per red light run (``driving.sim.SCORE_PENALTY``)."""


# --------------------------------------------------------------------------- 1. the episode score
def _log(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A made-up episode: a path that turns back on itself, and the stop lines it crossed.

    crossed[t] = state of the light whose stop line the rear crossed at step t (-1: none;
    0 green, 1 yellow, 2 red).
    """
    rng = np.random.default_rng(seed)
    t = 120
    heading = np.cumsum(rng.normal(0.0, 0.12, t)) + np.linspace(0, 2 * np.pi, t)  # a loop
    step = rng.uniform(0.0, 0.8, t)  # metres per 0.1 s step
    xy = np.vstack([[0.0, 0.0], np.cumsum(np.stack([step * np.cos(heading), step * np.sin(heading)], 1), 0)])
    crossed = np.full(t, -1)
    crossed[rng.choice(t, 9, replace=False)] = [2, 2, 0, 1, 2, 0, 1, 0, 2][:9]
    return xy, crossed


def _score_ref(xy, crossed, *, path=True, counts=(2,), penalty="power"):
    dist = float(np.hypot(*np.diff(xy, axis=0).T).sum()) if path else float(np.hypot(*(xy[-1] - xy[0])))
    n = int(np.isin(crossed, counts).sum())
    if penalty == "power":
        return dist * PENALTY**n
    if penalty == "linear":
        return dist * max(0.0, 1 - (1 - PENALTY) * n)
    if penalty == "times n":
        return dist * PENALTY * n
    if penalty == "subtract":
        return dist - (1 - PENALTY) * n
    return dist  # "none"


def check_episode_score(fn) -> Feedback:
    """Check ``fn(xy, crossed) -> float`` against distance driven x 0.7 ** (red lights run)."""
    from ibc_tutorial.driving.sim import score

    def check() -> Feedback:
        logs = [_log(s) for s in (0, 1)]
        clean = (logs[0][0], np.full(len(logs[0][1]), -1))  # no stop line crossed
        for xy, crossed in [clean] + logs:
            out = number_answer(fn(xy.copy(), crossed.copy()), "episode_score")
            if isinstance(out, Feedback):
                return out
            n_red = int((crossed == 2).sum())
            ref = score(float(np.hypot(*np.diff(xy, axis=0).T).sum()), n_red)
            if math.isclose(out, ref, rel_tol=1e-6, abs_tol=1e-6):
                continue
            mistakes = [
                (
                    dict(path=False),
                    "the distance driven is the length of the path, step by step, not the straight "
                    "line from the start to the end (this car drove a loop).",
                ),
                (dict(penalty="none"), "red lights cost: each one multiplies the score by 0.7."),
                (dict(counts=(1, 2)), "only red counts: crossing the stop line at yellow is legal."),
                (
                    dict(counts=(0, 1, 2)),
                    "only red counts: crossing a stop line at green or yellow is no infraction.",
                ),
                (
                    dict(penalty="linear"),
                    "the penalty compounds: each red light multiplies what is left by 0.7 "
                    "(0.7 ** n), it does not take 30 % of the distance each time.",
                ),
                (
                    dict(penalty="times n"),
                    "with n red lights the factor is 0.7 to the power n, not 0.7 times n "
                    "(an episode without infractions scores its distance).",
                ),
                (
                    dict(penalty="subtract"),
                    "the penalty is a factor on the distance, not metres taken off it.",
                ),
            ]
            for kwargs, message in mistakes:
                if math.isclose(out, _score_ref(xy, crossed, **kwargs), rel_tol=1e-6, abs_tol=1e-6):
                    return hint(message)
            return hint(
                f"for an episode of {len(crossed)} steps with {n_red} stop lines crossed at red, your score "
                f"is {out:.2f}: check the distance (a sum over steps) and the factor 0.7 per red light."
            )
        return correct(
            "That is the paper's score (``driving.sim.score``): a car that runs three red lights keeps "
            "34 % of its distance, one that stands still scores 0."
        )

    return run_check(check, "`episode_score`")


# --------------------------------------------------------------------------- 2. unseen samples per epoch
def _unseen_ref(p, b, *, draws="epoch", uniform=False, linear=False, count=False):
    m = len(p)
    p = np.full(m, 1.0 / m) if uniform else np.asarray(p, float)
    n = {"epoch": math.ceil(m / b) * b, "floor": (m // b) * b, "m": m, "batch": b}[draws]
    miss = np.clip(1 - n * p, 0, None) if linear else (1 - p) ** n
    return float(miss.sum() if count else miss.mean())


def _probs() -> np.ndarray:
    """Sampling probabilities of a dataset with a common action and a rare one (w ∝ 1 / ĝ-like)."""
    w = np.r_[np.full(900, 1.0), np.full(100, 6.0)]  # 900 common samples, 100 rare with 6x the weight
    return w / w.sum()  # (1000,)


def check_unseen_share(fn) -> Feedback:
    """Check ``fn(probs, batch_size) -> float``: mean_i (1 - p_i) ** (ceil(M / B) B)."""

    def check() -> Feedback:
        cases = [
            (np.full(1000, 1e-3), 128),
            (_probs(), 128),
            (_probs(), 96),
            (np.r_[0.5, np.full(50, 0.01)], 7),
        ]
        for p, b in cases:
            out = number_answer(fn(p.copy(), b), "unseen_share")
            if isinstance(out, Feedback):
                return out
            ref = _unseen_ref(p, b)
            if math.isclose(out, ref, rel_tol=1e-6, abs_tol=1e-9):
                continue
            if not 0.0 <= out <= 1.0:
                if math.isclose(out, _unseen_ref(p, b, count=True), rel_tol=1e-6):
                    return hint(
                        "that is the expected *number* of samples never drawn: return it as a share of M."
                    )
                return hint(f"a share lies between 0 and 1; yours is {out:.4g}.")
            mistakes = [
                (
                    dict(uniform=True),
                    "the minibatches are weighted: sample i is drawn with probability p_i, not 1/M, "
                    "so common samples are missed more often than rare ones.",
                ),
                (
                    dict(draws="m"),
                    "an epoch is ceil(M / B) minibatches of B: a few more than M draws when B does not "
                    "divide M.",
                ),
                (dict(draws="floor"), "an epoch is ceil(M / B) minibatches, rounded up, not down."),
                (dict(draws="batch"), "that is one minibatch: an epoch draws ceil(M / B) of them."),
                (
                    dict(linear=True, uniform=True),
                    "draws are with replacement: a sample can be drawn twice and "
                    "another never, even in M draws or more; the chance that n "
                    "independent draws all miss sample i is (1 - p_i) ** n.",
                ),
                (
                    dict(linear=True),
                    "1 - n p_i is only the first term: with n independent draws the chance of never "
                    "drawing sample i is (1 - p_i) ** n.",
                ),
            ]
            for kwargs, message in mistakes:
                if math.isclose(out, _unseen_ref(p, b, **kwargs), rel_tol=1e-6, abs_tol=1e-9):
                    return hint(message)
            if abs(out - ref) < 0.02:
                return hint(
                    f"your {out:.4f} is near the expected share {ref:.4f} but not it: compute the "
                    "expectation exactly (a simulation only estimates it)."
                )
            return hint(
                f"for M = {len(p)} samples and B = {b} your share is {out:.4f}: the expected share is the "
                "average over samples of the chance that none of the epoch's draws picks it."
            )
        return correct(
            "That is the protocol's price: with the second case's weights (rare samples 6 times as likely) "
            "an epoch of B = 128 misses about half of the common samples and under 2 % of the rare ones."
        )

    return run_check(check, "`unseen_share`")


# --------------------------------------------------------------------------- 3. the three agents
FIELDS = ("loss", "negatives", "dfo_init", "dfo_select")
"""The keys of a recipe."""
CHOICES = {
    "loss": ("beta nll", "infonce"),
    "negatives": (None, "uniform", "expert + noise"),
    "dfo_init": (None, "uniform", "inverse-kde"),
    "dfo_select": (None, "argmax", "sample"),
}
"""The allowed value of each key (None: the method has no such step)."""


RECIPES = {
    "bc": {"loss": "beta nll", "negatives": None, "dfo_init": None, "dfo_select": None},
    "ibc": {"loss": "infonce", "negatives": "uniform", "dfo_init": "uniform", "dfo_select": "argmax"},
    "da-ibc": {
        "loss": "infonce",
        "negatives": "expert + noise",
        "dfo_init": "inverse-kde",
        "dfo_select": "sample",
    },
}
"""The chapter's table of the three methods (``tests/test_exercises_ch08.py`` checks it against the
library's ``experiments.agents.train.objective_for`` and ``agent.dfo_config``)."""


HINTS = {
    ("bc", "loss"): "BC is the explicit policy of eq. 1: which loss trains a Beta head?",
    ("bc", "negatives"): "BC has no energy and so no counter-examples.",
    ("bc", "dfo_init"): "BC acts with its Beta's mean: it never runs DFO.",
    ("bc", "dfo_select"): "BC acts with its Beta's mean: it never runs DFO.",
    ("ibc", "loss"): "IBC trains an energy model: with which loss (eq. 2)?",
    ("ibc", "negatives"): "IBC is Florence et al.'s original: where do its counter-examples come from?",
    ("ibc", "dfo_init"): "the original IBC starts DFO without looking at the expert's actions.",
    ("ibc", "dfo_select"): "IBC runs DFO too, and ends it by choosing one of the final candidates.",
    ("da-ibc", "loss"): "DA-IBC trains an energy model: with which loss (eq. 2)?",
    ("da-ibc", "negatives"): "DA-IBC's counter-examples are built from the minibatch's own expert actions "
    "(sec. 2.4).",
    (
        "da-ibc",
        "dfo_init",
    ): "DA-IBC starts DFO from expert actions, weighted so that rare ones are drawn more (sec. 2.4.1).",
    (
        "da-ibc",
        "dfo_select",
    ): "DA-IBC's last line of Algorithm 1 draws the action from the final distribution.",
}


ALSO_ACCEPTED = {("ibc", "dfo_select"): ("sample",)}
"""Answers accepted besides ``RECIPES``'s, each a defensible reading of the DA-IBC paper. Its
conclusion names two changes from IBC: the counter-examples and the DFO's *initialisation*; the final
draw (Algorithm 1, line 14) is introduced in sec. 2.4.1 as a change from the original IBC's argmax,
but the paper does not say which ending its IBC baseline used. The book's IBC (the library's) ends
with the argmax; a reader who gives IBC the paper's Algorithm 1 with a uniform start, ending in a
draw, has read the paper no worse."""


def check_recipe(fn) -> Feedback:
    """Check ``fn(method) -> {"loss", "negatives", "dfo_init", "dfo_select"}`` against the library's
    agents (``RECIPES``), accepting ``ALSO_ACCEPTED``'s other readings of the paper."""

    def check() -> Feedback:
        other_reading = False
        for method in ("bc", "ibc", "da-ibc"):
            out = fn(method)
            if not isinstance(out, dict) or set(out) != set(FIELDS):
                return hint(
                    f"recipe must return a dict with exactly the keys {', '.join(FIELDS)}; for {method!r} "
                    f"it returned {out!r:.80}."
                )
            for key in FIELDS:
                value = out[key].strip().lower() if isinstance(out[key], str) else out[key]
                if value not in CHOICES[key]:
                    return hint(f"{key} must be one of {CHOICES[key]}; for {method!r} it is {out[key]!r}.")
                if value in ALSO_ACCEPTED.get((method, key), ()):
                    other_reading = True
                elif value != RECIPES[method][key]:
                    return hint(f"{method}'s {key}: {HINTS[(method, key)]}")
        shared = (
            "IBC and DA-IBC share the loss. The paper's conclusion names two changes: the counter-examples "
            "(from the expert's actions) and how DFO is initialised (from the expert's actions, weighted by "
            "1/ĝ); the final draw of Algorithm 1 is introduced in sec. 2.4.1 as a change from the original "
            "IBC's argmax."
        )
        if other_reading:
            return correct(
                f"{shared} You let IBC end with a draw too, as the conclusion's two changes allow: the paper "
                "does not say which ending its IBC baseline used. The book's IBC ends with the argmax of the "
                "original IBC, so that IBC and DA-IBC differ in DFO's start and end."
            )
        return correct(
            f"{shared} Ending the book's IBC with the argmax is the book's reading (the paper does not say "
            "which "
            "ending its IBC baseline used); an IBC ending with a draw is accepted too."
        )

    return run_check(check, "`recipe`")
