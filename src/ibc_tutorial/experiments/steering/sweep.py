"""``ibc-tutorial sweep-steering``: the road-following study at several side-road shares.

    ibc-tutorial sweep-steering --preset laptop --out book/results/steering-sweep --workers 2 --threads 1

The chapter's study takes the side road in 15 % of the passes; whether a model represents, or swerves
towards, the rare mode depends on how rare it is. The sweep runs the study at each share of ``--shares``
(``SWEEP.shares``: 15 %, 30 % and 50 %; at 50 % the side road is as likely as keeping straight, as the
stems of a T are in every share's data) with the models and seeds of ``SWEEP`` (fewer than the study's
six: the budget, see ``SWEEP``), and drives every trained model in ``SWEEP.sessions`` driving sessions
(``evaluate.SESSION_SHIFT_M``), so its results have a session-to-session spread (the paper's Table 1 ±)
beside the seed-to-seed one.

The evaluation routes and the expert's path are the study's (straight past every side road): a swerve
and a crash are still measured against keeping straight. The measures of each side-road pass
(``evaluate.drive_route``): the peak offset towards the side road (m; the paper's swerve thresholds
1.0 m and 0.5 m give the secondary swerve rate), the model's probability on the side road's steering at
the junction (``junctions.side_road_mass``: EBMs, classifier, MDN; not the regression), and the W of the
commands inside the junction sections (``junctions.section_whiteness``).

Its settings are ``SweepSettings`` (``SWEEP``). Folder: ``sweep.json`` (the settings),
``references.npz`` (the expert's drives of every route and session, shared by every share),
``share<p>/data/town01.npz`` (each share's demonstrations), ``share<p>/runs/<model>/seed<k>/``
(``last.pt`` while training, then ``passes.npz``, the per-state traces of every pass, and ``eval.json``,
written last), ``results.json``, ``provenance.json`` and ``PROVENANCE.md``. Interrupted, the same
command resumes: a run with its ``eval.json`` is skipped, an unfinished one continues from ``last.pt``.
Other settings in the folder are refused before any work. The folder lives through the lifecycle every
study's folder does (``experiments.runs.StudyFolder``: ``FOLDER``), its runs in the parts ``share<p>``.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ibc_tutorial.driving.dataset import DemoDataset, DemoLog
from ibc_tutorial.experiments.runs import (
    DATA,
    PROVENANCE,
    PROVENANCE_MD,
    RESULTS,
    Run,
    StudyFolder,
    read_run_file,
    write_json,
    write_npz,
)
from ibc_tutorial.experiments.settings import StoredSettings
from ibc_tutorial.experiments.steering import evaluate as ev
from ibc_tutorial.experiments.steering.evaluate import REFERENCES
from ibc_tutorial.experiments.steering.junctions import MASS_THRESHOLD
from ibc_tutorial.experiments.steering.models import LABELS, MODELS
from ibc_tutorial.experiments.steering.presets import LAPTOP, SteeringPreset, differences
from ibc_tutorial.experiments.steering.task import preset_demonstrations, side_road_counts
from ibc_tutorial.experiments.steering.train import EVAL, SteeringModel, train_model
from ibc_tutorial.parallel import imap_unordered
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
    """A share's folder name, the part of the sweep that holds its data and runs: ``share0.15``."""
    return f"share{float(share):g}"


def share_preset(base: SteeringPreset, share: float) -> SteeringPreset:
    """The base preset at side-road share ``share``."""
    return replace(base, side_road_share=float(share))


FOLDER = StudyFolder(
    what="sweep",
    command="ibc-tutorial sweep-steering",
    entries=ENTRIES,
    done=EVAL,
    part_prefix="share",
)
"""A sweep's folder (``experiments.runs.StudyFolder``): its runs sit in the parts ``share<p>``."""


def sweep_run(share: float, model: str, seed: int) -> Run:
    """The run of ``model`` with ``seed`` at side-road share ``share``."""
    return Run(model, seed, share_name(share))


