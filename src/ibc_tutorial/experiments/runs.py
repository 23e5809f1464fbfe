"""What both studies' folders share: JSON and NPZ files, folder checks, provenance and its heartbeat.

The driving replication (``experiments.agents``, chapters 08-09) and the road-following study
(``experiments.steering``, chapter 10) each write a resumable folder: the demonstrations, one
sub-folder per training run, a ``results.json`` the chapters read, and ``provenance.json`` with
``PROVENANCE.md``. What such a folder needs whatever the study lives here, so that neither study
imports the other:

- reading and writing: ``write_json``, ``read_json_dict``, ``write_npz``, ``read_folder`` (every
  file checked as it is read; a damaged one is a ``ValueError`` naming it and what to do);
- the folder cleared by ``--force``: ``clear_entries``;
- provenance: ``machine``, ``git_commit``, ``now``, and ``Provenance``, which records every
  invocation of a resumable command (its start and its last heartbeat, so a killed invocation's
  time counts up to its last heartbeat) and writes ``provenance.json`` and ``PROVENANCE.md``.

The worker processes of both studies are ``parallel.imap_unordered``'s.
"""

from __future__ import annotations

import io
import json
import os
import platform
import shutil
import subprocess
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import torch

from ibc_tutorial import __version__
from ibc_tutorial.utils import atomic_write_bytes

PROVENANCE = "provenance.json"
"""How, where and when a folder's results were made (``PROVENANCE.md`` says the same for readers)."""
PROVENANCE_MD = "PROVENANCE.md"
"""The readers' copy of ``provenance.json``."""
RESULTS = "results.json"
"""A finished folder's tables and numbers: the file its chapter reads (every study's folder holds one)."""
HEARTBEAT_S = 30.0
"""How often a running command records in ``provenance.json`` that it is still running."""
CPU_ENVIRONMENT = ("ATEN_CPU_CAPABILITY", "MKL_ENABLE_INSTRUCTIONS", "ONEDNN_MAX_CPU_ISA", "OMP_NUM_THREADS")
"""Environment variables that change which CPU instructions (and threads) torch's arithmetic uses: a run
made with them set (an emulated older CPU, CONTRIBUTING.md) records them."""


# ---------------------------------------------------------------------- files
def write_json(path, obj) -> Path:
    """``obj`` as indented JSON, written atomically."""
    return atomic_write_bytes(path, json.dumps(obj, indent=1).encode())


def read_json(path, fix: str):
    """A JSON file's content; ValueError naming the file and ``fix`` (what to do) if it is not JSON."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path} is damaged, not readable JSON ({type(exc).__name__}): {fix}") from None


def read_json_dict(path, fix: str) -> dict:
    """A JSON file that must hold a dict; ValueError naming the file and ``fix`` (what to do) otherwise."""
    obj = read_json(path, fix)
    if not isinstance(obj, dict):
        raise ValueError(f"{path} is damaged: it holds a {type(obj).__name__}, not a JSON object: {fix}")
    return obj


def write_npz(path, arrays: dict) -> Path:
    """Arrays as a compressed ``.npz``, written atomically."""
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return atomic_write_bytes(path, buf.getvalue())


def read_npz(path, fix: str) -> dict:
    """The arrays of a ``.npz`` file as a dict; ValueError naming the file and ``fix`` if it is damaged."""
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except Exception as exc:  # zip, zlib, format errors of a truncated or altered file
        raise ValueError(f"{path} is truncated or damaged ({type(exc).__name__}): {fix}") from None


def read_folder(out, results: str, arrays: dict[str, str], command: str) -> dict:
    """``results`` and ``provenance.json`` of a finished folder as dicts, and each ``.npz`` of ``arrays``
    ({key: file name}) as a dict of arrays ({} if absent). ValueError naming a missing or damaged file and
    ``command``, the command that makes it again."""
    out = Path(out)
    if not (out / results).is_file():
        raise ValueError(f"no {results} in {out}: run '{command} --out {out}' first")
    fix = f"delete it and re-run '{command}' with the same --preset and --out {out} to make it again"
    res = {
        "results": read_json_dict(out / results, fix),
        "provenance": read_json_dict(out / PROVENANCE, fix) if (out / PROVENANCE).exists() else {},
    }
    for key, name in arrays.items():
        res[key] = read_npz(out / name, fix) if (out / name).exists() else {}
    return res


def read_torch_file(path, what: str, fix: str) -> dict:
    """A checkpoint file read with ``torch.load(..., weights_only=True)`` onto the CPU: plain data only,
    no pickled code runs. Its errors are one ValueError naming the file, ``what`` it should be (e.g.
    "agent checkpoint") and ``fix`` (never torch's advice to load with ``weights_only=False``: that
    would run code stored in the file). Both studies' checkpoints are read here."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path} is a folder, expected a file ({what})")
    if not path.is_file():
        raise ValueError(f"no checkpoint at {path}")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        text = str(exc)
        if "weights_only" in text or "Unsupported global" in text:
            why = "it holds Python objects, not only tensors and plain data (refused: loading them runs code)"
        elif "zip" in text.lower() or "central directory" in text or isinstance(exc, (EOFError, OSError)):
            why = "it is truncated or damaged"
        else:
            why = f"{type(exc).__name__}: {' '.join(text.split()[:16])}"
        raise ValueError(f"{path} is not a readable {what} ({why}): {fix}") from None


