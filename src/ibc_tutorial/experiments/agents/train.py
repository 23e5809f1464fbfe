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

On a GPU (``--device cuda``): the network and each minibatch are on the device; the minibatch
indices, the counter-examples and the evaluations' DFO draws are still drawn with the run's seeded
CPU generators and then moved, so a CPU run is unchanged by the option and a GPU run draws the same
numbers (its arithmetic, hence its results, differ in the last bits). Checkpoints are written from
CPU copies and read back onto the CPU first: a run trained on a GPU resumes or evaluates anywhere.

Interrupted, the same command resumes from ``last.pt`` and continues exactly as the
uninterrupted run would have. A run's folder records what it is (``run.json``: method, seed,
preset, the demonstrations' checksum), and ``inspect_run`` compares it with a request before any
work: a folder holding another run (another method, seed, setting or data) is refused, a
finished run is never overwritten (``--force`` starts over), and a run already trained beyond
``--epochs`` is refused rather than returned as if trained.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import hashlib
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import torch

from ibc_tutorial.cli import UserError, check_input_file, check_output_dir
from ibc_tutorial.driving.dataset import DemoDataset, DemoLog
from ibc_tutorial.experiments.agents.agent import Agent, build_network
from ibc_tutorial.experiments.agents.checkpoints import load_agent, load_checkpoint, save_checkpoint
from ibc_tutorial.experiments.agents.evaluate import EVAL_SEED, episode_rows, evaluate_agent, summarize
from ibc_tutorial.experiments.agents.presets import METHODS, Preset, get_preset
from ibc_tutorial.kde import inverse_density_weights
from ibc_tutorial.negatives import ExpertSampler, UniformSampler
from ibc_tutorial.objectives import info_nce_objective, likelihood_objective
from ibc_tutorial.training import Objective, TrainConfig, Trainer
from ibc_tutorial.utils import atomic_write_bytes, check_choice, check_device, check_int


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
    resumed_from: int = 0
    """The epoch the run was resumed after (0: trained from the start)."""
    already_done: bool = False
    """True when the folder held this run finished already: nothing was trained or written."""


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


def _read_json(path: Path, what_to_do: str):
    try:
        return json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path} is damaged, not JSON ({type(exc).__name__}): {what_to_do}") from None


def _identity(out: Path) -> tuple[dict, int, str]:
    """The stored run's (identity, epochs trained, file it was read from), from the best source in the folder."""
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
        ev = _read_json(out / "final_eval.json", fix)
        if not isinstance(ev, dict) or not isinstance(ev.get("episodes"), list) or "summary" not in ev:
            raise ValueError(f"{out / 'final_eval.json'} is damaged (not a final evaluation): {fix}")
        ident = ident or {"method": ev.get("method"), "seed": ev.get("seed")}
        source = source or str(out / "final_eval.json")
    if (out / RUN_INFO).exists():
        info = _read_json(out / RUN_INFO, fix)
        if not isinstance(info, dict) or not {"method", "seed", "preset", "data_sha256"} <= set(info):
            raise ValueError(f"{out / RUN_INFO} is damaged (not a run description): {fix}")
        ident, source = info, str(out / RUN_INFO)
    return ident, epoch, source


