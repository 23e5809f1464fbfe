"""What the side-road share sweep varies and where its files sit (``sweep``, ``ibc-tutorial sweep-steering``).

``SweepSettings`` (``SWEEP``: the budgeted choice of models, seeds and sessions), ``check_shares`` (the
``--shares`` rule), and the folder's names: one run's folder is ``share<p>/runs/<model>/seed<k>/``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from ibc_tutorial.experiments.runs import PROVENANCE, PROVENANCE_MD, RESULTS
from ibc_tutorial.experiments.settings import StoredSettings
from ibc_tutorial.experiments.steering.evaluate import REFERENCES
from ibc_tutorial.experiments.steering.junctions import MASS_THRESHOLD
from ibc_tutorial.experiments.steering.models import MODELS
from ibc_tutorial.experiments.steering.presets import SteeringPreset
from ibc_tutorial.experiments.steering.train import EVAL
from ibc_tutorial.utils import check_choice, check_int, check_positive

SETTINGS = "sweep.json"
"""The sweep's settings (``SweepSettings`` and the base preset)."""
PASSES = "passes.npz"
"""A finished run's per-pass traces: offsets towards the side road and the probability on it, per state."""
ENTRIES = (SETTINGS, REFERENCES, RESULTS, PROVENANCE, PROVENANCE_MD)
"""The files of a sweep folder beside its ``share<p>`` folders."""
MEASURES = ("peak_m", "side_mass", "section_w_cmd", "w_cmd", "crashes_per_km", "swerve_rate")
"""What the table reports per share and model (``evaluate.summarize_run_routes``'s names)."""


@dataclass(frozen=True)
class SweepSettings(StoredSettings):
    """What the sweep varies and how much of it it runs (the base preset holds everything else); stored flat
    (``to_dict``, ``from_dict``)."""

    shares: tuple = (0.15, 0.3, 0.5)
    """The side-road shares (``SteeringPreset.side_road_share``); 0.5 is the limit where the side road is
    as likely as keeping straight (as the stems' left and right)."""
    models: tuple = ("ebm", "ebm-soft", "regression", "mdn")
    """The models trained at every share: four of the study's six, for the budget. The grid EBM (the
    paper's subject), soft targets (the EBM variant that keeps steering: temporal smoothing at α = 1
    collapsed in the chapter's study, and trains on pairs, twice the time per step), the MAE regression
    (the model the paper saw swerve) and the MDN (the explicit multimodal model; the classifier asks the
    same question of a density, with bins)."""
    seeds: tuple = (0, 1, 2)
    """Training seeds per model and share."""
    sessions: int = 3
    """Driving sessions per trained model (``evaluate.SESSION_SHIFT_M``)."""
    mass_threshold: float = MASS_THRESHOLD
    """How far beyond the expert's steer (towards the side road) a steering value counts as the side
    road's (``junctions.side_road_mass``)."""

    def __post_init__(self):
        check_shares(self.shares)
        if not self.models or not self.seeds:
            raise ValueError("models and seeds must name at least one each")
        for m in self.models:
            check_choice("models", m, MODELS)
        for s in self.seeds:
            check_int("seeds", s, minimum=0)
        check_int("sessions", self.sessions, minimum=1)
        check_positive("mass_threshold", self.mass_threshold, allow_zero=True)


def check_shares(shares) -> tuple:
    """``shares`` (a tuple of numbers, or the text "0.15,0.3,0.5") as a tuple of distinct shares in (0, 1],
    in the order given; ValueError naming ``--shares`` otherwise."""
    if isinstance(shares, str):
        try:
            shares = tuple(float(x) for x in shares.split(",") if x.strip())
        except ValueError:
            raise ValueError(
                f"--shares must be numbers separated by commas, e.g. 0.15,0.3,0.5, got {shares!r}"
            ) from None
    shares = tuple(shares)
    if not shares:
        raise ValueError("--shares must name at least one side-road share")
    for s in shares:
        if isinstance(s, bool) or not isinstance(s, (int, float)) or not 0.0 < float(s) <= 1.0:
            raise ValueError(f"--shares: each share must be a number in (0, 1], got {s!r}")
    if len({round(float(s), 6) for s in shares}) != len(shares):
        raise ValueError(f"--shares: each share once, got {list(shares)}")
    return tuple(float(s) for s in shares)


SWEEP = SweepSettings()
"""The side-road sweep at the laptop preset: 3 shares x 4 models x 3 seeds = 36 runs, 3 sessions each.

Its budget, about 60 minutes with ``--workers 2 --threads 1``, from CPU time (``time.process_time``)
measured on a fraction of the work, on a loaded 2-core machine (AMD EPYC): 200 of the 3000 Adam steps
took 5.85 s (grid EBM) and 5.06 s (regression) once the BEVs were cached (7.4 s and 7.9 s with the
rendering), so about 90 s per model for 3000 steps; one session of loop-cw (about 2,050 steps) with
the side-road mass took 8.0 s (EBM) and 8.6 s (MDN), so about 23 s for the four routes' 5,600 steps and
70 s for 3 sessions. About 160 s per run, x 36 runs = 96 CPU minutes: 48 minutes on 2 workers, plus
under a minute for the demonstrations (0.36 s per route) and the references (about 2 s per route and
session). A 4th seed (48 runs) would take about 64 minutes, all six models (54 runs, smoothing at twice
the training time) about 75."""


def share_name(share: float) -> str:
    """A share's folder name: ``share0.15``."""
    return f"share{float(share):g}"


def share_preset(base: SteeringPreset, share: float) -> SteeringPreset:
    """The base preset at side-road share ``share``."""
    return replace(base, side_road_share=float(share))


def run_dir(out, share: float, model: str, seed: int) -> Path:
    """Folder of one run."""
    return Path(out) / share_name(share) / "runs" / model / f"seed{seed}"


def planned(settings: SweepSettings) -> list[tuple[float, str, int]]:
    """Every run, (share, model, seed), shares first (each share's data is then loaded once per worker)."""
    return [(p, m, s) for p in settings.shares for s in settings.seeds for m in settings.models]


def run_name(share: float, model: str, seed: int) -> str:
    return f"{share_name(share)}/{model}/seed{seed}"


def finished_runs(out, settings: SweepSettings) -> list[str]:
    """The runs with their ``eval.json``, in planned order."""
    return [run_name(*r) for r in planned(settings) if (run_dir(out, *r) / EVAL).exists()]