# ---------------------------------------------------------------------- folders (--force)
def read_run_file(path, valid, what: str) -> dict:
    """A run's JSON file, checked by ``valid(d)`` (called on a dict only); ValueError naming the file, what it
    should be (``what``, e.g. "a run's evaluation") and how to make it again otherwise."""
    path = Path(path)
    fix = f"delete {path.parent} and re-run the same command to make that run again"
    d = read_json(path, fix)
    if not isinstance(d, dict) or not valid(d):
        raise ValueError(f"{path} is damaged (not {what}): {fix}")
    return d


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


# ---------------------------------------------------------------------- provenance
def now() -> str:
    """The current UTC time, ISO 8601 to the second."""
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def machine() -> dict:
    """CPU count and model, OS, Python and torch versions, torch's threads, the instruction set torch's
    kernels use (``torch.backends.cpu.get_cpu_capability()``) and the ``CPU_ENVIRONMENT`` variables set."""
    model = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "nproc": os.cpu_count(),
        "cpu": model,
        "os": platform.platform(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "torch_threads": torch.get_num_threads(),
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "cpu_environment": {k: os.environ[k] for k in CPU_ENVIRONMENT if k in os.environ},
    }


def git_commit() -> str:
    """``git rev-parse HEAD`` of the working tree (or "unknown"), with "+changes" if it is not clean."""
    try:
        head = subprocess.run(
            ["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
        return (head or "unknown") + (" +uncommitted changes" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def invocations_of(prov: dict) -> list[dict]:
    """The invocations recorded in a ``provenance.json`` dict (an older file's ``wall_seconds`` as one)."""
    inv = prov.get("invocations")
    if isinstance(inv, list) and all(
        isinstance(i, dict) and isinstance(i.get("seconds"), (int, float)) for i in inv
    ):
        return [dict(i) for i in inv]
    if isinstance(prov.get("wall_seconds"), (int, float)):
        return [
            {
                "started": prov.get("started"),
                "last_seen": prov.get("updated"),
                "seconds": prov["wall_seconds"],
            }
        ]
    return []


def begin_invocation(out) -> tuple[str, list[dict]]:
    """When a resumable command in ``out`` first started, and its invocations so far plus this one (from
    its ``provenance.json``, if any): what ``Provenance`` sums into the wall time."""
    prov = Path(out) / PROVENANCE
    previous = read_json_dict(prov, "delete it and re-run") if prov.exists() else {}
    this = {"started": now(), "last_seen": now(), "seconds": 0.0}
    return previous.get("started") or this["started"], invocations_of(previous) + [this]


@dataclass
class Provenance:
    """The provenance of one resumable command's folder, kept up to date while it runs.

    ``with Provenance(...) as prov:`` records this invocation beside the earlier ones, writes
    ``provenance.json`` and ``PROVENANCE.md`` at once and then every ``HEARTBEAT_S`` seconds from a
    thread, and once more on leaving (an interrupted invocation's time counts too); ``prov.write()``
    writes them now, ``prov.write(complete=True)`` marks the folder finished.
    """

    out: Path
    """The folder."""
    title: str
    """What the folder holds, for ``PROVENANCE.md``'s title, e.g. "the `laptop` replication"."""
    command: str
    """The command line that makes it (the CLI passes it in; the library never reads ``sys.argv``)."""
    preset: dict
    """The settings, as stored (``Preset.to_dict()``)."""
    differences: dict
    """``{field: (reference value, this value)}``: what the settings change from ``reference``."""
    reference: str
    """What ``differences`` compares with, e.g. "the paper's settings"."""
    planned: list
    """The runs the command makes (``method/seed<k>``)."""
    finished: Callable[[], list]
    """The runs finished so far (called at every write)."""
    overrides: list = field(default_factory=list)
    """The ``--set FIELD=VALUE`` overrides of the command line, recorded as given."""

    def __post_init__(self):
        self.out = Path(self.out)
        self.started, self.invocations = begin_invocation(self.out)
        self._t0 = time.perf_counter()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self.complete = False

    @property
    def wall_seconds(self) -> float:
        """The wall time over every invocation so far, this one included."""
        return sum(float(i["seconds"]) for i in self.invocations)

    def write(self, complete: bool = False) -> None:
        """Write ``provenance.json`` and ``PROVENANCE.md`` now (``complete``: the folder is finished)."""
        with self._lock:
            self.complete = self.complete or complete
            self.invocations[-1].update(last_seen=now(), seconds=round(time.perf_counter() - self._t0, 1))
            self._write()

    def __enter__(self) -> Provenance:
        self.write()

        def beat() -> None:
            while not self._stop.wait(HEARTBEAT_S):
                self.write()

        threading.Thread(target=beat, daemon=True, name="provenance heartbeat").start()
        return self

    def __exit__(self, *exc) -> bool:
        self._stop.set()
        if not self.complete:
            self.write()  # an interrupted invocation's time counts too
        return False

    def _write(self) -> None:
        out, complete = self.out, self.complete
        old = read_json_dict(out / PROVENANCE, "delete it and re-run") if (out / PROVENANCE).exists() else {}
        notes = list(old["notes"]) if isinstance(old.get("notes"), list) else []  # kept across invocations
        done, wall = self.finished(), self.wall_seconds
        prov = {
            "command": self.command,
            "commit": git_commit(),
            "package_version": __version__,
            "started": self.started,
            "finished": now() if complete else None,
            "updated": now(),
            "wall_seconds": round(wall, 1),
            "invocations": self.invocations,
            "resumed": len(self.invocations) > 1,
            "complete": complete,
            "runs_done": done,
            "runs_planned": list(self.planned),
            "machine": machine(),
            "preset": self.preset,
            "overrides": list(self.overrides),
            "notes": notes,
        }
        write_json(out / PROVENANCE, prov)
        m = prov["machine"]
        ended = (
            f"finished: {prov['finished']}" if complete else f"NOT FINISHED (last update {prov['updated']})"
        )
        lines = [
            f"# Provenance of {self.title}",
            "",
            f"- command: `{self.command}`",
            f"- commit: `{prov['commit']}` (ibc_tutorial {__version__})",
            f"- started: {self.started}; {ended}",
            f"- wall time: {wall / 60:.1f} min over {len(self.invocations)} invocation(s)"
            + (" (resumed)" if prov["resumed"] else ""),
            f"- machine: {m['nproc']} CPUs ({m['cpu']}), {m['os']}, Python {m['python']}, torch {m['torch']} "
            f"with {m['torch_threads']} thread(s)"
            + (f", kernels for {m['cpu_capability']}" if m.get("cpu_capability") else "")
            + "".join(f", {k}={v}" for k, v in m.get("cpu_environment", {}).items()),
            f"- runs finished: {len(done)} of {len(self.planned)}"
            + ("" if complete else f" (missing: {sorted(set(self.planned) - set(done))})"),
        ]
        if self.overrides:
            lines.append(f"- overrides: {', '.join(f'`{o}`' for o in self.overrides)}")
        lines += ["", f"Differences of these settings from {self.reference} (field: reference -> these):", ""]
        lines += [f"- `{k}`: {a} -> {b}" for k, (a, b) in self.differences.items()] or ["- none"]
        if notes:
            lines += ["", "Notes:", ""] + [f"- {n}" for n in notes]
        atomic_write_bytes(out / PROVENANCE_MD, ("\n".join(lines) + "\n").encode())


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
