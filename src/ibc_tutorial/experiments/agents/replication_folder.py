"""The replication folder (``ibc-tutorial replicate --out FOLDER``): where everything sits, and reading it.

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

The names are here, once, with the folder's lifecycle (``FOLDER``, an ``experiments.runs.StudyFolder``);
``replicate`` writes the files. ``load_results(folder)`` is what chapters 08-09 call;
``episode_table(folder, method)`` gives one method's per-episode values, agents by seed, for the
statistics of chapter 09 (``stats``, which knows numbers only, never files). ``collect_results``
aggregates the finished runs into what ``results.json`` holds. Every file is checked as it is read; a
damaged one gives a ``ValueError`` naming it and saying how to make it again.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ibc_tutorial.experiments.agents.evaluate import summarize_episodes
from ibc_tutorial.experiments.agents.presets import PAPER, Preset, differences
from ibc_tutorial.experiments.agents.training_run import read_metrics
from ibc_tutorial.experiments.runs import (
    DATA,
    PROVENANCE,
    PROVENANCE_MD,
    RESULTS,
    Run,
    StudyFolder,
    read_json_dict,
    run_dir,
)
from ibc_tutorial.utils import check_choice

__all__ = [  # the folder's names (``DATA`` and ``run_dir`` are every study's: ``experiments.runs``)
    "ADDED",
    "DATA",
    "ENTRIES",
    "EPISODE_KEYS",
    "EVALUATIONS",
    "FINAL_EVAL",
    "FOLDER",
    "FREE_DRIVING",
    "LANDSCAPES",
    "STEM_DRIVE",
    "EpisodeTable",
    "collect_results",
    "episode_table",
    "expert_dir",
    "finished_runs",
    "load_results",
    "planned",
    "preset_results",
    "read_final_eval",
    "run_dir",
]

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
observations of its stem crossings and red stops (``stem_drives.recorded_drive``), which the stem analysis
reads."""
FINAL_EVAL = EVALUATIONS["final"]
"""A run is finished once this file exists (it is written last)."""
FOLDER = StudyFolder(
    what="replication",
    command="ibc-tutorial replicate",
    entries=ENTRIES,
    done=FINAL_EVAL,
    arrays={"free_driving": FREE_DRIVING, "landscapes": LANDSCAPES},
    markers=("data", "runs", RESULTS, PROVENANCE),
)
"""The replication's folder (``experiments.runs.StudyFolder``): the stem and route analyses write their
own folders into it too, so a folder holding any of ``markers`` is taken for a replication's."""


def expert_dir(out) -> Path:
    """Folder of the PID expert's evaluations on the agents' starts (the table's reference row)."""
    return Path(out) / "runs" / "expert"


def planned(preset) -> list[Run]:
    """The runs of a preset, in the order a replication makes them (seed by seed)."""
    return [Run(m, s) for s in preset.seeds for m in preset.methods]


def finished_runs(out, preset) -> list[str]:
    """The runs of ``preset`` under ``out`` that have their ``final_eval.json``, in planned order."""
    return FOLDER.finished(out, planned(preset))


EPISODE_KEYS = ("seed", "steps", "distance_m", "red_light_infractions", "score", "termination")
"""What every episode row of a ``final_eval.json`` holds."""
EPISODE_VALUES = ("score", "distance_m", "red_light_infractions", "steps")
"""The numeric values of an episode row that ``episode_table`` reads."""


def read_final_eval(path) -> dict:
    """A run's ``final_eval.json`` (or ``heldout_eval.json``), checked: its summary and one row per episode
    with ``EPISODE_KEYS``."""
    fix = f"delete {Path(path).parent} and re-run the same command to train and evaluate that run again"
    ev = read_json_dict(path, fix)
    rows = ev.get("episodes")
    if (
        not isinstance(ev.get("summary"), dict)
        or not isinstance(rows, list)
        or not rows
        or not all(isinstance(r, dict) and all(k in r for k in EPISODE_KEYS) for r in rows)
        or not all(isinstance(r["score"], (int, float)) for r in rows)
    ):
        raise ValueError(
            f"{path} is damaged: not a final evaluation (summary, episodes with "
            f"{', '.join(EPISODE_KEYS)}): {fix}"
        )
    return ev


# ---------------------------------------------------------------------- one method's episodes
@dataclass(frozen=True)
class EpisodeTable:
    """One method's per-episode values in a replication folder."""

    values: np.ndarray
    """(A, E): row a is agent ``agents[a]``, column j the episode started from ``starts[j]``."""
    agents: tuple[int, ...]
    """The agents' training seeds (``(0,)`` for the expert, which has one row)."""
    starts: tuple[int, ...]
    """The episodes' environment seeds (the same starts for every agent)."""


