"""Two runs of the same replication compared by their conclusions (chapter 09's re-run under another CPU).

A replication re-run elsewhere (another CPU's kernels, say) does not reproduce its episodes bit for
bit; what should survive is what the chapter concludes from them. This module compares two folders of
the same preset on each method's share of the expert (``expert_shares``) and on the free-driving
visit-count test (``visit_count_tests``); the five claims are compared by ``claims.compare_verdicts``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ibc_tutorial import stats
from ibc_tutorial.experiments.agents.claims import CLAIMS, stem_counts
from ibc_tutorial.experiments.agents.replication_folder import episode_table, load_results


@dataclass(frozen=True)
class ExpertShares:
    """Each method's share of the expert's mean score in two runs, on one evaluation's starts."""

    evaluation: str
    """``"final"`` (the table's starts) or ``"heldout"``."""
    first: dict[str, stats.Interval]
    """method -> mean score / the expert's mean score, with its interval, in the first run."""
    second: dict[str, stats.Interval]
    """the same in the second run."""
    same_expert: bool
    """whether the expert's episodes scored exactly the same in both runs (the expert uses no torch)."""


def expert_shares(first, second, methods, evaluation: str = "final") -> ExpertShares:
    """Each method's ``stats.ratio_interval`` of its agents' scores in two replication folders.

    Both runs' ratios divide by the *second* run's expert (E,) episodes, so that ``same_expert`` is
    what says whether the two denominators agree; the agents' scores are (A agents, E episodes).
    """
    expert = episode_table(second, "expert", "score", evaluation).values[0]  # (E,)
    shares: tuple[dict, dict] = ({}, {})
    for m in methods:
        for out, folder in zip(shares, (first, second), strict=True):
            out[m] = stats.ratio_interval(episode_table(folder, m, "score", evaluation).values, expert)
    same = np.array_equal(expert, episode_table(first, "expert", "score", evaluation).values[0])
    return ExpertShares(evaluation, shares[0], shares[1], bool(same))


def format_expert_shares(shares: ExpertShares, name: str, labels=("native", "emulated CPU")) -> str:
    """``shares`` as the lines chapter 09 prints: one row per method, the two runs side by side."""
    lines = [f"share of the expert's mean score, {name}:", f"  {'':7s} {labels[0]:20s} {labels[1]}"]
    lines += [f"  {m:7s} {str(shares.first[m]):20s} {shares.second[m]}" for m in shares.first]
    lines.append(
        f"  the expert's episodes are {'the same' if shares.same_expert else 'NOT the same'} in both runs"
    )
    return "\n".join(lines)


def visit_count_tests(folders: dict, a: str = "da-ibc", b: str = "bc") -> dict[str, stats.ExitTest]:
    """``stats.exit_spread_test`` of method ``a`` against ``b`` on each folder's free-driving visits.

    ``folders``: run name -> replication folder; each one's ``free_driving`` episodes' visits (per
    junction approach, the exit taken) of all its agents are pooled per method.
    """
    tests = {}
    for run, folder in folders.items():
        free = load_results(folder)["results"]["free_driving"]
        visits = {m: [x for e in free[m]["episodes"] for x in e["visits"]] for m in (a, b)}
        tests[run] = stats.exit_spread_test(visits[a], visits[b])
    return tests


def format_visit_count_tests(tests: dict[str, stats.ExitTest]) -> str:
    """One line per run: the visit-count test's verdict, its p-value and how many approaches it shared."""
    return "\n".join(
        f"the visit-count test, {run:8s}: {t.verdict} "
        f"(p = {t.p_greater:.4f}, {t.approaches} shared approaches)"
        for run, t in tests.items()
    )


def format_agreement(agreement: dict, first, second, detail=(3,), labels=("native", "emulated")) -> str:
    """``claims.compare_verdicts``'s ``agreement`` of two judged folders as chapter 09 prints it.

    One line per claim: both verdicts and whether they agree, or the first's verdict and why the
    second run could not judge it (its ``missing`` reason, cut to 60 characters). For a judged claim
    whose verdicts differ, or whose number is in ``detail``, every part's judgement in both runs follows.
    """
    lines = []
    for k, a in agreement.items():
        if second[k].missing:
            lines.append(
                f"{k}. {CLAIMS[k]}: {labels[0]} {a.first}; not judged on the re-run: "
                f"{second[k].missing[0][:60]}..."
            )
            continue
        lines.append(
            f"{k}. {CLAIMS[k]}: {labels[0]} {a.first}, {labels[1]} {a.second}: "
            f"{'same' if a.same else 'DIFFERENT'}"
        )
        if not a.same or k in detail:
            lines += [
                f"     {run:8s} {part}"
                for run, j in zip(labels, (first, second), strict=True)
                for part in j.claims[k].parts
            ]
    return "\n".join(lines)


def stem_counts_by_run(runs: dict[str, dict], methods) -> dict[str, dict]:
    """method -> {run -> ``claims.stem_counts``}: each method's exits and stem ends in each run's files.

    ``runs``: run name -> stem-analysis files (``claims.stem_files``, one per agent and the expert).
    """
    return {m: {run: stem_counts(files, m) for run, files in runs.items()} for m in methods}


def format_stem_counts(counts: dict[str, dict]) -> str:
    """``stem_counts_by_run``'s two runs side by side: minority exit, left of crossings, stem ends."""
    lines = [
        f"\n{'':8s} {'minority exit at the stems (95 %)':>36s}   "
        f"{'left/crossings':>19s}   {'ended at a stem':>16s}"
    ]
    first_run, second_run = next(iter(counts.values()))
    lines.append(
        f"{'':8s} {first_run:>17s} {second_run:>18s}   "
        f"{first_run:>9s} {second_run:>9s}   {first_run:>7s} {second_run:>8s}"
    )
    for m, by_run in counts.items():
        a, b = by_run[first_run], by_run[second_run]
        lines.append(
            f"{m:8s} {str(a.minority):>17s} {str(b.minority):>18s}   {f'{a.left}/{a.crossings}':>9s} "
            f"{f'{b.left}/{b.crossings}':>9s}   {a.ended_at_stem:7d} {b.ended_at_stem:8d}"
        )
    return "\n".join(lines)
