"""Checkers of exercises/03_energy_models.ipynb: solution -> correct, stub -> not attempted,
typical mistakes -> a hint naming the mistake, code that raises -> a hint (never an exception)."""

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from ibc_tutorial.exercises import ch03, solutions
from ibc_tutorial.losses import info_nce, soft_targets
from ibc_tutorial.metrics import whiteness


def stub(*args, **kwargs):
    raise NotImplementedError


def raises(*args, **kwargs):
    raise IndexError("list index out of range")


# --------------------------------------------------------------------------- InfoNCE
def test_info_nce_solution_and_library_are_correct():
    assert ch03.check_info_nce(solutions.ch03_info_nce).status == "correct"
    assert ch03.check_info_nce(info_nce).status == "correct"


def test_info_nce_stub_and_crash():
    assert ch03.check_info_nce(stub).status == "not attempted"
    fb = ch03.check_info_nce(raises)
    assert fb.status == "hint" and "IndexError" in fb.message


def _terms(pos, neg):
    return torch.logsumexp(torch.cat([-pos[:, None], -neg], 1), 1) + pos


NCE_MISTAKES = {
    "sign of energies": (
        lambda p, n, w=None: (torch.logsumexp(torch.cat([p[:, None], n], 1), 1) - p).mean(),
        "softmax of −E",
    ),
    "no positive in denominator": (lambda p, n, w=None: (torch.logsumexp(-n, 1) + p).mean(), "denominator"),
    "sum over batch": (lambda p, n, w=None: _terms(p, n).sum(), "average"),
    "unstable": (
        lambda p, n, w=None: (
            (-torch.log(torch.exp(-p) / (torch.exp(-p) + torch.exp(-n).sum(1)))).mean()
            if w is None
            else (w * -torch.log(torch.exp(-p) / (torch.exp(-p) + torch.exp(-n).sum(1)))).mean()
        ),
        "log-sum-exp",
    ),
    "ignores weights": (lambda p, n, w=None: _terms(p, n).mean(), "ignores `weights`"),
    "weighted average": (
        lambda p, n, w=None: _terms(p, n).mean() if w is None else (w * _terms(p, n)).sum() / w.sum(),
        "sum of the weights",
    ),
    "vector": (lambda p, n, w=None: _terms(p, n), "scalar"),
    "python float": (lambda p, n, w=None: float(_terms(p, n).mean()), "Python number"),
    "detached": (
        lambda p, n, w=None: (
            _terms(p, n).mean().detach() if w is None else (w * _terms(p, n)).mean().detach()
        ),
        "autograd",
    ),
}


@pytest.mark.parametrize("name", list(NCE_MISTAKES))
def test_info_nce_mistakes_get_a_hint_naming_them(name):
    fn, words = NCE_MISTAKES[name]
    fb = ch03.check_info_nce(fn)
    assert fb.status == "hint", (name, fb)
    assert words in fb.message, (name, fb.message)


# --------------------------------------------------------------------------- soft targets
def test_soft_targets_solution_and_library_are_correct():
    assert ch03.check_soft_targets(solutions.ch03_soft_targets).status == "correct"
    assert ch03.check_soft_targets(soft_targets).status == "correct"


def test_soft_targets_stub_and_crash():
    assert ch03.check_soft_targets(stub).status == "not attempted"
    assert ch03.check_soft_targets(raises).status == "hint"


def _sq(c, a):
    return ((c[None] - a[:, None]) ** 2).sum(-1)


SOFT_MISTAKES = {
    "transcription sign": (lambda c, a, t: torch.softmax(_sq(c, a) / t, 1), "farthest"),
    "distance not squared": (lambda c, a, t: torch.softmax(-_sq(c, a).sqrt() / t, 1), "squared"),
    "times temperature": (lambda c, a, t: torch.softmax(-_sq(c, a) * t, 1), "divide by T"),
    "softmax over batch": (lambda c, a, t: torch.softmax(-_sq(c, a) / t, 0), "sum to 1"),
    "only first dim": (lambda c, a, t: torch.softmax(-((c[None, :, 0] - a[:, None, 0]) ** 2) / t, 1), "2-D"),
    "wrong shape": (lambda c, a, t: torch.softmax(-_sq(c, a) / t, 1).T, "shape"),
}


@pytest.mark.parametrize("name", list(SOFT_MISTAKES))
def test_soft_targets_mistakes(name):
    fn, words = SOFT_MISTAKES[name]
    fb = ch03.check_soft_targets(fn)
    assert fb.status == "hint" and words in fb.message, (name, fb)


# --------------------------------------------------------------------------- whiteness
def test_whiteness_solution_and_library_are_correct():
    assert ch03.check_whiteness(solutions.ch03_whiteness).status == "correct"
    assert ch03.check_whiteness(whiteness).status == "correct"


