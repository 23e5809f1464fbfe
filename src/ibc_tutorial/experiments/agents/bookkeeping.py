"""The bookkeeping around one training run (``train.train_agent``): its folder, evaluations, checkpoints.

``train_agent`` is the learning; this module is what happens beside it:

- ``open_run``: the demonstrations (loaded, rendered, their inverse-KDE probabilities), the folder
  compared with the request (``run_folder.inspect_run``), ``run.json`` written before the first epoch;
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
from ibc_tutorial.experiments.agents.route_eval import periodic_route_rows
from ibc_tutorial.experiments.agents.run_folder import inspect_run, write_metrics, write_run_info
from ibc_tutorial.kde import inverse_density_weights
from ibc_tutorial.training import Trainer


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
    checksums of older versions' runs (``run_folder.inspect_run``)."""

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
    """``run_folder.RunState.status``: "new", "resume" or "done"."""
    epoch: int
    """Epochs already trained."""


def open_run(method: str, data, preset: Preset, seed: int, out: Path) -> OpenedRun:
    """Check the data and the folder before any work; write ``run.json`` unless the run is finished.

    ``data``: a file, a ``DemoLog``, or the demonstrations already rendered, a ``DemoDataset`` or a
    ``TrainingData`` (saves rendering them again when several runs share them). ValueError: see
    ``run_folder.inspect_run``."""
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
