"""Two replication folders' scores compared method by method on the seeds and starts they share (chapter 08's
ablations: each a ``replicate`` with ``--set`` overrides that its ``PROVENANCE.md`` records)."""

from __future__ import annotations

from dataclasses import dataclass

from ibc_tutorial import stats
from ibc_tutorial.experiments.agents.replication_folder import episode_table

FOLDER_METHODS = ("bc", "da-ibc")
"""The methods ``compare_folders`` compares unless told: the paper's baseline and its method."""
STILL_M = 10.0
"""An episode of 3000 steps (300 s) in which the car drove less than this many metres: it stood still."""


@dataclass(frozen=True)
class FolderComparison:
    """One method of two replication folders compared on the agents (seeds) and starts they share."""

    method: str
    """The method compared."""
    seeds: tuple[int, ...]
    """The training seeds both folders hold for it."""
    score: tuple[float, float]
    """Mean episode score (variant, reference)."""
    red_lights: tuple[float, float]
    """Mean red lights run per episode (variant, reference)."""
    standing_still: tuple[int, int]
    """Episodes in which the car drove less than ``STILL_M`` (variant, reference)."""
    difference: stats.Interval
    """Mean score of the variant minus the reference's, with its 95 % two-level bootstrap interval."""
    verdict: str
    """``stats.verdict`` of ``difference`` against 0: does the variant score higher?"""


def compare_folders(variant, reference, methods: tuple[str, ...] = FOLDER_METHODS) -> list[FolderComparison]:
    """Compare two replication folders method by method, on their shared seeds and the table's starts.

    Each folder is read with ``episode_table``; ValueError if a method has no shared seeds or
    the folders' episodes started elsewhere (their columns would not be comparable)."""
    rows = []
    for m in methods:
        tables = {}
        for key in ("score", "red_light_infractions", "distance_m"):
            a, b = episode_table(variant, m, key), episode_table(reference, m, key)
            if a.starts != b.starts:
                raise ValueError(f"{variant} and {reference} evaluated {m} from other starts: not comparable")
            seeds = tuple(s for s in a.agents if s in b.agents)
            if not seeds:
                raise ValueError(f"{variant} and {reference} share no seed of {m}")
            rows_a, rows_b = [a.agents.index(s) for s in seeds], [b.agents.index(s) for s in seeds]
            tables[key] = (a.values[rows_a], b.values[rows_b])  # (S, E) each
        va, vb = tables["score"]
        diff = stats.difference_interval(va, vb)
        rows.append(
            FolderComparison(
                m,
                seeds,
                (float(va.mean()), float(vb.mean())),
                tuple(float(x.mean()) for x in tables["red_light_infractions"]),
                tuple(int((x < STILL_M).sum()) for x in tables["distance_m"]),
                diff,
                stats.verdict(diff),
            )
        )
    return rows
