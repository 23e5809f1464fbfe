"""The files of a replication folder: where each run goes, what ``results.json`` aggregates, provenance, loading.

A replication folder (``ibc-tutorial replicate --out FOLDER``) holds

- ``data/town01.npz``: the demonstrations;
- ``runs/<method>/seed<k>/``: one training run each (``metrics.jsonl``, ``final_eval.json``,
  ``heldout_eval.json`` and the agent, ``final.pt``);
- ``runs/expert/``: the PID expert's ``final_eval.json`` and ``heldout_eval.json`` on the same starts;
- ``results.json``: everything the chapters read (the table, the per-seed finals, the Fig. 4
  curves, the preset and its differences from the paper's, the Fig. 5/6 summaries);
- ``free_driving.npz`` and ``landscapes.npz``: the arrays of the Fig. 5 and Fig. 6 analogues;
- ``provenance.json`` and ``PROVENANCE.md``: command, commit, date, machine, wall time, what is
  finished. The wall time is the sum over every invocation, each recorded with its start and
  its last heartbeat (so a killed invocation's time counts up to its last heartbeat).

``load_results(folder)`` is what chapters 08-09 call. Every file is checked as it is read; a
damaged one gives a ``ValueError`` naming it and saying how to make it again.
"""

from __future__ import annotations

import io
import json
import os
import platform
import shutil
import subprocess
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import torch

from ibc_tutorial import __version__
from ibc_tutorial.experiments.agents.evaluate import summarize
from ibc_tutorial.experiments.agents.presets import PAPER, Preset, differences
from ibc_tutorial.experiments.agents.train import read_metrics
from ibc_tutorial.utils import atomic_write_bytes

EPISODE_KEYS = ("seed", "steps", "distance_m", "red_light_infractions", "score", "termination")
"""What every episode row of a ``final_eval.json`` holds."""

RESULTS = "results.json"
"""The file the chapters read."""
PROVENANCE = "provenance.json"
"""How, where and when the results were made (``PROVENANCE.md`` says the same for readers)."""
FREE_DRIVING = "free_driving.npz"
"""Trajectories of the free-driving episodes (Fig. 5 analogue)."""
LANDSCAPES = "landscapes.npz"
"""Energy grids, observations and DFO inferences (Fig. 6 analogue)."""
DATA = "data/town01.npz"
"""The demonstrations, relative to the folder."""


def now() -> str:
    """The current UTC time, ISO 8601 to the second."""
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


CPU_ENVIRONMENT = ("ATEN_CPU_CAPABILITY", "MKL_ENABLE_INSTRUCTIONS", "ONEDNN_MAX_CPU_ISA", "OMP_NUM_THREADS")
"""Environment variables that change which CPU instructions (and threads) torch's arithmetic uses: a run made with
them set (an emulated older CPU, CONTRIBUTING.md) records them."""


def machine() -> dict:
    """CPU count and model, OS, Python and torch versions, torch's threads, the instruction set torch's kernels use
    (``torch.backends.cpu.get_cpu_capability()``) and the ``CPU_ENVIRONMENT`` variables that are set."""
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


def run_dir(out, method: str, seed: int) -> Path:
    """Folder of one training run."""
    return Path(out) / "runs" / method / f"seed{seed}"


def expert_dir(out) -> Path:
    """Folder of the PID expert's evaluations on the agents' starts (the table's reference row)."""
    return Path(out) / "runs" / "expert"


def run_name(method: str, seed: int) -> str:
    """How a run is named in the provenance: ``method/seed<k>``."""
    return f"{method}/seed{seed}"


def finished_runs(out, preset: Preset) -> list[str]:
    """The runs of ``preset`` under ``out`` that have their ``final_eval.json``, in planned order."""
    return [
        run_name(m, s)
        for s in preset.seeds
        for m in preset.methods
        if (run_dir(out, m, s) / "final_eval.json").exists()
    ]


def write_json(path, obj) -> Path:
    """``obj`` as indented JSON, written atomically."""
    return atomic_write_bytes(path, json.dumps(obj, indent=1).encode())


