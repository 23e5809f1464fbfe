"""Ablations of the laptop replication: which of its departures from the paper decide how the agents drive.

    ibc-tutorial replicate --preset laptop --ablation no-brake-noise --out
    book/results/ablations/no-brake-noise

An ablation is a replication of a variant of a preset (``ablation_preset``): one setting changed
back (or away), with BC and DA-IBC only, three seeds, the table's final evaluation and nothing
else (no held-out starts, no free driving). Its runs use the same seeds, data and evaluation
starts as the replication it varies, so chapter 08 compares each variant with the replication's
own agents of those seeds, method by method.

The variants of the laptop preset (``ABLATIONS``):

- ``no-brake-noise``: demonstrations collected without the expert's held brakes
  (``driving.expert``), as the paper's;
- ``intensity-lights``: the light channels drawn by state (red 1.0, yellow 0.6, green 0.3,
  ``driving.bev``) instead of one "must stop" bit;
- ``constant-lr``: 6 epochs at a constant step size instead of 8 epochs of cosine decay;
- ``previous-preset``: the laptop preset of the book's previous edition, i.e. no held brakes and 6
  epochs at a constant step size (one-bit lights, as now); against ``no-brake-noise`` it measures
  the training schedule alone.

The book's ablation folders were made as the laptop preset changed, each at its own commit
(``PROVENANCE.md`` in each): ``flag-lights`` when the preset drew lights by intensity and had no held
brakes, so that it is today's ``no-brake-noise`` variant (chapter 08 checks that the two presets
are equal), and ``intensity-lights`` is the replication of that time.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from ibc_tutorial import stats
from ibc_tutorial.experiments.agents.presets import Preset
from ibc_tutorial.experiments.agents.results import episode_table
from ibc_tutorial.utils import check_choice

ABLATIONS = {
    "no-brake-noise": (
        "demonstrations without the expert's held brakes (as the paper's)",
        {"brake_noise": 0.0},
    ),
    "intensity-lights": (
        "the lights drawn by state (red 1.0, yellow 0.6, green 0.3), not as one 'must stop' bit",
        {"light_encoding": "intensity"},
    ),
    "constant-lr": (
        "6 epochs at a constant step size (the previous laptop training)",
        {"epochs": 6, "lr_schedule": "constant"},
    ),
    "previous-preset": (
        "the previous edition's laptop preset: no held brakes, 6 epochs at a constant step size",
        {"brake_noise": 0.0, "epochs": 6, "lr_schedule": "constant"},
    ),
}
"""Each variant: (what it changes, in words; the preset fields it changes)."""

ABLATION_METHODS = ("bc", "da-ibc")
"""The methods an ablation trains: the paper's baseline and its method."""
ABLATION_SEEDS = (0, 1, 2)
"""The seeds an ablation trains (the first three of the replication's)."""


def ablation_preset(base: Preset, name: str) -> Preset:
    """``base`` with the variant ``name`` of ``ABLATIONS`` applied, trained for ``ABLATION_METHODS`` and
    ``ABLATION_SEEDS`` and evaluated on the table's starts only."""
    check_choice("ablation", name, tuple(ABLATIONS))
    return replace(
        base,
        name=f"{base.name}+{name}",
        methods=ABLATION_METHODS,
        seeds=ABLATION_SEEDS,
        routeless_episodes=0,
        heldout_episodes=0,
        **ABLATIONS[name][1],
    )


STILL_M = 10.0
"""An episode of 3000 steps (300 s) in which the car drove less than this many metres: it stood still."""


@dataclass(frozen=True)
class AblationRow:
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


def compare_folders(variant, reference, methods: tuple[str, ...] = ABLATION_METHODS) -> list[AblationRow]:
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
            AblationRow(
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