def inspect_run(
    out, method: str, preset: Preset, seed: int, data_sha256: str | None, data_file=None
) -> RunState:
    """Compare what ``out`` holds with a request to train ``method`` / ``seed`` / ``preset`` on data of checksum
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
            {k: v for k, v in ident["preset"].items() if k != "epochs"}
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


class DemoBatches:
    """A ``DemoDataset`` as ``training.Minibatches``: minibatches ``{"obs": {"bev", "state"}, "actions"}``,
    rendered on the CPU and moved to ``device`` (the CPU by default)."""

    def __init__(self, dataset: DemoDataset, device: torch.device | str = "cpu"):
        self.dataset = dataset
        self.device = check_device("device", device)

    def __len__(self) -> int:
        return len(self.dataset)

    def batch(self, indices: torch.Tensor) -> dict:
        obs, actions = self.dataset.batch(indices)  # {"bev": (B, 5, S, S) uint8, "state": (B, 3)}, (B, 2)
        obs = {k: v.to(self.device) for k, v in obs.items()}
        return {"obs": obs, "actions": actions.to(self.device)}


def _cpu(obj):
    """``obj`` (tensors in dicts, lists, tuples) with every tensor on the CPU: what a checkpoint stores."""
    if isinstance(obj, torch.Tensor):
        return obj.cpu()
    if isinstance(obj, dict):
        return {k: _cpu(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(_cpu(v) for v in obj)
    return obj


def _cpu_network(network: torch.nn.Module) -> torch.nn.Module:
    """``network`` itself if it is on the CPU, else a CPU copy (``save_checkpoint`` stores its state dict)."""
    if all(p.device.type == "cpu" for p in network.parameters()):
        return network
    return copy.deepcopy(network).cpu()


def objective_for(method: str, network: torch.nn.Module, preset: Preset) -> Objective:
    """The training objective of a method (see the module docstring)."""
    check_choice("method", method, METHODS)
    if method == "bc":
        return likelihood_objective(network)  # eq. 1
    sampler = UniformSampler(-1.0, 1.0) if method == "ibc" else ExpertSampler(preset.neg_sigma)
    return info_nce_objective(network, sampler, preset.n_neg)  # eq. 2


@torch.no_grad()
def round_to_half(network: torch.nn.Module) -> None:
    """Round every floating-point weight to the nearest float16 value, in place (kept as float32).

    A final checkpoint stores its weights in float16 (half the file: every agent of a replication
    can then be shipped); rounding before the final evaluation makes the evaluated agent exactly
    the shipped one, so ``ibc-tutorial evaluate`` on ``final.pt`` reproduces ``final_eval.json``.
    """
    for value in network.state_dict().values():
        if value.is_floating_point():
            value.copy_(value.half().float())


def steps_per_epoch(n_samples: int, batch_size: int) -> int:
    """Minibatches in one epoch: ceil(M / batch_size)."""
    return max(1, math.ceil(n_samples / batch_size))


def train_agent(
    method: str,
    data,
    preset: Preset,
    seed: int,
    out,
    *,
    dataset: DemoDataset | None = None,
    sample_probs: torch.Tensor | None = None,
    eval_town: str = "town02",
    show_progress: bool | None = None,
    log=print,
    force: bool = False,
    device: torch.device | str = "cpu",
) -> RunResult:
    """Train one agent (see the module docstring); resumes from ``out/last.pt`` if present.

    A folder holding another run, or this run trained beyond ``preset.epochs``, is refused with a
    ValueError (``inspect_run``); a folder holding this run finished returns it, training nothing.

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
        force: delete the run already in ``out`` (``RUN_FILES``) and start over.
        device: where the network trains and acts ("cpu", "cuda", "cuda:1", "mps"; see the module
            docstring); the returned agent is on it.
    """
    check_choice("method", method, METHODS)
    seed = check_int("seed", seed, minimum=0)
    device = check_device("device", device)
    out = Path(out)
    t0 = time.perf_counter()
    if dataset is not None and dataset.renderer.light_encoding != preset.light_encoding:
        raise ValueError(
            f"dataset must draw the lights as {preset.light_encoding!r}, got "
            f"{dataset.renderer.light_encoding!r}"
        )
    if dataset is not None and dataset.bev_size != preset.bev_size:
        raise ValueError(f"dataset must be rendered at bev_size {preset.bev_size}, got {dataset.bev_size}")
    log_ = dataset.log if dataset is not None else data if isinstance(data, DemoLog) else DemoLog.load(data)
    data_hash = log_.checksum()  # the demonstrations' content
    data_file = None if isinstance(data, DemoLog) else data
    if force:
        clear_run(out)
    state = inspect_run(out, method, preset, seed, data_hash, data_file)
    if state.status == "done":
        if not (out / "final.pt").exists():
            raise ValueError(
                f"{out} holds this run finished, without its final.pt (not kept): nothing to load; "
                "--force to train it again"
            )
        agent, ckpt = load_agent(out / "final.pt", method=method, preset=preset)
        agent.to(device)
        if log:
            log(f"{method} seed {seed}: already trained to epoch {state.epoch} in {out}; nothing to do")
        return RunResult(out, list(ckpt["metrics"]), agent, 0.0, state.epoch, already_done=True)
    out.mkdir(parents=True, exist_ok=True)
    if not (out / RUN_INFO).exists():
        atomic_write_bytes(
            out / RUN_INFO,
            json.dumps(
                {"method": method, "seed": seed, "preset": preset.to_dict(), "data_sha256": data_hash},
                indent=1,
            ).encode(),
        )
    if dataset is None:
        dataset = DemoDataset(
            log_, bev_size=preset.bev_size, cache=True, light_encoding=preset.light_encoding
        )
    actions = dataset.actions  # (M, 2)
    if sample_probs is None:
        sample_probs = inverse_density_weights(actions, preset.kde_bandwidth)  # (M,) eqs. 4-5, by sampling

    last = out / "last.pt"
    ckpt = (
        load_checkpoint(last, method=method, preset=preset, resumable=True)
        if state.status == "resume"
        else None
    )
    torch.manual_seed(seed)  # the network's initial weights (drawn on the CPU, whatever the device)
    network = build_network(method, preset).to(device)
    agent = Agent(method, network, preset, actions, init_weights=sample_probs if method == "da-ibc" else None)
    agent.to(device)
    n_steps = steps_per_epoch(len(dataset), preset.batch_size)
    epochs = preset.epochs  # inspect_run refused a run already beyond it
    config = TrainConfig(
        steps=epochs * n_steps,
        batch_size=preset.batch_size,
        lr=preset.lr,
        lr_schedule=preset.lr_schedule,
        seed=seed,
        log_every=preset.eval_every * n_steps,
        progress=show_progress,
        desc=f"{method} seed {seed}",
    )
    trainer = Trainer(
        network,
        objective_for(method, network, preset),
        DemoBatches(dataset, device),
        config,
        sample_probs=sample_probs,
    )  # minibatch indices drawn on the CPU, with sample_probs (M,)
    metrics: list = []
    if ckpt is not None:
        trainer.load_state_dict(
            {
                "model": ckpt["model"],
                "optimizer": ckpt["optimizer"],
                "generator": ckpt["generator"],
                "step": ckpt["epoch"] * n_steps,
            }
        )
        metrics = list(ckpt["metrics"])
        if log:
            log(f"resuming {method} seed {seed} after epoch {ckpt['epoch']}")

    def evaluate_and_save(step: int, loss: float) -> None:
        te = time.perf_counter()
        rows = episode_rows(
            evaluate_agent(
                agent,
                eval_town,
                preset.eval_episodes,
                preset.eval_steps,
                seed=EVAL_SEED,
                policy_seed=seed,
                show_progress=False,
            )
        )
        entry = {
            "method": method,
            "seed": seed,
            "epoch": step // n_steps,
            "step": step,
            "loss": round(loss, 5),
            "town": eval_town,
            "eval_steps": preset.eval_steps,
            "eval": summarize(rows),
            "episodes": rows,
            "eval_seconds": round(time.perf_counter() - te, 1),
        }
        metrics.append(entry)
        state = trainer.state_dict()
        save_checkpoint(
            last,
            method=method,
            preset=preset,
            network=_cpu_network(network),
            data_sha256=data_hash,
            epoch=entry["epoch"],
            expert_actions=actions,
            init_weights=agent.init_weights,
            optimizer=_cpu(state["optimizer"]),
            generator=state["generator"],
            metrics=metrics,
            seed=seed,
        )
        atomic_write_bytes(out / "metrics.jsonl", "".join(json.dumps(m) + "\n" for m in metrics).encode())
        if log:
            log(
                f"{method} seed {seed} epoch {entry['epoch']}: loss {entry['loss']:.4f}, town02 score "
                f"{entry['eval']['score_mean']:.1f} ± {entry['eval']['score_std']:.1f}"
            )

    if trainer.step < config.steps:
        trainer.run(callback=evaluate_and_save)
    network.eval()
    round_to_half(network)  # the agent evaluated is the one final.pt ships (weights in float16)
    final_epoch = metrics[-1]["epoch"] if metrics else preset.epochs
    save_checkpoint(
        out / "final.pt",
        method=method,
        preset=preset,
        network=_cpu_network(network),
        data_sha256=data_hash,
        epoch=final_epoch,
        expert_actions=actions,
        init_weights=agent.init_weights,
        metrics=metrics,
        seed=seed,
        half=True,
    )
    return RunResult(out, metrics, agent, time.perf_counter() - t0, ckpt["epoch"] if ckpt else 0)


METRIC_KEYS = ("method", "seed", "epoch", "loss", "eval")
"""What every line of ``metrics.jsonl`` holds (at least)."""


def read_metrics(path) -> list[dict]:
    """The lines of a run's ``metrics.jsonl`` (or of the file at ``path``), checked: ValueError naming the file."""
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


