"""One lifecycle for every study's folder: its layout, its checks, clearing, resuming, results, loading.

The replication (``experiments.agents``, chapters 08-09), the road-following study and its side-road
sweep (``experiments.steering``, chapter 10) each write a resumable folder of the same shape:

- ``data/town01.npz``: the demonstrations (``DATA``);
- ``runs/<method>/seed<k>/``: one training run each (``run_dir``; the sweep's runs sit under a part of
  the study, ``share<p>/runs/...``), finished once its ``done`` file exists (written last);
- ``results.json`` (the tables the chapter reads), ``provenance.json`` and ``PROVENANCE.md``, and any
  arrays beside them.

A study describes its folder once, as a ``StudyFolder``, and lives through the same steps:

1. ``check`` before any work: a folder holding anything but this study is refused, naming what differs
   and what to do: other files, other settings (those recorded in its JSON files), a damaged run;
2. ``clear``: ``--force`` deletes the study's entries and nothing else;
3. ``todo``: the planned runs without their ``done`` file (an interrupted command resumes there);
   ``provenance`` records the planned and the finished runs (``finished``);
4. ``run``: the work, with ``results.json`` and the provenance written after every run (``save``);
5. ``load``: ``results.json``, ``provenance.json`` and the arrays, every file checked as it is read.

Neither study imports the other: what they share is here. ``run_missing`` is the same resumable loop
for the analyses that write one file per driver.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

from ibc_tutorial.experiments.runs.files import (
    PROVENANCE,
    RESULTS,
    read_json_dict,
    read_npz,
    write_json,
)
from ibc_tutorial.experiments.runs.provenance import Provenance, git_commit, machine, now

DATA = "data/town01.npz"
"""The demonstrations, relative to a study's folder (or to one part of it)."""


class Run(NamedTuple):
    """One training run of a study: a method (or model) and a seed, in a part of the study or its root."""

    method: str
    """The method (the replication) or model (the road-following study) trained."""
    seed: int
    """The training seed."""
    part: str = ""
    """The sub-folder of the study that holds the run (the sweep's ``share0.15``), "" for the folder."""

    @property
    def name(self) -> str:
        """How the provenance names the run: ``method/seed<k>`` (``part/method/seed<k>`` in a part)."""
        return "/".join(([self.part] if self.part else []) + [self.method, f"seed{self.seed}"])


def run_dir(out, method: str, seed: int, part: str = "") -> Path:
    """Folder of one training run: ``<out>/runs/<method>/seed<k>`` (``<out>/<part>/runs/...`` in a part)."""
    return Path(out) / part / "runs" / method / f"seed{seed}"


# ---------------------------------------------------------------------- the folder's entries
def check_folder_entries(out, entries: tuple, what: str, allowed=None) -> bool:
    """Whether ``out`` exists as a folder to check further: False if it does not exist; ValueError if it is
    a file, or holds files (hidden ones aside) other than ``entries`` or names ``allowed(name)`` accepts,
    naming up to three of them and the ``what`` it is not (e.g. "sweep"); True otherwise."""
    out = Path(out)
    if not out.exists():
        return False
    if not out.is_dir():
        raise ValueError(f"{out} is a file, expected a folder")
    names = {p.name for p in out.iterdir() if not p.name.startswith(".")}
    foreign = sorted(n for n in names - set(entries) if not (allowed and allowed(n)))
    if foreign:
        raise ValueError(
            f"{out} holds other files ({', '.join(foreign[:3])}), not a {what}: use another --out"
        )
    return True


def clear_entries(out, entries: tuple, what: str) -> None:
    """``--force``: delete ``entries`` (files or folders) from ``out``, nothing else. ValueError, before
    anything is deleted, if ``out`` holds files other than ``entries`` (hidden ones aside): what ``--force``
    may delete is a ``what``'s files (e.g. "replication"), never anything else."""
    out = Path(out)
    if out.is_dir() and any(p.name not in entries and not p.name.startswith(".") for p in out.iterdir()):
        raise ValueError(
            f"{out} holds files that are not a {what}'s: --force deletes only a {what}; use another --out"
        )
    for name in entries:
        p = out / name
        if p.is_dir():
            shutil.rmtree(p)
        elif p.exists():
            p.unlink()


