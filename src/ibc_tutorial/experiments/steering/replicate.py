"""``ibc-tutorial replicate-steering``: the steering-EBM paper's road-following study, end to end.

    ibc-tutorial replicate-steering --preset laptop --out book/results/steering-laptop

Steps:

1. the demonstrations: the expert drives ``preset.routes`` town01 routes (``task``), side roads
   taken with probability ``preset.side_road_share`` (``data/town01.npz``);
2. the references: the expert drives every evaluation route of town02 (``evaluate``), and the
   observations of 5 s of one side-road pass are kept for the Fig. 5 analogue (``references.npz``);
3. for each seed, each of the six models (``models``): train, drive every route under the
   crash-and-restart protocol, record its outputs along the Fig. 5 window (``train.run_one``),
   in ``--workers`` processes;
4. after every run: ``results.json`` (the tables), ``traces.npz`` (Fig. 5), ``provenance.json``
   and ``PROVENANCE.md`` (command, commit, machine, wall time over every invocation, resumed or not).

Interrupted, the same command resumes: finished runs are kept, an unfinished one continues from
its ``last.pt``. A folder holding another preset's study, other files, or damaged files is
refused before any work (``--force`` starts over). Chapter 10 only reads the folder
(``load_results``).
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import torch

from ibc_tutorial.driving.dataset import DemoDataset, DemoLog
from ibc_tutorial.experiments.runs import (
    DATA,
    PROVENANCE,
    PROVENANCE_MD,
    RESULTS,
    Run,
    StudyFolder,
    differing,
    read_npz,
    run_dir,
    write_npz,
)
from ibc_tutorial.experiments.steering import evaluate as ev
from ibc_tutorial.experiments.steering.evaluate import REFERENCES
from ibc_tutorial.experiments.steering.models import LABELS, MODELS
from ibc_tutorial.experiments.steering.presets import LAPTOP, SteeringPreset, differences
from ibc_tutorial.experiments.steering.task import preset_demonstrations, side_road_counts
from ibc_tutorial.experiments.steering.train import EVAL, TRACE, StudyInputs, read_eval, run_one
from ibc_tutorial.parallel import imap_unordered
from ibc_tutorial.utils import check_int

TRACES = "traces.npz"
"""The Fig. 5 analogue's arrays."""
ENTRIES = ("data", "runs", REFERENCES, RESULTS, TRACES, PROVENANCE, PROVENANCE_MD)
"""What a study folder holds (``--force`` deletes these, and only these)."""
FOLDER = StudyFolder(
    what="road-following study",
    command="ibc-tutorial replicate-steering",
    entries=ENTRIES,
    done=EVAL,
    arrays={"traces": TRACES},
)
"""The study's folder (``experiments.runs.StudyFolder``): its checks, ``--force``, resuming, loading."""

PAPER = {
    "table1": {  # per run: real-world interventions, W_eff, W_cmd (°/s); VISTA crashes, W_cmd (°/s)
        "ebm": [[4, 35.25, 176.93, 2, 114.33], [1, 32.34, 96.94, 1, 121.57], [2, 28.57, 223.59, 2, 121.67]],
        "ebm-smooth": [
            [5, 49.92, 119.39, 3, 58.70],
            [2, 38.96, 137.22, 2, 60.37],
            [3, 34.21, 77.28, 2, 48.86],
        ],
        "ebm-soft": [[5, 27.80, 56.33, 3, 85.72], [5, 46.83, 57.15, 3, 74.97], [4, 33.72, 56.86, 3, 81.87]],
        "regression": [[2, 26.69, 37.84, 0, 24.39], [2, 29.65, 75.34, 0, 24.75], [1, 26.28, 33.10, 0, 24.25]],
        "classification": [
            [1, 41.05, 182.39, 1, 123.69],
            [7, 62.17, 287.14, 1, 105.13],
            [1, 34.11, 162.27, 1, 104.31],
        ],
        "mdn": [[1, 25.32, 33.62, 3, 37.22], [5, 24.82, 35.46, 3, 35.74], [5, 26.66, 37.39, 3, 35.84]],
    },
    "table1_columns": ["interventions", "w_eff_deg_s", "w_cmd_deg_s", "vista_crashes", "vista_w_cmd_deg_s"],
    "table2_swerve_rate": {
        "ebm": 0.44,
        "ebm-smooth": 0.66,
        "ebm-soft": 0.39,
        "regression": 0.89,
        "classification": 0.44,
        "mdn": 0.33,
    },
}
"""The steering-EBM paper's Tables 1 (the three runs of each model; its means follow from them)
and 2, as printed."""


def planned(preset: SteeringPreset) -> list[Run]:
    """The runs of ``preset``, seed by seed."""
    return [Run(m, s) for s in preset.seeds for m in MODELS]


