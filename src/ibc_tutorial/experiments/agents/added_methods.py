"""More methods trained into a finished replication folder, beside its agents, without retraining them.

    ibc-tutorial two-answers --out book/results/two-answers --methods flow,da-ibc-rnce --workers 2 --threads 1

``add_methods`` trains every seed of the folder's preset for each added method (``presets.FAMILY_METHODS``,
or any method the preset does not train) on the folder's own demonstrations (``data/town01.npz``) with the
folder's own settings: the preset stored in its ``results.json``, unchanged, so the added agents get the same
minibatches' weighting, epochs, step size, network sizes and evaluations as the others
(``replicate.run_one``: training with its periodic town02 evaluation, then the table's and the held-out
evaluations). They go to ``runs/<method>/seed<k>/`` like the others. Nothing of the folder's replication is
changed: not its data, runs, ``results.json`` or figures. What the added runs make is recorded in
``ADDED`` (``added_methods.json``: the methods, every invocation with its command, commit, machine and
times, and the table of the added agents as ``results.json`` gives it,
``replication_folder.collect_results``), and one note per invocation is appended to the folder's
provenance (``provenance.json`` notes, ``PROVENANCE.md``).

Interrupted, the same command resumes: finished runs are skipped, an unfinished one resumes from its
``last.pt`` (``train.train_agent``), and a run folder of other settings or data is refused before any work
(``training_run.inspect_run``).
"""

from __future__ import annotations

import functools
import time
from dataclasses import replace
from pathlib import Path

import torch

from ibc_tutorial.driving.dataset import DemoLog
from ibc_tutorial.experiments.agents.presets import ALL_METHODS, Preset
from ibc_tutorial.experiments.agents.replicate import run_one, run_options
from ibc_tutorial.experiments.agents.replication_folder import (
    ADDED,
    DATA,
    FINAL_EVAL,
    collect_results,
    finished_runs,
    planned,
    run_dir,
)
from ibc_tutorial.experiments.agents.training_run import inspect_run
from ibc_tutorial.experiments.runs import (
    RESULTS,
    Run,
    add_note,
    git_commit,
    machine,
    now,
    read_json_dict,
    write_json,
)
from ibc_tutorial.parallel import imap_unordered
from ibc_tutorial.utils import check_device, check_int

__all__ = [
    "ADDED",
    "add_methods",
    "added_runs",
    "check_methods",
    "folder_preset",
    "parse_methods",
    "replication_finished",
]


def parse_methods(text: str) -> tuple[str, ...]:
    """``"flow,da-ibc-rnce"`` -> ``("flow", "da-ibc-rnce")`` (spaces ignored); ValueError naming ``methods``
    for an empty list, an unknown or a repeated method."""
    methods = tuple(m.strip() for m in str(text).split(",") if m.strip())
    if not methods or any(m not in ALL_METHODS for m in methods) or len(set(methods)) < len(methods):
        raise ValueError(
            f"methods must name distinct methods of {ALL_METHODS}, separated by commas, got {text!r}"
        )
    return methods