def read_json_dict(path, fix: str) -> dict:
    """A JSON file that must hold a dict; ValueError naming the file and ``fix`` (what to do) otherwise."""
    path = Path(path)
    try:
        obj = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path} is damaged, not readable JSON ({type(exc).__name__}): {fix}") from None
    if not isinstance(obj, dict):
        raise ValueError(f"{path} is damaged: it holds a {type(obj).__name__}, not a JSON object: {fix}")
    return obj


def read_final_eval(path) -> dict:
    """A run's ``final_eval.json``, checked (its summary and one row per episode with ``EPISODE_KEYS``)."""
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
            f"{path} is damaged: not a final evaluation (summary, episodes with {', '.join(EPISODE_KEYS)}): {fix}"
        )
    return ev


def write_npz(path, arrays: dict) -> Path:
    """Arrays as a compressed ``.npz``, written atomically."""
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return atomic_write_bytes(path, buf.getvalue())


# ---------------------------------------------------------------------- aggregation
def collect_results(out, preset: Preset) -> dict:
    """Read every finished run under ``out`` into the table, per-seed finals and curves of ``results.json``."""
    out = Path(out)
    table, curves, finals, heldout = {}, {}, {}, {}
    for method in preset.methods:
        rows, per_seed, held = [], {}, []
        curves[method] = {}
        for seed in preset.seeds:
            d = run_dir(out, method, seed)
            if (d / "metrics.jsonl").exists():
                m = read_metrics(d)
                curves[method][str(seed)] = {
                    "epoch": [e["epoch"] for e in m],
                    "score": [e["eval"]["score_mean"] for e in m],
                    "distance_m": [e["eval"]["distance_m_mean"] for e in m],
                    "infractions": [e["eval"]["red_light_infractions_mean"] for e in m],
                    "loss": [e["loss"] for e in m],
                }
            f = d / "final_eval.json"
            if f.exists():
                ev = read_final_eval(f)
                rows += ev["episodes"]
                per_seed[str(seed)] = ev["summary"]
                if (d / "heldout_eval.json").exists():
                    held += read_final_eval(d / "heldout_eval.json")["episodes"]
        finals[method] = per_seed
        if rows:
            table[method] = dict(summarize(rows), agents=len(per_seed))  # episodes of every seed pooled
        if held:
            heldout[method] = dict(summarize(held), agents=len(per_seed))
    e = expert_dir(out)
    for name, into in (("final_eval.json", table), ("heldout_eval.json", heldout)):
        if (e / name).exists():
            into["expert"] = dict(summarize(read_final_eval(e / name)["episodes"]), agents=1)
    return {"table": table, "heldout": heldout, "final_per_seed": finals, "curves": curves}


def preset_results(preset: Preset, complete: bool) -> dict:
    """The entries of ``results.json`` that describe the settings: the preset, the paper's, their differences."""
    return {
        "preset": preset.to_dict(),
        "paper": PAPER.to_dict(),
        "differences": {k: list(v) for k, v in differences(PAPER, preset).items()},
        "complete": complete,
    }


# ---------------------------------------------------------------------- provenance
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