def check_folder(out, preset: SteeringPreset) -> None:
    """Refuse (ValueError: what differs and what to do) a folder holding anything but this preset's study."""
    out = Path(out)
    if not FOLDER.check_entries(out):
        return

    def describe(stored) -> str:
        return f"a study of another preset (differs in {differing(stored, preset)})"

    FOLDER.check_settings(out, lambda stored: stored == preset.to_dict(), describe)
    if (out / DATA).exists() and DemoLog.load(out / DATA).meta.get("config") != _data_config(preset):
        raise ValueError(f"{out / DATA} was collected with other settings: use another --out, or --force")
    FOLDER.check_runs(out, planned(preset), read_eval)


def _data_config(p: SteeringPreset) -> dict:
    return {
        "town": "town01",
        "routes": p.routes,
        "minutes": p.route_minutes,
        "side_road_share": p.side_road_share,
        "speed": p.speed,
        "steer_noise": p.steer_noise,
        "seed": p.collect_seed,
    }


def make_references(out: Path, preset: SteeringPreset) -> None:
    """Step 2: the expert's drives of the evaluation routes and the Fig. 5 window (``references.npz``)."""
    arrays, window = {}, None
    for name in preset.eval_routes:
        ref, _ = ev.expert_reference(name, preset)
        arrays.update(ref.to_arrays())
        w = ev.fig5_window(ref)
        if window is None and w is not None:
            _, obs = ev.expert_reference(name, preset, keep_obs=w)
            window = (name, w, obs)
    if window is None:  # no pass at speed (the tiny preset's short routes): the first 5 s of the first route
        name = preset.eval_routes[0]
        w = (0, min(ev.FIG5_STEPS, len(arrays[f"{name}/poses"])))
        _, obs = ev.expert_reference(name, preset, keep_obs=w)
        window = (name, w, obs)
    name, (a, b), obs = window
    arrays.update(
        {
            "fig5/route": np.array(name),
            "fig5/steps": np.array([a, b]),
            "fig5/bev": obs["bev"],
            "fig5/state": obs["state"],
            "fig5/expert_steer": arrays[f"{name}/steer"][a:b],
        }
    )
    write_npz(out / REFERENCES, arrays)


def fig5_window(arrays: dict) -> dict:
    """The Fig. 5 window's observations in a ``REFERENCES`` file's arrays: {"bev" (W, 5, S, S), "state"}."""
    return {"bev": arrays["fig5/bev"], "state": arrays["fig5/state"]}


_WORKER: dict = {}
"""Per process: the rendered dataset, the references and the window (made once)."""


def _work_one(model: str, seed: int, out: str, preset_d: dict) -> dict:
    preset = SteeringPreset.from_dict(preset_d)
    key = (out, repr(preset_d))
    if key not in _WORKER:
        log = DemoLog.load(Path(out) / DATA)
        ds = DemoDataset(log, bev_size=preset.bev_size, cache=True)
        (refs,), arrays = ev.read_references(Path(out) / REFERENCES, preset.eval_routes)
        window = fig5_window(arrays)
        _WORKER.clear()
        _WORKER[key] = (ds, log.checksum(), refs, window)
    ds, sha, refs, window = _WORKER[key]
    return run_one(
        model, seed, out, preset, StudyInputs(ds, sha, refs, window), keep_final=seed == preset.seeds[0]
    )


def _stats(values: list) -> dict:
    v = np.array([x for x in values if x is not None], dtype=float)
    if not len(v):
        return {"mean": None, "std": None, "n": 0}
    return {
        "mean": round(float(v.mean()), 4),
        "std": round(float(v.std(ddof=1)) if len(v) > 1 else 0.0, 4),
        "n": int(len(v)),
    }


def collect_results(out: Path, preset: SteeringPreset) -> dict:
    """The runs finished under ``out``: per seed and route, and the table (mean and spread over seeds)."""
    runs, table, traces = {}, {}, {}
    for model in MODELS:
        runs[model] = {}
        for seed in preset.seeds:
            d = run_dir(out, model, seed)
            if (d / EVAL).exists():
                runs[model][str(seed)] = read_eval(d / EVAL)
                trace = read_npz(d / TRACE, f"delete {d} and re-run the same command")
                traces.update({f"{model}/seed{seed}/{k}": v for k, v in trace.items()})
        per_seed = [r["summary"] for r in runs[model].values()]
        if per_seed:
            table[model] = {
                k: _stats([s[k] for s in per_seed]) for k in ("crashes_per_km", "w_cmd", "swerve_rate")
            }
            table[model]["w_cmd_paper_deg_s"] = _stats(
                [s["w_cmd"] * ev.PAPER_DEG_PER_STEER for s in per_seed]
            )
            table[model]["crashes"] = int(sum(s["crashes"] for s in per_seed))
            table[model]["distance_km"] = round(sum(s["distance_m"] for s in per_seed) / 1000, 3)
            table[model]["passes"] = int(sum(s["passes"] for s in per_seed))
            table[model]["seeds"] = len(per_seed)
    return {"runs": runs, "table": table, "traces": traces}


