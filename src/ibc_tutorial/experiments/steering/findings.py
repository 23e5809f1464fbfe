"""Chapter 10's findings: claims about the models of the road-following study, judged over the seeds.

Each comparison is "model A's mean is above model B's" on one value per trained seed (e.g. a model's mean
W_cmd over its driving passes), judged by Welch's t interval over the seeds (``stats.compare_few``, honest
at three seeds); its claim names both models with their per-seed values, so that a reader sees what the
interval rests on. A finding made of several comparisons ("the regression has the fewest crashes", one
comparison per other model) gets the verdict of ``stats.combine_verdicts``: it holds only if every
comparison does.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from ibc_tutorial import stats


@dataclass(frozen=True)
class Finding:
    """A finding in words, its verdict, and the comparisons it combines: what chapter 10 prints."""

    claim: str
    """The finding in words, e.g. "MAE regression has the fewest crashes per km"."""
    verdict: str
    """``stats.combine_verdicts`` of the comparisons' verdicts."""
    comparisons: tuple[stats.Judgement, ...]
    """Each comparison, with its interval."""

    def __str__(self) -> str:
        return "\n".join([f"{self.claim}: {self.verdict.upper()}", *(str(j) for j in self.comparisons)])


def _values(per_seed: Mapping, model: str) -> np.ndarray:
    if model not in per_seed:
        raise ValueError(f"model must be one of {sorted(per_seed)}, got {model!r}")
    return np.asarray(per_seed[model], dtype=float)


def seed_values(per_seed: Mapping, model: str) -> str:
    """A model's per-seed values as printed in a claim, e.g. ``[0.12, 0.3]`` (3 significant digits)."""
    return "[" + ", ".join(f"{v:.3g}" for v in _values(per_seed, model)) + "]"


def above(per_seed: Mapping, a: str, b: str, labels: Mapping[str, str]) -> stats.Judgement:
    """ "a's mean is above b's" over the seeds. ``per_seed``: {model: (S,) one value per seed};
    ``labels``: {model: its name in the claim}."""
    va, vb = _values(per_seed, a), _values(per_seed, b)  # (S,), (S,)
    claim = f"  {labels[a]} {seed_values(per_seed, a)} above {labels[b]} {seed_values(per_seed, b)}"
    return stats.compare_few(va, vb, claim)


def one_above(per_seed: Mapping, a: str, b: str, labels: Mapping[str, str], claim: str) -> Finding:
    """The finding ``claim``, made of the one comparison "a above b"."""
    j = above(per_seed, a, b, labels)
    return Finding(claim, j.verdict, (j,))


def against_all(
    per_seed: Mapping,
    model: str,
    others: Iterable[str],
    labels: Mapping[str, str],
    claim: str,
    *,
    lower: bool = False,
) -> Finding:
    """The finding ``claim`` that ``model`` is above (``lower``: below) every other model of ``others``,
    one comparison per model; it holds only if every comparison does."""
    others = list(others)
    rest = [o for o in others if o != model]
    if not rest:
        raise ValueError(f"others must name at least one model besides {model!r}, got {others!r}")
    js = tuple(
        above(per_seed, o, model, labels) if lower else above(per_seed, model, o, labels) for o in rest
    )
    return Finding(claim, stats.combine_verdicts(*(j.verdict for j in js)), js)
