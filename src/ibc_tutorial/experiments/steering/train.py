"""One run of the road-following study: train one model with one seed, then evaluate it.

A run's folder ``runs/<model>/seed<k>/`` holds ``last.pt`` while training (every
``CHECKPOINT_EVERY`` steps: the network, Adam's state, the minibatch generator, the losses so
far), then ``eval.json`` (the per-route metrics and the loss curve; written last, so a run with
it is finished) and ``trace.npz`` (the model's outputs along the Fig. 5 window), and, for the
first seed, ``final.pt`` (the weights). Checkpoints are plain dicts of tensors and numbers,
written atomically and read with ``torch.load(..., weights_only=True)``; a checkpoint of another
model, preset or dataset is refused. An interrupted run resumes from ``last.pt`` bit for bit.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ibc_tutorial import __version__
from ibc_tutorial.driving.dataset import DemoDataset
from ibc_tutorial.experiments.runs import read_run_file, read_torch_file, run_dir, write_json, write_npz
from ibc_tutorial.experiments.steering.evaluate import (
    Reference,
    drive_route,
    expert_whiteness,
    summarize_run_routes,
)
from ibc_tutorial.experiments.steering.models import (
    MODELS,
    SteeringModel,
    build_network,
    objective_for,
    uses_pairs,
)
from ibc_tutorial.experiments.steering.presets import SteeringPreset
from ibc_tutorial.experiments.steering.task import SteeringBatches
from ibc_tutorial.training import Trainer
from ibc_tutorial.utils import atomic_torch_save, check_choice, check_int

FORMAT = "ibc_tutorial.steering_model"
"""The ``format`` entry of every checkpoint of this study."""
CHECKPOINT_EVERY = 250
"""Steps between two ``last.pt`` (and between two points of the loss curve)."""
EVAL = "eval.json"
"""A finished run's results."""
TRACE = "trace.npz"
"""A finished run's outputs along the Fig. 5 window."""


def save_model_checkpoint(
    path,
    *,
    model: str,
    preset: SteeringPreset,
    data_sha256: str,
    trainer: Trainer | None,
    network: torch.nn.Module,
    losses: list,
) -> Path:
    """Write a checkpoint (``trainer``'s states for resuming, or None for the final weights) atomically."""
    ckpt = {
        "format": FORMAT,
        "package_version": __version__,
        "model": model,
        "preset": preset.to_dict(),
        "data_sha256": data_sha256,
        "losses": [list(map(float, x)) for x in losses],
        "weights": {k: v.detach().clone() for k, v in network.state_dict().items()},
    }
    if trainer is not None:
        state = trainer.state_dict()
        ckpt.update(
            step=state["step"],
            optimizer=state["optimizer"],
            generator=state["generator"],
            running_loss=state["running_loss"],
            running_count=state["running_count"],
        )
    return atomic_torch_save(ckpt, path)


def load_model_checkpoint(
    path, *, model: str, preset: SteeringPreset, data_sha256: str | None = None
) -> dict:
    """Read a checkpoint with ``weights_only=True`` and check that it is of ``model``, ``preset`` and the
    data."""
    path = Path(path)
    ckpt = read_torch_file(path, "checkpoint of the road-following study", "delete it and re-run")
    if not isinstance(ckpt, dict) or ckpt.get("format") != FORMAT:
        raise ValueError(f"{path} is not a checkpoint of the road-following study: delete it and re-run")
    if ckpt.get("model") != model or ckpt.get("preset") != preset.to_dict():
        raise ValueError(
            f"{path} holds model {ckpt.get('model')!r} of other settings, not {model!r} of preset "
            f"{preset.name!r}: delete it and re-run"
        )
    if data_sha256 is not None and ckpt.get("data_sha256") != data_sha256:
        raise ValueError(f"{path} was trained on other demonstrations: delete it and re-run")
    if not isinstance(ckpt.get("weights"), dict):
        raise ValueError(f"{path} is damaged (no weights): delete it and re-run")
    return ckpt


def load_model(path, model: str, preset: SteeringPreset) -> SteeringModel:
    """A ``SteeringModel`` from a run's ``final.pt`` (or ``last.pt``)."""
    ckpt = load_model_checkpoint(path, model=model, preset=preset)
    net = build_network(model, preset)
    try:
        net.load_state_dict(ckpt["weights"], strict=True)
    except RuntimeError as exc:
        raise ValueError(
            f"{path}: its weights do not fit model {model!r} ({str(exc).splitlines()[0]})"
        ) from None
    return SteeringModel(model, net, preset)


