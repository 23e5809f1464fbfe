"""Checkers for ``exercises/12_tree_in_the_town.ipynb``: a fork and its gap, two valleys, the minority exit.

- ``check_fork(fn)``: the fork of an episode and its twin (``driving.forks``' rule),
  ``fn(recorded, twin) -> (index, gap)``: the first state at which the two (T, 2) label arrays
  [steer, acceleration] differ and the steering gap there; ``ValueError`` when they never differ.
- ``check_two_sided(fn)``: whether an energy profile over steering keeps both exits of a stem,
  ``fn(steer, profile) -> bool``: two valleys by the book's criterion (``energy_profiles.valleys``:
  within 3 nats of the minimum, a barrier of at least 1 nat), one left and one right of straight.
- ``check_exit_summary(fn)``: a method's stem exits over its agents,
  ``fn(counts) -> {"minority": share, "both": n_agents}`` with ``counts`` a list of (left, right) per
  agent: the pooled minority share (``stats.minority`` of the pooled left share) and the agents that
  took both exits.

Each compares the reader's function with the library's rule on chosen cases and, when they differ, tests
the usual mistakes one by one to name the one made, without giving the answer away.
"""

from __future__ import annotations

import numbers

import numpy as np

from ibc_tutorial.driving.energy_profiles import BARRIER, DEPTH, boltzmann_sides, valleys
from ibc_tutorial.exercises.core import Feedback, close, correct, hint, number_answer, run_check
from ibc_tutorial.stats import minority


# --------------------------------------------------------------------------- 1. the fork and its gap
def _labels(steer, accel) -> np.ndarray:
    return np.stack([np.asarray(steer, dtype=np.float32), np.asarray(accel, dtype=np.float32)], axis=1)


def _fork_case(steer, accel, twin_steer, twin_accel) -> tuple[np.ndarray, np.ndarray]:
    return _labels(steer, accel), _labels(twin_steer, twin_accel)


_TINY = 2.0**-20
"""A difference of about a millionth in steering: float32 tells it apart at 0.25, ``np.isclose`` does not."""

FORK_CASES = [
    # (recorded (T, 2), twin (T, 2)): float32 labels, as a log stores them, identical up to the fork
    _fork_case(  # fork at 3; recorded steers more to the right than the twin; acceleration differs too
        [0.0, 0.01, 0.015, 0.02, 0.3, 0.6, 0.7],
        [0.5, 0.4, 0.3, 0.3, 0.1, 0.0, 0.0],
        [0.0, 0.01, 0.015, -0.085, -0.3, -0.6, -0.7],
        [0.5, 0.4, 0.3, 0.1, 0.05, 0.0, 0.0],
    ),
    _fork_case(  # fork at 5; recorded steers more to the left than the twin
        [0.0, 0.0, -0.01, -0.02, -0.03, -0.06, -0.4, -0.7, -0.7],
        [0.3, 0.3, 0.3, 0.3, 0.3, 0.2, 0.0, -0.1, 0.0],
        [0.0, 0.0, -0.01, -0.02, -0.03, 0.048, 0.4, 0.7, 0.7],
        [0.3, 0.3, 0.3, 0.3, 0.3, 0.45, 0.2, 0.1, 0.0],
    ),
    _fork_case(  # fork at 2 by a millionth in steering; the clear difference comes two states later
        [0.1, 0.2, 0.25, 0.25, 0.3, 0.5],
        [0.4, 0.4, 0.4, 0.4, 0.4, 0.4],
        [0.1, 0.2, 0.25 + _TINY, 0.25, -0.3, -0.5],
        [0.4, 0.4, 0.4, 0.4, 0.4, 0.4],
    ),
    _fork_case(  # fork at 3 in the acceleration only (gap 0); the steering parts one state later
        [0.0, 0.0, 0.01, 0.02, 0.02, 0.2, 0.5],
        [0.6, 0.5, 0.5, 0.5, 0.4, 0.2, 0.1],
        [0.0, 0.0, 0.01, 0.02, -0.09, -0.2, -0.5],
        [0.6, 0.5, 0.5, 0.45, 0.3, 0.2, 0.1],
    ),
]


def _fork_ref(recorded, twin, *, steer_only=False, tolerant=False) -> tuple[int, float]:
    a, b = (recorded[:, :1], twin[:, :1]) if steer_only else (recorded, twin)
    differ = ~np.isclose(a, b) if tolerant else a != b
    i = int(np.flatnonzero(differ.any(axis=1))[0])
    return i, float(abs(float(recorded[i, 0]) - float(twin[i, 0])))


