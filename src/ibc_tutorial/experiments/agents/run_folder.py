"""A training run's folder: what it holds, whether a request may train there, its metrics.

A run's folder records what it is (``run.json``: method, seed, preset, the demonstrations'
checksum, written before the first epoch), and ``inspect_run`` compares it with a request before
any work: a folder holding another run (another method, seed, setting or data) is refused, a
finished run is never overwritten (``--force`` starts over: ``clear_run``), and a run already
trained beyond ``epochs`` is refused rather than returned as if trained. ``metrics.jsonl`` holds
one line per periodic evaluation (``read_metrics``, ``write_metrics``).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from ibc_tutorial.experiments.agents.checkpoints import load_checkpoint
from ibc_tutorial.experiments.agents.presets import Preset
from ibc_tutorial.experiments.runs import read_json, write_json
from ibc_tutorial.utils import atomic_write_bytes

RUN_INFO = "run.json"
"""A run's identity (method, seed, preset, data checksum), written before its first epoch."""
RUN_FILES = (RUN_INFO, "last.pt", "final.pt", "metrics.jsonl", "final_eval.json")
"""The files of a run's folder (``--force`` deletes these, and only these)."""


@dataclass
class RunState:
    """What a run's folder holds, compared with a request (``inspect_run``)."""

    status: str
    """"new" (nothing there), "resume" (an unfinished run of this request) or "done" (finished)."""
    epoch: int = 0
    """Epochs already trained."""


