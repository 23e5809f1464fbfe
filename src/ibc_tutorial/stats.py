"""Uncertainty for the replication's claims (chapter 09): bootstrap intervals, a verdict rule, an exit test.

An agent's score varies from episode to episode (other starts, other light phases), and two
agents of one method, trained from other seeds, differ again. A claim such as "DA-IBC travels
farther than IBC" is about the *method*, so its uncertainty has both parts. This module gives

- ``mean_interval``, ``difference_interval``, ``ratio_interval``: 95 % percentile intervals from a
  **hierarchical (two-level) bootstrap** over agents and episodes, for one method's mean, for the
  difference of two methods' means, and for a method's mean over the expert's on the same starts;
- ``verdict`` and ``compare``: the rule that turns an interval into "holds", "does not hold" or
  "cannot tell at this scale" (the ordering of two means never decides);
- ``exit_spread`` and ``exit_spread_test`` (over ``driving.analysis.exit_counts``): the free-driving
  (Fig. 5) question, does one agent leave the same junction approach by different exits more than
  another does, beyond what chance gives with so few visits (a stratified permutation test);

The intervals take (agents, episodes) arrays of numbers; this module reads no file and knows no
folder. A replication folder's arrays come from ``experiments.agents.replication_folder.episode_table``.

Everything is numpy, seeded (``seed``: an int or a ``np.random.Generator``) and vectorised over
the resamples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ibc_tutorial.driving.analysis import exit_counts
from ibc_tutorial.driving.lanes import TURNS  # the exits of a junction approach
from ibc_tutorial.utils import check_int, check_positive, check_probability

DEFAULT_RESAMPLES = 10_000
"""Bootstrap resamples (and permutations) unless told otherwise."""
LEVEL = 0.95
"""Coverage of the intervals: 95 %, the 2.5th to the 97.5th percentile of the resampled statistic."""
HOLDS, DOES_NOT_HOLD, CANNOT_TELL = "holds", "does not hold", "cannot tell at this scale"
"""The three verdicts of ``verdict``."""
EQUIVALENT = "equivalent within ±δ"
"""The fourth verdict: the difference is established to lie within ±δ (``ibc_tutorial.equivalence``)."""
_CHUNK = 1 << 22
"""Largest number of drawn (resample, agent, episode) cells held at once (32 MB of indices)."""


# --------------------------------------------------------------------------- arguments
def resampling_generator(seed) -> np.random.Generator:
    """``seed`` itself if it is a ``np.random.Generator``, else a new one seeded with it (an int >= 0)."""
    if isinstance(seed, np.random.Generator):
        return seed
    return np.random.default_rng(check_int("seed", seed, minimum=0))


def check_scores(name: str, scores) -> np.ndarray:
    """``scores`` as a finite float (A, E) array: one row per agent, one column per episode (A, E >= 1)."""
    try:
        x = np.asarray(scores, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(
            f"{name} must be an (agents, episodes) array of numbers, got {type(scores).__name__}"
        ) from None
    if x.ndim != 2 or x.shape[0] < 1 or x.shape[1] < 1:
        raise ValueError(
            f"{name} must be an (agents, episodes) array with at least one of each, got shape {x.shape}"
        )
    if not np.isfinite(x).all():
        raise ValueError(f"{name} must be finite, got NaN or inf")
    return x


def check_expert(expert, n_starts: int) -> np.ndarray:
    """``expert`` as a (E,) array of E = ``n_starts`` finite scores > 0: the expert's score at each start."""
    ex = np.asarray(expert, dtype=float)
    if ex.ndim != 1 or len(ex) != n_starts:
        raise ValueError(
            f"expert must be a 1-D array of {n_starts} episode scores (one per column of scores), "
            f"got shape {ex.shape}"
        )
    if not (np.isfinite(ex).all() and (ex > 0).all()):
        raise ValueError("expert must hold finite scores > 0 in every episode")
    return ex


def check_level(level) -> float:
    """``level`` as a coverage strictly between 0 and 1."""
    level = check_probability("level", level)
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be strictly between 0 and 1, got {level!r}")
    return level


