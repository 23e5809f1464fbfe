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

The settings and the folder's names are in ``sweep_settings``. Folder: ``sweep.json`` (the settings),
``references.npz`` (the expert's drives of every route and session, shared by every share),
``share<p>/data/town01.npz`` (each share's demonstrations), ``share<p>/runs/<model>/seed<k>/``
(``last.pt`` while training, then ``passes.npz``, the per-state traces of every pass, and ``eval.json``,
written last), ``results.json``, ``provenance.json`` and ``PROVENANCE.md``. Interrupted, the same
command resumes: a run with its ``eval.json`` is skipped, an unfinished one continues from ``last.pt``.
Other settings in the folder are refused before any work.
"""

from __future__ import annotations

import functools
import time
from pathlib import Path

import numpy as np

from ibc_tutorial.driving.dataset import DemoDataset, DemoLog
from ibc_tutorial.experiments.runs import (
    Provenance,
    check_folder_entries,
    clear_entries,
    read_folder,
    read_json_dict,
    read_run_file,
    write_json,
    write_npz,
)
from ibc_tutorial.experiments.steering import evaluate as ev
from ibc_tutorial.experiments.steering.models import LABELS
from ibc_tutorial.experiments.steering.presets import LAPTOP, SteeringPreset, differences
from ibc_tutorial.experiments.steering.sweep_settings import (
    ENTRIES,
    EVAL,
    MEASURES,
    PASSES,
    REFERENCES,
    RESULTS,
    SETTINGS,
    SWEEP,
    SweepSettings,
    check_shares,
    finished_runs,
    planned,
    run_dir,
    run_name,
    share_name,
    share_preset,
)
from ibc_tutorial.experiments.steering.task import preset_demonstrations, side_road_counts
from ibc_tutorial.experiments.steering.train import SteeringModel, train_model
from ibc_tutorial.parallel import imap_unordered
from ibc_tutorial.utils import check_int


def _stored(settings: SweepSettings, base: SteeringPreset) -> dict:
    return {"sweep": settings.to_dict(), "preset": base.to_dict()}


# ---------------------------------------------------------------------- the folder
def check_folder(out, settings: SweepSettings, base: SteeringPreset) -> None:
    """Refuse (ValueError: what and what to do) a folder holding anything but this sweep's files, or this
    sweep with other settings; a damaged run's ``eval.json`` is named."""
    out = Path(out)
    if not check_folder_entries(out, ENTRIES, "sweep", allowed=lambda name: name.startswith("share")):
        return
    if (out / SETTINGS).exists():
        stored = read_json_dict(out / SETTINGS, "delete it and re-run the same command")
        if stored != _stored(settings, base):
            diff = sorted(
                k
                for part in ("sweep", "preset")
                for k in set(stored.get(part) or {}) | set(_stored(settings, base)[part])
                if (stored.get(part) or {}).get(k) != _stored(settings, base)[part].get(k)
            )
            raise ValueError(
                f"{out} holds a sweep of other settings (differs in {', '.join(diff[:5]) or 'its form'}): "
                "use another --out, or --force to start over"
            )
    for r in planned(settings):
        if (run_dir(out, *r) / EVAL).exists():
            read_sweep_eval(run_dir(out, *r) / EVAL)


def clear_folder(out) -> None:
    """``--force``: delete a sweep's files and ``share*`` folders from ``out``, nothing else."""
    out = Path(out)
    if not out.is_dir():
        return
    shares = tuple(p.name for p in out.iterdir() if p.is_dir() and p.name.startswith("share"))
    clear_entries(out, ENTRIES + shares, "sweep")


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
    path = Path(out) / share_name(share) / "data" / "town01.npz"
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
        log = DemoLog.load(Path(out) / share_name(share) / "data" / "town01.npz")
        ds = DemoDataset(log, bev_size=preset.bev_size, cache=True)
        _WORKER[key] = (
            ds,
            log.checksum(),
            ev.read_references(Path(out) / REFERENCES, base.eval_routes, settings.sessions)[0],
        )
    ds, sha, refs = _WORKER[key]
    d = run_dir(out, share, model, seed)
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
            done = {
                str(seed): read_sweep_eval(run_dir(out, share, model, seed) / EVAL)
                for seed in settings.seeds
                if (run_dir(out, share, model, seed) / EVAL).exists()
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
    provenance = Provenance(
        out,
        title=f"the side-road share sweep on the `{base.name}` preset",
        command=command or f"ibc-tutorial sweep-steering --preset {base.name} --out {out}",
        preset=_stored(settings, base),
        differences=differences(LAPTOP, base),
        reference="the `laptop` preset (the sweep's own settings are in `sweep.json`)",
        planned=[run_name(*r) for r in runs],
        finished=lambda: finished_runs(out, settings),
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

    def save(complete: bool) -> None:
        results.update(collect_results(out, settings), complete=complete)
        write_json(out / RESULTS, results)
        provenance.write(complete)

    with provenance:
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
        results["data"] = {share_name(p): data[share_name(p)] for p in settings.shares}
        save(False)
        # 2. every run not finished yet
        todo = [r for r in runs if not (run_dir(out, *r) / EVAL).exists()]
        if log:
            log(f"{len(runs) - len(todo)} of {len(runs)} runs already finished; {len(todo)} to run")
        calls = [
            functools.partial(_run_one, str(out), p, m, s, base.to_dict(), settings.to_dict())
            for p, m, s in todo
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
        save(True)
    if log:
        log(f"sweep finished in {provenance.wall_seconds / 60:.1f} min; results in {out}")
    return results


def load_results(out) -> dict:
    """``results.json`` and ``provenance.json`` of a sweep folder (ValueError naming a missing or damaged
    file)."""
    return read_folder(out, RESULTS, {}, "ibc-tutorial sweep-steering")


__all__ = [
    "EVAL",
    "MEASURES",
    "PASSES",
    "SWEEP",
    "SweepSettings",
    "check_folder",
    "check_shares",
    "clear_folder",
    "collect_results",
    "finished_runs",
    "load_results",
    "read_sweep_eval",
    "run_dir",
    "sweep",
]
