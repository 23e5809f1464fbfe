"""Where everything sits in a replication folder (``ibc-tutorial replicate --out FOLDER``).

A replication folder holds

- ``data/town01.npz``: the demonstrations (``DATA``);
- ``runs/<method>/seed<k>/``: one training run each (``run_dir``: ``run.json``, ``metrics.jsonl``,
  the evaluations of ``EVALUATIONS``, the agent, ``final.pt``, and the record of its table's episodes
  for the stem analysis, ``STEM_DRIVE``);
- ``runs/expert/``: the PID expert's evaluations on the same starts (``expert_dir``);
- ``results.json``: everything the chapters read (``RESULTS``);
- ``added_methods.json``: methods trained into the folder after its replication (``ADDED``,
  ``added_methods``), with their own table and invocations;
- ``free_driving.npz`` and ``landscapes.npz``: the arrays of the Fig. 5 and Fig. 6 analogues;
- ``provenance.json`` and ``PROVENANCE.md`` (``experiments.runs.Provenance``).

The names are here, once; ``results`` reads the files, ``replicate`` writes them.
"""

from __future__ import annotations

from pathlib import Path

from ibc_tutorial.experiments.runs import PROVENANCE, PROVENANCE_MD, RESULTS

DATA = "data/town01.npz"
"""The demonstrations, relative to the folder."""
FREE_DRIVING = "free_driving.npz"
"""Trajectories of the free-driving episodes (Fig. 5 analogue)."""
LANDSCAPES = "landscapes.npz"
"""Energy grids, observations and DFO inferences (Fig. 6 analogue)."""
ADDED = "added_methods.json"
"""The record of the methods added to a finished replication (``added_methods``)."""
ENTRIES = ("data", "runs", RESULTS, PROVENANCE, PROVENANCE_MD, FREE_DRIVING, LANDSCAPES, ADDED)
"""What a replication folder holds (``--force`` deletes these, and only these)."""
EVALUATIONS = {"final": "final_eval.json", "heldout": "heldout_eval.json"}
"""The evaluations of a run, by name: the table's starts (``final``, ``evaluate.EVAL_SEED``) and the
held-out starts (``heldout``, ``evaluate.HELDOUT_SEED``), with the file each is written to."""
STEM_DRIVE = "stem_drive.npz"
"""In a run folder (and ``runs/expert/``): the per-state record of the table's episodes and the
observations of its stem crossings and red stops (``stems.recorded_drive``), which the stem analysis reads."""
FINAL_EVAL = EVALUATIONS["final"]
"""A run is finished once this file exists (it is written last)."""


def run_dir(out, method: str, seed: int) -> Path:
    """Folder of one training run."""
    return Path(out) / "runs" / method / f"seed{seed}"


def expert_dir(out) -> Path:
    """Folder of the PID expert's evaluations on the agents' starts (the table's reference row)."""
    return Path(out) / "runs" / "expert"


def run_name(method: str, seed: int) -> str:
    """How a run is named in the provenance: ``method/seed<k>``."""
    return f"{method}/seed{seed}"


def planned_runs(preset) -> list[tuple[str, int]]:
    """The (method, seed) runs of a preset, in the order a replication makes them (seed by seed)."""
    return [(m, s) for s in preset.seeds for m in preset.methods]


def finished_runs(out, preset) -> list[str]:
    """The runs of ``preset`` under ``out`` that have their ``final_eval.json``, in planned order."""
    return [run_name(m, s) for m, s in planned_runs(preset) if (run_dir(out, m, s) / FINAL_EVAL).exists()]