def train_model(
    model: str, seed: int, dataset: DemoDataset, preset: SteeringPreset, out, *, data_sha256: str
) -> tuple[SteeringModel, list, float, int]:
    """Train (or resume) one model in ``out``; returns (model, loss curve [[step, loss]], seconds, resumed
    step)."""
    check_choice("model", model, MODELS)
    seed = check_int("seed", seed, minimum=0)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    torch.manual_seed(seed)  # the network's initial weights
    network = build_network(model, preset)
    data = SteeringBatches(dataset, pairs=uses_pairs(model))
    config = preset.train_config(
        seed, log_every=CHECKPOINT_EVERY, progress=False, desc=f"{model} seed {seed}"
    )
    trainer = Trainer(network, objective_for(model, network, preset), data, config)
    losses: list = []
    resumed = 0
    last = out / "last.pt"
    if last.exists():
        ck = load_model_checkpoint(last, model=model, preset=preset, data_sha256=data_sha256)
        trainer.load_state_dict(
            {
                "model": ck["weights"],
                "optimizer": ck["optimizer"],
                "generator": ck["generator"],
                "step": ck["step"],
                "running_loss": ck["running_loss"],
                "running_count": ck["running_count"],
            }
        )
        losses, resumed = ck["losses"], int(ck["step"])

    def checkpoint(step: int, loss: float) -> None:
        losses.append([step, round(loss, 6)])
        save_model_checkpoint(
            last,
            model=model,
            preset=preset,
            data_sha256=data_sha256,
            trainer=trainer,
            network=network,
            losses=losses,
        )

    if trainer.step < config.steps:
        trainer.run(callback=checkpoint)
    network.eval()
    return SteeringModel(model, network, preset), losses, time.perf_counter() - t0, resumed


def evaluate_model(steering: SteeringModel, references: list[Reference], preset: SteeringPreset) -> dict:
    """Drive every reference route (``evaluate.drive_route``); per-route rows and their pooled summary."""

    def policy(obs):
        return float(steering.steer(obs)[0])

    routes = []
    for ref in references:
        r = drive_route(policy, ref, preset)
        r.pop("steer")
        r.pop("pass_offsets")  # the sweep keeps these traces (``sweep``); this study its peaks
        r["expert_w_cmd"] = round(expert_whiteness(ref), 5)
        routes.append(r)
    return {"routes": routes, "summary": summarize_run_routes(routes)}


@dataclass
class StudyInputs:
    """What every run of a study shares (made once per process): the data, the routes, the Fig. 5 window."""

    dataset: DemoDataset
    """The rendered demonstrations."""
    data_sha256: str
    """Their content checksum (``DemoLog.checksum``), stored in every checkpoint."""
    references: list[Reference]
    """The expert's drives of the evaluation routes."""
    window_obs: dict | None
    """The observations of the Fig. 5 window (None: no trace)."""


def run_one(
    model: str, seed: int, out, preset: SteeringPreset, inputs: StudyInputs, keep_final: bool
) -> dict:
    """Train, evaluate, trace; write the run's files (``eval.json`` last) and return its ``eval.json``."""
    d = run_dir(out, model, seed)
    dataset, data_sha256, window_obs = inputs.dataset, inputs.data_sha256, inputs.window_obs
    steering, losses, seconds, resumed = train_model(model, seed, dataset, preset, d, data_sha256=data_sha256)
    te = time.perf_counter()
    ev = evaluate_model(steering, inputs.references, preset)
    arrays = {}
    if window_obs is not None:
        arrays["steer"] = steering.steer(window_obs).numpy().astype(np.float32)  # (T,)
        scores = steering.scores(window_obs)
        if scores is not None:
            arrays["scores"] = scores.numpy().astype(np.float32)  # (T, G)
    write_npz(d / TRACE, arrays)
    if keep_final:
        save_model_checkpoint(
            d / "final.pt",
            model=model,
            preset=preset,
            data_sha256=data_sha256,
            trainer=None,
            network=steering.network,
            losses=losses,
        )
    ev.update(
        model=model,
        seed=seed,
        losses=losses,
        train_seconds=round(seconds, 1),
        resumed_from_step=resumed,
        eval_seconds=round(time.perf_counter() - te, 1),
    )
    write_json(d / EVAL, ev)  # last: with it the run is finished
    (d / "last.pt").unlink(missing_ok=True)
    return ev


def read_eval(path) -> dict:
    """A run's ``eval.json``, checked; ValueError naming the file otherwise."""
    keys = {"route", "crashes", "distance_m", "w_cmd", "swerve_score"}

    def valid(ev):
        routes = ev.get("routes")
        return (
            isinstance(routes, list)
            and isinstance(ev.get("summary"), dict)
            and all(isinstance(r, dict) and keys <= set(r) for r in routes)
        )

    return read_run_file(path, valid, "a run's evaluation")