def episode_table(folder, method: str, key: str = "score", evaluation: str = "final") -> EpisodeTable:
    """The ``key`` of every episode of one method's runs in a replication folder, agents by seed.

    Reads ``folder/runs/<method>/seed<k>/final_eval.json`` (``evaluation="heldout"``:
    ``heldout_eval.json``) for whatever agents are there, or for ``method="expert"`` the one
    ``folder/runs/expert/final_eval.json`` as a single row. ValueError if there are none, or if the
    agents did not drive the same starts in the same order (their columns would not be comparable).
    The expert's row of the same ``evaluation`` has the same starts: ``table.starts ==
    expert.starts`` says so before ``stats.ratio_interval(table.values, expert.values[0])``.
    """
    check_choice("key", key, EPISODE_VALUES)
    check_choice("evaluation", evaluation, tuple(EVALUATIONS))
    name = EVALUATIONS[evaluation]
    root = Path(folder) / "runs" / str(method)
    if method == "expert":
        files, agents = ([root / name], [0]) if (root / name).is_file() else ([], [])
    else:
        files = [f for f in root.glob(f"seed*/{name}") if f.parent.name[4:].isdigit()]
        files.sort(key=lambda f: int(f.parent.name[4:]))
        agents = [int(f.parent.name[4:]) for f in files]
    if not files:
        raise ValueError(f"method {method!r} has no runs with a {name} under {root}")
    rows = [read_final_eval(f)["episodes"] for f in files]  # ValueError naming a damaged file
    starts = tuple(int(r["seed"]) for r in rows[0])
    for a, r in zip(agents, rows, strict=True):
        if tuple(int(x["seed"]) for x in r) != starts:
            raise ValueError(
                f"{method} seed {a} drove other starts than seed {agents[0]}: its {name} "
                "must list the same episode seeds in the same order"
            )
    values = np.array([[float(x[key]) for x in r] for r in rows])  # (A, E)
    return EpisodeTable(values, tuple(agents), starts)


# ---------------------------------------------------------------------- aggregation
def _curve(metrics: list[dict]) -> dict:
    """A run's Fig. 4 curve from its ``metrics.jsonl``: per evaluation, epoch, score, distance, infractions,
    loss."""
    return {
        "epoch": [e["epoch"] for e in metrics],
        "score": [e["eval"]["score_mean"] for e in metrics],
        "distance_m": [e["eval"]["distance_m_mean"] for e in metrics],
        "infractions": [e["eval"]["red_light_infractions_mean"] for e in metrics],
        "loss": [e["loss"] for e in metrics],
    }


def collect_results(out, preset: Preset) -> dict:
    """Read every finished run under ``out`` into the table, per-seed finals and curves of
    ``results.json``."""
    out = Path(out)
    final, heldout = EVALUATIONS["final"], EVALUATIONS["heldout"]
    table, curves, finals, held_table = {}, {}, {}, {}
    for method in preset.methods:
        rows, per_seed, held = [], {}, []
        curves[method] = {}
        for seed in preset.seeds:
            d = run_dir(out, method, seed)
            if (d / "metrics.jsonl").exists():
                curves[method][str(seed)] = _curve(read_metrics(d))
            if (d / final).exists():
                ev = read_final_eval(d / final)
                rows += ev["episodes"]
                per_seed[str(seed)] = ev["summary"]
                if (d / heldout).exists():
                    held += read_final_eval(d / heldout)["episodes"]
        finals[method] = per_seed
        if rows:
            table[method] = dict(
                summarize_episodes(rows), agents=len(per_seed)
            )  # every seed's episodes pooled
        if held:
            held_table[method] = dict(summarize_episodes(held), agents=len(per_seed))
    e = expert_dir(out)
    for name, into in ((final, table), (heldout, held_table)):
        if (e / name).exists():
            into["expert"] = dict(summarize_episodes(read_final_eval(e / name)["episodes"]), agents=1)
    return {"table": table, "heldout": held_table, "final_per_seed": finals, "curves": curves}


def preset_results(preset: Preset, complete: bool) -> dict:
    """The entries of ``results.json`` that describe the settings: the preset, the paper's, their
    differences."""
    return {
        "preset": preset.to_dict(),
        "paper": PAPER.to_dict(),
        "differences": {k: list(v) for k, v in differences(PAPER, preset).items()},
        "complete": complete,
    }


# ---------------------------------------------------------------------- reading (the chapters)
def load_results(out) -> dict:
    """What the chapters read from a replication folder: ``results.json`` and ``provenance.json`` as
    dicts, ``free_driving.npz`` and ``landscapes.npz`` as dicts of arrays (empty if absent).

    ValueError naming the file if one is missing or damaged."""
    return FOLDER.load(out)