FORK_HINTS = {
    "last identical": "that is the last state at which the two labels agree; the fork is where they part.",
    "tolerant": "a difference of a millionth is still a difference: before the fork an episode and its twin "
    "are equal bit for bit (the simulator and the expert are deterministic), so compare exactly, without a "
    "tolerance or rounding.",
    "steer only": "a label is [steer, acceleration]: the two labels can part in the acceleration first, and "
    "the fork is there even if the steering is still equal.",
    "norm": "the label gap is the distance between the two labels in steering only, not in the whole action.",
    "signed": "the label gap is a distance: it does not depend on which of the two is the recorded episode.",
}


def _index_answer(out) -> tuple[int, float] | Feedback:
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        return hint(f"fork must return a pair (index, gap), got {type(out).__name__} {out!r}.")
    index, gap = out
    if isinstance(index, (bool, np.bool_)) or not isinstance(index, numbers.Integral):
        return hint(f"the index fork returns must be a whole number (an int), got {type(index).__name__}.")
    gap = number_answer(gap, "fork's gap")
    if isinstance(gap, Feedback):
        return gap
    return int(index), gap


def check_fork(fn) -> Feedback:
    """Check ``fn(recorded, twin)``: the first index at which the labels differ (any component) and
    ``|recorded[i, 0] - twin[i, 0]|`` there; ``ValueError`` for labels that never differ."""

    def check() -> Feedback:
        for recorded, twin in FORK_CASES:
            out = _index_answer(fn(recorded.copy(), twin.copy()))
            if isinstance(out, Feedback):
                return out
            index, gap = out
            ref_index, ref_gap = _fork_ref(recorded, twin)
            if index == ref_index and close(gap, ref_gap, rtol=1e-5, atol=1e-7):
                continue
            if index == ref_index - 1:
                return hint(FORK_HINTS["last identical"])
            if index == _fork_ref(recorded, twin, tolerant=True)[0] != ref_index:
                return hint(FORK_HINTS["tolerant"])
            if index == _fork_ref(recorded, twin, steer_only=True)[0] != ref_index:
                return hint(FORK_HINTS["steer only"])
            if index == ref_index:
                d = recorded[index].astype(float) - twin[index].astype(float)
                if close(gap, float(np.linalg.norm(d)), rtol=1e-5, atol=1e-7):
                    return hint(FORK_HINTS["norm"])
                if ref_gap > 0 and close(gap, -ref_gap, rtol=1e-5, atol=1e-7):
                    return hint(FORK_HINTS["signed"])
                return hint(
                    f"your index is right for these labels, but the gap {gap:.6f} is not: the label gap is "
                    "the difference in steering between the two labels at the fork."
                )
            return hint(
                f"for labels that part at one state your index is {index}: look for the first state at which "
                "the two labels differ."
            )
        same = FORK_CASES[0][0]
        try:
            out = fn(same.copy(), same.copy())
        except ValueError:
            return correct(
                "That is how driving.forks finds each stem crossing's fork and its label gap in the data."
            )
        except (IndexError, StopIteration) as exc:  # the first of no differing states
            return hint(
                f"for an episode and a twin that never differ your code raised {type(exc).__name__}: "
                "there is no fork; say so with a ValueError."
            )
        return hint(
            f"for an episode and a twin that never differ your function returned {out!r}: there is no fork; "
            "raise a ValueError."
        )

    return run_check(check, "`fork`")


# --------------------------------------------------------------------------- 2. two valleys, one each side
STEER = np.linspace(-1.0, 1.0, 161)
"""The chapter's reading grid over steering (0.0125 apart, straight exactly 0)."""


def _wells(steer, *wells) -> np.ndarray:
    """A profile made of parabolas ``(centre, floor, curvature)``: the lowest of them, minus its minimum."""
    s = np.asarray(steer, dtype=float)
    e = np.min([k * (s - m) ** 2 + d for m, d, k in wells], axis=0)
    return e - e.min()