def planned(settings: SweepSettings) -> list[Run]:
    """Every run, shares first (each share's data is then loaded once per worker)."""
    return [sweep_run(p, m, s) for p in settings.shares for s in settings.seeds for m in settings.models]


def _stored(settings: SweepSettings, base: SteeringPreset) -> dict:
    return {"sweep": settings.to_dict(), "preset": base.to_dict()}


# ---------------------------------------------------------------------- the folder
def check_folder(out, settings: SweepSettings, base: SteeringPreset) -> None:
    """Refuse (ValueError: what and what to do) a folder holding anything but this sweep's files, or this
    sweep with other settings; a damaged run's ``eval.json`` is named."""
    if not FOLDER.check_entries(out):
        return
    mine = _stored(settings, base)

    def describe(stored: dict) -> str:
        diff = sorted(
            k
            for part in ("sweep", "preset")
            for k in set(stored.get(part) or {}) | set(mine[part])
            if (stored.get(part) or {}).get(k) != mine[part].get(k)
        )
        return f"a sweep of other settings (differs in {', '.join(diff[:5]) or 'its form'})"

    FOLDER.check_settings(out, lambda stored: stored == mine, describe, files=(SETTINGS,), key=None)
    FOLDER.check_runs(out, planned(settings), read_sweep_eval)


def clear_folder(out) -> None:
    """``--force``: delete a sweep's files and ``share*`` folders from ``out``, nothing else."""
    FOLDER.clear(out)


def read_sweep_eval(path) -> dict:
    """A run's ``eval.json``, checked; ValueError naming the file otherwise."""

    def valid(r):
        sessions = r.get("sessions")
        return (
            isinstance(sessions, list)
            and isinstance(r.get("summary"), dict)
            and all(isinstance(s, dict) and isinstance(s.get("summary"), dict) for s in sessions)
        )

    return read_run_file(path, valid, "a sweep run's evaluation")


# ---------------------------------------------------------------------- the work of one process
def make_references(out: Path, base: SteeringPreset, sessions: int) -> None:
    """The expert's drive of every evaluation route in every session (``references.npz``)."""
    arrays = {}
    for k in range(sessions):
        for name in base.eval_routes:
            ref, _ = ev.expert_reference(name, base, session=k)
            arrays.update(ref.to_arrays())
    write_npz(out / REFERENCES, arrays)


def _collect_one(out: str, share: float, base_d: dict) -> dict:
    """Collect one share's demonstrations (a worker's call); returns the side-road counts."""
    p = share_preset(SteeringPreset.from_dict(base_d), share)
    path = Path(out) / share_name(share) / DATA
    return {"share": share, "counts": side_road_counts(preset_demonstrations(p, path))}


_WORKER: dict = {}
"""Per process: one share's rendered demonstrations, and the references."""


def _run_one(out: str, share: float, model: str, seed: int, base_d: dict, settings_d: dict) -> dict:
    """Train one model at one share, drive it in every session, write ``passes.npz`` and ``eval.json``."""
    base, settings = SteeringPreset.from_dict(base_d), SweepSettings.from_dict(settings_d)
    preset = share_preset(base, share)
    key = (out, share, repr(base_d))
    if key not in _WORKER:
        _WORKER.clear()
        log = DemoLog.load(Path(out) / share_name(share) / DATA)
        ds = DemoDataset(log, bev_size=preset.bev_size, cache=True)
        _WORKER[key] = (
            ds,
            log.checksum(),
            ev.read_references(Path(out) / REFERENCES, base.eval_routes, settings.sessions)[0],
        )
    ds, sha, refs = _WORKER[key]
    d = FOLDER.run_dir(out, sweep_run(share, model, seed))
    c0 = time.process_time()
    steering, losses, seconds, resumed = train_model(model, seed, ds, preset, d, data_sha256=sha)
    c1 = time.process_time()
    result = evaluate_sessions(steering, refs, preset, settings.mass_threshold)
    arrays = result.pop("arrays")
    write_npz(d / PASSES, arrays)
    result.update(
        share=share,
        model=model,
        seed=seed,
        losses=losses,
        train_seconds=round(seconds, 1),
        train_cpu_seconds=round(c1 - c0, 1),
        eval_cpu_seconds=round(time.process_time() - c1, 1),
        resumed_from_step=resumed,
    )
    write_json(d / EVAL, result)  # last: with it the run is finished
    (d / "last.pt").unlink(missing_ok=True)
    return result


