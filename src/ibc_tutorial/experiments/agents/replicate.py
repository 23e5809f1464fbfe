"""One command from data to every table and figure of chapters 08-09: the closed-loop replication.

    ibc-tutorial replicate --preset laptop --out book/results/laptop
    ibc-tutorial replicate --preset laptop --commands --set command_branches=true \
        --out book/results/commands-branched

With ``--commands`` (``Preset.commands``: chapter 11) every method's agents take a route command, are
trained on the same town01 demonstrations with their commands (``driving.commands``), and their final
evaluation (and the expert's row) drives the town02 routes (``driving.route_following``, ``route_driving``)
instead of the routeless episodes; there is no held-out set and no Fig. 5/6 analogue.

Steps (the DA-IBC paper's secs. 4.1-4.3, at the preset's scale):

1. collect the expert's demonstrations in town01 (``data/town01.npz``);
2. for each seed, for each method (bc, ibc, da-ibc): train an agent (``train.train_agent``), with
   its periodic town02 evaluations (the Fig. 4 curve), then its final evaluation: the preset's
   ``final_episodes`` batched episodes of ``final_steps`` steps in town02 (the table), and a second
   one of ``heldout_episodes`` from other starts (``evaluate.HELDOUT_SEED``: ``heldout_eval.json``);
   the PID expert drives both sets of starts too (``runs/expert/``), the table's reference row;
3. once the first seed's BC and DA-IBC agents are done: free driving in town02 (the Fig. 5
   analogue) and DA-IBC's energy landscapes (the Fig. 6 analogue), see ``figures``;
4. after every run: ``results.json``, ``PROVENANCE.md`` and ``provenance.json`` (see ``replication_folder``).

Interrupted, the same command resumes: finished runs are skipped and an unfinished one resumes
from its ``last.pt``. Before any work, ``check_folder`` compares the folder with the request: a
folder holding a replication of other settings, other demonstrations or runs that do not match
is refused (another ``--out``, or ``--force`` to start over), and so is a damaged file in it,
named with what to do. Every agent's ``final.pt`` is kept (its weights in float16: about 1 MB
each), so that any agent of the table can be evaluated again; ``last.pt`` is deleted once a run
is finished.

``--device cuda`` trains and evaluates every agent on a GPU (each worker process uses it); the
demonstrations, the expert's row and every random draw stay on the CPU (see ``train``).
"""

from __future__ import annotations

import functools
import sys
import time
from dataclasses import asdict
from pathlib import Path

import torch

from ibc_tutorial.driving.collect import collect, episode_steps
from ibc_tutorial.driving.command_balance import balanced_routes
from ibc_tutorial.driving.dataset import DemoLog
from ibc_tutorial.driving.route_following import ROUTES
from ibc_tutorial.driving.towns import get_town
from ibc_tutorial.experiments.agents.checkpoints import load_agent
from ibc_tutorial.experiments.agents.evaluate import (
    EVAL_SEED,
    EVAL_TOWN,
    HELDOUT_SEED,
    episode_rows,
    evaluate_agent,
    summarize_episodes,
)
from ibc_tutorial.experiments.agents.figures import free_driving, landscapes
from ibc_tutorial.experiments.agents.presets import PAPER, Preset, differences
from ibc_tutorial.experiments.agents.replication_folder import (
    DATA,
    EVALUATIONS,
    FINAL_EVAL,
    FOLDER,
    STEM_DRIVE,
    collect_results,
    expert_dir,
    planned,
    preset_results,
    run_dir,
)
from ibc_tutorial.experiments.agents.route_driving import ROUTE_SEED, evaluate_on_routes, summarize_route_rows
from ibc_tutorial.experiments.agents.stem_drives import recorded_drive
from ibc_tutorial.experiments.agents.train import train_agent
from ibc_tutorial.experiments.agents.training_run import TrainingData, inspect_run
from ibc_tutorial.experiments.runs import RESULTS, differing, read_json_dict, write_json, write_npz
from ibc_tutorial.parallel import imap_unordered
from ibc_tutorial.utils import check_device, check_int, plural, quiet

FIGURE_METHODS = ("bc", "da-ibc")
"""The agents of the first seed kept for the Fig. 5/6 analogues (their ``final.pt`` is kept too)."""


