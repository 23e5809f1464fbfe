"""Checkers of exercises/05_kde_weighting.ipynb: solution -> correct, stub -> not attempted,
typical mistakes -> a hint naming the mistake, code that raises -> a hint (never an exception)."""

import math

import pytest
import torch

from ibc_tutorial import kde
from ibc_tutorial.exercises import ch05, solutions


@pytest.mark.parametrize(
    "checker", [ch05.check_kde_1d, ch05.check_inverse_weights, ch05.check_choose_bandwidth]
)
def test_stub_is_not_attempted_and_a_crash_is_a_hint(checker, stub_and_crash):
    stub_and_crash(checker)


def test_kde_1d_solution_and_library_are_correct():
    assert ch05.check_kde_1d(solutions.ch05_kde_1d).status == "correct"
    assert (
        ch05.check_kde_1d(lambda x, data, h: kde.kde_density(x[:, None], data[:, None], h)).status
        == "correct"
    )


def _k(x, data, h, half=0.5, const=True):
    u = (x[:, None] - data[None, :]) / h
    k = torch.exp(-half * u**2)
    return k / math.sqrt(2 * math.pi) if const else k


KDE_MISTAKES = {
    "no 1/h": (lambda x, d, h: _k(x, d, h).sum(1) / len(d), "1/h is missing"),
    "no 1/N": (lambda x, d, h: _k(x, d, h).sum(1) / h, "number of data points"),
    "no kernel constant": (
        lambda x, d, h: _k(x, d, h, const=False).sum(1) / (len(d) * h),
        "constant in front",
    ),
    "exponent without 1/2": (lambda x, d, h: _k(x, d, h, half=1.0).sum(1) / (len(d) * h), "exponent"),
    "h squared": (lambda x, d, h: _k(x, d, h * h).sum(1) / (len(d) * h * h), "not h²"),
    "hard-coded h": (lambda x, d, h: solutions.ch05_kde_1d(x, d, 0.2), "hard-coding"),
    "wrong shape": (lambda x, d, h: solutions.ch05_kde_1d(x, d, h)[:, None], "shape"),
    "numpy": (lambda x, d, h: solutions.ch05_kde_1d(x, d, h).numpy(), "torch.Tensor"),
}


@pytest.mark.parametrize("name", list(KDE_MISTAKES))
def test_kde_1d_mistakes_get_a_hint_naming_them(name):
    fn, words = KDE_MISTAKES[name]
    fb = ch05.check_kde_1d(fn)
    assert fb.status == "hint", (name, fb)
    assert words in fb.message, (name, fb.message)


def test_kde_1d_hint_does_not_give_the_answer():
    fb = ch05.check_kde_1d(KDE_MISTAKES["no kernel constant"][0])
    assert "sqrt" not in fb.message and "2π" not in fb.message


def test_inverse_weights_solution_and_library_are_correct():
    assert ch05.check_inverse_weights(solutions.ch05_inverse_weights).status == "correct"
    assert ch05.check_inverse_weights(lambda a, h: kde.inverse_density_weights(a, h)).status == "correct"


def _g(a, h):
    return kde.kde_density(a, a, h).double()


WEIGHT_MISTAKES = {
    "not normalised": (lambda a, h: 1 / _g(a, h), "sum to 1"),
    "proportional to density": (lambda a, h: _g(a, h) / _g(a, h).sum(), "*rare* actions"),
    "uniform": (lambda a, h: torch.full((len(a),), 1 / len(a)), "rare actions should get larger weights"),
    "first dimension only": (
        lambda a, h: (1 / _g(a[:, :1], h)) / (1 / _g(a[:, :1], h)).sum(),
        "D dimensions",
    ),
    "hard-coded h": (lambda a, h: kde.inverse_density_weights(a, 0.2), "use the bandwidth"),
}


