"""Ablations of the laptop replication: which of its departures from the paper decide how the agents drive.

    ibc-tutorial replicate --preset laptop --ablation flag-lights --out book/results/ablations/flag-lights

An ablation is a replication of a variant of a preset (``ablation_preset``): one setting changed
back (or away), with BC and DA-IBC only, three seeds, the table's final evaluation and nothing
else (no held-out starts, no free driving). Its runs use the same seeds, data and evaluation
starts as the replication it varies, so chapter 08 compares each variant with the replication's
own agents of those seeds, method by method.

The variants (``ABLATIONS``):

- ``flag-lights``: the light channels as one "must stop" bit (red and yellow drawn at 1, green not
  drawn), the encoding the book used before it drew each state by intensity (``driving.bev``);
- ``constant-lr``: the training of the previous laptop preset, 6 epochs at a constant step size,
  instead of 8 epochs of cosine decay;
- ``previous-preset``: both at once, i.e. the previous laptop preset (one-bit lights, 6 epochs at a
  constant step size); against ``flag-lights`` it measures the training schedule alone on the
  one-bit lights.
"""

from __future__ import annotations

from dataclasses import replace

from ibc_tutorial.experiments.agents.presets import Preset
from ibc_tutorial.utils import check_choice

ABLATIONS = {
    "flag-lights": ("the lights as one 'must stop' bit (red and yellow drawn, green not)",
                    {"light_encoding": "flag"}),
    "constant-lr": ("6 epochs at a constant step size (the previous laptop training)",
                    {"epochs": 6, "lr_schedule": "constant"}),
    "previous-preset": ("the previous laptop preset: one-bit lights and 6 epochs at a constant step size",
                        {"light_encoding": "flag", "epochs": 6, "lr_schedule": "constant"}),
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
    return replace(base, name=f"{base.name}+{name}", methods=ABLATION_METHODS, seeds=ABLATION_SEEDS,
                   routeless_episodes=0, heldout_episodes=0, **ABLATIONS[name][1])
