"""The starts as a level of the bootstrap: agents and starts resampled as two crossed factors (chapter 09).

In the replication every agent drove the *same* starts: episode j of every agent, of every method and
of the expert began at the same pose with the same light phases (``experiments.agents.evaluate.EVAL_SEED``).
``stats.bootstrap_means`` draws agents and then, within each drawn agent, its episodes independently, so
it treats a start as noise private to an agent. The starts are shared: another draw of ten starts would
move every agent's score together (a start with long red phases lowers all of them), and a claim about
the method in town02, not on these ten starts, has that variation in it.

The **crossed two-level bootstrap** (the "pigeonhole" bootstrap of a two-way crossed design: Owen 2007,
*The pigeonhole bootstrap*, Ann. Appl. Stat. 1(2):386-411) draws, in every resample, E starts with
replacement and A agents with replacement, independently, and averages the A x E cells of the drawn
agents at the drawn starts. For scores y_ij = mu + a_i + b_j + e_ij (agent effect a, start effect b,
residual e) the variance of its resampled mean is about Var(a) / A + Var(b) / E + Var(e) / (A E), each
part counted once or a little more (Owen shows it errs on the wide side). With ``resample_starts=False``
the starts stay as they are and only agents are drawn: the interval of a claim about *these* starts;
the difference between the two says how much the choice of starts moves a result.

Two methods compared on the same starts share one draw of starts (``crossed_difference_replicates``): a
hard start lowers both, and the difference compares like with like; their agents are drawn
independently. The expert's mean in a ratio is taken over the same drawn starts (``crossed_ratio_interval``).

Numbers only, seeded (``seed``: an int or a ``np.random.Generator``), vectorised over the resamples.
"""

from __future__ import annotations

import numpy as np

from ibc_tutorial.stats import (
    DEFAULT_RESAMPLES,
    LEVEL,
    Interval,
    check_expert,
    check_level,
    check_scores,
    percentile_interval,
    ratio_interval,
    resampling_generator,
)
from ibc_tutorial.utils import check_int

_CHUNK = 1 << 22
"""Largest number of drawn (resample, agent, start) cells held at once."""