def read_folder(out, arrays: dict[str, str], command: str) -> dict:
    """``results.json`` and ``provenance.json`` of a finished folder as dicts, and each ``.npz`` of
    ``arrays`` ({key: file name}) as a dict of arrays ({} if absent). ValueError naming a missing or damaged
    file and ``command``, the command that makes it again."""
    out = Path(out)
    if not (out / RESULTS).is_file():
        raise ValueError(f"no {RESULTS} in {out}: run '{command} --out {out}' first")
    fix = f"delete it and re-run '{command}' with the same --preset and --out {out} to make it again"
    res = {
        "results": read_json_dict(out / RESULTS, fix),
        "provenance": read_json_dict(out / PROVENANCE, fix) if (out / PROVENANCE).exists() else {},
    }
    for key, name in arrays.items():
        res[key] = read_npz(out / name, fix) if (out / name).exists() else {}
    return res


def differing(stored, settings) -> str:
    """For a message: the fields (up to five, sorted) in which a stored settings dict differs from
    ``settings`` (a preset: ``experiments.settings.StoredSettings``), "name" if only the name does, "a
    damaged preset" if ``stored`` cannot be read as one."""
    try:
        return ", ".join(sorted(type(settings).from_dict(stored).differences(settings))[:5]) or "name"
    except (TypeError, ValueError):
        return "a damaged preset"


# ---------------------------------------------------------------------- a study's folder
@dataclass(frozen=True)
class StudyFolder:
    """What one study's folder holds, and the lifecycle every study's folder goes through (module
    docstring)."""

    what: str
    """What the folder is, in the messages: "replication", "road-following study", "sweep"."""
    command: str
    """The command that makes it, e.g. "ibc-tutorial replicate"."""
    entries: tuple
    """What the folder holds (``--force`` deletes these, and only these)."""
    done: str
    """The file of a run's folder written last: with it, the run is finished."""
    arrays: dict = field(default_factory=dict)
    """The arrays ``load`` reads beside ``results.json``: {key: ``.npz`` file name}."""
    part_prefix: str = ""
    """The name with which the folder's parts begin (the sweep's "share"): those folders are the study's."""
    markers: tuple = ()
    """Empty: the folder holds the study's ``entries`` and nothing else. Else other analyses may write into
    the folder too (the replication's stem and route analyses), and a folder holding files, none of them
    ``markers``, is not this study's."""

    # -- 1. check
    def check_entries(self, out) -> bool:
        """Whether ``out`` exists as a folder to check further (False: nothing there yet); ValueError if it
        is a file or holds files that are not this study's."""
        out = Path(out)
        study_here = self.markers and out.is_dir() and any((out / m).exists() for m in self.markers)

        def allowed(name: str) -> bool:  # beside the entries: the parts, or anything once the study is here
            return bool(study_here or (self.part_prefix and name.startswith(self.part_prefix)))

        return check_folder_entries(out, self.entries, self.what, allowed)

    def check_settings(
        self, out, same: Callable[[object], bool], describe: Callable[[object], str], files=None, key="preset"
    ) -> None:
        """Refuse (ValueError) a folder whose recorded settings are not these: ``key`` of each of ``files``
        (default: ``provenance.json``, ``results.json``) that exists (``key`` None: the whole file), for
        which ``same(stored)`` is False; the message says ``out`` holds ``describe(stored)``."""
        out = Path(out)
        for name in files or (PROVENANCE, RESULTS):
            if not (out / name).exists():
                continue
            d = read_json_dict(out / name, "delete it and re-run the same command to make it again")
            stored = d if key is None else d.get(key)
            if stored is not None and not same(stored):
                raise ValueError(
                    f"{out} holds {describe(stored)}: use another --out, or --force to start over"
                )

    def check_runs(self, out, runs, check: Callable[[Path], object]) -> None:
        """``check(run's done file)`` for every run of ``runs`` that is finished (it raises on a damaged
        one)."""
        for r in runs:
            if self.is_done(out, r):
                check(self.run_dir(out, r) / self.done)

    # -- 2. clear
    def clear(self, out) -> None:
        """``--force``: delete the study's entries (and its parts' folders) from ``out``, nothing else;
        ValueError if ``out`` holds other files (they are not the study's to delete)."""
        out = Path(out)
        parts = ()
        if self.part_prefix and out.is_dir():
            parts = tuple(p.name for p in out.iterdir() if p.is_dir() and p.name.startswith(self.part_prefix))
        clear_entries(out, self.entries + parts, self.what)

    # -- 3. resume
    @staticmethod
    def run_dir(out, run: Run) -> Path:
        """The folder of ``run``."""
        return run_dir(out, run.method, run.seed, run.part)

    def is_done(self, out, run: Run) -> bool:
        """Whether ``run`` is finished (its ``done`` file exists)."""
        return (self.run_dir(out, run) / self.done).exists()

    def todo(self, out, runs) -> list[Run]:
        """The runs of ``runs`` not finished yet, in their order."""
        return [r for r in runs if not self.is_done(out, r)]

    def finished(self, out, runs) -> list[str]:
        """The names of the runs of ``runs`` that are finished, in their order."""
        return [r.name for r in runs if self.is_done(out, r)]

    def provenance(self, out, runs, **described) -> Provenance:
        """The ``Provenance`` of the folder, its planned and finished runs those of ``runs``; ``described``:
        its other fields (``title``, ``command``, ``preset``, ...)."""
        runs = list(runs)
        return Provenance(
            Path(out), planned=[r.name for r in runs], finished=lambda: self.finished(out, runs), **described
        )

    # -- 4. run
    def run(
        self,
        out,
        provenance: Provenance,
        results: dict,
        collect: Callable[[bool], dict],
        work: Callable[[Callable[[bool], None]], None],
        log=print,
    ) -> dict:
        """``work(save)`` under ``provenance``, then ``save(True)``; returns ``results``. ``save(complete)``
        updates ``results`` with ``collect(complete)`` (the finished runs, read again), writes
        ``results.json`` and the provenance: ``work`` calls it after every run."""
        out = Path(out)

        def save(complete: bool) -> None:
            results.update(collect(complete))
            write_json(out / RESULTS, results)
            provenance.write(complete)

        with provenance:
            work(save)
            save(True)
        if log:
            log(f"{self.what} finished in {provenance.wall_seconds / 60:.1f} min; results in {out}")
        return results

    # -- 5. load
    def load(self, out) -> dict:
        """What the chapters read: ``results.json`` and ``provenance.json`` as dicts, the ``arrays`` as dicts
        of arrays (empty if absent). ValueError naming the file if one is missing or damaged."""
        return read_folder(out, self.arrays, self.command)


