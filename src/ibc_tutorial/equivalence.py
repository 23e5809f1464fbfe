"""Equivalence within ±δ, the fourth verdict: two one-sided tests (TOST) on a difference of means.

``stats.verdict`` judges "A is above B" by the 95 % interval of the difference d = mean(A) - mean(B):
"holds" (A better), "does not hold" (A worse) or "cannot tell at this scale". The last mixes two
situations: the methods are close, and the data are too few to say anything. An **equivalence test**
separates them. Given δ > 0, the smallest difference the claim cares about, stated *before* the data are
read, the **two one-sided tests** (TOST; Schuirmann 1987, "A comparison of the two one-sided tests
procedure and the power approach for assessing the equivalence of average bioavailability",
J. Pharmacokinet. Biopharm. 15(6):657-680) test

    H0-: d <= -δ  against  d > -δ,      and      H0+: d >= +δ  against  d < +δ,

each one-sided at level α, and declare the two means **equivalent within ±δ** if both are rejected:
p = max(p-, p+) < α. Schuirmann showed that this is the same as the (1 - 2α) interval of d lying inside
(-δ, +δ): at α = 0.05 the 90 % interval.

Here the one-sided tests use the same bootstrap resamples as the claim's interval (``stats`` or
``crossed_bootstrap``): p- is the share of resampled differences at or below -δ, p+ the share at or above
+δ, so "equivalent" is the α and 1 - α percentiles of the resamples both inside ±δ.

``judge_difference`` gives the four verdicts of a claim "A is above B":

- ``stats.EQUIVALENT`` if TOST rejects both hypotheses (a difference established but smaller than δ is
  equivalent too: δ is, by its definition, the smallest difference that matters);
- else ``stats.HOLDS`` (A better) if the whole (1 - α) interval lies above 0, ``stats.DOES_NOT_HOLD`` (A
  worse) if below;
- else ``stats.CANNOT_TELL``: the interval holds 0 and reaches beyond ±δ, too few agents or starts to say.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ibc_tutorial import stats
from ibc_tutorial.crossed_bootstrap import crossed_difference_replicates
from ibc_tutorial.utils import check_positive

ALPHA = 1 - stats.LEVEL
"""Level of each one-sided test: 0.05, so the equivalence interval is the 90 % one."""


@dataclass(frozen=True)
class Equivalence:
    """The two one-sided tests of a difference against ±δ (``tost``)."""

    delta: float
    """δ: the two means are called equivalent if their difference is shown to lie within ±δ."""
    p_lower: float
    """p-value of H0-: d <= -δ (the share of resampled differences at or below -δ)."""
    p_upper: float
    """p-value of H0+: d >= +δ (the share at or above +δ)."""
    interval: stats.Interval
    """The (1 - 2 α) percentile interval of the difference (90 % at α = 0.05)."""
    alpha: float
    """Level of each one-sided test."""

    @property
    def p(self) -> float:
        """TOST's p-value: the larger of the two."""
        return max(self.p_lower, self.p_upper)

    @property
    def equivalent(self) -> bool:
        """Both one-sided hypotheses rejected at ``alpha``."""
        return self.p < self.alpha


def _check_alpha(alpha) -> float:
    try:
        a = float(alpha)
    except (TypeError, ValueError):
        raise ValueError(f"alpha must be a number in (0, 0.5), got {alpha!r}") from None
    if not 0.0 < a < 0.5:
        raise ValueError(f"alpha must be in (0, 0.5), got {alpha!r}")
    return a


def tost(estimate: float, replicates, delta: float, *, alpha: float = ALPHA) -> Equivalence:
    """The two one-sided tests of the difference ``estimate`` against ±``delta`` from its (R,) bootstrap
    ``replicates`` (e.g. ``stats.difference_replicates``)."""
    delta = check_positive("delta", delta)
    alpha = _check_alpha(alpha)
    reps = np.asarray(replicates, dtype=float).ravel()  # (R,)
    if reps.size == 0 or not np.isfinite(reps).all():
        raise ValueError("replicates must be a non-empty array of finite resampled differences")
    p_lower = float((reps <= -delta).mean())
    p_upper = float((reps >= delta).mean())
    return Equivalence(
        float(delta), p_lower, p_upper, stats.percentile_interval(estimate, reps, 1 - 2 * alpha), alpha
    )


def four_verdicts(interval: stats.Interval, equivalence: Equivalence) -> str:
    """``stats.EQUIVALENT`` if ``equivalence`` holds, else ``stats.verdict(interval, 0)``."""
    if not isinstance(equivalence, Equivalence):
        raise ValueError(f"equivalence must be an Equivalence (tost), got {type(equivalence).__name__}")
    return stats.EQUIVALENT if equivalence.equivalent else stats.verdict(interval, 0.0)


def judge_difference(
    scores_a,
    scores_b,
    claim: str,
    delta: float,
    *,
    shared_starts: bool = True,
    n_resamples: int = stats.DEFAULT_RESAMPLES,
    seed=0,
) -> stats.Judgement:
    """The claim "A's mean is above B's" with four verdicts: better, worse, equivalent within ±δ, or cannot
    tell.

    ``scores_a`` (A, E) and ``scores_b`` (B, E'): each method's (agents, episodes) values. With
    ``shared_starts`` (E = E', episode j of every agent from the same start) the resamples are the crossed
    bootstrap of agents and starts (``crossed_bootstrap``); without, the nested one of ``stats.compare``
    (agents, then each agent's episodes). The 95 % interval and TOST read the same resamples."""
    if shared_starts:
        estimate, reps = crossed_difference_replicates(scores_a, scores_b, n_resamples=n_resamples, seed=seed)
    else:
        estimate, reps = stats.difference_replicates(scores_a, scores_b, n_resamples=n_resamples, seed=seed)
    interval = stats.percentile_interval(estimate, reps, stats.LEVEL)
    eq = tost(estimate, reps, delta)
    return stats.Judgement(
        str(claim), interval, 0.0, four_verdicts(interval, eq), eq.delta, eq.interval, eq.p
    )
