"""Checkers of exercises/09_replication.ipynb: solution -> correct, stub -> not attempted,
typical mistakes -> a hint naming the mistake, code that raises -> a hint (never an exception)."""

import numpy as np
import pytest

from ibc_tutorial import stats
from ibc_tutorial.driving.analysis import exit_counts
from ibc_tutorial.exercises import ch09, solutions


def library_difference(a, b, n_resamples, rng):
    """The answer is a library function: ``stats.difference_interval``."""
    iv = stats.difference_interval(a, b, n_resamples=n_resamples, seed=rng)
    return iv.low, iv.high


def looped_difference(a, b, n_resamples, rng):
    """The same bootstrap as a reader may write it, one resample at a time."""
    diffs = []
    for _ in range(n_resamples):
        means = []
        for x in (a, b):
            agents = rng.integers(len(x), size=len(x))
            means.append(np.mean([x[i][rng.integers(x.shape[1], size=x.shape[1])] for i in agents]))
        diffs.append(means[0] - means[1])
    return tuple(np.percentile(diffs, [2.5, 97.5]))


CHECKS = [
    (ch09.check_bootstrap_difference, library_difference),
    (ch09.check_bootstrap_difference, solutions.ch09_bootstrap_difference),
    (ch09.check_exit_shares, solutions.ch09_exit_shares),
    (ch09.check_verdict, solutions.ch09_verdict),
]


@pytest.mark.parametrize("check, solution", CHECKS)
def test_solution_stub_and_crash(check, solution, stub_and_crash):
    assert check(solution).status == "correct"
    stub_and_crash(check)


def test_a_loop_written_bootstrap_and_other_seeds_pass():
    assert ch09.check_bootstrap_difference(looped_difference).status == "correct"
    for seed in range(5):  # the tolerance is not met by luck: other draws of a correct answer pass too

        def other_seed(a, b, n, rng, seed=seed):
            return library_difference(a, b, n, np.random.default_rng([seed, int(rng.integers(1 << 30))]))

        assert ch09.check_bootstrap_difference(other_seed).status == "correct"


def test_exit_shares_solution_matches_the_library_counts():
    visits = ch09._visits()
    counts = exit_counts(visits)
    for ap, c in counts.items():
        shares = solutions.ch09_exit_shares(visits, ap)
        assert shares == {t: n / sum(c.values()) for t, n in c.items()}


# --------------------------------------------------------------------------- typical mistakes
def _boot_mistake(**kwargs):
    def fn(a, b, n, rng):
        return ch09._q(ch09._boot(a, n, rng, **kwargs) - ch09._boot(b, n, rng, **kwargs))

    return fn


def _shared(a, b, n, rng):
    idx = (rng.integers(a.shape[0], size=(n, a.shape[0])), rng.integers(a.shape[1], size=(n, *a.shape)))
    return ch09._q(ch09._boot(a, n, rng, idx=idx) - ch09._boot(b, n, rng, idx=idx))


def _unseeded(a, b, n, rng):
    return library_difference(a, b, n, np.random.default_rng())


BOOT_MISTAKES = {
    "pooled episodes": (_boot_mistake(pooled=True), "one pool"),
    "agent means only": (_boot_mistake(episodes=False), "within each drawn agent"),
    "episodes only": (_boot_mistake(agents=False), "draw the agents with replacement"),
    "B - A": (lambda a, b, n, rng: tuple(-v for v in library_difference(a, b, n, rng))[::-1], "the sign"),
    "90 %": (
        lambda a, b, n, rng: ch09._q(
            stats.bootstrap_means(a, n, rng) - stats.bootstrap_means(b, n, rng), 0.9
        ),
        "2.5th to the 97.5th",
    ),
    "mean of A only": (lambda a, b, n, rng: ch09._q(stats.bootstrap_means(a, n, rng)), "mean(A) alone"),
    "shared draws": (_shared, "independently"),
    "ignores the generator": (_unseeded, "generator"),
    "high before low": (lambda a, b, n, rng: library_difference(a, b, n, rng)[::-1], "low <= high"),
    "one number": (lambda a, b, n, rng: 3.0, "two numbers"),
    "nan": (lambda a, b, n, rng: (np.nan, 1.0), "NaN"),
    "a normal interval": (
        lambda a, b, n, rng: (a.mean() - b.mean() - 200.0, a.mean() - b.mean() + 200.0),
        "two levels of the resampling",
    ),
}


@pytest.mark.parametrize("name", list(BOOT_MISTAKES))
def test_bootstrap_difference_mistakes(name):
    fn, words = BOOT_MISTAKES[name]
    fb = ch09.check_bootstrap_difference(fn)
    assert fb.status == "hint" and words in fb.message, fb.message


def _shares(**kwargs):
    def fn(visits, approach):
        node = next(v["node"] for v in visits if v["approach"] == approach)
        return ch09._shares_ref(visits, approach, node=node, **kwargs)

    return fn


def _only_taken(visits, approach):
    return {t: s for t, s in solutions.ch09_exit_shares(visits, approach).items() if s > 0}