def crossed_draws(n_agents: int, n_starts: int, n_resamples: int, rng: np.random.Generator, *, starts=True):
    """Yield (agents (r, A), starts (r, E)) index arrays of the crossed bootstrap, in chunks of resamples.

    ``starts=False``: every resample keeps the E starts as they are (``starts`` is then 0..E-1 in each row).
    """
    chunk = max(1, _CHUNK // (n_agents * n_starts))
    for first in range(0, n_resamples, chunk):
        r = min(chunk, n_resamples - first)
        agents = rng.integers(n_agents, size=(r, n_agents))  # (r, A)
        if starts:
            drawn = rng.integers(n_starts, size=(r, n_starts))  # (r, E)
        else:
            drawn = np.broadcast_to(np.arange(n_starts), (r, n_starts))  # (r, E) the starts as they are
        yield agents, drawn


def _cells(x: np.ndarray, agents: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """(r,) means of ``x`` (A, E) over the drawn agents (r, A) at the drawn starts (r, E)."""
    return x[agents[:, :, None], starts[:, None, :]].mean(axis=(1, 2))  # (r, A, E) -> (r,)


def crossed_means(scores, n_resamples: int = DEFAULT_RESAMPLES, seed=0, *, resample_starts: bool = True):
    """(R,) resampled grand means of ``scores`` (A agents, E shared starts): the crossed bootstrap."""
    x = check_scores("scores", scores)
    n_resamples = check_int("n_resamples", n_resamples, minimum=1)
    rng = resampling_generator(seed)
    draws = crossed_draws(*x.shape, n_resamples, rng, starts=bool(resample_starts))
    return np.concatenate([_cells(x, agents, starts) for agents, starts in draws])  # (R,)


def crossed_mean_interval(
    scores,
    *,
    resample_starts: bool = True,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed=0,
    level: float = LEVEL,
) -> Interval:
    """The mean of one method's (A, E) scores with its crossed-bootstrap percentile interval."""
    x = check_scores("scores", scores)
    level = check_level(level)
    reps = crossed_means(x, n_resamples, seed, resample_starts=resample_starts)
    return percentile_interval(x.mean(), reps, level)


def crossed_ratio_interval(
    scores,
    expert,
    *,
    resample_starts: bool = True,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed=0,
    level: float = LEVEL,
) -> Interval:
    """mean(method) / mean(expert) with its crossed-bootstrap interval; the expert drove the same E starts.

    ``scores`` (A, E), ``expert`` (E,) with every score > 0. Each resample draws agents and starts, and
    the expert's mean is over the same drawn starts (as ``stats.ratio_interval`` does)."""
    x = check_scores("scores", scores)
    ex = check_expert(expert, x.shape[1])
    level = check_level(level)
    n_resamples = check_int("n_resamples", n_resamples, minimum=1)
    rng = resampling_generator(seed)
    reps = [
        _cells(x, agents, starts) / ex[starts].mean(axis=1)
        for agents, starts in crossed_draws(*x.shape, n_resamples, rng, starts=bool(resample_starts))
    ]
    return percentile_interval(x.mean() / ex.mean(), np.concatenate(reps), level)


def crossed_difference_replicates(
    scores_a, scores_b, *, resample_starts: bool = True, n_resamples: int = DEFAULT_RESAMPLES, seed=0
) -> tuple[float, np.ndarray]:
    """(mean(A) - mean(B), its (R,) resamples): two methods' (A, E) and (B, E) scores on the same E starts.

    Each resample draws one set of starts for both methods and each method's agents independently."""
    a = check_scores("scores_a", scores_a)
    b = check_scores("scores_b", scores_b)
    if a.shape[1] != b.shape[1]:
        raise ValueError(
            f"scores_a and scores_b must hold the same starts (columns), got {a.shape[1]} and {b.shape[1]}"
        )
    n_resamples = check_int("n_resamples", n_resamples, minimum=1)
    rng = resampling_generator(seed)
    e = a.shape[1]
    reps = []
    for agents_a, starts in crossed_draws(a.shape[0], e, n_resamples, rng, starts=bool(resample_starts)):
        agents_b = rng.integers(b.shape[0], size=(len(starts), b.shape[0]))  # (r, B)
        reps.append(_cells(a, agents_a, starts) - _cells(b, agents_b, starts))
    return float(a.mean() - b.mean()), np.concatenate(reps)  # (R,)


def crossed_difference_interval(
    scores_a,
    scores_b,
    *,
    resample_starts: bool = True,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed=0,
    level: float = LEVEL,
) -> Interval:
    """mean(A) - mean(B) on the same starts with its crossed-bootstrap interval."""
    level = check_level(level)
    estimate, reps = crossed_difference_replicates(
        scores_a, scores_b, resample_starts=resample_starts, n_resamples=n_resamples, seed=seed
    )
    return percentile_interval(estimate, reps, level)


def share_per_start(scores, expert) -> np.ndarray:
    """(E,) the method's mean over its agents at each start over the expert's score there."""
    x = check_scores("scores", scores)
    return x.mean(axis=0) / check_expert(expert, x.shape[1])  # (E,)


def fresh_starts_interval(
    scores,
    expert,
    n_starts: int = 10,
    *,
    n_resamples: int = DEFAULT_RESAMPLES,
    seed=0,
    level: float = LEVEL,
) -> Interval:
    """Where the *same* agents' share of the expert should fall on ``n_starts`` starts drawn afresh: a
    bootstrap prediction interval, not a confidence interval.

    ``scores`` (A, E) of the agents at the E observed starts, ``expert`` (E,) the expert's there. Each
    resample draws ``n_starts`` of the E starts with replacement, the same for every agent and the expert, and
    takes mean(agents at them) / mean(expert at them); the agents are not resampled, since a check on new
    starts drives the same agents. The estimate is the share over all E starts. The observed starts stand in
    for town02's population of starts, so the interval is as good as E is large: with few starts it misses
    starts unlike any observed one, and its tails come out too short (Efron & Tibshirani 1993, ch. 13's
    caution for any bootstrap from a small sample)."""
    x = check_scores("scores", scores)
    ex = check_expert(expert, x.shape[1])
    n_starts = check_int("n_starts", n_starts, minimum=1)
    n_resamples = check_int("n_resamples", n_resamples, minimum=1)
    level = check_level(level)
    rng = resampling_generator(seed)
    agent_means = x.mean(axis=0)  # (E,) the mean over the agents at each start
    drawn = rng.integers(x.shape[1], size=(n_resamples, n_starts))  # (R, n) the fresh starts
    reps = agent_means[drawn].mean(axis=1) / ex[drawn].mean(axis=1)  # (R,)
    return percentile_interval(x.mean() / ex.mean(), reps, level)


SHARE_LEVELS = (
    "agents only (these starts)",
    "agents, then each agent's episodes",
    "agents and starts, crossed",
)
"""The three bootstraps of a share of the expert that chapter 09 sets side by side (``share_levels``)."""


def share_levels(scores, expert, seed=0) -> dict[str, Interval]:
    """One method's share of the expert, mean(scores) / mean(expert), with its interval at each level of
    ``SHARE_LEVELS``: the agents resampled at these starts (``resample_starts=False``), the agents then each
    drawn agent's episodes (``stats.ratio_interval``, the two-level bootstrap), and agents and starts crossed
    (``crossed_ratio_interval``). ``scores`` (A, E), ``expert`` (E,)."""
    return dict(
        zip(
            SHARE_LEVELS,
            (
                crossed_ratio_interval(scores, expert, resample_starts=False, seed=seed),
                ratio_interval(scores, expert, seed=seed),
                crossed_ratio_interval(scores, expert, seed=seed),
            ),
            strict=True,
        )
    )
