"""The provenance of a study's folder: the machine, the commit, every invocation and its heartbeat.

``Provenance`` records every invocation of a resumable command (its start and its last heartbeat, so a
killed invocation's time counts up to its last heartbeat) and writes ``provenance.json`` and
``PROVENANCE.md``; ``machine``, ``git_commit`` and ``now`` describe where and when, for the studies
that write their own provenance files.
"""

from __future__ import annotations

import os
import platform
import subprocess
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import torch

from ibc_tutorial import __version__
from ibc_tutorial.experiments.runs.files import PROVENANCE, PROVENANCE_MD, read_json_dict, write_json
from ibc_tutorial.utils import atomic_write_bytes

HEARTBEAT_S = 30.0
"""How often a running command records in ``provenance.json`` that it is still running."""
CPU_ENVIRONMENT = ("ATEN_CPU_CAPABILITY", "MKL_ENABLE_INSTRUCTIONS", "ONEDNN_MAX_CPU_ISA", "OMP_NUM_THREADS")
"""Environment variables that change which CPU instructions (and threads) torch's arithmetic uses: a run
made with them set (an emulated older CPU, CONTRIBUTING.md) records them."""


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
    """The invocations recorded in a ``provenance.json`` dict (one, if it records only ``wall_seconds``)."""
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


def add_note(folder, text: str) -> None:
    """Append ``text`` to the folder's provenance notes (``provenance.json`` and ``PROVENANCE.md``), which
    ``Provenance`` keeps across a resumable command's invocations."""
    folder = Path(folder)
    prov_file = folder / PROVENANCE
    if prov_file.exists():
        prov = read_json_dict(prov_file, "delete it and re-run the command that made it")
        notes = list(prov["notes"]) if isinstance(prov.get("notes"), list) else []
        prov["notes"] = notes + [text]
        write_json(prov_file, prov)
    md = folder / PROVENANCE_MD
    if md.exists():
        body = md.read_text().rstrip("\n")
        body += ("\n" if "\nNotes:\n" in body else "\n\nNotes:\n\n") + f"- {text}\n"
        atomic_write_bytes(md, body.encode())