def _same_preset(stored, preset: Preset) -> bool:
    """Whether a stored preset dict describes ``preset`` (fields added since it was written take their
    defaults)."""
    try:
        return isinstance(stored, dict) and Preset.from_dict(stored) == preset
    except (TypeError, ValueError):
        return False


def check_folder(out, preset: Preset) -> None:
    """Refuse (ValueError, one line: what differs and how to proceed) a folder that holds anything but an
    unfinished or finished replication of ``preset``: other files, another preset, other demonstrations,
    runs of other settings or data, or a damaged file (named, with what to do)."""
    out = Path(out)
    if not FOLDER.check_entries(out):
        return

    def describe(stored) -> str:
        name = stored.get("name") if isinstance(stored, dict) else None
        return (
            f"a replication of preset {name!r}, not {preset.name!r} (differs in {differing(stored, preset)})"
        )

    FOLDER.check_settings(out, lambda stored: _same_preset(stored, preset), describe)
    data, checksum = out / DATA, None
    if data.exists():
        log = DemoLog.load(data)
        config = log.meta.get("config")
        if not isinstance(config, dict) or any(
            config.get(k, 0.0 if k == "brake_noise" else None) != v
            for k, v in asdict(preset.collect_config()).items()
            if k in ("town", "routes", "seed", "min_minutes", "max_minutes", "brake_noise")
        ):
            raise ValueError(
                f"{data} was collected with other settings than preset {preset.name!r}'s: use another "
                "--out, or --force to start over"
            )
        checksum = log.checksum()
    for r in planned(preset):
        inspect_run(
            FOLDER.run_dir(out, r), r.method, preset, r.seed, checksum, data if data.exists() else None
        )


def clear_folder(out) -> None:
    """Delete a replication's entries (``replication_folder.ENTRIES``) from ``out``, nothing else:
    ``--force``. ValueError if ``out`` holds other files (they are not a replication's to delete)."""
    FOLDER.clear(out)


_WORKER_DATA: dict = {}
"""Per worker process: the rendered dataset and its KDE probabilities, made once."""


def _training_data(data: Path, preset: Preset) -> TrainingData:
    """The rendered demonstrations and their minibatch probabilities w ∝ 1 / ĝ, made once per process."""
    key = (
        str(data),
        data.stat().st_mtime_ns,
        preset.bev_size,
        preset.kde_bandwidth,
        preset.light_encoding,
        preset.commands,
    )
    if key not in _WORKER_DATA:
        _WORKER_DATA[key] = TrainingData.of(data, preset)
    return _WORKER_DATA[key]


def final_evaluations(
    agent,
    out_dir: Path,
    preset: Preset,
    policy_seed: int,
    show_progress: bool | None = False,
    extra: dict | None = None,
) -> dict:
    """The table's evaluation (``final_eval.json``, its episodes recorded for the stem analysis in
    ``stem_drive.npz``: ``stem_drives.recorded_drive``) and the held-out one (``heldout_eval.json``) of an
    agent (an ``Agent`` or "expert") into ``out_dir``; returns the first. With ``preset.commands``: the town02
    routes instead (``route_evaluation``)."""
    if preset.commands:
        return route_evaluation(agent, out_dir, preset, policy_seed, show_progress, extra)
    evals = {}
    for name, seed, episodes in (
        (EVALUATIONS["heldout"], HELDOUT_SEED, preset.heldout_episodes),
        (EVALUATIONS["final"], EVAL_SEED, preset.final_episodes),
    ):
        if not episodes:
            continue
        te = time.perf_counter()
        if name == FINAL_EVAL:  # the table's episodes, recorded for the stem analysis (same episodes)
            binary = preset.light_encoding == "flag"  # the observations are bit-packed: 0/1 views only
            results, arrays = recorded_drive(agent, episodes, preset.final_steps, seed, policy_seed, binary)
            write_npz(out_dir / STEM_DRIVE, arrays)
        else:
            results = evaluate_agent(
                agent,
                EVAL_TOWN,
                episodes,
                preset.final_steps,
                seed=seed,
                policy_seed=policy_seed,
                show_progress=show_progress,
            )
        rows = episode_rows(results)
        evals[name] = dict(
            extra or {},
            town=EVAL_TOWN,
            steps=preset.final_steps,
            start_seed=seed,
            summary=summarize_episodes(rows),
            episodes=rows,
            eval_seconds=round(time.perf_counter() - te, 1),
        )
        write_json(out_dir / name, evals[name])  # final_eval.json last: once it exists, the run is finished
    return evals[FINAL_EVAL]


