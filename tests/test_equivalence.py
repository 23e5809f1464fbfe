"""Equivalence within ±δ (``ibc_tutorial.equivalence``) and the crossed bootstrap of agents and starts
(``ibc_tutorial.crossed_bootstrap``): against scipy's t-tests and on data whose verdict is known."""

import numpy as np
import pytest
from scipy import stats as sps

from ibc_tutorial import stats
from ibc_tutorial.crossed_bootstrap import (
    crossed_difference_interval,
    crossed_difference_replicates,
    crossed_mean_interval,
    crossed_means,
    crossed_ratio_interval,
    share_per_start,
)
from ibc_tutorial.equivalence import ALPHA, Equivalence, four_verdicts, judge_difference, tost


# --------------------------------------------------------------------------- TOST against scipy
def test_tost_p_values_match_scipy_welch_t_tests_for_many_units():
    """One value per agent (E = 1), 400 agents per method: the bootstrap's one-sided p-values are those
    of Welch's one-sided t-tests of a - b against -δ and +δ, to the bootstrap's resolution."""
    rng = np.random.default_rng(1)
    a, b = rng.normal(0.1, 1.0, 400), rng.normal(0.0, 1.2, 400)
    delta = 0.25
    j = judge_difference(a[:, None], b[:, None], "A > B", delta, shared_starts=False, n_resamples=40_000)
    est, reps = stats.difference_replicates(a[:, None], b[:, None], n_resamples=40_000)
    eq = tost(est, reps, delta)
    p_lower = sps.ttest_ind(a + delta, b, equal_var=False, alternative="greater").pvalue  # H0: d <= -δ
    p_upper = sps.ttest_ind(a - delta, b, equal_var=False, alternative="less").pvalue  # H0: d >= +δ
    assert 0.01 < p_upper < 0.5 and p_lower < 1e-3  # a case where both p-values say something
    assert eq.p_lower == pytest.approx(p_lower, abs=0.005) and eq.p_upper == pytest.approx(p_upper, abs=0.01)
    assert j.p_equivalent == pytest.approx(max(p_lower, p_upper), abs=0.01)
    assert j.delta == delta and j.verdict == (
        stats.EQUIVALENT if max(p_lower, p_upper) < ALPHA else j.verdict
    )


def test_tost_on_shared_starts_matches_scipy_paired_t_test():
    """One agent per method on 300 shared starts: the crossed bootstrap resamples the starts, so the
    difference is paired by start, and TOST's p-values are those of one-sample t-tests of the per-start
    differences against -δ and +δ (the start effect, shared, cancels)."""
    rng = np.random.default_rng(2)
    start_effect = rng.normal(0.0, 10.0, 300)  # (E,) a hard start lowers both methods
    a = start_effect + rng.normal(0.05, 1.0, 300)
    b = start_effect + rng.normal(0.0, 1.0, 300)
    delta = 0.1
    est, reps = crossed_difference_replicates(a[None], b[None], n_resamples=40_000)
    eq = tost(est, reps, delta)
    d = a - b
    p_lower = sps.ttest_1samp(d, -delta, alternative="greater").pvalue
    p_upper = sps.ttest_1samp(d, delta, alternative="less").pvalue
    assert 0.01 < p_upper < 0.5 and 0.01 < p_lower < 0.5
    assert eq.p_lower == pytest.approx(p_lower, abs=0.01) and eq.p_upper == pytest.approx(p_upper, abs=0.01)