SHARE_MISTAKES = {
    "counts": (_shares(counts=True), "those are counts"),
    "over all visits": (_shares(all_visits=True), "this approach"),
    "by node": (_shares(key="node"), "'approach' is the one asked"),
    "exits never taken left out": (_only_taken, "0 for one that was never taken"),
    "a list": (lambda visits, approach: [0.5, 0.5, 0.0], "must return a dict"),
    "other keys": (lambda visits, approach: {"l": 1.0, "s": 0.0, "r": 0.0}, "keys must be exactly"),
    "uniform": (
        lambda visits, approach: {"left": 1 / 3, "straight": 1 / 3, "right": 1 / 3},
        "count its visits",
    ),
}


@pytest.mark.parametrize("name", list(SHARE_MISTAKES))
def test_exit_shares_mistakes(name):
    fn, words = SHARE_MISTAKES[name]
    fb = ch09.check_exit_shares(fn)
    assert fb.status == "hint" and words in fb.message, fb.message


# --------------------------------------------------------------------------- 3. the verdict
def library_verdict(estimate, low, high, threshold):
    """The answer is a library function: ``stats.verdict`` of the interval."""
    return stats.verdict(stats.Interval(estimate, low, high), threshold)


def test_verdict_library_stub_and_crash(stub_and_crash):
    assert ch09.check_verdict(library_verdict).status == "correct"
    stub_and_crash(ch09.check_verdict)


def _inclusive(est, lo, hi, t):
    return "holds" if lo >= t else ("does not hold" if hi <= t else "cannot tell at this scale")


VERDICT_MISTAKES = {
    "the estimate decides": (
        lambda est, lo, hi, t: "holds" if est > t else "does not hold",
        "ordering does not decide",
    ),
    "containing means no": (
        lambda est, lo, hi, t: "holds" if lo > t else "does not hold",
        "contains the threshold",
    ),
    "an end on the threshold": (_inclusive, "ends exactly on the threshold"),
    "swapped": (
        lambda est, lo, hi, t: {"holds": "does not hold", "does not hold": "holds"}.get(
            library_verdict(est, lo, hi, t), "cannot tell at this scale"
        ),
        "whole interval lies",
    ),
    "a bool": (lambda est, lo, hi, t: lo > t, "three strings"),
    "another word": (lambda est, lo, hi, t: "unclear", "must return"),
}


@pytest.mark.parametrize("name", list(VERDICT_MISTAKES))
def test_verdict_mistakes(name):
    fn, words = VERDICT_MISTAKES[name]
    fb = ch09.check_verdict(fn)
    assert fb.status == "hint" and words in fb.message, fb.message


def _symmetric_interval(kind):
    """The two-level bootstrap's differences, read as mean ± 1.96 sd or reflected about the estimate."""

    def fn(a, b, n, rng):
        ref = solutions.ch09_bootstrap_difference(a, b, n, rng)  # consumes rng like the reference
        diffs = []
        for x in (a, b):
            agents = rng.integers(len(x), size=(n, len(x)))
            episodes = rng.integers(x.shape[1], size=(n, len(x), x.shape[1]))
            diffs.append(x[agents[:, :, None], episodes].mean(axis=(1, 2)))
        d = diffs[0] - diffs[1]
        if kind == "normal":
            return d.mean() - 1.96 * d.std(), d.mean() + 1.96 * d.std()
        estimate = a.mean() - b.mean()
        return 2 * estimate - ref[1], 2 * estimate - ref[0]

    return fn


@pytest.mark.parametrize("kind", ["normal", "basic"])
def test_bootstrap_symmetric_intervals_get_a_hint_about_the_percentiles(kind):
    """With one agent far from its siblings the differences are skewed: mean ± 1.96 sd and the 'basic'
    bootstrap's reflection both passed when every case was nearly symmetric."""
    fb = ch09.check_bootstrap_difference(_symmetric_interval(kind))
    assert fb.status == "hint" and "percentiles" in fb.message, fb.message


def test_verdict_by_width_and_estimate_gets_a_hint():
    """'Cannot tell when the interval is wider than twice the distance of the estimate from the
    threshold, else the estimate's side' is the rule itself for intervals symmetric about the estimate."""

    def fn(estimate, low, high, threshold):
        if high - low > 2 * abs(estimate - threshold):
            return "cannot tell at this scale"
        return "holds" if estimate > threshold else "does not hold"

    fb = ch09.check_verdict(fn)
    assert fb.status == "hint" and "whole interval lies" in fb.message, fb.message


def test_verdict_with_the_upper_end_non_strict_gets_a_hint():
    """'does not hold' for an interval ending exactly on the threshold: no case had its upper end there."""

    def fn(estimate, low, high, threshold):
        if low > threshold:
            return "holds"
        if high <= threshold:
            return "does not hold"
        return "cannot tell at this scale"

    fb = ch09.check_verdict(fn)
    assert fb.status == "hint" and "ends exactly on the threshold" in fb.message, fb.message
