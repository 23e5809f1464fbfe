"""ibc_tutorial.stats: the two-level bootstrap against hand-computed and scipy-computed cases, the
verdict rule, the stratified permutation test of exits, and reading a replication folder."""

import numpy as np
import pytest
import scipy.stats

from ibc_tutorial import stats
from ibc_tutorial.driving.analysis import exit_counts


# --------------------------------------------------------------------------- the bootstrap, hand-computed
def test_one_agent_two_episodes_gives_the_exact_distribution():
    # one agent, episodes {0, 1}: the mean of two draws is 0, 0.5, 1 with probabilities 1/4, 1/2, 1/4
    reps = stats.bootstrap_means([[0.0, 1.0]], n_resamples=40_000, seed=1)
    values, counts = np.unique(reps, return_counts=True)
    assert values.tolist() == [0.0, 0.5, 1.0]
    assert np.allclose(counts / len(reps), [0.25, 0.5, 0.25], atol=0.01)
    iv = stats.mean_interval([[0.0, 1.0]], n_resamples=40_000, seed=1)
    assert (iv.estimate, iv.low, iv.high) == (0.5, 0.0, 1.0)


def test_agents_are_resampled_not_only_episodes():
    # two agents, each the same in every episode: resampling pooled episodes within agents alone
    # would give a zero-width interval; drawing agents gives 0, 0.5 and 1 as above
    reps = stats.bootstrap_means([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], n_resamples=40_000, seed=2)
    values, counts = np.unique(reps, return_counts=True)
    assert values.tolist() == [0.0, 0.5, 1.0]
    assert np.allclose(counts / len(reps), [0.25, 0.5, 0.25], atol=0.01)


def test_episodes_are_resampled_within_agents():
    # agents with equal means but noisy episodes: resampling agent means alone would give zero width
    iv = stats.mean_interval([[0.0, 2.0], [2.0, 0.0]], n_resamples=20_000, seed=3)
    assert iv.low < 0.5 and iv.high > 1.5


def test_variance_of_the_resampled_mean_is_the_two_level_formula():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(4, 1)) * 3 + rng.normal(size=(4, 6))  # (A, E): agent effects and episode noise
    a, e = x.shape
    expected = (x.mean(1).var() + x.var(1).mean() / e) / a
    reps = stats.bootstrap_means(x, n_resamples=200_000, seed=4)
    assert reps.mean() == pytest.approx(x.mean(), abs=0.02)
    assert reps.var() == pytest.approx(expected, rel=0.03)


def test_chunks_do_not_change_the_distribution(monkeypatch):
    x = np.arange(12.0).reshape(3, 4)
    monkeypatch.setattr(stats, "_CHUNK", 24)  # two resamples per chunk
    reps = stats.bootstrap_means(x, n_resamples=20_001, seed=5)
    assert reps.shape == (20_001,)
    assert reps.var() == pytest.approx((x.mean(1).var() + x.var(1).mean() / 4) / 3, rel=0.05)


# --------------------------------------------------------------------------- the bootstrap against scipy
@pytest.mark.parametrize("shape", [(40, 1), (1, 40)])
def test_one_level_cases_match_scipy_percentile_bootstrap(shape):
    # one episode per agent, or one agent: the two-level bootstrap is the ordinary one
    rng = np.random.default_rng(6)
    x = rng.gamma(2.0, 300.0, size=shape)
    ours = stats.mean_interval(x, n_resamples=40_000, seed=7)
    ref = scipy.stats.bootstrap(
        (x.ravel(),),
        np.mean,
        n_resamples=40_000,
        method="percentile",
        confidence_level=0.95,
        random_state=np.random.default_rng(8),
    ).confidence_interval
    width = ref.high - ref.low
    assert ours.low == pytest.approx(ref.low, abs=0.03 * width)
    assert ours.high == pytest.approx(ref.high, abs=0.03 * width)


def test_difference_of_one_level_cases_matches_scipy():
    rng = np.random.default_rng(9)
    a, b = rng.normal(5.0, 2.0, size=(30, 1)), rng.normal(4.0, 1.0, size=(25, 1))
    ours = stats.difference_interval(a, b, n_resamples=40_000, seed=10)
    ref = scipy.stats.bootstrap(
        (a.ravel(), b.ravel()),
        lambda u, v, axis: u.mean(axis) - v.mean(axis),
        n_resamples=40_000,
        method="percentile",
        vectorized=True,
        random_state=np.random.default_rng(11),
    ).confidence_interval
    width = ref.high - ref.low
    assert ours.estimate == pytest.approx(a.mean() - b.mean())
    assert ours.low == pytest.approx(ref.low, abs=0.03 * width)
    assert ours.high == pytest.approx(ref.high, abs=0.03 * width)