def test_tost_is_the_90_percent_interval_inside_plus_minus_delta():
    """Schuirmann's result, in the bootstrap's form: both one-sided tests reject at α exactly when the
    (1 - 2α) percentile interval lies inside (-δ, +δ)."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        reps = rng.normal(rng.uniform(-1, 1), rng.uniform(0.05, 1.0), 2_000)
        delta = rng.uniform(0.1, 1.5)
        eq = tost(float(reps.mean()), reps, delta)
        inside = -delta < eq.interval.low and eq.interval.high < delta
        near_edge = min(abs(eq.interval.low + delta), abs(eq.interval.high - delta)) < 0.01
        assert eq.equivalent == inside or near_edge
        assert eq.interval.level == pytest.approx(1 - 2 * ALPHA) and eq.p == max(eq.p_lower, eq.p_upper)


# --------------------------------------------------------------------------- verdicts known beforehand
@pytest.mark.parametrize("data_seed", range(5))
def test_the_four_verdicts_on_data_whose_answer_is_known(data_seed):
    """30 agents x 40 starts with a true difference 0: equivalent within ±δ; a true difference of 2δ:
    better (and not equivalent); -2δ: worse; 2 agents x 3 starts of noisy data: cannot tell."""
    rng = np.random.default_rng(data_seed)
    delta = 0.5

    def method(shift, agents, starts, start_effect):
        agent_effect = rng.normal(0.0, 0.5, (agents, 1))  # (A, 1)
        return 10.0 + shift + agent_effect + start_effect[None, :] + rng.normal(0.0, 1.0, (agents, starts))

    starts = rng.normal(0.0, 1.0, 40)  # (E,) shared by both methods
    base = method(0.0, 30, 40, starts)
    for shift, expected in (
        (0.0, stats.EQUIVALENT),
        (2 * delta, stats.HOLDS),
        (-2 * delta, stats.DOES_NOT_HOLD),
    ):
        j = judge_difference(method(shift, 30, 40, starts), base, "A > B", delta, n_resamples=4_000)
        assert j.verdict == expected, (shift, str(j))
    few = rng.normal(0.0, 3.0, 3)
    noisy = judge_difference(
        10 + few + rng.normal(0, 3, (2, 3)), 10 + few + rng.normal(0, 3, (2, 3)), "A > B", delta
    )
    e = noisy.equivalence_interval  # the 90 % interval reaches past ±δ, the 95 % one holds 0
    assert (
        noisy.verdict == stats.CANNOT_TELL
        and noisy.interval.contains(0.0)
        and (e.low < -delta or e.high > delta)
    )


def test_a_small_established_difference_is_equivalent_and_the_rule_reads_its_inputs():
    i = stats.Interval(0.2, 0.1, 0.3)  # 95 %: above 0
    inside = Equivalence(0.5, 0.0, 0.0, stats.Interval(0.2, 0.12, 0.28, 0.9), ALPHA)
    outside = Equivalence(0.25, 0.0, 0.2, stats.Interval(0.2, 0.12, 0.28, 0.9), ALPHA)
    assert four_verdicts(i, inside) == stats.EQUIVALENT  # established, and smaller than δ
    assert four_verdicts(i, outside) == stats.HOLDS
    assert four_verdicts(stats.Interval(0.0, -0.3, 0.3), outside) == stats.CANNOT_TELL
    with pytest.raises(ValueError, match="equivalence"):
        four_verdicts(i, 0.5)
    for call, name in (
        (lambda: tost(0.0, [0.1, 0.2], 0.0), "delta"),
        (lambda: tost(0.0, [], 0.5), "replicates"),
        (lambda: tost(0.0, [0.1, np.nan], 0.5), "replicates"),
        (lambda: tost(0.0, [0.1], 0.5, alpha=0.5), "alpha"),
    ):
        with pytest.raises(ValueError, match=name):
            call()


def test_a_judgement_prints_its_equivalence_test():
    j = judge_difference(np.ones((3, 4)) * 2.0, np.ones((3, 4)), "A > B", 0.5, n_resamples=200)
    assert j.verdict == stats.HOLDS and "±δ = ±0.50" in str(j) and "TOST p = 1.000" in str(j)
    plain = stats.compare(np.ones((3, 4)) * 2.0, np.ones((3, 4)), n_resamples=200)
    assert "TOST" not in str(plain) and plain.delta is None


# --------------------------------------------------------------------------- the crossed bootstrap
def test_crossed_variance_is_agents_plus_starts_for_additive_scores():
    """y_ij = a_i + b_j: the resampled mean is the mean of drawn a plus the mean of drawn b, so its variance
    is Var(a) / A + Var(b) / E (population variances); with the starts kept, Var(a) / A alone."""
    rng = np.random.default_rng(4)
    a, b = rng.normal(0, 2.0, 7), rng.normal(0, 3.0, 10)
    x = a[:, None] + b[None, :]  # (7, 10)
    both = crossed_means(x, 40_000, seed=0)
    agents_only = crossed_means(x, 40_000, seed=0, resample_starts=False)
    assert both.var() == pytest.approx(a.var() / 7 + b.var() / 10, rel=0.03)
    assert agents_only.var() == pytest.approx(a.var() / 7, rel=0.03)
    assert crossed_mean_interval(x).estimate == pytest.approx(x.mean())


def test_a_shared_start_effect_cancels_in_a_difference():
    rng = np.random.default_rng(5)
    starts = rng.normal(0, 50.0, 10)  # (E,) large, shared
    a, c = rng.normal(0, 1.0, 7), rng.normal(0, 1.0, 5)
    xa, xb = a[:, None] + starts, c[:, None] + starts  # (7, 10), (5, 10)
    est, reps = crossed_difference_replicates(xa, xb, n_resamples=40_000)
    assert est == pytest.approx(a.mean() - c.mean())
    assert reps.var() == pytest.approx(a.var() / 7 + c.var() / 5, rel=0.03)  # no trace of the starts
    nested = stats.difference_interval(xa, xb)
    crossed = crossed_difference_interval(xa, xb)
    assert crossed.high - crossed.low < (nested.high - nested.low) / 5


def test_the_expert_ratio_uses_the_same_drawn_starts():
    rng = np.random.default_rng(6)
    expert = rng.uniform(500, 1500, 10)  # (E,)
    x = np.tile(2 * expert, (4, 1))  # (4, 10): every agent scores twice the expert at every start
    r = crossed_ratio_interval(x, expert, n_resamples=500)
    assert [r.estimate, r.low, r.high] == pytest.approx([2.0, 2.0, 2.0], abs=1e-12)
    assert share_per_start(x, expert) == pytest.approx(np.full(10, 2.0))


def test_crossed_interval_covers_with_a_start_effect_where_the_nested_one_does_not():
    """Simulated replications with agent, start and residual effects (7 agents, 10 starts): the crossed
    interval of the mean covers the true mean (the mean over *all* starts) about 95 % of the time or more;
    the nested one, which treats starts as private to an agent, much less."""
    rng = np.random.default_rng(7)
    cover = {"crossed": 0, "nested": 0}
    n = 150
    for k in range(n):
        y = (
            rng.normal(0, 1.0, (7, 1))
            + rng.normal(0, 2.0, (1, 10))
            + rng.normal(0, 1.0, (7, 10))
        )  # fmt: skip
        cover["crossed"] += crossed_mean_interval(y, n_resamples=1_000, seed=k).contains(0.0)
        cover["nested"] += stats.mean_interval(y, n_resamples=1_000, seed=k).contains(0.0)
    assert cover["crossed"] / n >= 0.85 and cover["nested"] / n < 0.8


def test_crossed_bootstrap_refuses_bad_input():
    with pytest.raises(ValueError, match="same starts"):
        crossed_difference_replicates(np.ones((2, 3)), np.ones((2, 4)))
    with pytest.raises(ValueError, match="expert"):
        crossed_ratio_interval(np.ones((2, 3)), [1.0, 1.0])
    with pytest.raises(ValueError, match="expert"):
        share_per_start(np.ones((2, 3)), [1.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="n_resamples"):
        crossed_means(np.ones((2, 3)), 0)
    with pytest.raises(ValueError, match="scores"):
        crossed_means(np.ones(3))


def test_fresh_starts_interval_covers_new_sets_of_starts_as_often_as_its_level():
    """With many observed starts from a known population, 95 % of new 10-start sets fall inside."""
    from ibc_tutorial.crossed_bootstrap import fresh_starts_interval

    rng = np.random.default_rng(3)

    def population(n):  # (3 agents, n starts), (n,) expert: a start effect shared by all, agent offsets
        start = rng.gamma(4.0, 250.0, size=n)  # (n,) the expert's score at each start
        agents = start[None, :] * rng.uniform(0.6, 1.4, size=(1, n)) + np.array([[-50.0], [0.0], [40.0]])
        return np.clip(agents, 1.0, None), start

    scores, expert = population(400)
    iv = fresh_starts_interval(scores, expert, 10, n_resamples=4000, seed=0)
    inside = []
    for _ in range(2000):
        s, e = population(10)
        inside.append(iv.contains(s.mean() / e.mean()))
    assert 0.92 < np.mean(inside) < 0.98
    assert iv.contains(scores.mean() / expert.mean()) and iv.estimate == scores.mean() / expert.mean()
    # the agents are not resampled: identical agents give the same interval as their mean alone
    same = fresh_starts_interval(np.repeat(scores[:1], 3, axis=0), expert, 10, n_resamples=500, seed=1)
    alone = fresh_starts_interval(scores[:1], expert, 10, n_resamples=500, seed=1)
    assert (same.low, same.high) == (alone.low, alone.high)
    # a prediction for 10 new starts is wider than the crossed interval of the 400 observed ones
    from ibc_tutorial.crossed_bootstrap import crossed_ratio_interval

    ci = crossed_ratio_interval(scores, expert, n_resamples=500)
    assert iv.high - iv.low > 3 * (ci.high - ci.low)
    with pytest.raises(ValueError, match="n_starts"):
        fresh_starts_interval(scores, expert, 0)
    with pytest.raises(ValueError, match="expert must be"):
        fresh_starts_interval(scores, expert[:-1])


def test_share_levels_are_the_three_bootstraps_side_by_side():
    from ibc_tutorial.crossed_bootstrap import SHARE_LEVELS, crossed_ratio_interval, share_levels

    rng = np.random.default_rng(0)
    scores, expert = rng.uniform(500, 1200, size=(5, 8)), rng.uniform(600, 1100, size=8)
    levels = share_levels(scores, expert)
    assert tuple(levels) == SHARE_LEVELS
    assert levels[SHARE_LEVELS[0]] == crossed_ratio_interval(scores, expert, resample_starts=False)
    assert levels[SHARE_LEVELS[1]] == stats.ratio_interval(scores, expert)
    assert levels[SHARE_LEVELS[2]] == crossed_ratio_interval(scores, expert)