def folder_preset(folder) -> Preset:
    """The preset a replication folder was made with (its ``results.json``)."""
    stored = read_json_dict(Path(folder) / RESULTS, "run the replication first")
    try:
        return Preset.from_dict(stored["preset"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{Path(folder) / RESULTS} is damaged: no valid preset ({exc})") from None


def check_methods(methods, preset: Preset) -> tuple[str, ...]:
    """``methods`` (a tuple, or text for ``parse_methods``) checked as additions to ``preset``'s replication:
    ValueError naming ``methods`` if one of them is a method the replication trains already."""
    methods = parse_methods(",".join(methods) if not isinstance(methods, str) else methods)
    own = [m for m in methods if m in preset.methods]
    if own:
        raise ValueError(
            f"methods must be methods the {preset.name!r} replication does not train ({preset.methods}), got "
            f"{', '.join(own)}: its own runs are made by the replication itself"
        )
    return methods


def replication_finished(folder, preset: Preset) -> bool:
    """Whether ``folder`` holds ``preset``'s replication finished: its ``results.json`` complete and every
    planned run evaluated (then adding methods needs no step of the replication, which is left untouched)."""
    folder = Path(folder)
    if not (folder / RESULTS).exists():
        return False
    results = read_json_dict(folder / RESULTS, "delete it and re-run the replication")
    return results.get("complete") is True and finished_runs(folder, preset) == [
        r.name for r in planned(preset)
    ]


def added_runs(preset: Preset, methods: tuple[str, ...]) -> list[tuple[str, int]]:
    """The (method, seed) runs of the added ``methods``, seed by seed (the first seed's first)."""
    return [(m, s) for s in preset.seeds for m in methods]


def _check_runs(folder: Path, preset: Preset, methods: tuple[str, ...]) -> None:
    """Before any work: the folder's data exist, and every added run folder holds nothing, this run
    unfinished, or this run finished (``training_run.inspect_run``; ValueError otherwise)."""
    data = folder / DATA
    if not data.exists():
        raise ValueError(f"{folder} holds no demonstrations ({DATA}): run the replication first")
    sha = DemoLog.load(data).checksum()
    for m, s in added_runs(preset, methods):
        inspect_run(run_dir(folder, m, s), m, preset, s, sha, data)


def add_methods(
    folder,
    methods,
    *,
    command: str = "",
    workers: int = 1,
    log=print,
    show_progress: bool | None = None,
    device: str = "cpu",
) -> dict:
    """Train and evaluate every seed of each of ``methods`` in the replication ``folder`` (module docstring);
    returns the contents of ``added_methods.json``. ValueError (before any work) for a folder without a
    replication's ``results.json`` and data, a method the replication trains already, or a run folder that
    holds another run."""
    folder = Path(folder)
    device = str(check_device("device", device))
    workers = check_int("workers", workers, minimum=1)
    preset = folder_preset(folder)
    methods = check_methods(methods, preset)
    _check_runs(folder, preset, methods)
    record_file = folder / ADDED
    record = (
        read_json_dict(record_file, "delete it and re-run the same command") if record_file.exists() else {}
    )
    known = tuple(record.get("methods", ()))
    record["methods"] = list(known) + [m for m in methods if m not in known]
    record["preset"] = preset.name
    invocation = {"command": command, "methods": list(methods), "commit": git_commit(), "started": now()}
    invocation["machine"] = machine()
    record["invocations"] = list(record.get("invocations", [])) + [invocation]
    t0 = time.perf_counter()

    def save() -> None:
        invocation.update(last_seen=now(), seconds=round(time.perf_counter() - t0, 1))
        every = replace(preset, methods=tuple(record["methods"]))
        invocation["runs_done"] = [
            Run(m, s).name
            for m, s in added_runs(preset, methods)
            if (run_dir(folder, m, s) / FINAL_EVAL).exists()
        ]
        record["runs_planned"] = [Run(m, s).name for m, s in added_runs(every, every.methods)]
        record["results"] = collect_results(folder, every)  # the added agents' table (and the expert's row)
        write_json(record_file, record)

    save()
    todo = [
        (m, s) for m, s in added_runs(preset, methods) if not (run_dir(folder, m, s) / FINAL_EVAL).exists()
    ]
    here = run_options(workers, log, show_progress)
    runs = imap_unordered(
        [
            functools.partial(run_one, m, s, str(folder), preset.to_dict(), device=device, **here)
            for m, s in todo
        ],
        workers=workers,
        threads=torch.get_num_threads(),
    )
    for ev in runs:
        if log:
            log(
                f"{ev['method']} seed {ev['seed']}: final town02 score {ev['summary']['score_mean']:.1f} ± "
                f"{ev['summary']['score_std']:.1f} ({ev['train_seconds']:.0f} s training, "
                f"{ev['eval_seconds']:.0f} s evaluation)"
            )
        save()
    invocation["finished"] = now()
    save()
    add_note(
        folder,
        f"methods added ({', '.join(methods)}; {len(invocation['runs_done'])} runs, {len(todo)} trained now, "
        f"{invocation['seconds'] / 60:.1f} min): `{command or 'add_methods'}` at {invocation['commit']}, "
        f"finished {invocation['finished']}; see {ADDED}",
    )
    return record