def route_evaluation(
    agent, out_dir: Path, preset: Preset, policy_seed: int, show_progress=False, extra: dict | None = None
) -> dict:
    """A command replication's final evaluation: ``preset.route_episodes`` drives of every town02 route
    (``route_driving.evaluate_on_routes``) into ``final_eval.json``, its rows one per route drive; returns
    it."""
    te = time.perf_counter()
    rows = evaluate_on_routes(
        agent,
        drives=preset.route_episodes,
        seed=ROUTE_SEED,
        policy_seed=policy_seed,
        max_steps=preset.route_max_steps or None,
        show_progress=show_progress,
    )
    ev = dict(
        extra or {},
        town=EVAL_TOWN,
        routes=list(ROUTES),
        start_seed=ROUTE_SEED,
        summary=summarize_route_rows(rows),
        episodes=rows,
        eval_seconds=round(time.perf_counter() - te, 1),
    )
    write_json(out_dir / FINAL_EVAL, ev)
    return ev


def run_one(
    method: str, seed: int, out, preset, *, show_progress: bool | None = False, log=print, device: str = "cpu"
) -> dict:
    """Train one agent on ``device``, evaluate it finally in town02 and write its ``final_eval.json``; returns
    that dict."""
    preset = preset if isinstance(preset, Preset) else Preset.from_dict(preset)
    out = Path(out)
    data = out / DATA
    d = run_dir(out, method, seed)
    res = train_agent(
        method,
        _training_data(data, preset),  # rendered once per worker process, shared by its runs
        preset,
        seed,
        d,
        show_progress=show_progress,
        log=log,
        device=device,
    )
    ev = final_evaluations(
        res.agent,
        d,
        preset,
        seed,
        show_progress,
        extra={"method": method, "seed": seed, "train_seconds": round(res.seconds, 1)},
    )
    (d / "last.pt").unlink(missing_ok=True)
    return ev


def run_options(workers: int, log, show_progress: bool | None) -> dict:
    """``run_one``'s ``log`` and ``show_progress`` for runs in ``workers`` processes: here, the caller's; in
    workers, their evaluation lines printed, and a training bar on each worker's own line when the caller
    would show one (``show_progress``, or None: on a terminal and not ``TQDM_DISABLE``)."""
    if workers == 1:
        return {"log": log, "show_progress": show_progress}
    bars = (not quiet() and sys.stderr.isatty()) if show_progress is None else bool(show_progress)
    return {"show_progress": bars}


def run_plan(todo: int, total: int, workers: int) -> str:
    """The line that opens the training: how many runs are left of how many, and how many at a time."""
    return f"{plural(todo, 'training run')} to do of {total}, {min(workers, todo)} at a time"


def time_left(elapsed: float, done: int, todo: int) -> str:
    """Elapsed time and an estimate of the time left, from the mean time per finished run so far."""
    left = elapsed / done * (todo - done) if done else float("nan")
    return f"{elapsed / 60:.1f} min elapsed, " + (
        "none left" if done >= todo else f"about {max(left / 60, 0.1):.0f} min left"
    ).replace("about 0 min", "under a minute")


def expert_row(out: Path, preset: Preset, log=print) -> None:
    """The PID expert on the same starts as the agents (``runs/expert/``), unless already there."""
    d = expert_dir(out)
    if (d / FINAL_EVAL).exists():
        return
    d.mkdir(parents=True, exist_ok=True)
    ev = final_evaluations("expert", d, preset, 0, extra={"method": "expert"})
    if log:
        log(f"expert: town02 score {ev['summary']['score_mean']:.1f} ± {ev['summary']['score_std']:.1f}")