TWO_SIDED_CASES = [
    # (what the profile shows, steer, profile)
    ("one broad valley at straight", STEER, _wells(STEER, (0.0, 0.0, 3.0))),
    ("two valleys, both left of straight", STEER, _wells(STEER, (-0.7, 0.0, 30.0), (-0.2, 0.5, 30.0))),
    ("a valley left and one right", STEER, _wells(STEER, (-0.4, 0.0, 30.0), (0.4, 1.0, 30.0))),
    ("a valley left and one right 4 nats up", STEER, _wells(STEER, (-0.4, 0.0, 30.0), (0.4, 4.0, 30.0))),
    ("two minima, left and right, 0.5 nat apart", STEER, _wells(STEER, (-0.2, 0.0, 12.5), (0.2, 0.0, 12.5))),
    ("a valley at straight and one right", STEER, _wells(STEER, (0.0, 0.0, 30.0), (0.5, 1.0, 30.0))),
    ("a valley at straight and one left", STEER, _wells(STEER, (0.0, 0.8, 30.0), (-0.5, 0.0, 30.0))),
    (
        "three valleys: left, straight and right",
        STEER,
        _wells(STEER, (-0.6, 0.5, 30.0), (0.0, 0.0, 30.0), (0.6, 1.5, 30.0)),
    ),
    (
        "a valley left and a deeper one right, on a coarser grid",
        np.linspace(-1.0, 1.0, 81),
        _wells(np.linspace(-1.0, 1.0, 81), (-0.3, 2.0, 30.0), (0.5, 0.0, 30.0)),
    ),
]


def _local_minima(steer, profile) -> list[float]:
    e = np.asarray(profile, dtype=float)
    inner = np.flatnonzero((e[1:-1] < e[:-2]) & (e[1:-1] < e[2:])) + 1
    ends = [0] if e[0] < e[1] else []
    ends += [len(e) - 1] if e[-1] < e[-2] else []
    return [float(steer[i]) for i in sorted([*inner, *ends])]


_RULES = {"book": (DEPTH, BARRIER), "no depth": (1e9, BARRIER), "no barrier": (DEPTH, 0.0)}
"""(depth, barrier) of the book's valley rule and of the rule with one of its two parts left out."""


def _two_sided_ref(steer, profile, *, rule="book", left=np.less, right=np.greater) -> bool:
    if rule == "local minima":
        at = _local_minima(steer, profile)
    else:
        depth, barrier = _RULES[rule]
        at = [v["steer"] for v in valleys(steer, profile, depth=depth, barrier=barrier)]
    return bool(any(left(s, 0.0) for s in at) and any(right(s, 0.0) for s in at))


def _mistakes_two_sided() -> dict[str, list[bool]]:
    """Each usual mistake's answers on ``TWO_SIDED_CASES``."""

    def each(f):
        return [bool(f(s, p)) for _, s, p in TWO_SIDED_CASES]

    return {
        "count": each(lambda s, p: len(valleys(s, p)) >= 2),
        "exactly two": each(lambda s, p: len(valleys(s, p)) == 2 and _two_sided_ref(s, p)),
        "local minima": each(lambda s, p: _two_sided_ref(s, p, rule="local minima")),
        "no depth": each(lambda s, p: _two_sided_ref(s, p, rule="no depth")),
        "no barrier": each(lambda s, p: _two_sided_ref(s, p, rule="no barrier")),
        "zero left": each(lambda s, p: _two_sided_ref(s, p, left=np.less_equal)),
        "zero right": each(lambda s, p: _two_sided_ref(s, p, right=np.greater_equal)),
        "zero both": each(lambda s, p: _two_sided_ref(s, p, left=np.less_equal, right=np.greater_equal)),
        "mass": each(lambda s, p: min(boltzmann_sides(s, p).values()) >= 0.2),
    }


TWO_SIDED_HINTS = {
    "count": "two valleys on the same side of straight are two ways of turning the same way: the question "
    "is whether both exits are kept, so where the valleys lie matters, not only how many there are.",
    "exactly two": "a third valley (at straight, say) does not undo a valley left and one right: do not ask "
    "for exactly two.",
    "local minima": "every dip of a profile is not a valley: the book keeps only those low enough (the depth "
    "rule) and separated from a lower one by a high enough barrier (the barrier rule).",
    "no depth": "a valley far above the minimum is one the policy almost never picks: apply the depth rule.",
    "no barrier": "two minima that a small bump separates are one valley with a wrinkle: apply the barrier "
    "rule.",
    "zero left": "a valley at straight (steer 0) is neither left nor right: do not count it as left.",
    "zero right": "a valley at straight (steer 0) is neither left nor right: do not count it as right.",
    "zero both": "a valley at straight (steer 0) is neither left nor right: do not count it on either side.",
    "mass": "mass on both sides of straight is not two valleys: one broad valley at straight has it too. "
    "Find the valleys.",
}


