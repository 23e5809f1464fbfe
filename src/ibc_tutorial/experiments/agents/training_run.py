"""One training run (``train.train_agent``): its folder, and what happens beside the learning.

A run's folder records what it is (``run.json``: method, seed, preset, the demonstrations'
checksum, written before the first epoch), and ``inspect_run`` compares it with a request before
any work: a folder holding another run (another method, seed, setting or data) is refused, a
finished run is never overwritten (``--force`` starts over: ``clear_run``), and a run already
trained beyond ``epochs`` is refused rather than returned as if trained. ``metrics.jsonl`` holds
one line per periodic evaluation (``read_metrics``, ``write_metrics``).

``train_agent`` is the learning; beside it:

- ``open_run``: the demonstrations (loaded, rendered, their inverse-KDE probabilities), the folder
  compared with the request (``inspect_run``), ``run.json`` written before the first epoch;
- ``RunBook.resume``: an interrupted run continues from ``last.pt`` exactly as the uninterrupted run
  would have (weights, Adam's state, the minibatch generator, the metrics so far);
- ``RunBook.after_epochs``: every ``eval_every`` epochs (and after the last), a closed-loop evaluation
  in town02 (``eval_episodes`` batched episodes of ``eval_steps`` steps, scored as the paper scores
  them: its Fig. 4), one line in ``metrics.jsonl`` and a ``last.pt`` with the trainer's states;
- ``RunBook.save_final``: ``final.pt``, the weights in float16 (``train.round_to_half``).

Checkpoints are written from CPU copies and read back onto the CPU first: a run trained on a GPU
resumes or evaluates anywhere.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path

import torch

from ibc_tutorial.driving.dataset import DemoDataset, DemoLog
from ibc_tutorial.experiments.agents.agent import Agent
from ibc_tutorial.experiments.agents.checkpoints import load_agent, load_checkpoint, save_checkpoint
from ibc_tutorial.experiments.agents.evaluate import (
    EVAL_SEED,
    EVAL_TOWN,
    episode_rows,
    evaluate_agent,
    summarize_episodes,
)
from ibc_tutorial.experiments.agents.presets import Preset
from ibc_tutorial.experiments.agents.route_driving import periodic_route_rows
from ibc_tutorial.experiments.runs import read_json, write_json
from ibc_tutorial.kde import inverse_density_weights
from ibc_tutorial.training import Trainer
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
    checksum ``data_sha256`` (``data_file``'s bytes' SHA-256 is accepted too: some shipped runs record the
    file's checksum, not its content's; None: the data is not compared).

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


# ---------------------------------------------------------------------- beside the learning
@dataclass
class TrainingData:
    """The demonstrations of a run, rendered, with their minibatch probabilities (made once, shared by
    runs)."""

    dataset: DemoDataset
    """The rendered demonstrations (at the preset's ``bev_size`` and ``light_encoding``)."""
    sample_probs: torch.Tensor
    """(M,) w ∝ 1 / ĝ of the expert actions (eqs. 4-5): the minibatch probabilities and DA-IBC's DFO initial
    weights."""
    source: Path | None = None
    """The file the demonstrations were read from (None: given in memory); a run compares it with the
    checksums of runs that record the file's (``inspect_run``)."""

    @classmethod
    def of(cls, data, preset: Preset) -> TrainingData:
        """``data`` (a path, a ``DemoLog`` or a ``DemoDataset``) rendered as ``preset`` asks; a path is kept
        as ``source``."""
        ds = data if isinstance(data, DemoDataset) else None
        if ds is None:
            log = data if isinstance(data, DemoLog) else DemoLog.load(data)
            ds = DemoDataset(
                log,
                bev_size=preset.bev_size,
                cache=True,
                light_encoding=preset.light_encoding,
                commands=preset.commands,
            )
        if ds.renderer.light_encoding != preset.light_encoding:
            raise ValueError(
                f"dataset must draw the lights as {preset.light_encoding!r}, "
                f"got {ds.renderer.light_encoding!r}"
            )
        if (ds.commands is not None) != preset.commands:
            raise ValueError(
                f"dataset must {'' if preset.commands else 'not '}give the route commands "
                f"(preset.commands is {preset.commands})"
            )
        if ds.bev_size != preset.bev_size:
            raise ValueError(f"dataset must be rendered at bev_size {preset.bev_size}, got {ds.bev_size}")
        source = None if isinstance(data, (DemoDataset, DemoLog)) else Path(data)
        return cls(ds, inverse_density_weights(ds.actions, preset.kde_bandwidth), source)  # (M,) eqs. 4-5


@dataclass
class OpenedRun:
    """What ``open_run`` found: the data, its checksum, and the folder's state."""

    data: TrainingData | None
    """The rendered demonstrations (None when the run is finished already)."""
    data_sha256: str
    """The demonstrations' content checksum (``DemoLog.checksum``), stored in every checkpoint."""
    status: str
    """``RunState.status``: "new", "resume" or "done"."""
    epoch: int
    """Epochs already trained."""


def open_run(method: str, data, preset: Preset, seed: int, out: Path) -> OpenedRun:
    """Check the data and the folder before any work; write ``run.json`` unless the run is finished.

    ``data``: a file, a ``DemoLog``, or the demonstrations already rendered, a ``DemoDataset`` or a
    ``TrainingData`` (saves rendering them again when several runs share them). ValueError: see
    ``inspect_run``."""
    if isinstance(data, DemoDataset):
        data = TrainingData.of(data, preset)
    if isinstance(data, TrainingData):
        TrainingData.of(data.dataset, preset)  # the same checks, for a shared one
        rendered, log, data_file = data, data.dataset.log, data.source
    else:
        rendered, log = None, data if isinstance(data, DemoLog) else DemoLog.load(data)
        data_file = None if isinstance(data, DemoLog) else data
    sha = log.checksum()  # the demonstrations' content
    state = inspect_run(out, method, preset, seed, sha, data_file)
    if state.status == "done":
        return OpenedRun(None, sha, state.status, state.epoch)
    out.mkdir(parents=True, exist_ok=True)
    write_run_info(out, method, preset, seed, sha)
    return OpenedRun(rendered or TrainingData.of(log, preset), sha, state.status, state.epoch)


def finished_run(out: Path, method: str, preset: Preset, device) -> tuple[Agent, list]:
    """The agent (on ``device``) and metrics of a finished run: its ``final.pt``."""
    if not (out / "final.pt").exists():
        raise ValueError(
            f"{out} holds this run finished, without its final.pt (not kept): nothing to load; "
            "--force to train it again"
        )
    agent, ckpt = load_agent(out / "final.pt", method=method, preset=preset)
    return agent.to(device), list(ckpt["metrics"])


class RunBook:
    """The files of one run while it trains: resume, periodic evaluations, checkpoints, ``metrics.jsonl``."""

    def __init__(self, out: Path, agent: Agent, seed: int, data_sha256: str, log=print):
        self.out, self.agent, self.seed, self.data_sha256, self.log = Path(out), agent, seed, data_sha256, log
        self.metrics: list[dict] = []
        self.resumed_from = 0

    def resume(self, trainer: Trainer, steps_per_epoch: int) -> None:
        """Load ``last.pt`` into ``trainer`` (weights, Adam, minibatch generator) and the metrics so far."""
        a = self.agent
        ckpt = load_checkpoint(self.out / "last.pt", method=a.method, preset=a.preset, resumable=True)
        trainer.load_state_dict(
            {
                "model": ckpt["model"],
                "optimizer": ckpt["optimizer"],
                "generator": ckpt["generator"],
                "step": ckpt["epoch"] * steps_per_epoch,
            }
        )
        self.metrics, self.resumed_from = list(ckpt["metrics"]), ckpt["epoch"]
        if self.log:
            self.log(f"resuming {a.method} seed {self.seed} after epoch {ckpt['epoch']}")

    def after_epochs(self, trainer: Trainer, steps_per_epoch: int):
        """The trainer's callback ``(step, loss)``: evaluate, append to the metrics, write ``last.pt`` and
        ``metrics.jsonl``, log one line."""
        a, p = self.agent, self.agent.preset

        def callback(step: int, loss: float) -> None:
            te = time.perf_counter()
            if a.takes_command:  # the first eval_episodes town02 routes, eval_steps each, with their commands
                rows = periodic_route_rows(a, p.eval_episodes, p.eval_steps, policy_seed=self.seed)
            else:
                episodes = evaluate_agent(
                    a,
                    EVAL_TOWN,
                    p.eval_episodes,
                    p.eval_steps,
                    seed=EVAL_SEED,
                    policy_seed=self.seed,
                    show_progress=False,
                )
                rows = episode_rows(episodes)
            entry = {
                "method": a.method,
                "seed": self.seed,
                "epoch": step // steps_per_epoch,
                "step": step,
                "loss": round(loss, 5),
                "town": EVAL_TOWN,
                "eval_steps": p.eval_steps,
                "eval": summarize_episodes(rows),
                "episodes": rows,
                "eval_seconds": round(time.perf_counter() - te, 1),
            }
            self.metrics.append(entry)
            self._save("last.pt", entry["epoch"], resume=trainer.state_dict())
            write_metrics(self.out, self.metrics)
            if self.log:
                self.log(
                    f"{a.method} seed {self.seed} epoch {entry['epoch']}: loss {entry['loss']:.4f}, "
                    "town02 score "
                    f"{entry['eval']['score_mean']:.1f} ± {entry['eval']['score_std']:.1f}"
                )

        return callback

    def save_final(self) -> None:
        """``final.pt``: the weights in float16 (round them first: ``train.round_to_half``)."""
        epoch = self.metrics[-1]["epoch"] if self.metrics else self.agent.preset.epochs
        self._save("final.pt", epoch, half=True)

    def _save(self, name: str, epoch: int, resume: dict | None = None, half: bool = False) -> None:
        save_checkpoint(
            self.out / name,
            self.agent,
            data_sha256=self.data_sha256,
            epoch=epoch,
            seed=self.seed,
            metrics=self.metrics,
            resume=resume,
            half=half,
        )