@pytest.mark.parametrize("name", list(WEIGHT_MISTAKES))
def test_inverse_weights_mistakes_get_a_hint_naming_them(name):
    fn, words = WEIGHT_MISTAKES[name]
    fb = ch05.check_inverse_weights(fn)
    assert fb.status == "hint", (name, fb)
    assert words in fb.message, (name, fb.message)


# -------------------------------------------------------------- choosing a bandwidth by effective sample size
def _table(actions, rare, candidates):
    out = {}
    for h in candidates:
        w = kde.inverse_density_weights(actions, h)
        out[h] = (float(w[rare].sum()), float(1 / (w**2).sum()))
    return out


def _ignore_ess(actions, rare, candidates, min_ess):
    t = _table(actions, rare, candidates)
    return max(candidates, key=lambda h: t[h][0])


def _max_ess(actions, rare, candidates, min_ess):
    t = _table(actions, rare, candidates)
    return max(candidates, key=lambda h: t[h][1])


def _ess_without_square(actions, rare, candidates, min_ess):
    best, share = candidates[-1], -1.0
    for h in candidates:
        w = kde.inverse_density_weights(actions, h)
        if (
            float(1 / w.abs().max()) >= min_ess and float(w[rare].sum()) > share
        ):  # 1/max w, not 1/Σw²: too strict
            best, share = h, float(w[rare].sum())
    return best


def _smallest_passing(actions, rare, candidates, min_ess):
    t = _table(actions, rare, candidates)
    return min(h for h in candidates if t[h][1] >= min_ess)


BANDWIDTH_MISTAKES = {
    "ignores the effective sample size": (_ignore_ess, "effective sample size is only"),
    "largest effective sample size": (_max_ess, "nearly uniform"),
    "another ESS formula": (_ess_without_square, "nearly uniform"),
    "the paper's h whatever the data": (lambda a, r, c, m: 0.2, "compute it as 1 / Σ w_i²"),
    "smallest passing bandwidth": (_smallest_passing, "passes it too"),
    "index instead of bandwidth": (lambda a, r, c, m: 4, "not its index"),
    "not a candidate": (lambda a, r, c, m: 0.25, "not one of the candidates"),
    "not a number": (lambda a, r, c, m: "0.2", "one bandwidth"),
    "fixed answer": (lambda a, r, c, m: 0.3, "use the min_ess you are given"),
}


def test_choose_bandwidth_solution_is_correct():
    assert ch05.check_choose_bandwidth(solutions.ch05_choose_bandwidth).status == "correct"


@pytest.mark.parametrize("name", list(BANDWIDTH_MISTAKES))
def test_choose_bandwidth_mistakes(name):
    fn, words = BANDWIDTH_MISTAKES[name]
    fb = ch05.check_choose_bandwidth(fn)
    assert fb.status == "hint" and words in fb.message, fb.message


def test_choose_bandwidth_with_a_hard_coded_floor_is_told_to_use_min_ess():
    """min_ess hard-coded to the first case's 200: the hint names the floor, not the share comparison
    (which the answer gets right)."""
    fb = ch05.check_choose_bandwidth(lambda a, r, c, m: solutions.ch05_choose_bandwidth(a, r, c, 200.0))
    assert fb.status == "hint" and "use the min_ess you are given" in fb.message, fb.message


def test_choose_bandwidth_with_a_wrong_effective_sample_size_is_not_sent_to_the_shares_alone():
    """An effective sample size of the unnormalised weights (M w) rejects every candidate: the hint names
    the test as well as the shares."""
    from ibc_tutorial.kde import inverse_density_weights

    def fn(actions, rare, candidates, min_ess):
        ok = [
            h
            for h in candidates
            if float(1 / ((len(actions) * inverse_density_weights(actions, h)) ** 2).sum()) >= min_ess
        ]
        return (
            max(ok, key=lambda h: float(inverse_density_weights(actions, h)[rare].sum()))
            if ok
            else candidates[0]
        )

    fb = ch05.check_choose_bandwidth(fn)
    assert fb.status == "hint" and "normalised to sum to 1" in fb.message, fb.message