def run(args: argparse.Namespace) -> int:
    """``ibc-tutorial train`` (arguments in ``ibc_tutorial.cli``): check the inputs, the data and the folder, then
    train. Errors are raised for ``cli.main`` to print on one line."""
    preset = get_preset(args.preset)
    if args.epochs is not None:
        preset = dataclasses.replace(preset, epochs=check_int("--epochs", args.epochs, minimum=1))
    seed = check_int("--seed", args.seed, minimum=0)
    threads = check_int("--threads", args.threads, minimum=0)
    device = check_device("--device", getattr(args, "device", "cpu"))
    force = bool(getattr(args, "force", False))
    demo = DemoLog.load(check_input_file("--data", args.data, "demonstration file (.npz)"))
    out = check_output_dir("--out", args.out)
    if not force:
        state = inspect_run(out, args.method, preset, seed, demo.checksum(), args.data)
        if state.status == "done":
            print(
                f"{out} holds this run trained to epoch {state.epoch} already: nothing to do "
                "(--epochs N to train on, --force to start over)"
            )
            return 0
    if threads:
        torch.set_num_threads(threads)
    result = train_agent(args.method, args.data, preset, seed, out, force=force, device=device)
    if not result.metrics or result.metrics[-1]["epoch"] != preset.epochs:
        raise UserError(
            f"{out}: the run ended at epoch {result.metrics[-1]['epoch'] if result.metrics else 0}, "
            f"not {preset.epochs}"
        )
    again = f" (resumed after epoch {result.resumed_from})" if result.resumed_from else ""
    print(
        f"trained {args.method} (seed {seed}) to epoch {preset.epochs}{again} in {result.seconds:.0f} s; "
        f"checkpoints in {result.out}"
    )
    return 0
