"""Checkers of exercises/04_da_ibc_negatives.ipynb: solution -> correct, stub -> not attempted,
typical mistakes -> a hint naming the mistake, code that raises -> a hint (never an exception)."""

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from ibc_tutorial.exercises import ch04, solutions
from ibc_tutorial.metrics import grid_nll
from ibc_tutorial.negatives import expert_negatives, uniform_negatives


@pytest.mark.parametrize(
    "checker", [ch04.check_expert_negatives, ch04.check_grid_nll, ch04.check_predicted_shares]
)
def test_stub_is_not_attempted_and_a_crash_is_a_hint(checker, stub_and_crash):
    stub_and_crash(checker)


# --------------------------------------------------------------------------- the DA-IBC sampler
def test_sampler_solution_and_library_are_correct():
    assert ch04.check_expert_negatives(solutions.ch04_expert_negatives).status == "correct"
    assert ch04.check_expert_negatives(expert_negatives).status == "correct"


def _draw(a, b, n, g):
    return a[torch.randint(0, len(a), (b, n), generator=g)]


SAMPLER_MISTAKES = {
    "uniform": (
        lambda a, b, n, s, g=None: uniform_negatives(
            b, n, [-1.0] * a.shape[1], [1.0] * a.shape[1], generator=g
        ),
        "exactly one of the expert actions",
    ),
    "sigma as variance": (
        lambda a, b, n, s, g=None: _draw(a, b, n, g) + s**2 * torch.randn(b, n, a.shape[1], generator=g),
        "standard deviation",
    ),
    "sqrt sigma": (
        lambda a, b, n, s, g=None: (
            _draw(a, b, n, g) + math.sqrt(s) * torch.randn(b, n, a.shape[1], generator=g)
        ),
        "standard deviation",
    ),
    "no noise": (lambda a, b, n, s, g=None: _draw(a, b, n, g), "no noise"),
    "without replacement": (
        lambda a, b, n, s, g=None: (
            torch.stack([a[torch.randperm(len(a), generator=g)[:n]] for _ in range(b)])
            + s * torch.randn(b, n, a.shape[1], generator=g)
        ),
        "with replacement",
    ),
    "same set for every sample": (
        lambda a, b, n, s, g=None: (
            a[torch.randint(0, len(a), (n,), generator=g)] + s * torch.randn(n, a.shape[1], generator=g)
        ).expand(b, n, a.shape[1]),
        "fresh set",
    ),
    "only the first actions": (
        lambda a, b, n, s, g=None: (
            a[torch.randint(0, max(1, len(a) // 2), (b, n), generator=g)]
            + s * torch.randn(b, n, a.shape[1], generator=g)
        ),
        "equal probability",
    ),
    "ignores generator": (
        lambda a, b, n, s, g=None: _draw(a, b, n, None) + s * torch.randn(b, n, a.shape[1]),
        "generator",
    ),
    "wrong order": (
        lambda a, b, n, s, g=None: (
            _draw(a, b, n, g) + s * torch.randn(b, n, a.shape[1], generator=g)
        ).transpose(0, 1),
        "shape",
    ),
    "biased noise": (
        lambda a, b, n, s, g=None: _draw(a, b, n, g) + s * torch.rand(b, n, a.shape[1], generator=g),
        "mean 0",
    ),
    # the right variance, the wrong shape: uniform on [−√3 σ, √3 σ], Laplace with scale σ/√2
    "uniform noise of variance σ²": (
        lambda a, b, n, s, g=None: (
            _draw(a, b, n, g) + s * math.sqrt(3) * (2 * torch.rand(b, n, a.shape[1], generator=g) - 1)
        ),
        "Gaussian shape",
    ),
    "Laplace noise of variance σ²": (
        lambda a, b, n, s, g=None: (
            _draw(a, b, n, g)
            + s
            / math.sqrt(2)
            * torch.sign(torch.rand(b, n, a.shape[1], generator=g) - 0.5)
            * -torch.log(torch.rand(b, n, a.shape[1], generator=g))
        ),
        "Gaussian shape",
    ),
    "one noise value for both coordinates": (
        lambda a, b, n, s, g=None: _draw(a, b, n, g) + s * torch.randn(b, n, 1, generator=g),
        "correlated",
    ),
    "clipped to the box": (
        lambda a, b, n, s, g=None: (_draw(a, b, n, g) + s * torch.randn(b, n, a.shape[1], generator=g)).clamp(
            -1, 1
        ),
        "do not clip",
    ),
}


@pytest.mark.parametrize("name", list(SAMPLER_MISTAKES))
def test_sampler_mistakes(name):
    fn, words = SAMPLER_MISTAKES[name]
    fb = ch04.check_expert_negatives(fn)
    assert fb.status == "hint" and words in fb.message, (name, fb)


# --------------------------------------------------------------------------- grid NLL
def test_grid_nll_solution_and_library_are_correct():
    assert ch04.check_grid_nll(solutions.ch04_grid_nll).status == "correct"
    assert ch04.check_grid_nll(grid_nll).status == "correct"


NLL_MISTAKES = {
    "no cell area": (lambda p, e, c: p + torch.logsumexp(-e, 1), "cell area"),
    "cell sign": (lambda p, e, c: p + torch.logsumexp(-e, 1) - math.log(c), "sign"),
    "mean not sum": (lambda p, e, c: p + torch.logsumexp(-e, 1) - math.log(e.shape[1]) + math.log(c), "sums"),
    "energy sign": (lambda p, e, c: -p + torch.logsumexp(e, 1) + math.log(c), "sign of the energies"),
    "unstable": (lambda p, e, c: p + torch.log(torch.exp(-e).sum(1)) + math.log(c), "logsumexp"),
    "averaged": (lambda p, e, c: (p + torch.logsumexp(-e, 1) + math.log(c)).mean(), "one NLL per sample"),
}


@pytest.mark.parametrize("name", list(NLL_MISTAKES))
def test_grid_nll_mistakes(name):
    fn, words = NLL_MISTAKES[name]
    fb = ch04.check_grid_nll(fn)
    assert fb.status == "hint" and words in fb.message, (name, fb)


# --------------------------------------------------------------------------- the tilt of a DA-IBC landscape
def _q(modes, actions, s):
    from ibc_tutorial.kde import kde_density

    return kde_density(modes, actions, s)


SHARE_MISTAKES = {
    "the expert's thirds": (lambda m, a, s: torch.full((len(m),), 1 / len(m)), "p(y|x)"),
    "proportional to q": (lambda m, a, s: _q(m, a, s) / _q(m, a, s).sum(), "wrong way round"),
    "chapter 05's bandwidth": (
        lambda m, a, s: (1 / _q(m, a, 0.2)) / (1 / _q(m, a, 0.2)).sum(),
        "bandwidth σ",
    ),
    "not normalised": (lambda m, a, s: 1 / _q(m, a, s), "sum to 1"),
    "fixed sigma": (lambda m, a, s: (1 / _q(m, a, 0.1)) / (1 / _q(m, a, 0.1)).sum(), "σ = 0.3"),
    "wrong shape": (lambda m, a, s: torch.ones(2), "shape"),
}


def test_predicted_shares_solution_is_correct():
    assert ch04.check_predicted_shares(solutions.ch04_predicted_shares).status == "correct"


@pytest.mark.parametrize("name", list(SHARE_MISTAKES))
def test_predicted_shares_mistakes(name):
    fn, words = SHARE_MISTAKES[name]
    fb = ch04.check_predicted_shares(fn)
    assert fb.status == "hint" and words in fb.message, fb.message


def test_grid_nll_with_the_expert_among_the_grid_gets_a_hint():
    """Z(x) over the grid and the expert's action too: the first sample's NLL agrees to four digits, and
    the hint used to quote that sample."""

    def fn(p, e, c):
        return p + torch.logsumexp(torch.cat([-p[:, None], -e], 1), 1) + math.log(c)

    fb = ch04.check_grid_nll(fn)
    assert fb.status == "hint" and "grid points alone" in fb.message, fb.message


@settings(max_examples=30, deadline=None)
@given(k=st.integers(0, 5), offset=st.one_of(st.floats(-5.0, -0.05), st.floats(0.05, 5.0)))
def test_grid_nll_hint_quotes_a_sample_the_answer_gets_wrong(k, offset):
    """An answer wrong at one sample only: the fallback hint names that sample, never one it got right."""

    def fn(p, e, c):
        out = solutions.ch04_grid_nll(p, e, c).clone()
        out[k] += offset
        return out

    fb = ch04.check_grid_nll(fn)
    assert fb.status == "hint", fb.message
    if "sample" in fb.message:
        assert f"sample {k} " in fb.message, fb.message


def _distinct_rows(acts, b, n, sigma, generator=None):
    """Draws from the set's distinct actions, as if repeated ones were one."""
    rows = torch.unique(acts, dim=0)
    idx = torch.randint(0, len(rows), (b, n), generator=generator)
    return rows[idx] + sigma * torch.randn(b, n, acts.shape[1], generator=generator)


@settings(max_examples=10, deadline=None)
@given(batch_size=st.integers(1, 39))
def test_sampler_that_draws_from_the_first_rows_only_gets_a_hint(batch_size):
    """Rows drawn among the first ``batch_size`` (or fewer) of the expert set: correct while the set is no
    larger than the batch, which every case was."""

    def fn(acts, b, n, sigma, generator=None):
        idx = torch.randint(0, min(batch_size, len(acts)), (b, n), generator=generator)
        return acts[idx] + sigma * torch.randn(b, n, acts.shape[1], generator=generator)

    fb = ch04.check_expert_negatives(fn)
    assert fb.status == "hint", fb.message


def test_sampler_over_distinct_actions_gets_a_hint():
    fb = ch04.check_expert_negatives(_distinct_rows)
    assert fb.status == "hint" and "repeated actions included" in fb.message, fb.message


def test_grid_nll_with_the_chapters_cell_area_hard_coded_gets_a_hint():
    """The chapter's cell area, 0.04, fixed in the code: the checker's only area used to be 0.04."""
    fb = ch04.check_grid_nll(lambda p, e, c: solutions.ch04_grid_nll(p, e, (2 / 10) ** 2))
    assert fb.status == "hint" and "use the `cell_volume` you are given" in fb.message, fb.message