def _file_sha256(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _identity(out: Path) -> tuple[dict, int, str]:
    """The stored run's (identity, epochs trained, file it was read from), from the best source in the
    folder."""
    fix = "delete it, or pass --force to start the run over"
    last, final = out / "last.pt", out / "final.pt"
    epoch, ident, source = 0, {}, ""
    ck = (
        load_checkpoint(last, resumable=True)
        if last.exists()
        else load_checkpoint(final)
        if final.exists()
        else None
    )
    if ck is not None:
        source = str(last if last.exists() else final)
        ident = {
            "method": ck["method"],
            "preset": ck["preset"],
            "data_sha256": ck["data_sha256"],
            "seed": ck.get("seed", ck["metrics"][0].get("seed") if ck["metrics"] else None),
        }
        epoch = ck["epoch"]
    if (out / "metrics.jsonl").exists():
        m = read_metrics(out / "metrics.jsonl")
        if m and ck is None:
            ident, epoch, source = (
                {"method": m[0]["method"], "seed": m[0]["seed"]},
                m[-1]["epoch"],
                str(out / "metrics.jsonl"),
            )
    if (out / "final_eval.json").exists():
        ev = read_json(out / "final_eval.json", fix)
        if not isinstance(ev, dict) or not isinstance(ev.get("episodes"), list) or "summary" not in ev:
            raise ValueError(f"{out / 'final_eval.json'} is damaged (not a final evaluation): {fix}")
        ident = ident or {"method": ev.get("method"), "seed": ev.get("seed")}
        source = source or str(out / "final_eval.json")
    if (out / RUN_INFO).exists():
        info = read_json(out / RUN_INFO, fix)
        if not isinstance(info, dict) or not {"method", "seed", "preset", "data_sha256"} <= set(info):
            raise ValueError(f"{out / RUN_INFO} is damaged (not a run description): {fix}")
        ident, source = info, str(out / RUN_INFO)
    return ident, epoch, source


def _completed(stored: dict) -> dict:
    """A stored preset dict with the fields added since it was written at their defaults (as
    ``Preset.from_dict`` reads it); the dict itself if it is not a valid preset."""
    try:
        return Preset.from_dict(stored).to_dict()
    except (TypeError, ValueError):
        return stored


def inspect_run(
    out, method: str, preset: Preset, seed: int, data_sha256: str | None, data_file=None
) -> RunState:
    """Compare what ``out`` holds with a request to train ``method`` / ``seed`` / ``preset`` on data of
    checksum
    ``data_sha256`` (``data_file``'s bytes' SHA-256 is accepted too: the identity of files of older versions;
    None: the data is not compared).

    Raises ValueError, one line saying what differs and how to proceed, if the folder holds another run,
    a run trained beyond ``preset.epochs``, or a finished run that cannot be extended (no ``last.pt``).
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out} is a file, expected a run's folder")
    if not out.exists() or not any((out / f).exists() for f in RUN_FILES):
        return RunState("new")
    ident, epoch, source = _identity(out)
    if (
        not ident
    ):  # only run.json's temporary predecessor or nothing readable: a run that never reached epoch 1
        return RunState("new")
    differs = []
    if ident.get("method") != method:
        differs.append(f"method {ident.get('method')!r}, not {method!r}")
    if ident.get("seed") is not None and ident.get("seed") != seed:
        differs.append(f"seed {ident.get('seed')}, not {seed}")
    if "preset" in ident:
        mine = {k: v for k, v in preset.to_dict().items() if k != "epochs"}
        theirs = (
            {k: v for k, v in _completed(ident["preset"]).items() if k != "epochs"}
            if isinstance(ident["preset"], dict)
            else {}
        )
        diff = sorted(k for k in set(mine) | set(theirs) if mine.get(k) != theirs.get(k))
        if diff:
            differs.append(
                f"other settings (preset {theirs.get('name')!r}; differs in {', '.join(diff[:5])})"
            )
    if (
        data_sha256 is not None
        and "data_sha256" in ident
        and ident["data_sha256"] != data_sha256
        and (data_file is None or ident["data_sha256"] != _file_sha256(data_file))
    ):
        differs.append("other demonstrations (another data checksum)")
    if differs:
        raise ValueError(
            f"{out} holds another run ({Path(source).name}: {'; '.join(differs)}): use another --out, "
            "or --force to start over"
        )
    finished = (out / "final.pt").exists() or (out / "final_eval.json").exists()
    if epoch > preset.epochs:
        raise ValueError(
            f"{out} holds this run trained to epoch {epoch} already, beyond the {preset.epochs} epochs "
            "asked for: ask for at least as many, use another --out, or --force to start over"
        )
    if (out / "last.pt").exists():
        return RunState("done" if epoch == preset.epochs and (out / "final.pt").exists() else "resume", epoch)
    if finished and epoch == preset.epochs:
        return RunState("done", epoch)
    if epoch > 0 or finished:
        raise ValueError(
            f"{out} holds this run trained to epoch {epoch} without its resume state (last.pt), so it "
            "cannot continue: use another --out, or --force to start over"
        )
    return RunState("new")


def clear_run(out) -> None:
    """Delete a run's files (``RUN_FILES``) from its folder, nothing else: ``--force``."""
    for name in RUN_FILES:
        (Path(out) / name).unlink(missing_ok=True)


def write_run_info(out, method: str, preset: Preset, seed: int, data_sha256: str) -> None:
    """``run.json``: the run's identity, written once, before its first epoch."""
    if not (Path(out) / RUN_INFO).exists():
        write_json(
            Path(out) / RUN_INFO,
            {"method": method, "seed": seed, "preset": preset.to_dict(), "data_sha256": data_sha256},
        )


def write_metrics(out, metrics: list[dict]) -> None:
    """``metrics.jsonl``: one JSON line per evaluation so far, written atomically."""
    atomic_write_bytes(Path(out) / "metrics.jsonl", "".join(json.dumps(m) + "\n" for m in metrics).encode())


METRIC_KEYS = ("method", "seed", "epoch", "loss", "eval")
"""What every line of ``metrics.jsonl`` holds (at least)."""


def read_metrics(path) -> list[dict]:
    """The lines of a run's ``metrics.jsonl`` (or of the file at ``path``), checked: ValueError naming the
    file."""
    path = Path(path)
    if path.is_dir():
        path = path / "metrics.jsonl"
    fix = "delete the run's folder (or pass --force) to train the run again"
    try:
        lines = path.read_text().splitlines()
    except UnicodeDecodeError:
        raise ValueError(f"{path} is damaged (not text): {fix}") from None
    out = []
    for i, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            m = json.loads(line)
        except json.JSONDecodeError:
            raise ValueError(f"{path} is damaged (line {i} is not JSON): {fix}") from None
        if (
            not isinstance(m, dict)
            or any(k not in m for k in METRIC_KEYS)
            or not isinstance(m["eval"], dict)
            or not isinstance(m["epoch"], int)
            or not all(
                isinstance(m["eval"].get(f"{k}_mean"), (int, float))
                for k in ("score", "distance_m", "red_light_infractions")
            )
        ):
            raise ValueError(
                f"{path} is damaged (line {i} is not a metrics entry with {', '.join(METRIC_KEYS)}): {fix}"
            )
        out.append(m)
    return out
