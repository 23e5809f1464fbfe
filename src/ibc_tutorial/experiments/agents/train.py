"""Training a driving agent (BC, IBC, DA-IBC, flow or DA-IBC with ranking NCE) on town01 demonstrations,
evaluated in town02 as it learns.

    ibc-tutorial train --method da-ibc --data data/town01.npz --preset laptop --seed 0 --out runs/da-ibc/seed0

What one run does (the DA-IBC paper's secs. 2.4-2.5, 4.2 and Fig. 4, at the preset's scale), on
top of the book's one loop, ``training.Trainer``:

- minibatches of ``batch_size`` drawn with the inverse-KDE probabilities of the expert actions
  (eq. 5 applied by sampling, sec. 2.5; ``kde.inverse_density_weights``), ``ceil(M / batch_size)``
  of them per epoch;
- the objective: the Beta NLL (eq. 1) for bc; InfoNCE (eq. 2) with ``n_neg`` counter-examples,
  uniform over the action box for ibc, expert actions plus N(0, σ²I) for da-ibc; for da-ibc-rnce the
  same counter-examples in ranking NCE (``losses.ranking_nce``: the logits minus log q, q the expert
  sampler's exact Gaussian-mixture density, ``ExpertSampler.log_prob``); for flow the conditional
  flow-matching loss (``objectives.flow_matching_objective``; Lipman et al. 2023, eq. 23);
- Adam with step size ``lr``;
- every ``eval_every`` epochs (and after the last), a closed-loop evaluation in town02, one JSON
  line in ``metrics.jsonl`` and a checkpoint ``last.pt``; at the end ``final.pt`` (weights only).
  What happens beside the learning is ``training_run``'s; this module is the learning.

On a GPU (``--device cuda``): the network and each minibatch are on the device; the minibatch
indices, the counter-examples and the evaluations' DFO draws are still drawn with the run's seeded
CPU generators and then moved, so a CPU run is unchanged by the option and a GPU run draws the same
numbers (its arithmetic, hence its results, differ in the last bits). Checkpoints are written from
CPU copies and read back onto the CPU first: a run trained on a GPU resumes or evaluates anywhere.

Interrupted, the same command resumes from ``last.pt`` and continues exactly as the
uninterrupted run would have. A folder holding another run is refused before any work
(``training_run.inspect_run``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import torch

from ibc_tutorial.driving.dataset import DemoDataset
from ibc_tutorial.experiments.agents.agent import Agent, build_network
from ibc_tutorial.experiments.agents.presets import ALL_METHODS, DA_IBC_METHODS, Preset
from ibc_tutorial.experiments.agents.training_run import (
    RunBook,
    TrainingData,
    clear_run,
    finished_run,
    inspect_run,
    open_run,
    read_metrics,
)
from ibc_tutorial.negatives import ExpertSampler, NegativeSampler, UniformSampler
from ibc_tutorial.objectives import flow_matching_objective, info_nce_objective, likelihood_objective
from ibc_tutorial.training import Objective, Trainer
from ibc_tutorial.utils import check_choice, check_device, check_int

__all__ = [
    "DemoBatches",
    "RunResult",
    "TrainingData",
    "clear_run",
    "counter_examples",
    "inspect_run",
    "objective_for",
    "read_metrics",
    "round_to_half",
    "steps_per_epoch",
    "train_agent",
]


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


def counter_examples(method: str, preset: Preset) -> NegativeSampler | None:
    """The counter-example sampler of a method: uniform for IBC, expert + noise for DA-IBC (and DA-IBC with
    ranking NCE), None for BC and flow."""
    check_choice("method", method, ALL_METHODS)
    if method in ("bc", "flow"):
        return None
    return UniformSampler(-1.0, 1.0) if method == "ibc" else ExpertSampler(preset.neg_sigma)


def objective_for(method: str, network: torch.nn.Module, preset: Preset) -> Objective:
    """The training objective of a method (see the module docstring): ``train_agent``'s, and that of code
    that trains outside it (tests, benchmarks)."""
    sampler = counter_examples(method, preset)
    if method == "flow":
        return flow_matching_objective(network)  # Lipman et al. 2023, eq. 23 (σ_min = 0)
    if sampler is None:
        return likelihood_objective(network)  # eq. 1
    ranking = method == "da-ibc-rnce"  # logits − log q(ỹ) of the expert sampler (Ma & Collins 2018)
    return info_nce_objective(network, sampler, preset.n_neg, ranking=ranking)  # eq. 2, or its ranking form


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
    show_progress: bool | None = None,
    log=print,
    device: torch.device | str = "cpu",
) -> RunResult:
    """Train one agent (see the module docstring); resumes from ``out/last.pt`` if present.

    A folder holding another run, or this run trained beyond ``preset.epochs``, is refused with a
    ValueError (``training_run.inspect_run``; ``training_run.clear_run`` starts over); a folder holding this
    run finished returns it, training nothing.

    Args:
        method: "bc", "ibc", "da-ibc", "flow" or "da-ibc-rnce".
        data: the demonstrations (their content's SHA-256 goes into every checkpoint): a file, a ``DemoLog``,
            or already rendered at the preset's BEV, a ``DemoDataset`` or a ``TrainingData`` (with its
            minibatch probabilities: saves making them again when several runs share them).
        preset: the settings.
        seed: seeds the network's initialisation, the minibatches, the counter-examples and the
            evaluations' DFO draws.
        out: the run's folder.
        show_progress: a progress bar (None: tqdm's choice; ``TQDM_DISABLE=1`` silences it).
        log: where one line per evaluation goes (``None``: nowhere).
        device: where the network trains and acts ("cpu", "cuda", "cuda:1", "mps"; see the module
            docstring); the returned agent is on it.
    """
    check_choice("method", method, ALL_METHODS)
    seed = check_int("seed", seed, minimum=0)
    device = check_device("device", device)
    out, t0 = Path(out), time.perf_counter()
    run = open_run(method, data, preset, seed, out)  # the folder checked, run.json written
    if run.status == "done":
        agent, metrics = finished_run(out, method, preset, device)
        if log:
            log(f"{method} seed {seed}: already trained to epoch {run.epoch} in {out}; nothing to do")
        return RunResult(out, metrics, agent, 0.0, run.epoch, already_done=True)

    torch.manual_seed(seed)  # the network's initial weights (drawn on the CPU, whatever the device)
    network = build_network(method, preset).to(device)
    probs = run.data.sample_probs  # (M,) w ∝ 1 / ĝ: eqs. 4-5 applied by sampling, and DA-IBC's DFO start
    agent = Agent(
        method, network, preset, run.data.dataset.actions, probs if method in DA_IBC_METHODS else None
    )
    agent.to(device)
    n_steps = steps_per_epoch(len(run.data.dataset), preset.batch_size)
    config = preset.train_config(n_steps, seed, progress=show_progress, desc=f"{method} seed {seed}")
    batches = DemoBatches(run.data.dataset, device)  # minibatch indices drawn on the CPU, with probs (M,)
    objective = objective_for(method, network, preset)  # eq. 1 of the DA-IBC paper (BC), eq. 2, R-NCE or CFM
    trainer = Trainer(network, objective, batches, config, sample_probs=probs)
    book = RunBook(out, agent, seed, run.data_sha256, log)
    if run.status == "resume":
        book.resume(trainer, n_steps)
    if trainer.step < config.steps:
        trainer.run(callback=book.after_epochs(trainer, n_steps))  # evaluations and checkpoints
    network.eval()
    round_to_half(network)  # the agent evaluated is the one final.pt ships (weights in float16)
    book.save_final()
    return RunResult(out, book.metrics, agent, time.perf_counter() - t0, book.resumed_from)