def run_missing(named, path_of, work, *, only=None, on_done=None, log=print) -> list[str]:
    """For each ``(name, item)`` of ``named`` (those in ``only``, if given) whose file ``path_of(name)`` does
    not exist yet: ``work(name, item, path)``, which writes it, then ``on_done(name, cpu_seconds)``; so an
    interrupted loop resumes where it stopped. Returns the names done; ``log`` prints one line per name."""
    done = []
    for name, item in named:
        path = Path(path_of(name))
        if (only and name not in only) or path.exists():
            continue
        t0 = time.process_time()
        work(name, item, path)
        cpu = time.process_time() - t0
        if on_done is not None:
            on_done(name, cpu)
        done.append(name)
        if log:
            log(f"{now()} {name}: {cpu:.0f} s of CPU", flush=True)
    return done


def run_missing_recorded(
    named, out, protocol: dict, path_of, work, *, only=None, log=print, command: str = ""
) -> list[str]:
    """``run_missing`` into the folder ``out``, with every invocation recorded in ``out/provenance.json``:
    its command, commit, machine, start, finish and each name's CPU seconds, under one ``protocol`` (a dict
    that every invocation on ``out`` must share; ValueError naming ``out`` otherwise, before any work).
    What the driving commands that write one file per driver share (``routes``, ``starts``,
    ``stems drive``)."""
    out = Path(out)
    prov_path = out / PROVENANCE
    prov = read_json_dict(prov_path, "use another --out") if prov_path.exists() else {"invocations": []}
    if prov.get("protocol", protocol) != protocol:
        raise ValueError(f"{out} holds drives of another protocol {prov['protocol']}: use another --out")
    prov["protocol"] = protocol
    inv = {"command": command, "commit": git_commit(), "machine": machine(), "started": now()}
    prov["invocations"].append(inv)
    write_json(prov_path, prov)

    def record(name, cpu):
        inv.setdefault("cpu_seconds", {})[name] = round(cpu, 1)
        write_json(prov_path, prov)

    done = run_missing(named, path_of, work, only=only, on_done=record, log=log)
    inv["finished"] = now()
    write_json(prov_path, prov)
    return done


def read_driver_files(out, what: str) -> dict[str, dict]:
    """name -> the JSON of every ``<name>.json`` in ``out`` but the provenance (one file per driver, as the
    ``routes`` and ``starts`` commands write them); ValueError naming ``out`` and ``what`` it should hold if
    there is none."""
    out = Path(out)
    files = sorted(p for p in out.glob("*.json") if p.name != PROVENANCE)
    if not files:
        raise ValueError(f"out must hold {what} (<name>.json), found none in {out}")
    return {p.stem: read_json_dict(p, "drive it again") for p in files}