def evaluate_sessions(
    steering: SteeringModel, refs: list[list[ev.Reference]], preset: SteeringPreset, threshold: float
) -> dict:
    """Drive every route of every session (``evaluate.drive_route`` with the model's scores); per session
    its routes and summary, the summary over all sessions, and ``arrays``: the per-pass traces, keyed
    ``s<session>/<route>/p<pass>/offset`` and ``.../mass`` (for ``passes.npz``)."""

    def policy(obs):
        return float(steering.steer(obs)[0])

    scorer = None
    if steering.name != "regression":

        def scorer(obs):
            return steering.scores(obs)[0].numpy()  # (G,)

    grid = steering.display_grid.numpy()
    sessions, arrays, every = [], {}, []
    for k, session_refs in enumerate(refs):
        routes = []
        for ref in session_refs:
            r = ev.drive_route(policy, ref, preset, scorer=scorer, grid=grid, mass_threshold=threshold)
            r.pop("steer")
            offsets, masses = r.pop("pass_offsets"), r.pop("pass_mass", None)
            for p, tr in enumerate(offsets):
                arrays[f"s{k}/{ref.name}/p{p}/offset"] = np.asarray(tr, dtype=np.float32)
                if masses is not None:
                    arrays[f"s{k}/{ref.name}/p{p}/mass"] = np.asarray(masses[p], dtype=np.float32)
            routes.append(r)
        every += routes
        sessions.append({"session": k, "routes": routes, "summary": ev.summarize_run_routes(routes)})
    return {"sessions": sessions, "summary": ev.summarize_run_routes(every), "arrays": arrays}


# ---------------------------------------------------------------------- results
def _values(xs) -> list:
    return [float(x) for x in xs if x is not None and not (isinstance(x, float) and np.isnan(x))]


def spread(per_seed_sessions: list[list]) -> dict:
    """One measure of one model at one share: ``per_seed_sessions[i][k]`` is seed i's value in session k.

    Returns the seeds' means (each over its sessions), their mean and standard deviation over seeds, the
    session-to-session standard deviation (within each seed, averaged over the seeds that have 2 or more
    sessions), and the raw values."""
    seed_means = [float(np.mean(v)) for v in (_values(s) for s in per_seed_sessions) if v]
    within = [float(np.std(v, ddof=1)) for v in (_values(s) for s in per_seed_sessions) if len(v) > 1]
    return {
        "mean": round(float(np.mean(seed_means)), 5) if seed_means else None,
        "seed_std": round(float(np.std(seed_means, ddof=1)), 5) if len(seed_means) > 1 else None,
        "session_std": round(float(np.mean(within)), 5) if within else None,
        "seed_means": [round(v, 5) for v in seed_means],
        "values": [[None if x is None else round(float(x), 5) for x in s] for s in per_seed_sessions],
    }


def collect_results(out: Path, settings: SweepSettings) -> dict:
    """The finished runs: per share, model and seed their ``eval.json``; the table (``spread`` of every
    ``MEASURES``) per share and model."""
    runs, table = {}, {}
    for share in settings.shares:
        sn = share_name(share)
        runs[sn], table[sn] = {}, {}
        for model in settings.models:
            runs_here = [sweep_run(share, model, seed) for seed in settings.seeds]
            done = {
                str(r.seed): read_sweep_eval(FOLDER.run_dir(out, r) / EVAL)
                for r in runs_here
                if FOLDER.is_done(out, r)
            }
            runs[sn][model] = done
            if done:
                table[sn][model] = {
                    m: spread([[s["summary"].get(m) for s in r["sessions"]] for r in done.values()])
                    for m in MEASURES
                }
                table[sn][model]["seeds"] = len(done)
    return {"runs": runs, "table": table}