def write_provenance(
    out,
    preset: Preset,
    started: str,
    invocations: list[dict],
    done: list[str],
    planned: list[str],
    command: str,
    complete: bool,
) -> None:
    """``provenance.json`` and ``PROVENANCE.md``: how, where and when the results were made.

    ``invocations``: one ``{"started", "last_seen", "seconds"}`` per invocation of the command; the wall
    time is their sum."""
    out = Path(out)
    old = read_json_dict(out / PROVENANCE, "delete it and re-run") if (out / PROVENANCE).exists() else {}
    notes = (
        list(old.get("notes", [])) if isinstance(old.get("notes"), list) else []
    )  # kept across invocations
    wall_s = sum(float(i["seconds"]) for i in invocations)
    prov = {
        "command": command,
        "commit": git_commit(),
        "package_version": __version__,
        "started": started,
        "finished": now() if complete else None,
        "updated": now(),
        "wall_seconds": round(wall_s, 1),
        "invocations": invocations,
        "complete": complete,
        "runs_done": done,
        "runs_planned": planned,
        "machine": machine(),
        "preset": preset.to_dict(),
        "notes": notes,
    }
    write_json(out / PROVENANCE, prov)
    m = prov["machine"]
    lines = [
        f"# Provenance of the `{preset.name}` replication",
        "",
        f"- command: `{command}`",
        f"- commit: `{prov['commit']}` (ibc_tutorial {__version__})",
        f"- started: {started}; {'finished: ' + prov['finished'] if complete else 'NOT FINISHED (last update ' + prov['updated'] + ')'}",
        f"- wall time: {wall_s / 60:.1f} min over {len(invocations)} invocation(s)",
        f"- machine: {m['nproc']} CPUs ({m['cpu']}), {m['os']}, Python {m['python']}, torch {m['torch']} "
        f"with {m['torch_threads']} thread(s)"
        + (f", kernels for {m['cpu_capability']}" if m.get("cpu_capability") else "")
        + ("".join(f", {k}={v}" for k, v in m.get("cpu_environment", {}).items())),
        f"- runs finished: {len(done)} of {len(planned)}"
        + ("" if complete else f" (missing: {sorted(set(planned) - set(done))})"),
        "",
        "Differences of this preset from the paper's settings (field: paper -> this preset):",
        "",
    ]
    lines += [f"- `{k}`: {a} -> {b}" for k, (a, b) in differences(PAPER, preset).items()]
    if notes:
        lines += ["", "Notes:", ""] + [f"- {n}" for n in notes]
    atomic_write_bytes(out / "PROVENANCE.md", ("\n".join(lines) + "\n").encode())


def check_only_entries(out, entries: tuple, what: str) -> None:
    """Refuse (ValueError) ``out`` if it holds files other than ``entries`` (hidden ones aside): what ``--force``
    may delete is a ``what``'s files (e.g. "replication"), never anything else."""
    out = Path(out)
    if out.is_dir() and any(p.name not in entries and not p.name.startswith(".") for p in out.iterdir()):
        raise ValueError(
            f"{out} holds files that are not a {what}'s: --force deletes only a {what}; use another --out"
        )


def delete_entries(out, entries: tuple) -> None:
    """Delete ``entries`` (files or folders) from ``out``, nothing else (``--force``, after ``check_only_entries``)."""
    for name in entries:
        p = Path(out) / name
        if p.is_dir():
            shutil.rmtree(p)
        elif p.exists():
            p.unlink()


def begin_invocation(out) -> tuple[str, list[dict]]:
    """When a resumable run in ``out`` first started, and its invocations so far plus this one (from its
    ``provenance.json``, if any): what ``write_provenance`` sums into the wall time."""
    prov = Path(out) / PROVENANCE
    previous = read_json_dict(prov, "delete it and re-run") if prov.exists() else {}
    this = {"started": now(), "last_seen": now(), "seconds": 0.0}
    return previous.get("started") or this["started"], invocations_of(previous) + [this]


def read_folder(out, results: str, arrays: dict[str, str], command: str) -> dict:
    """``results`` and ``provenance.json`` of a finished run's folder as dicts, and each ``.npz`` of ``arrays``
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
        res[key] = {}
        if (out / name).exists():
            try:
                with np.load(out / name, allow_pickle=False) as z:
                    res[key] = {k: z[k] for k in z.files}
            except Exception as exc:  # zip, zlib, format errors of a truncated or altered file
                raise ValueError(
                    f"{out / name} is truncated or damaged ({type(exc).__name__}): {fix}"
                ) from None
    return res


# ---------------------------------------------------------------------- reading (the chapters)
def load_results(out) -> dict:
    """What the chapters read from a replication folder: ``results.json`` and ``provenance.json`` as
    dicts, ``free_driving.npz`` and ``landscapes.npz`` as dicts of arrays (empty if absent).

    ValueError naming the file if one is missing or damaged."""
    return read_folder(
        out, RESULTS, {"free_driving": FREE_DRIVING, "landscapes": LANDSCAPES}, "ibc-tutorial replicate"
    )
