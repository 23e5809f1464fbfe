"""Training a driving agent (BC, IBC or DA-IBC) on town01 demonstrations, evaluated in town02 as it learns.

    ibc-tutorial train --method da-ibc --data data/town01.npz --preset laptop --seed 0 --out runs/da-ibc/seed0

What one run does (the DA-IBC paper's secs. 2.4-2.5, 4.2 and Fig. 4, at the preset's scale), on
top of the book's one loop, ``training.Trainer``:

- minibatches of ``batch_size`` drawn with the inverse-KDE probabilities of the expert actions
  (eq. 5 applied by sampling, sec. 2.5; ``kde.inverse_density_weights``), ``ceil(M / batch_size)``
  of them per epoch;
- the objective: the Beta NLL (eq. 1) for bc; InfoNCE (eq. 2) with ``n_neg`` counter-examples,
  uniform over the action box for ibc, expert actions plus N(0, σ²I) for da-ibc;
- Adam with step size ``lr``;
- every ``eval_every`` epochs (and after the last), a closed-loop evaluation in town02:
  ``eval_episodes`` batched episodes of ``eval_steps`` steps, scored as the paper scores them;
- after each evaluation, one JSON line in ``metrics.jsonl`` and a checkpoint ``last.pt`` with
  the trainer's optimiser and generator states; at the end ``final.pt`` (weights only) too.

Interrupted, the same command resumes from ``last.pt`` (its method, architecture, seed and
demonstrations must match) and continues exactly as the uninterrupted run would have.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import torch

from ibc_tutorial.driving.dataset import DemoDataset
from ibc_tutorial.experiments.agents.agent import Agent, build_network
from ibc_tutorial.experiments.agents.checkpoints import load_checkpoint, save_checkpoint
from ibc_tutorial.experiments.agents.evaluate import EVAL_SEED, episode_rows, evaluate_agent, summarize
from ibc_tutorial.experiments.agents.presets import METHODS, Preset, get_preset
from ibc_tutorial.kde import inverse_density_weights
from ibc_tutorial.negatives import ExpertSampler, UniformSampler
from ibc_tutorial.objectives import info_nce_objective, likelihood_objective
from ibc_tutorial.training import Objective, TrainConfig, Trainer
from ibc_tutorial.utils import atomic_write_bytes, check_choice, check_int


@dataclass
class RunResult:
    """What ``train_agent`` returns."""

    out: Path
    """The run's folder."""
    metrics: list
    """One dict per evaluation (also the lines of ``metrics.jsonl``)."""
    agent: Agent
    """The trained agent."""
    seconds: float
    """Wall time of this call (a resumed run counts only what it did)."""


class DemoBatches:
    """A ``DemoDataset`` as ``training.Minibatches``: minibatches ``{"obs": {"bev", "state"}, "actions"}``."""

    def __init__(self, dataset: DemoDataset):
        self.dataset = dataset

    def __len__(self) -> int:
        return len(self.dataset)

    def batch(self, indices: torch.Tensor) -> dict:
        obs, actions = self.dataset.batch(indices)  # {"bev": (B, 5, S, S) uint8, "state": (B, 3)}, (B, 2)
        return {"obs": obs, "actions": actions}


def objective_for(method: str, network: torch.nn.Module, preset: Preset) -> Objective:
    """The training objective of a method (see the module docstring)."""
    check_choice("method", method, METHODS)
    if method == "bc":
        return likelihood_objective(network)  # eq. 1
    sampler = UniformSampler(-1.0, 1.0) if method == "ibc" else ExpertSampler(preset.neg_sigma)
    return info_nce_objective(network, sampler, preset.n_neg)  # eq. 2


def steps_per_epoch(n_samples: int, batch_size: int) -> int:
    """Minibatches in one epoch: ceil(M / batch_size)."""
    return max(1, math.ceil(n_samples / batch_size))


def _resume(last: Path, method: str, preset: Preset, seed: int, data_hash: str) -> dict:
    """The checked checkpoint of an interrupted run of this very method, preset, seed and data."""
    ckpt = load_checkpoint(last, method=method, preset=preset)
    if ckpt["data_sha256"] != data_hash:
        raise ValueError(f"{last} was trained on another data file (SHA-256 {ckpt['data_sha256'][:12]}..., "
                         f"this one {data_hash[:12]}...): use another --out")
    if {k: v for k, v in ckpt["preset"].items() if k != "epochs"} != {k: v for k, v in preset.to_dict().items() if k != "epochs"}:
        raise ValueError(f"{last} was trained with other settings (preset {ckpt['preset']['name']!r}): use another --out")
    if ckpt["metrics"] and ckpt["metrics"][0].get("seed") != seed:
        raise ValueError(f"{last} belongs to seed {ckpt['metrics'][0].get('seed')}, not {seed}: use another --out")
    return ckpt