def test_whiteness_stub_and_crash():
    assert ch03.check_whiteness(stub).status == "not attempted"
    assert ch03.check_whiteness(raises).status == "hint"


WHITE_MISTAKES = {
    "no dt": (lambda x, dt: float(np.sqrt(np.mean(np.diff(np.asarray(x)) ** 2))), "time step"),
    "no sqrt": (lambda x, dt: float(np.mean((np.diff(np.asarray(x)) / dt) ** 2)), "square root"),
    "divide by T": (
        lambda x, dt: float(np.sqrt(np.sum((np.diff(np.asarray(x)) / dt) ** 2) / len(x))),
        "number of changes",
    ),
    "std of commands": (lambda x, dt: float(np.std(np.asarray(x)) / dt), "changes"),
    "mean abs": (lambda x, dt: float(np.mean(np.abs(np.diff(np.asarray(x)) / dt))), "squared"),
    "returns array": (lambda x, dt: np.diff(np.asarray(x)) / dt, "number"),
}


@pytest.mark.parametrize("name", list(WHITE_MISTAKES))
def test_whiteness_mistakes(name):
    fn, words = WHITE_MISTAKES[name]
    fb = ch03.check_whiteness(fn)
    assert fb.status == "hint" and words in fb.message, (name, fb)
    assert math.isfinite(len(fb.message))


# --------------------------------------------------------------------------- the finding, predicted
def test_decision_prediction_solution_is_correct_and_matches_the_data():
    ref = ch03.decision_reference()
    assert 0.2 < ref["mse"] < 0.5 and ref["mae"] > 0.7 and ref["argmin"] == "right"
    assert abs(ref["sample_right"] - ch03.DECISION_RIGHT_PROB) < 0.05
    assert ch03.check_decision_prediction(solutions.ch03_predict_decision).status == "correct"
    exact = dict(ref)
    assert ch03.check_decision_prediction(lambda: exact).status == "correct"


def test_decision_prediction_stub_and_crash():
    assert ch03.check_decision_prediction(stub).status == "not attempted"
    fb = ch03.check_decision_prediction(raises)
    assert fb.status == "hint" and "IndexError" in fb.message


GOOD = {"mse": 0.35, "mae": 0.85, "argmin": "right", "sample_right": 0.7}
DECISION_MISTAKES = {
    "mean of the modes unweighted": ({"mse": 0.0}, "weighted"),
    "mse as the median": ({"mse": 0.85}, "mean"),
    "mae as the mean": ({"mae": 0.35}, "median"),
    "mae on the minority side": ({"mae": -0.85}, "more than half"),
    "argmin on the minority side": ({"argmin": "left"}, "most probable"),
    "sampling always the deeper valley": ({"sample_right": 1.0}, "as often as the experts"),
    "sampling at 50/50": ({"sample_right": 0.5}, "shares"),
    "not a side": ({"argmin": "straight"}, '"right" or "left"'),
    "not a number": ({"mse": "zero"}, "numbers"),
}


@pytest.mark.parametrize("name", list(DECISION_MISTAKES))
def test_decision_prediction_mistakes_get_a_hint_naming_them(name):
    change, words = DECISION_MISTAKES[name]
    fb = ch03.check_decision_prediction(lambda: {**GOOD, **change})
    assert fb.status == "hint", (name, fb)
    assert words in fb.message, (name, fb.message)


def test_decision_prediction_wrong_keys():
    fb = ch03.check_decision_prediction(lambda: {"mse": 0.35})
    assert fb.status == "hint" and "keys" in fb.message


# --------------------------------------------------------------------------- holes closed (issue 26)
@pytest.mark.parametrize(
    "wrong",
    [
        lambda x, dt: float(np.std(np.diff(np.asarray(x)) / dt)),  # 0 for any steady ramp
        lambda x, dt: float((torch.diff(torch.as_tensor(x)) / dt).std()),  # the same, unbiased
    ],
)
def test_whiteness_as_the_spread_of_the_rates_gets_a_hint(wrong):
    fb = ch03.check_whiteness(wrong)
    assert fb.status == "hint" and "spread" in fb.message, fb.message


@settings(max_examples=20, deadline=None)
@given(rate=st.floats(-5.0, 5.0).filter(lambda r: abs(r) > 0.05), n=st.integers(3, 40))
def test_whiteness_of_a_ramp_is_its_rate(rate, n):
    """The property the checker now tests: a steady ramp's whiteness is |its rate| (the solution and
    the library agree), while the rates' standard deviation is 0."""
    dt = 0.1
    x = rate * dt * np.arange(n)
    assert math.isclose(solutions.ch03_whiteness(torch.tensor(x), dt), abs(rate), rel_tol=1e-9)
    assert math.isclose(whiteness(x, dt), abs(rate), rel_tol=1e-6)
    assert float(np.std(np.diff(x) / dt)) < 1e-9 * max(1.0, abs(rate))
