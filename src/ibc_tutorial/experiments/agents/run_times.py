"""Where a replication's time goes, from the seconds its files record (the appendix: "where the hour goes").

Each run's ``final_eval.json`` records its training seconds (the evaluations during training included) and
its final evaluation's seconds, ``heldout_eval.json`` the held-out evaluation's, and every line of
``metrics.jsonl`` the seconds of that evaluation during training. ``run_seconds`` reads them per run,
``phase_means`` averages them per method and ``serial_shares`` says which share of the runs' serial time
each phase took.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ibc_tutorial.experiments.agents.replication_folder import read_final_eval, run_dir
from ibc_tutorial.experiments.agents.training_run import read_metrics

PHASES = ("training", "evaluations during training", "final evaluation", "held-out evaluation")
"""The phases of a run, as ``RunSeconds`` holds them (the second is part of the first)."""


@dataclass(frozen=True)
class RunSeconds:
    """One run's wall seconds per phase, as its files record them."""

    training: float
    """The training call, its periodic evaluations included."""
    evaluations_during_training: float
    """Of which the periodic evaluations in town02 (``metrics.jsonl``)."""
    final_evaluation: float
    """The table's evaluation (``final_eval.json``)."""
    heldout_evaluation: float
    """The evaluation from the held-out starts (``heldout_eval.json``; 0 if the run has none)."""

    @property
    def total(self) -> float:
        """The run's seconds, all phases."""
        return self.training + self.final_evaluation + self.heldout_evaluation


def run_seconds(folder, methods, seeds) -> dict[tuple[str, int], RunSeconds]:
    """``{(method, seed): RunSeconds}`` of every run of ``folder`` (a finished replication)."""
    out = {}
    for m in methods:
        for s in seeds:
            d = run_dir(folder, m, s)
            final = read_final_eval(d / "final_eval.json")
            held = d / "heldout_eval.json"
            held_s = read_final_eval(held)["eval_seconds"] if held.exists() else 0.0
            during = sum(float(r.get("eval_seconds", 0.0)) for r in read_metrics(d))
            out[m, s] = RunSeconds(final["train_seconds"], during, final["eval_seconds"], held_s)
    return out


def expert_seconds(folder) -> float:
    """The seconds of the expert's rows (its final and held-out evaluations) in ``folder``."""
    d = Path(folder) / "runs" / "expert"
    return sum(read_final_eval(d / f)["eval_seconds"] for f in ("final_eval.json", "heldout_eval.json"))


def phase_means(runs: dict[tuple[str, int], RunSeconds]) -> dict[str, dict[str, float]]:
    """``{phase: {method: mean seconds per run}}`` over the runs of each method, for each of ``PHASES``."""
    methods = list(dict.fromkeys(m for m, _ in runs))
    fields = ("training", "evaluations_during_training", "final_evaluation", "heldout_evaluation")
    return {
        phase: {m: float(np.mean([getattr(r, f) for (k, _), r in runs.items() if k == m])) for m in methods}
        for phase, f in zip(PHASES, fields, strict=True)
    }


def serial_shares(
    runs: dict[tuple[str, int], RunSeconds], energy_methods=("ibc", "da-ibc")
) -> dict[str, float]:
    """Shares of the runs' serial time: ``training`` (all runs), ``energy training`` (the runs of
    ``energy_methods``) and ``evaluations`` (final and held-out)."""
    total = sum(r.total for r in runs.values())
    if total <= 0:
        raise ValueError("runs must hold at least one run with recorded seconds")
    train = sum(r.training for r in runs.values())
    energy = sum(r.training for (m, _), r in runs.items() if m in energy_methods)
    return {"training": train / total, "energy training": energy / total, "evaluations": 1 - train / total}