def train_agent(method: str, data, preset: Preset, seed: int, out, *, dataset: DemoDataset | None = None,
                sample_probs: torch.Tensor | None = None, eval_town: str = "town02", show_progress: bool | None = None,
                log=print) -> RunResult:
    """Train one agent (see the module docstring); resumes from ``out/last.pt`` if present.

    Args:
        method: "bc", "ibc" or "da-ibc".
        data: path of the demonstration file (its content's SHA-256 goes into every checkpoint).
        preset: the settings.
        seed: seeds the network's initialisation, the minibatches, the counter-examples and the
            evaluation's DFO draws.
        out: the run's folder.
        dataset: an already rendered ``DemoDataset`` of ``data`` at ``preset.bev_size`` (saves
            rendering it again when several runs share it).
        sample_probs: the minibatch probabilities ``kde.inverse_density_weights(dataset.actions, h)``
            if already computed (they are also DA-IBC's DFO initial weights: both are w ∝ 1 / ĝ).
        log: where one line per evaluation goes (``None``: nowhere).
    """
    check_choice("method", method, METHODS)
    seed = check_int("seed", seed, minimum=0)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if dataset is None:
        dataset = DemoDataset(data, bev_size=preset.bev_size, cache=True)
    elif dataset.bev_size != preset.bev_size:
        raise ValueError(f"dataset must be rendered at bev_size {preset.bev_size}, got {dataset.bev_size}")
    data_hash = dataset.log.checksum()  # the demonstrations' content
    actions = dataset.actions  # (M, 2)
    if sample_probs is None:
        sample_probs = inverse_density_weights(actions, preset.kde_bandwidth)  # (M,) eqs. 4-5, by sampling

    last = out / "last.pt"
    ckpt = _resume(last, method, preset, seed, data_hash) if last.exists() else None
    torch.manual_seed(seed)  # the network's initial weights
    network = build_network(method, preset)
    agent = Agent(method, network, preset, actions, init_weights=sample_probs if method == "da-ibc" else None)
    n_steps = steps_per_epoch(len(dataset), preset.batch_size)
    epochs = max(preset.epochs, ckpt["epoch"] if ckpt else 0)
    config = TrainConfig(steps=epochs * n_steps, batch_size=preset.batch_size, lr=preset.lr, seed=seed,
                         log_every=preset.eval_every * n_steps, progress=show_progress, desc=f"{method} seed {seed}")
    trainer = Trainer(network, objective_for(method, network, preset), DemoBatches(dataset), config,
                      sample_probs=sample_probs)
    metrics: list = []
    if ckpt is not None:
        trainer.load_state_dict({"model": ckpt["model"], "optimizer": ckpt["optimizer"], "generator": ckpt["generator"],
                                 "step": ckpt["epoch"] * n_steps})
        metrics = list(ckpt["metrics"])
        if log:
            log(f"resuming {method} seed {seed} after epoch {ckpt['epoch']}")

    def evaluate_and_save(step: int, loss: float) -> None:
        te = time.perf_counter()
        rows = episode_rows(evaluate_agent(agent, eval_town, preset.eval_episodes, preset.eval_steps, seed=EVAL_SEED,
                                           policy_seed=seed, show_progress=False))
        entry = {"method": method, "seed": seed, "epoch": step // n_steps, "step": step, "loss": round(loss, 5),
                 "town": eval_town, "eval_steps": preset.eval_steps, "eval": summarize(rows), "episodes": rows,
                 "eval_seconds": round(time.perf_counter() - te, 1)}
        metrics.append(entry)
        state = trainer.state_dict()
        save_checkpoint(last, method=method, preset=preset, network=network, data_sha256=data_hash, epoch=entry["epoch"],
                        expert_actions=actions, init_weights=agent.init_weights, optimizer=state["optimizer"],
                        generator=state["generator"], metrics=metrics)
        atomic_write_bytes(out / "metrics.jsonl", "".join(json.dumps(m) + "\n" for m in metrics).encode())
        if log:
            log(f"{method} seed {seed} epoch {entry['epoch']}: loss {entry['loss']:.4f}, town02 score "
                f"{entry['eval']['score_mean']:.1f} ± {entry['eval']['score_std']:.1f}")

    if trainer.step < config.steps:
        trainer.run(callback=evaluate_and_save)
    network.eval()
    final_epoch = metrics[-1]["epoch"] if metrics else preset.epochs
    save_checkpoint(out / "final.pt", method=method, preset=preset, network=network, data_sha256=data_hash,
                    epoch=final_epoch, expert_actions=actions, init_weights=agent.init_weights, metrics=metrics)
    return RunResult(out, metrics, agent, time.perf_counter() - t0)


def read_metrics(path) -> list[dict]:
    """The lines of a run's ``metrics.jsonl`` (or of the file at ``path``)."""
    path = Path(path)
    if path.is_dir():
        path = path / "metrics.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def run(args: argparse.Namespace) -> int:
    """``ibc-tutorial train`` (arguments in ``ibc_tutorial.cli``): check the inputs, then train."""
    try:
        preset = get_preset(args.preset)
        if args.epochs is not None:
            preset = dataclasses.replace(preset, epochs=check_int("--epochs", args.epochs, minimum=1))
        check_int("--seed", args.seed, minimum=0)
        threads = check_int("--threads", args.threads, minimum=0)
        if not Path(args.data).is_file():
            raise ValueError(f"--data: no demonstration file at {args.data}")
        if threads:
            torch.set_num_threads(threads)
        result = train_agent(args.method, args.data, preset, args.seed, args.out)
    except ValueError as exc:
        raise SystemExit(f"ibc-tutorial train: {exc}") from None
    print(f"trained {args.method} (seed {args.seed}) in {result.seconds:.0f} s; checkpoints in {result.out}")
    return 0