def clear_folder(out) -> None:
    """Delete a study's entries (``ENTRIES``) from ``out``, nothing else: ``--force``."""
    FOLDER.clear(out)


def finished_runs(out, preset: SteeringPreset) -> list[str]:
    """The runs of ``preset`` under ``out`` that have their ``eval.json``, in planned order."""
    return FOLDER.finished(out, planned(preset))


def replicate(
    preset: SteeringPreset, out, *, command: str = "", overrides: tuple = (), workers: int = 1, log=print
) -> dict:
    """Run the whole study (module docstring) into ``out``; returns the contents of ``results.json``.

    ``out`` is checked first (``check_folder``; ``clear_folder`` is ``--force``); ``command`` and
    ``overrides`` (the ``--set`` items that made ``preset``) are recorded in the provenance."""
    out = Path(out)
    workers = check_int("workers", workers, minimum=1)
    check_folder(out, preset)
    out.mkdir(parents=True, exist_ok=True)
    provenance = FOLDER.provenance(
        out,
        planned(preset),
        title=f"the `{preset.name}` road-following study",
        command=command or f"ibc-tutorial replicate-steering --preset {preset.name} --out {out}",
        preset=preset.to_dict(),
        differences=differences(LAPTOP, preset),
        reference="the `laptop` preset",
        overrides=list(overrides),
    )
    results: dict = {}

    def collect(complete: bool) -> dict:
        agg = collect_results(out, preset)
        write_npz(out / TRACES, agg.pop("traces"))
        return dict(agg, complete=complete)

    def work(save) -> None:
        _work(out, preset, results, save, workers, log)

    return FOLDER.run(out, provenance, results, collect, work, log)


def _work(out: Path, preset: SteeringPreset, results: dict, save, workers: int, log) -> None:
    demo = preset_demonstrations(preset, out / DATA)
    counts = side_road_counts(demo)
    results.update(
        preset=preset.to_dict(),
        paper=PAPER,
        labels=LABELS,
        models=list(MODELS),
        data={
            "file": DATA,
            "samples": len(demo),
            "routes": preset.routes,
            "km": round(sum(e["distance_m"] for e in demo.meta["episodes"]) / 1000, 3),
            "side_roads": counts,
        },
        protocol={
            "crash_distance_m": ev.CRASH_DISTANCE_M,
            "restart_s": ev.RESTART_S,
            "slight_m": ev.SLIGHT_M,
            "clear_m": ev.CLEAR_M,
            "section_before_m": ev.SECTION_BEFORE_M,
            "dt": ev.DT,
            "paper_deg_per_steer": ev.PAPER_DEG_PER_STEER,
            "front_wheel_deg_per_steer": round(ev.FRONT_WHEEL_DEG_PER_STEER, 3),
        },
    )
    if log:
        log(
            f"demonstrations: {len(demo)} samples; side roads taken {counts['side_road']} of "
            f"{counts['straight'] + counts['side_road']} passes"
        )
    if not (out / REFERENCES).exists():
        make_references(out, preset)
    (refs,), arrays = ev.read_references(out / REFERENCES, preset.eval_routes)
    results["references"] = {
        r.name: {
            "steps": int(len(r.poses)),
            "length_m": round(float(len(r.path)) * ev.PATH_SPACING_M, 1),
            "side_road_passes": int(len(r.sections)),
            "expert_w_cmd": round(ev.expert_whiteness(r), 5),
        }
        for r in refs
    }
    results["fig5"] = {"route": str(arrays["fig5/route"]), "steps": arrays["fig5/steps"].tolist()}
    save(False)
    todo = FOLDER.todo(out, planned(preset))

    def after(r: dict) -> None:
        if log:
            s = r["summary"]
            log(
                f"{r['model']} seed {r['seed']}: {s['crashes']} crashes in {s['distance_m'] / 1000:.2f} km, "
                f"W_cmd {s['w_cmd']:.3f}/s, swerve rate {s['swerve_rate']} "
                f"({r['train_seconds']:.0f} s training, "
                f"{r['eval_seconds']:.0f} s driving)"
            )
        save(False)

    runs = imap_unordered(
        [functools.partial(_work_one, r.method, r.seed, str(out), preset.to_dict()) for r in todo],
        workers=workers,
        threads=torch.get_num_threads(),
    )
    for r in runs:
        after(r)


def load_results(out) -> dict:
    """What chapter 10 reads: ``results.json`` and ``provenance.json`` as dicts, ``traces.npz`` as a dict of
    arrays. ValueError naming the file if one is missing or damaged."""
    res = FOLDER.load(out)
    if not res["traces"]:
        raise ValueError(
            f"{Path(out) / TRACES} is missing: delete {out} and re-run 'ibc-tutorial replicate-steering'"
        )
    return res