def check_two_sided(fn) -> Feedback:
    """Check ``fn(steer, profile)``: a valley (``energy_profiles.valleys``, its defaults) left of straight
    and one right of it."""

    def check() -> Feedback:
        answers = []
        for what, steer, profile in TWO_SIDED_CASES:
            out = fn(steer.copy(), profile.copy())
            if not isinstance(out, (bool, np.bool_)):
                return hint(f"two_sided must return True or False, got {type(out).__name__} for {what}.")
            answers.append(bool(out))
        refs = [_two_sided_ref(s, p) for _, s, p in TWO_SIDED_CASES]
        if answers == refs:
            return correct(
                "That is the reading the chapter counts at every fork and stem approach: two valleys, "
                "one each side of straight."
            )
        for name, mistake in _mistakes_two_sided().items():
            if answers == mistake:
                return hint(TWO_SIDED_HINTS[name])
        if all(answers) or not any(answers):
            return hint(f"your function answers {answers[0]} for every profile: read the profile's valleys.")
        wrong = next(w for (w, _, _), a, r in zip(TWO_SIDED_CASES, answers, refs, strict=True) if a != r)
        return hint(
            f"for a profile with {wrong} your answer is not the book's: find its valleys (within 3 nats of "
            "the minimum, a barrier of at least 1 nat), then where they lie."
        )

    return run_check(check, "`two_sided`")


# --------------------------------------------------------------------------- 3. the minority exit
EXIT_CASES = [
    [(3, 1), (0, 5), (2, 2)],
    [(5, 0), (0, 5)],  # one agent always left, another always right: the method takes both exits
    [(4, 1), (6, 0), (0, 0), (1, 1)],  # an agent that crossed no stem
]


def _summary_ref(counts, *, share="pooled", both="both") -> dict:
    left, right = sum(c[0] for c in counts), sum(c[1] for c in counts)
    crossed = [c for c in counts if c[0] + c[1] > 0]
    if share == "pooled":
        s = float(minority(left / (left + right)))
    elif share == "mean":
        s = float(np.mean([min(c) / sum(c) for c in crossed]))
    elif share == "minima":
        s = sum(min(c) for c in counts) / (left + right)
    else:  # the share of one exit, not the less taken one
        s = {"left": left, "right": right}[share] / (left + right)
    n = sum((c[0] > 0 and c[1] > 0) if both == "both" else (c[0] + c[1] > 0) for c in counts)
    return {"minority": s, "both": n}


SHARE_HINTS = {
    "mean": "an agent with 2 crossings would weigh as much as one with 20: pool the crossings over the "
    "agents.",
    "minima": "the minority is the method's less taken exit over all its crossings: an agent always left and "
    "another always right make a method that takes both exits, though neither agent does.",
    "left": "that is the share of left exits; the minority is the less taken exit's share.",
    "right": "that is the share of right exits; the minority is the less taken exit's share.",
}


def _summary_answer(out) -> dict | Feedback:
    if not isinstance(out, dict) or set(out) != {"minority", "both"}:
        return hint('exit_summary must return a dict with the keys "minority" and "both".')
    share = number_answer(out["minority"], 'exit_summary\'s "minority"')
    if isinstance(share, Feedback):
        return share
    n = out["both"]
    if isinstance(n, (bool, np.bool_)) or not isinstance(n, numbers.Integral):
        return hint(f'"both" must be a number of agents (an int), got {type(n).__name__}.')
    return {"minority": share, "both": int(n)}


def check_exit_summary(fn) -> Feedback:
    """Check ``fn(counts)``: ``{"minority": min(L, R) / (L + R) pooled over the agents, "both": agents with
    left > 0 and right > 0}``."""

    def check() -> Feedback:
        for counts in EXIT_CASES:
            out = _summary_answer(fn([tuple(c) for c in counts]))
            if isinstance(out, Feedback):
                return out
            ref = _summary_ref(counts)
            if not close(out["minority"], ref["minority"], rtol=1e-6, atol=1e-9):
                for share, words in SHARE_HINTS.items():
                    if close(out["minority"], _summary_ref(counts, share=share)["minority"], 1e-6, 1e-9):
                        return hint(words)
                return hint(
                    f"for the counts {counts} your minority share is {out['minority']:.4f}: the share of "
                    "the less taken exit, over every stem crossing of the method's agents."
                )
            if out["both"] != ref["both"]:
                if out["both"] == _summary_ref(counts, both="crossed")["both"]:
                    return hint(
                        "an agent that crossed a stem has not necessarily taken both exits: count the agents "
                        "that took each exit at least once."
                    )
                return hint(
                    f"for the counts {counts} your number of agents that took both exits is {out['both']}: "
                    "go through the agents one by one and check which exits each took."
                )
        return correct(
            "That is the chapter's pooled minority share (its interval resamples agents, then episodes) and "
            "its count of agents that kept both exits in closed loop."
        )

    return run_check(check, "`exit_summary`")
