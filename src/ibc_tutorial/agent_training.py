"""Training a driving agent (BC, IBC or DA-IBC) on town01 demonstrations, evaluated in town02 as it learns.

    ibc-tutorial train --method da-ibc --data data/town01.npz --preset laptop --seed 0 --out runs/da-ibc/seed0

What one run does (the DA-IBC paper's secs. 2.4-2.5, 4.2 and Fig. 4, at the preset's scale):

- minibatches of ``batch_size`` drawn with the inverse-KDE probabilities of the expert actions
  (eq. 5 applied by sampling, sec. 2.5; ``kde.sampling_probs``), ``ceil(M / batch_size)`` of
  them per epoch;
- the loss: the Beta NLL (eq. 1) for bc; InfoNCE (eq. 2) with ``n_neg`` counter-examples,
  uniform over the action box for ibc, expert actions plus N(0, σ²I) for da-ibc;
- Adam with step size ``lr``;
- every ``eval_every`` epochs (and after the last), a closed-loop evaluation in town02:
  ``eval_episodes`` batched episodes of ``eval_steps`` steps, scored as the paper scores them;
- after each evaluation, one JSON line in ``metrics.jsonl`` and a checkpoint ``last.pt`` with
  the optimiser and generator states; at the end ``final.pt`` (weights only) too.

Interrupted, the same command resumes from ``last.pt`` (its method, architecture, seed and
data file must match) and continues exactly as the uninterrupted run would have, since the
minibatch generator's state is stored with it.

(``training.train``, the chapters' loop, restarts Adam at every call and keeps no state to resume
from, so the epochs, evaluations and checkpoints of a long run are driven here.)
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import torch

from ibc_tutorial import kde
from ibc_tutorial.agents import Agent, build_network
from ibc_tutorial.checkpoints import file_sha256, load_checkpoint, save_checkpoint
from ibc_tutorial.evaluation import EVAL_SEED, episode_rows, evaluate_agent, summarize
from ibc_tutorial.negatives import ExpertSampler, UniformSampler
from ibc_tutorial.presets import METHODS, Preset, get_preset
from ibc_tutorial.training import info_nce_objective
from ibc_tutorial.utils import atomic_write_bytes, check_choice, check_int, progress


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


def loss_function(method: str, network, preset: Preset):
    """``loss_fn(obs, actions, generator) -> scalar`` for a method (see the module docstring)."""
    check_choice("method", method, METHODS)
    if method == "bc":
        return lambda obs, actions, gen: network.loss(obs, actions)  # eq. 1
    sampler = UniformSampler(-1.0, 1.0) if method == "ibc" else ExpertSampler(preset.neg_sigma)
    objective = info_nce_objective(network, sampler, preset.n_neg)  # eq. 2
    return lambda obs, actions, gen: objective({"obs": obs, "actions": actions}, gen)


def steps_per_epoch(n_samples: int, batch_size: int) -> int:
    """Minibatches in one epoch: ceil(M / batch_size)."""
    return max(1, math.ceil(n_samples / batch_size))


def train_agent(method: str, data, preset: Preset, seed: int, out, *, dataset=None, sample_probs=None, eval_town: str = "town02",
                show_progress: bool | None = None, log=print) -> RunResult:
    """Train one agent (see the module docstring); resumes from ``out/last.pt`` if present.

    Args:
        method: "bc", "ibc" or "da-ibc".
        data: path of the demonstration file (its SHA-256 goes into every checkpoint).
        preset: the settings.
        seed: seeds the network's initialisation, the minibatches, the counter-examples and the
            evaluation's DFO draws.
        out: the run's folder.
        dataset: an already rendered ``DemoDataset`` of ``data`` at ``preset.bev_size`` (saves
            rendering it again when several runs share it).
        sample_probs: the minibatch probabilities ``kde.sampling_probs(dataset.actions, h)`` if
            already computed (they are also DA-IBC's DFO initial weights: both are w ∝ 1 / ĝ).
        log: where one line per evaluation goes (``None``: nowhere).
    """
    from ibc_tutorial.driving.dataset import DemoDataset

    check_choice("method", method, METHODS)
    seed = check_int("seed", seed, minimum=0)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    data_hash = file_sha256(data)
    if dataset is None:
        dataset = DemoDataset(data, bev_size=preset.bev_size, cache=True)
    elif dataset.bev_size != preset.bev_size:
        raise ValueError(f"dataset must be rendered at bev_size {preset.bev_size}, got {dataset.bev_size}")
    actions = dataset.actions  # (M, 2)
    if sample_probs is None:
        sample_probs = kde.sampling_probs(actions, preset.kde_bandwidth, "inverse-kde")  # (M,) eqs. 4-5, by sampling
    probs = sample_probs

    torch.manual_seed(seed)  # the network's initial weights
    network = build_network(method, preset)
    optimizer = torch.optim.Adam(network.parameters(), lr=preset.lr)
    gen = torch.Generator().manual_seed(seed)
    agent = Agent(method, network, preset, actions, init_weights=probs if method == "da-ibc" else None)
    metrics: list = []
    start_epoch = 1
    last = out / "last.pt"
    if last.exists():
        ckpt = load_checkpoint(last, method=method, preset=preset)
        if ckpt["data_sha256"] != data_hash:
            raise ValueError(f"{last} was trained on another data file (SHA-256 {ckpt['data_sha256'][:12]}..., "
                             f"this one {data_hash[:12]}...): use another --out")
        if {k: v for k, v in ckpt["preset"].items() if k != "epochs"} != {k: v for k, v in preset.to_dict().items() if k != "epochs"}:
            raise ValueError(f"{last} was trained with other settings (preset {ckpt['preset']['name']!r}): use another --out")
        network.load_state_dict(ckpt["model"])
        optimizer.load_state_dict(ckpt["optimizer"])
        gen.set_state(ckpt["generator"])
        metrics = list(ckpt["metrics"])
        start_epoch = ckpt["epoch"] + 1
        if metrics and metrics[0].get("seed") != seed:
            raise ValueError(f"{last} belongs to seed {metrics[0].get('seed')}, not {seed}: use another --out")
        if log:
            log(f"resuming {method} seed {seed} after epoch {ckpt['epoch']}")
    loss_fn = loss_function(method, network, preset)
    n_steps = steps_per_epoch(len(dataset), preset.batch_size)
    bar = progress(total=(preset.epochs - start_epoch + 1) * n_steps, desc=f"{method} seed {seed}", enabled=show_progress)
    running, count = 0.0, 0
    for epoch in range(start_epoch, preset.epochs + 1):
        network.train()
        for _ in range(n_steps):
            idx = torch.multinomial(probs, preset.batch_size, replacement=True, generator=gen)  # (B,) KDE-weighted
            obs, act = dataset.batch(idx)  # {"bev": (B, 5, S, S) uint8, "state": (B, 3)}, (B, 2)
            loss = loss_fn(obs, act, gen)
            if not torch.isfinite(loss):
                raise FloatingPointError(f"{method} seed {seed}: the loss became {float(loss)} in epoch {epoch}")
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            running += float(loss.detach())
            count += 1
            bar.update(1)
        if epoch % preset.eval_every == 0 or epoch == preset.epochs:
            network.eval()
            te = time.perf_counter()
            results = evaluate_agent(agent, eval_town, preset.eval_episodes, preset.eval_steps, seed=EVAL_SEED,
                                     policy_seed=seed, show_progress=False)
            rows = episode_rows(results)
            entry = {"method": method, "seed": seed, "epoch": epoch, "step": epoch * n_steps,
                     "loss": round(running / max(count, 1), 5), "town": eval_town,
                     "eval_steps": preset.eval_steps, "eval": summarize(rows), "episodes": rows,
                     "eval_seconds": round(time.perf_counter() - te, 1)}
            metrics.append(entry)
            running, count = 0.0, 0
            save_checkpoint(last, method=method, preset=preset, network=network, data_sha256=data_hash, epoch=epoch,
                            expert_actions=actions, init_weights=agent.init_weights, optimizer=optimizer,
                            generator=gen, metrics=metrics)
            atomic_write_bytes(out / "metrics.jsonl", "".join(json.dumps(m) + "\n" for m in metrics).encode())
            if log:
                log(f"{method} seed {seed} epoch {epoch}: loss {entry['loss']:.4f}, town02 score "
                    f"{entry['eval']['score_mean']:.1f} ± {entry['eval']['score_std']:.1f}")
    bar.close()
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


# ---------------------------------------------------------------------- command line
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--method", required=True, choices=METHODS, help="bc (Beta), ibc or da-ibc")
    parser.add_argument("--data", required=True, help="demonstrations written by 'ibc-tutorial collect'")
    parser.add_argument("--preset", default="laptop", help="paper, laptop or tiny (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="training seed (default: %(default)s)")
    parser.add_argument("--out", required=True, help="folder for the checkpoints and metrics.jsonl")
    parser.add_argument("--epochs", type=int, default=None, help="override the preset's number of epochs")
    parser.add_argument("--threads", type=int, default=0,
                        help="torch CPU threads (default 0: torch's choice; 1 is fastest on a busy machine)")


def run(args: argparse.Namespace) -> int:
    try:
        preset = get_preset(args.preset)
        if args.epochs is not None:
            preset = preset.with_(epochs=check_int("--epochs", args.epochs, minimum=1))
        check_int("--seed", args.seed, minimum=0)
        if check_int("--threads", args.threads, minimum=0):
            torch.set_num_threads(args.threads)
        if not Path(args.data).is_file():
            raise ValueError(f"--data: no demonstration file at {args.data}")
        result = train_agent(args.method, args.data, preset, args.seed, args.out)
    except ValueError as exc:
        raise SystemExit(f"ibc-tutorial train: {exc}") from None
    print(f"trained {args.method} (seed {args.seed}) in {result.seconds:.0f} s; checkpoints in {result.out}")
    return 0