# --------------------------------------------------------------------------- difference and ratio
def test_difference_of_constant_methods_is_exact_and_decides():
    a, b = np.full((3, 5), 7.0), np.full((2, 4), 4.0)
    iv = stats.difference_interval(a, b, n_resamples=100)
    assert (iv.estimate, iv.low, iv.high) == (3.0, 3.0, 3.0)
    assert stats.compare(a, b, "A > B").verdict == "holds"
    assert stats.compare(b, a, "B > A").verdict == "does not hold"


def test_difference_draws_the_two_methods_independently():
    # the same data for A and B: a shared draw would give exactly 0 every time
    x = np.array([[0.0, 10.0], [5.0, 20.0]])
    iv = stats.difference_interval(x, x, n_resamples=5_000, seed=12)
    assert iv.estimate == 0.0 and iv.low < -3 and iv.high > 3
    assert stats.compare(x, x).verdict == "cannot tell at this scale"


def test_ratio_to_a_constant_expert_is_the_mean_interval_scaled():
    x = np.random.default_rng(13).uniform(0, 1000, size=(3, 10))
    r = stats.ratio_interval(x, np.full(10, 800.0), n_resamples=3_000, seed=14)
    m = stats.mean_interval(x, n_resamples=3_000, seed=14)  # the same draws, in the same order
    assert r.estimate == pytest.approx(m.estimate / 800)
    assert (r.low, r.high) == pytest.approx((m.low / 800, m.high / 800))


def test_ratio_pairs_the_expert_with_the_same_starts():
    # every agent scores 80 % of the expert on each start, starts of very different difficulty:
    # paired, the ratio is 0.8 in every resample; an unpaired ratio would scatter widely
    expert = np.array([100.0, 1500.0, 400.0, 900.0, 50.0])
    x = np.stack([0.8 * expert] * 3)  # (3, 5)
    r = stats.ratio_interval(x, expert, n_resamples=2_000, seed=15)
    assert (r.estimate, r.low, r.high) == pytest.approx((0.8, 0.8, 0.8))
    assert stats.judge("at least 75 % of the expert", r, 0.75).verdict == "holds"
    assert stats.judge("at least 85 % of the expert", r, 0.85).verdict == "does not hold"


def test_seeds_reproduce_and_generators_are_accepted():
    x = np.random.default_rng(16).normal(size=(3, 4))
    assert stats.mean_interval(x, seed=3) == stats.mean_interval(x, seed=3)
    assert stats.mean_interval(x, seed=3) != stats.mean_interval(x, seed=4)
    g1, g2 = np.random.default_rng(5), np.random.default_rng(5)
    assert stats.mean_interval(x, seed=g1, n_resamples=500) == stats.mean_interval(
        x, seed=g2, n_resamples=500
    )
    assert (
        stats.mean_interval(x, n_resamples=500, level=0.5).high < stats.mean_interval(x, n_resamples=500).high
    )


# --------------------------------------------------------------------------- the verdict rule
@pytest.mark.parametrize(
    "low, high, threshold, expected",
    [
        (0.1, 2.0, 0.0, "holds"),
        (-2.0, -0.1, 0.0, "does not hold"),
        (-1.0, 1.0, 0.0, "cannot tell at this scale"),
        (0.0, 1.0, 0.0, "cannot tell at this scale"),  # an end on the threshold: not above it
        (-1.0, 0.0, 0.0, "cannot tell at this scale"),
        (0.86, 0.95, 0.85, "holds"),
        (0.70, 0.84, 0.85, "does not hold"),
    ],
)
def test_verdict(low, high, threshold, expected):
    iv = stats.Interval((low + high) / 2, low, high)
    assert stats.verdict(iv, threshold) == expected
    j = stats.judge("claim", iv, threshold)
    assert j.verdict == expected and j.interval == iv and "claim: " + expected in str(j)


# --------------------------------------------------------------------------- exits per approach
def visits(*pairs):
    return [{"approach": ap, "node": 0, "turn": turn, "step": k} for k, (ap, turn) in enumerate(pairs)]


def test_exit_counts_and_spread_by_hand():
    v = visits((3, "left"), (3, "left"), (3, "right"), (5, "straight"), (7, "left"), (7, "straight"))
    assert exit_counts(v) == {
        3: {"left": 2, "straight": 0, "right": 1},
        5: {"left": 0, "straight": 1, "right": 0},
        7: {"left": 1, "straight": 1, "right": 0},
    }
    assert stats.exit_spread(v) == (2, 5)  # approach 5 (one visit) left out; 1 + 1 minority visits
    assert stats.exit_spread(v, min_visits=3) == (1, 3)
    assert stats.exit_spread(v, min_visits=1) == (2, 6)