# ---------------------------------------------------------------------- the command
def sweep(
    settings: SweepSettings,
    base: SteeringPreset,
    out,
    *,
    command: str = "",
    overrides: tuple = (),
    workers: int = 1,
    threads: int = 1,
    log=print,
) -> dict:
    """Run the sweep (module docstring) into ``out``; returns ``results.json``'s contents."""
    out = Path(out)
    workers = check_int("workers", workers, minimum=1)
    check_folder(out, settings, base)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / SETTINGS, _stored(settings, base))
    runs = planned(settings)
    provenance = FOLDER.provenance(
        out,
        runs,
        title=f"the side-road share sweep on the `{base.name}` preset",
        command=command or f"ibc-tutorial sweep-steering --preset {base.name} --out {out}",
        preset=_stored(settings, base),
        differences=differences(LAPTOP, base),
        reference="the `laptop` preset (the sweep's own settings are in `sweep.json`)",
        overrides=list(overrides),
    )
    results: dict = {
        "settings": settings.to_dict(),
        "preset": base.to_dict(),
        "labels": {m: LABELS[m] for m in settings.models},
        "measures": list(MEASURES),
        "protocol": {
            "mass_threshold": settings.mass_threshold,
            "section_before_m": ev.SECTION_BEFORE_M,
            "slight_m": ev.SLIGHT_M,
            "clear_m": ev.CLEAR_M,
            "session_shift_m": ev.SESSION_SHIFT_M,
            "dt": ev.DT,
        },
    }

    shares = {share_name(p): p for p in settings.shares}

    def work(save) -> None:
        # 1. each share's demonstrations, and the references, side by side
        calls = [functools.partial(_collect_one, str(out), p, base.to_dict()) for p in settings.shares]
        collected = imap_unordered(calls, workers=workers, threads=threads)  # submitted now (2+ workers)
        if not (out / REFERENCES).exists():
            make_references(out, base, settings.sessions)  # here, while the workers collect
        data = {}
        for r in collected:
            data[share_name(r["share"])] = r["counts"]
            if log:
                c = r["counts"]
                log(
                    f"share {r['share']:g}: side roads taken {c['side_road']} of "
                    f"{c['straight'] + c['side_road']} passes"
                )
        results["data"] = {name: data[name] for name in shares}
        save(False)
        # 2. every run not finished yet
        todo = FOLDER.todo(out, runs)
        if log:
            log(f"{len(runs) - len(todo)} of {len(runs)} runs already finished; {len(todo)} to run")
        calls = [
            functools.partial(
                _run_one, str(out), shares[r.part], r.method, r.seed, base.to_dict(), settings.to_dict()
            )
            for r in todo
        ]
        for r in imap_unordered(calls, workers=workers, threads=threads):
            if log:
                s = r["summary"]
                log(
                    f"share {r['share']:g} {r['model']} seed {r['seed']}: peak {s.get('peak_m')} m, "
                    f"side mass {s.get('side_mass')}, W_cmd at junctions {s.get('section_w_cmd')}/s, "
                    f"{s['crashes']} crashes ({r['train_cpu_seconds']:.0f} s training, "
                    f"{r['eval_cpu_seconds']:.0f} s driving, CPU)"
                )
            save(False)

    def collect(complete: bool) -> dict:
        return dict(collect_results(out, settings), complete=complete)

    return FOLDER.run(out, provenance, results, collect, work, log)


def load_results(out) -> dict:
    """``results.json`` and ``provenance.json`` of a sweep folder (ValueError naming a missing or damaged
    file)."""
    return FOLDER.load(out)