# --------------------------------------------------------------------------- the bootstrap
@dataclass(frozen=True)
class Interval:
    """A bootstrap estimate and its percentile interval."""

    estimate: float
    """The statistic on the data as they are (not resampled)."""
    low: float
    """Lower end: the (1 - level) / 2 quantile of the resampled statistic."""
    high: float
    """Upper end: the (1 + level) / 2 quantile."""
    level: float = LEVEL
    """Coverage, e.g. 0.95."""
    n_resamples: int = DEFAULT_RESAMPLES
    """How many resamples the quantiles come from."""

    def __str__(self) -> str:
        return f"{self.estimate:.2f} [{self.low:.2f}, {self.high:.2f}]"

    def contains(self, value: float) -> bool:
        return self.low <= value <= self.high


def _draws(n_agents: int, n_episodes: int, n_resamples: int, rng: np.random.Generator):
    """Yield index arrays of the two-level bootstrap, in chunks of resamples.

    Each resample draws ``n_agents`` agents with replacement, ``agents`` (R, A), then for every
    drawn agent ``n_episodes`` of its episodes with replacement, ``episodes`` (R, A, E).
    """
    chunk = max(1, _CHUNK // (n_agents * n_episodes))
    for start in range(0, n_resamples, chunk):
        r = min(chunk, n_resamples - start)
        agents = rng.integers(n_agents, size=(r, n_agents))  # (r, A)
        episodes = rng.integers(n_episodes, size=(r, n_agents, n_episodes))  # (r, A, E)
        yield agents, episodes


def bootstrap_means(scores, n_resamples: int = DEFAULT_RESAMPLES, seed=0) -> np.ndarray:
    """(R,) resampled grand means of ``scores`` (A agents, E episodes each): the two-level bootstrap.

    One resample draws A agents with replacement, then for each drawn agent E of its episodes
    with replacement, and averages the A x E drawn scores. Resampling agents carries the variation
    between training seeds (another run of the method gives other agents); resampling episodes
    within a drawn agent carries the variation between starts. Resampling the pooled episodes
    alone would treat the A x E scores as independent and give too narrow an interval when agents
    differ; resampling agent means alone would lose the episodes' noise when there are few agents.
    The variance of the resampled mean is (Var_a(m_a) + mean_a(v_a) / E) / A, with m_a and v_a each
    agent's mean and (population) variance over its episodes. Two known biases pull against each
    other: the episodes' noise counts twice (it already spreads the agent means m_a), which widens
    the interval, and Var_a with A = 3-5 agents is (A - 1) / A of the sample variance, which narrows
    it. Measured on simulated replications (agent effects of sd 200 and episode noise of sd 300, 10
    episodes per agent, 400 replications each; ``tests/test_stats.py``): the 95 % interval of the mean
    covers the true mean 86 % of the time with 3 agents, 90 % with 5, 93 % with 10 and 94 % with 20;
    with no agent effect at all it covers 98 % (5 agents). With as few agents as a laptop
    replication has, the interval is somewhat too narrow: a verdict near the edge is a weak one.
    """
    x = check_scores("scores", scores)
    n_resamples = check_int("n_resamples", n_resamples, minimum=1)
    rng = resampling_generator(seed)
    a, e = x.shape
    out = [
        x[agents[..., None], episodes].mean(axis=(1, 2))
        for agents, episodes in _draws(a, e, n_resamples, rng)
    ]
    return np.concatenate(out)  # (R,)


def percentile_interval(estimate: float, replicates: np.ndarray, level: float) -> Interval:
    """``estimate`` with the (1 - level) / 2 and (1 + level) / 2 quantiles of its (R,) ``replicates``."""
    lo, hi = np.percentile(replicates, [50 * (1 - level), 50 * (1 + level)])
    return Interval(float(estimate), float(lo), float(hi), level, len(replicates))


def mean_interval(scores, *, n_resamples: int = DEFAULT_RESAMPLES, seed=0, level: float = LEVEL) -> Interval:
    """The mean of one method's (A, E) scores with its percentile interval (``bootstrap_means``)."""
    x = check_scores("scores", scores)
    level = check_level(level)
    return percentile_interval(x.mean(), bootstrap_means(x, n_resamples, resampling_generator(seed)), level)


def difference_interval(
    scores_a, scores_b, *, n_resamples: int = DEFAULT_RESAMPLES, seed=0, level: float = LEVEL
) -> Interval:
    """mean(A) - mean(B) for two methods' (A, E) and (B, E') scores, with its percentile interval.

    The two methods' agents are different networks, so each resample draws the two-level
    bootstrap of each method independently (from one generator) and subtracts the means. The
    methods met the same starts, but the pairing is not used: a hard start lowers both methods'
    scores, so ignoring it errs on the wide side.
    """
    level = check_level(level)
    estimate, reps = difference_replicates(scores_a, scores_b, n_resamples=n_resamples, seed=seed)
    return percentile_interval(estimate, reps, level)


def difference_replicates(scores_a, scores_b, *, n_resamples: int = DEFAULT_RESAMPLES, seed=0):
    """(mean(A) - mean(B), its (R,) resamples) of ``difference_interval``: each method's two-level
    bootstrap drawn independently from one generator."""
    a = check_scores("scores_a", scores_a)
    b = check_scores("scores_b", scores_b)
    rng = resampling_generator(seed)
    reps = bootstrap_means(a, n_resamples, rng) - bootstrap_means(b, n_resamples, rng)  # (R,)
    return float(a.mean() - b.mean()), reps


def ratio_interval(
    scores, expert, *, n_resamples: int = DEFAULT_RESAMPLES, seed=0, level: float = LEVEL
) -> Interval:
    """mean(method) / mean(expert) with its percentile interval; the expert drove the same E starts.

    ``scores`` (A, E): the method's agents; ``expert`` (E,): the PID expert's score on each of the
    same starts (episode j of every row is the same start as ``expert[j]``). Each resample draws
    the two-level bootstrap of the method, and the denominator is the expert's mean over the
    *same* drawn starts: a hard start lowers both, and the ratio compares like with like.
    Every expert episode must score above 0 (a start the expert did not drive is no reference).
    For one agent ("every agent reaches 60 % of the expert"), pass its row as a (1, E) array: the
    bootstrap then resamples its episodes only.
    """
    x = check_scores("scores", scores)
    ex = check_expert(expert, x.shape[1])
    level = check_level(level)
    n_resamples = check_int("n_resamples", n_resamples, minimum=1)
    rng = resampling_generator(seed)
    a, e = x.shape
    reps = [
        x[agents[..., None], episodes].mean(axis=(1, 2)) / ex[episodes].mean(axis=(1, 2))
        for agents, episodes in _draws(a, e, n_resamples, rng)
    ]
    return percentile_interval(x.mean() / ex.mean(), np.concatenate(reps), level)


def _ratio_replicates(num: np.ndarray, den: np.ndarray, n_resamples: int, rng) -> np.ndarray:
    """(R,) resampled ratios sum(num) / sum(den) of the two-level bootstrap; NaN where the drawn
    denominators sum to 0."""
    reps = []
    for agents, episodes in _draws(*num.shape, n_resamples, rng):
        idx = (agents[..., None], episodes)
        top, bottom = num[idx].sum(axis=(1, 2)), den[idx].sum(axis=(1, 2))  # (r,)
        reps.append(np.where(bottom > 0, top / np.where(bottom > 0, bottom, 1.0), np.nan))
    return np.concatenate(reps)


def _resampled_shares(tables, transform, n_resamples: int, seed) -> tuple[list, list]:
    """f(pooled share) and the (R,) f(resampled shares) of each method's checked (numerators, denominators)
    tables, f = ``transform`` or the identity: one two-level bootstrap per method (``_ratio_replicates``),
    drawn in turn from one generator. Resamples in which any method drew denominators summing to 0 are
    left out of every method's; at least one must remain."""
    n_resamples = check_int("n_resamples", n_resamples, minimum=1)
    rng = resampling_generator(seed)
    reps = [_ratio_replicates(num, den, n_resamples, rng) for num, den in tables]
    keep = np.logical_and.reduce([np.isfinite(r) for r in reps])  # (R,)
    if not keep.any():
        raise ValueError("every resample drew denominators summing to 0")
    f = (lambda p: p) if transform is None else transform
    return [f(num.sum() / den.sum()) for num, den in tables], [f(r[keep]) for r in reps]


def _check_ratio_tables(num_name: str, numerators, den_name: str, denominators):
    num, den = check_scores(num_name, numerators), check_scores(den_name, denominators)
    if num.shape != den.shape:
        raise ValueError(f"{num_name} and {den_name} must have one shape, got {num.shape} and {den.shape}")
    if (den < 0).any() or den.sum() <= 0:
        raise ValueError(f"{den_name} must be >= 0 with a positive sum")
    return num, den


def minority(p):
    """min(p, 1 - p): the share of the less taken of two choices, given the share ``p`` of one of them
    (a ``transform`` for ``ratio_of_sums_interval``: the minority exit at the stem of a T)."""
    return np.minimum(p, 1 - p)


def ratio_of_sums_interval(
    numerators,
    denominators,
    *,
    transform=None,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed=0,
    level: float = LEVEL,
) -> Interval:
    """sum(numerators) / sum(denominators) over a method's (A, E) episodes, with its two-level interval.

    For a share pooled over events that episodes hold in different numbers (left turns of an
    episode's stem crossings: ``numerators``, its stem crossings: ``denominators``), each resample
    draws agents and then episodes as ``bootstrap_means`` does and divides the drawn sums, so an
    episode with many events weighs more, and events of one episode or agent are resampled
    together. ``transform`` (a vectorised function of the share, e.g. ``lambda p: np.minimum(p, 1 - p)``)
    is applied to the estimate and to every resample. Resamples whose drawn denominators sum to 0
    are left out (``n_resamples`` of the result counts those kept); at least one must remain.
    """
    num, den = _check_ratio_tables("numerators", numerators, "denominators", denominators)
    level = check_level(level)
    (share,), (reps,) = _resampled_shares([(num, den)], transform, n_resamples, seed)
    return percentile_interval(float(share), np.asarray(reps, dtype=float), level)


def ratio_of_sums_difference(
    numerators_a,
    denominators_a,
    numerators_b,
    denominators_b,
    *,
    transform=None,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed=0,
    level: float = LEVEL,
) -> Interval:
    """f(share A) - f(share B) of two methods' pooled shares (``ratio_of_sums_interval``), with its interval.

    Each resample draws the two-level bootstrap of each method independently (from one generator),
    as ``difference_interval`` does for means, and subtracts the transformed shares; resamples in
    which either method drew denominators summing to 0 are left out."""
    level = check_level(level)
    estimate, reps = ratio_of_sums_difference_replicates(
        numerators_a, denominators_a, numerators_b, denominators_b, transform=transform,
        n_resamples=n_resamples, seed=seed,
    )  # fmt: skip
    return percentile_interval(estimate, reps, level)


def ratio_of_sums_difference_replicates(
    numerators_a, denominators_a, numerators_b, denominators_b, *, transform=None,
    n_resamples: int = DEFAULT_RESAMPLES, seed=0,
):  # fmt: skip
    """(f(share A) - f(share B), its (R',) resamples) of ``ratio_of_sums_difference``."""
    na, da = _check_ratio_tables("numerators_a", numerators_a, "denominators_a", denominators_a)
    nb, db = _check_ratio_tables("numerators_b", numerators_b, "denominators_b", denominators_b)
    (sa, sb), (ra, rb) = _resampled_shares([(na, da), (nb, db)], transform, n_resamples, seed)
    return float(sa - sb), np.asarray(ra - rb, dtype=float)


# --------------------------------------------------------------------------- few seeds: Welch's t
def student_t_quantile(q: float, df: float) -> float:
    """The q-quantile of Student's t distribution with ``df`` degrees of freedom (df >= 1, may be
    fractional, as Welch's are): the density integrated numerically (the trapezoid rule on a fine grid in
    the variable u = atan(t), which maps the whole line onto a bounded interval) and the CDF
    inverted by interpolation. Accurate to about 1e-6 against scipy (tests/test_stats.py)."""
    q = check_probability("q", q)
    if not 0.0 < q < 1.0:
        raise ValueError(f"q must be strictly between 0 and 1, got {q!r}")
    df = check_positive("df", df)
    if df < 1:
        raise ValueError(f"df must be at least 1 (Welch's degrees of freedom are), got {df!r}")
    if q == 0.5:
        return 0.0
    u = np.linspace(0.0, np.pi / 2, 20_001)[:-1]  # (N,) t = tan(u) from 0 towards +inf
    t = np.tan(u)
    log_c = math.lgamma((df + 1) / 2) - math.lgamma(df / 2) - 0.5 * math.log(df * math.pi)
    dens = np.exp(log_c - (df + 1) / 2 * np.log1p(t**2 / df)) / np.cos(u) ** 2  # density in u
    du = u[1] - u[0]
    # cumulative integral by the trapezoid rule on the fine grid: CDF(t) - 1/2 for t >= 0
    cum = np.concatenate([[0.0], np.cumsum((dens[1:] + dens[:-1]) * du / 2)])
    p = abs(q - 0.5)
    x = float(np.interp(p, cum, t))
    return x if q > 0.5 else -x


def welch_interval(values_a, values_b, *, level: float = LEVEL) -> Interval:
    """mean(a) - mean(b) with Welch's t interval: for few units per group (3 seeds), where a
    percentile bootstrap has too few distinct resamples (10 for n = 3) and undercovers.

    ``values_a`` (n_a,) and ``values_b`` (n_b,), n >= 2 each: one number per unit (a trained
    model). It assumes each group's values are roughly normal, which a chapter using it says; with
    n = 3 the interval is wide (t quantile 4.30 at 2 degrees of freedom), as it should be. If both
    groups have no spread the interval is the observed difference itself. ``n_resamples`` of the
    returned ``Interval`` is 0: no resampling was done.
    """
    a = np.asarray(values_a, dtype=float).ravel()
    b = np.asarray(values_b, dtype=float).ravel()
    for name, x in (("values_a", a), ("values_b", b)):
        if len(x) < 2 or not np.isfinite(x).all():
            raise ValueError(f"{name} must hold at least 2 finite values, got {x.tolist()}")
    level = check_level(level)
    d = float(a.mean() - b.mean())
    va, vb = a.var(ddof=1) / len(a), b.var(ddof=1) / len(b)  # squared standard errors
    se = math.sqrt(va + vb)
    if se == 0.0:
        return Interval(d, d, d, level, 0)
    df = (va + vb) ** 2 / (va**2 / (len(a) - 1) + vb**2 / (len(b) - 1))  # Welch-Satterthwaite
    half = student_t_quantile(0.5 + level / 2, df) * se
    return Interval(d, d - half, d + half, level, 0)


def compare_few(values_a, values_b, claim: str = "A > B", *, level: float = LEVEL) -> Judgement:
    """The claim "A's mean is above B's" for one value per unit (e.g. per seed), judged by
    ``welch_interval``: the verdict rule of ``verdict`` on an interval honest at n = 3."""
    interval = welch_interval(values_a, values_b, level=level)
    return Judgement(str(claim), interval, 0.0, verdict(interval, 0.0))


VERDICTS = (HOLDS, DOES_NOT_HOLD, EQUIVALENT, CANNOT_TELL)
"""The four verdicts a claim, or a part of one, gets."""


def combine_verdicts(*verdicts: str) -> str:
    """The verdict of a claim made of several parts (each a verdict of ``VERDICTS``): it holds if every
    part does, does not hold if one part does not, is equivalent within ±δ if every part is, and else
    cannot be told."""
    for v in verdicts:
        if v not in VERDICTS:
            raise ValueError(f"verdicts must be one of {', '.join(map(repr, VERDICTS))}, got {v!r}")
    if DOES_NOT_HOLD in verdicts:
        return DOES_NOT_HOLD
    for whole in (HOLDS, EQUIVALENT):
        if verdicts and all(v == whole for v in verdicts):
            return whole
    return CANNOT_TELL


# --------------------------------------------------------------------------- the verdict
def verdict(interval: Interval, threshold: float = 0.0) -> str:
    """The claim "the quantity is above ``threshold``", judged by an interval of it.

    "holds" if the whole interval lies above the threshold, "does not hold" if it lies below,
    "cannot tell at this scale" if it contains the threshold (an end exactly on it counts as
    containing it). For "A > B" judge the interval of A - B against 0; for "at least 85 % of the
    expert's", the interval of the ratio against 0.85.
    """
    if not isinstance(interval, Interval):
        raise ValueError(f"interval must be an Interval, got {type(interval).__name__}")
    try:
        t = float(threshold)
    except (TypeError, ValueError):
        raise ValueError(f"threshold must be a finite number, got {threshold!r}") from None
    if not np.isfinite(t):
        raise ValueError(f"threshold must be a finite number, got {threshold!r}")
    if interval.low > t:
        return HOLDS
    if interval.high < t:
        return DOES_NOT_HOLD
    return CANNOT_TELL


@dataclass(frozen=True)
class Judgement:
    """A claim, the interval that tests it, and the verdict: what a chapter prints."""

    claim: str
    """The claim in words, e.g. "DA-IBC drives farther than IBC"."""
    interval: Interval
    """The interval of the quantity the claim is about (a difference, a ratio)."""
    threshold: float
    """The claim is "the quantity is above this"."""
    verdict: str
    """"holds", "does not hold", "cannot tell at this scale", or ``EQUIVALENT`` if an equivalence test was
    made (``ibc_tutorial.equivalence``)."""
    delta: float | None = None
    """δ of the equivalence test (the smallest difference that matters), None if none was made."""
    equivalence_interval: Interval | None = None
    """The (1 - 2 α) interval of the difference the equivalence test reads (90 % at α = 0.05)."""
    p_equivalent: float | None = None
    """The equivalence test's p-value: the larger of its two one-sided p-values."""

    def __str__(self) -> str:
        i = self.interval
        text = (
            f"{self.claim}: {self.verdict} (estimate {i.estimate:.2f}, {i.level:.0%} interval "
            f"[{i.low:.2f}, {i.high:.2f}], threshold {self.threshold:g}"
        )
        e = self.equivalence_interval
        if self.delta is None or e is None or self.p_equivalent is None:
            return text + ")"
        return (
            f"{text}; ±δ = ±{self.delta:.2f}: {e.level:.0%} interval [{e.low:.2f}, {e.high:.2f}], "
            f"TOST p = {self.p_equivalent:.3f})"
        )


def compare(
    scores_a,
    scores_b,
    claim: str = "A > B",
    *,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed=0,
    level: float = LEVEL,
) -> Judgement:
    """The claim "A's mean is above B's", judged by the hierarchical interval of mean(A) - mean(B)."""
    interval = difference_interval(scores_a, scores_b, n_resamples=n_resamples, seed=seed, level=level)
    return Judgement(str(claim), interval, 0.0, verdict(interval, 0.0))


def judge(claim: str, interval: Interval, threshold: float = 0.0) -> Judgement:
    """A ``Judgement`` of "the quantity is above ``threshold``" from any interval (e.g.
    ``ratio_interval``)."""
    v = verdict(interval, threshold)  # checks both
    return Judgement(str(claim), interval, float(threshold), v)


# --------------------------------------------------------------------------- free driving (Fig. 5)
def exit_spread(visits, min_visits: int = 2) -> tuple[int, int]:
    """(visits not by their approach's most common exit, visits) over approaches visited >= ``min_visits``
    times.

    Zero for an agent that always leaves an approach the same way; an agent that picks one of two
    exits at random on every visit leaves about half its visits by the less common one.
    """
    min_visits = check_int("min_visits", min_visits, minimum=1)
    minority = total = 0
    for c in exit_counts(visits).values():
        n = sum(c.values())
        if n >= min_visits:
            minority += n - max(c.values())
            total += n
    return minority, total


@dataclass(frozen=True)
class ExitTest:
    """The result of ``exit_spread_test``."""

    statistic: float
    """A's share of visits not by their approach's most common exit, minus B's (shared approaches only)."""
    p_greater: float
    """Permutation p-value of a statistic this large if the exits did not depend on the agent."""
    p_less: float
    """The same for a statistic this small (B spreads more)."""
    approaches: int
    """Approaches that both agents visited at least ``min_visits`` times (the only ones used)."""
    visits: tuple[int, int]
    """A's and B's visits to those approaches."""
    verdict: str
    """"holds" (A spreads more, p_greater < (1 - level) / 2), "does not hold" (B spreads more),
    or "cannot tell at this scale"."""


def exit_spread_test(
    visits_a,
    visits_b,
    *,
    min_visits: int = 2,
    n_permutations: int = DEFAULT_RESAMPLES,
    seed=0,
    level: float = LEVEL,
) -> ExitTest:
    """Does agent A leave the same junction approach by different exits more than agent B does?

    The paper's Fig. 5 claim is comparative (DA-IBC makes different decisions at the same
    intersections, BC does not), and for one agent alone there is no natural "chance": any noise
    gives some spread. So the test compares A with B **on the approaches both visited at least
    ``min_visits`` times**, where the statistic is

        T = (A's visits not by the approach's most common exit *for A*) / (A's visits there)
            - the same for B.

    The null hypothesis: at each approach, which exit a visit took does not depend on which agent
    drove it. Under it the visits of one approach are exchangeable between A and B, so each
    permutation shuffles the agent labels *within every approach* (keeping each agent's number of
    visits there: a stratified permutation test) and recomputes T. Two agents that each always take
    one exit, a different one, give T near 0, not a false "spread". The p-values count the
    observed T as one of the permutations, (1 + #{T_perm >= T}) / (1 + R). The verdict is "holds"
    if p_greater < (1 - level) / 2, "does not hold" if p_less is, else "cannot tell at this scale".
    Visits within one episode are treated as exchangeable too, an approximation: a car that loops
    meets the same approach in similar states.
    """
    min_visits = check_int("min_visits", min_visits, minimum=1)
    n_permutations = check_int("n_permutations", n_permutations, minimum=1)
    level = check_level(level)
    rng = resampling_generator(seed)
    ca, cb = exit_counts(visits_a), exit_counts(visits_b)
    shared = sorted(
        ap
        for ap in ca
        if ap in cb and sum(ca[ap].values()) >= min_visits and sum(cb[ap].values()) >= min_visits
    )
    if not shared:
        return ExitTest(0.0, 1.0, 1.0, 0, (0, 0), CANNOT_TELL)
    n_a = np.array([sum(ca[ap].values()) for ap in shared])  # (J,) A's visits per shared approach
    n_b = np.array([sum(cb[ap].values()) for ap in shared])  # (J,)
    minority_a = np.zeros(n_permutations, dtype=np.int64)  # (R,) A's minority visits, summed over approaches
    minority_b = np.zeros(n_permutations, dtype=np.int64)
    obs_a = obs_b = 0
    for j, ap in enumerate(shared):
        pooled = np.repeat(np.arange(3), [ca[ap][t] + cb[ap][t] for t in TURNS])  # (n_a + n_b,) exit ids
        obs_a += n_a[j] - max(ca[ap].values())
        obs_b += n_b[j] - max(cb[ap].values())
        perm = rng.permuted(np.broadcast_to(pooled, (n_permutations, len(pooled))), axis=1)  # (R, n)
        to_a = np.stack([(perm[:, : n_a[j]] == k).sum(1) for k in range(3)], axis=1)  # (R, 3) A's exits
        to_b = np.bincount(pooled, minlength=3)[None, :] - to_a  # (R, 3) B gets the rest
        minority_a += n_a[j] - to_a.max(1)
        minority_b += n_b[j] - to_b.max(1)
    total_a, total_b = int(n_a.sum()), int(n_b.sum())
    # T x total_a x total_b is an integer: compare those, exactly, rather than rounded fractions
    scaled_obs = int(obs_a) * total_b - int(obs_b) * total_a
    scaled_perm = minority_a.astype(np.int64) * total_b - minority_b.astype(np.int64) * total_a  # (R,)
    p_greater = (1 + int((scaled_perm >= scaled_obs).sum())) / (1 + n_permutations)
    p_less = (1 + int((scaled_perm <= scaled_obs).sum())) / (1 + n_permutations)
    t_obs = scaled_obs / (total_a * total_b)
    alpha = (1 - level) / 2
    v = HOLDS if p_greater < alpha else (DOES_NOT_HOLD if p_less < alpha else CANNOT_TELL)
    return ExitTest(float(t_obs), p_greater, p_less, len(shared), (total_a, total_b), v)