def replicate(
    preset: Preset,
    out,
    *,
    command: str = "",
    overrides: tuple = (),
    workers: int = 1,
    log=print,
    show_progress: bool | None = None,
    device: str = "cpu",
) -> dict:
    """Run the whole replication (see the module docstring); returns the contents of ``results.json``.

    ``out`` is checked first (``check_folder``; ``clear_folder`` is ``--force``). ``command`` and
    ``overrides``
    (the ``--set`` items that made ``preset``) are recorded in the provenance. ``device`` ("cpu", "cuda",
    "cuda:1", "mps") is where the agents train and drive."""
    device = str(check_device("device", device))  # a string: it goes to the worker processes
    workers = check_int("workers", workers, minimum=1)
    out = Path(out)
    check_folder(out, preset)
    out.mkdir(parents=True, exist_ok=True)
    res_file = out / RESULTS
    results = read_json_dict(res_file, "delete it and re-run") if res_file.exists() else {}
    provenance = FOLDER.provenance(
        out,
        planned(preset),
        title=f"the `{preset.name}` replication" + (" with route commands" if preset.commands else ""),
        command=command or f"ibc-tutorial replicate --preset {preset.name} --out {out}",
        preset=preset.to_dict(),
        differences=differences(PAPER, preset),
        reference="the paper's settings",
        overrides=list(overrides),
    )

    def collect(complete: bool) -> dict:
        return collect_results(out, preset) | preset_results(preset, complete)

    def work(save) -> None:
        _work(out, preset, results, save, workers, log, show_progress, device)

    return FOLDER.run(out, provenance, results, collect, work, log)


def collect_demonstrations(preset: Preset, show_progress: bool | None = None) -> DemoLog:
    """The expert's town01 demonstrations of ``preset`` (step 1): on random routes, or, with
    ``preset.balanced_routes``, on routes that command every turn about equally often."""
    config = preset.collect_config()
    routes = None  # random routes: the collection's own draw
    if preset.balanced_routes:
        routes = balanced_routes(get_town(config.town), episode_steps(config), seed=config.seed)
    return collect(config, show_progress=show_progress, routes=routes)


def _work(
    out: Path,
    preset: Preset,
    results: dict,
    save,
    workers: int,
    log,
    show_progress: bool | None,
    device: str = "cpu",
) -> None:
    """Steps 1-3 of the module docstring; ``save(False)`` after each run."""
    # 1. the demonstrations
    data = out / DATA
    if not data.exists():
        demo = collect_demonstrations(preset, show_progress)
        demo.save(data)
        if log:
            log(f"collected {len(demo)} samples in town01")
    results["data"] = {"file": DATA, "samples": len(DemoLog.load(data)), "routes": preset.routes}

    # 2-3. the runs, seed by seed (in ``workers`` processes: the first seed's runs are submitted first)
    todo = FOLDER.todo(out, planned(preset))
    total = len(planned(preset))
    if log:
        log(
            run_plan(len(todo), total, workers)
            if todo
            else f"nothing left to do: all {total} training runs of this replication were already finished"
        )
    started, finished = time.perf_counter(), []

    def after_run(ev: dict) -> None:
        finished.append(ev)
        if log:
            elapsed = time.perf_counter() - started
            log(
                f"run {total - len(todo) + len(finished)} of {total}, {ev['method']} seed {ev['seed']}: "
                f"final town02 score {ev['summary']['score_mean']:.1f} ± {ev['summary']['score_std']:.1f} "
                f"({ev['train_seconds']:.0f} s training, {ev['eval_seconds']:.0f} s evaluation); "
                + time_left(elapsed, len(finished), len(todo))
            )
        save(False)

    def figures_if_ready() -> None:
        s0 = preset.seeds[0]
        if (
            "free_driving" in results
            or preset.commands  # command agents do not drive routeless
            or not preset.routeless_episodes
            or not set(FIGURE_METHODS) <= set(preset.methods)
            or not all((run_dir(out, m, s0) / FINAL_EVAL).exists() for m in FIGURE_METHODS)
        ):
            return
        agents = {m: load_agent(run_dir(out, m, s0) / "final.pt")[0].to(device) for m in FIGURE_METHODS}
        summary, recordings = free_driving(out, preset, agents, log=log)
        results["free_driving"] = summary
        results["landscapes"] = landscapes(out, agents["da-ibc"], recordings, log=log)
        save(False)

    figures_if_ready()
    here = run_options(workers, log, show_progress)
    runs = imap_unordered(  # submitted now; with one worker, each run when its result is asked for
        [
            functools.partial(run_one, r.method, r.seed, str(out), preset.to_dict(), device=device, **here)
            for r in todo
        ],
        workers=workers,
        threads=torch.get_num_threads(),
    )
    expert_row(out, preset, log)  # here, while the workers train
    save(False)
    for ev in runs:
        after_run(ev)
        figures_if_ready()