def test_exit_test_one_approach_by_hand():
    # A: left, straight; B: straight, straight. Shuffled, A's pair holds the left half the time
    # (T = 1/2, as observed) and otherwise T = -1/2: p_greater = 1/2, p_less = 1
    t = stats.exit_spread_test(
        visits((1, "left"), (1, "straight")),
        visits((1, "straight"), (1, "straight")),
        n_permutations=20_000,
        seed=17,
    )
    assert t.statistic == 0.5 and t.approaches == 1 and t.visits == (2, 2)
    assert t.p_greater == pytest.approx(0.5, abs=0.015) and t.p_less == 1.0
    assert t.verdict == "cannot tell at this scale"


def test_exit_test_detects_spread_and_its_absence():
    rng = np.random.default_rng(18)
    aps = range(6)
    spread = visits(*[(ap, str(rng.choice(["left", "right"]))) for ap in aps for _ in range(8)])
    same = visits(*[(ap, "left") for ap in aps for _ in range(8)])
    t = stats.exit_spread_test(spread, same, n_permutations=5_000, seed=19)
    assert t.verdict == "holds" and t.p_greater < 0.01 and t.statistic > 0.2
    assert stats.exit_spread_test(same, spread, n_permutations=5_000, seed=19).verdict == "does not hold"
    # two agents that each always take one exit, a different one: no spread, no false verdict
    other = visits(*[(ap, "right") for ap in aps for _ in range(8)])
    t = stats.exit_spread_test(same, other, n_permutations=5_000, seed=20)
    assert t.statistic == 0.0 and t.verdict == "cannot tell at this scale"
    # approaches only one agent visited are not used
    t = stats.exit_spread_test(spread, visits((99, "left"), (99, "left")), n_permutations=100)
    assert t.approaches == 0 and t.verdict == "cannot tell at this scale"


def test_exit_test_is_calibrated_under_the_null():
    # both agents pick left or right at random: "holds" in about 2.5 % of the experiments
    rng = np.random.default_rng(21)
    wrong = 0
    for k in range(200):
        a = visits(*[(ap, str(rng.choice(["left", "right"]))) for ap in range(4) for _ in range(4)])
        b = visits(*[(ap, str(rng.choice(["left", "right"]))) for ap in range(4) for _ in range(4)])
        wrong += stats.exit_spread_test(a, b, n_permutations=400, seed=k).verdict == "holds"
    assert wrong <= 12  # 5 expected; P(> 12) < 0.5 % for a calibrated test


# --------------------------------------------------------------------------- Welch's t (few seeds)
def test_student_t_quantile_matches_scipy():
    sp = pytest.importorskip("scipy.stats")
    for df in (1, 2, 2.7, 5, 30, 300):
        for q in (0.025, 0.4, 0.5, 0.9, 0.975, 0.995):
            assert abs(stats.student_t_quantile(q, df) - sp.t.ppf(q, df)) < 1e-5 * max(
                1, abs(sp.t.ppf(q, df))
            )
    for bad in ({"q": 0.0, "df": 2}, {"q": 1.0, "df": 2}, {"q": 0.9, "df": 0.5}, {"q": 0.9, "df": -1}):
        with pytest.raises(ValueError, match="q|df"):
            stats.student_t_quantile(**bad)


def test_welch_interval_matches_scipy_and_refuses_bad_input():
    sp = pytest.importorskip("scipy.stats")
    rng = np.random.default_rng(1)
    for _ in range(20):
        a, b = rng.normal(size=3), rng.normal(0.5, 2.0, size=4)
        ci = sp.ttest_ind(a, b, equal_var=False).confidence_interval(0.95)
        got = stats.welch_interval(a, b)
        assert got.n_resamples == 0
        assert np.allclose([got.low, got.high], [ci.low, ci.high], atol=1e-5)
    # no spread in either group: the interval is the observed difference
    assert str(stats.welch_interval([0, 0, 0], [0, 0, 0])) == "0.00 [0.00, 0.00]"
    with pytest.raises(ValueError, match="values_a"):
        stats.welch_interval([1.0], [1, 2])
    with pytest.raises(ValueError, match="values_b"):
        stats.welch_interval([1, 2], [1, np.nan])


def test_welch_covers_at_three_seeds_where_the_percentile_bootstrap_does_not():
    # normal data, 3 units per group, true difference 0: Welch's 95 % interval covers about 95 %;
    # the percentile bootstrap over 3 units (10 distinct resample means each) covers far less
    rng = np.random.default_rng(0)
    welch = boot = 0
    trials = 300
    for i in range(trials):
        a, b = rng.normal(size=3), rng.normal(size=3)
        welch += stats.welch_interval(a, b).contains(0.0)
        boot += stats.difference_interval(a[:, None], b[:, None], n_resamples=2000, seed=i).contains(0.0)
    assert welch / trials > 0.9
    assert boot / trials < 0.85
    j = stats.compare_few([1, 2, 3], [0, 0.5, 0.2], "a above b")
    assert j.verdict == stats.CANNOT_TELL and j.interval.n_resamples == 0
    assert stats.compare_few([10, 11, 12], [0, 0.5, 0.2]).verdict == stats.HOLDS
