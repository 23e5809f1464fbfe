"""Agent checkpoints: the network's weights with everything needed to trust and reuse them.

A checkpoint is a ``torch.save`` of a plain dict (tensors, numbers, strings, lists, dicts), so
it loads with ``torch.load(..., weights_only=True)``: no pickled code runs. It holds

- ``format`` / ``format_version``: what the file is (``FORMAT``, ``FORMAT_VERSION``);
- ``package_version``: the ``ibc_tutorial`` version that wrote it;
- ``method``, ``architecture`` (``agent.architecture``: the network's class and sizes) and the
  whole ``preset``;
- ``data_sha256``: the SHA-256 of the demonstrations' content (``DemoLog.checksum``: every
  recorded step's state and action, not the file's bytes, which carry the time it was written);
- ``seed``: the training seed (also the policy seed of its evaluations; absent in older files,
  whose metrics record it);
- ``epoch``, ``model`` (the state dict; float16 in a ``final.pt``), the expert actions and DFO
  initial weights the agent acts with, and, for resuming, ``optimizer`` and ``generator`` states
  (``training.Trainer``) and the metrics so far.

It is written atomically (``utils.atomic_torch_save``). ``load_checkpoint`` checks every field
before anything uses it and refuses, with a ``ValueError`` naming the file and the field, a file
that is truncated or not a checkpoint, one of another format or package version (major.minor),
a missing or mistyped field, a preset that does not describe the stored architecture, weights
that do not fit it or are not finite, expert actions outside [-1, 1], DFO weights of the wrong
length, and, when resuming, a checkpoint without its optimiser and generator states.
"""

from __future__ import annotations

import re
from pathlib import Path

import torch

from ibc_tutorial import __version__
from ibc_tutorial.experiments.agents.agent import Agent, architecture, network_from_architecture
from ibc_tutorial.experiments.agents.presets import ALL_METHODS, Preset
from ibc_tutorial.experiments.runs import read_torch_file
from ibc_tutorial.utils import atomic_torch_save, check_choice

FORMAT = "ibc_tutorial.agent"
"""The ``format`` entry of every agent checkpoint."""
FORMAT_VERSION = 2
"""The layout version of the checkpoint dict; another one is refused. 2: the BEV draws lights by intensity
(red 1.0, yellow 0.6, green 0.3; version 1 agents saw a 0/1 "must stop" flag and cannot be fed version 2
views)."""


def _minor(version: str) -> str:
    return ".".join(str(version).split(".")[:2])


def _cpu_copy(t: torch.Tensor, dtype: torch.dtype | None = None) -> torch.Tensor:
    """A detached copy of ``t`` on the CPU (in ``dtype``, else its own), whatever its device: ``t`` is not
    moved."""
    return t.detach().to("cpu", dtype=t.dtype if dtype is None else dtype, copy=True)


def save_checkpoint(
    path,
    agent: Agent,
    *,
    data_sha256: str,
    epoch: int,
    seed: int | None = None,
    metrics: list | None = None,
    resume: dict | None = None,
    half: bool = False,
) -> Path:
    """Write an agent checkpoint atomically (see the module docstring for its contents).

    ``agent``: an ``Agent`` (or anything with its ``method``, ``preset``, ``network``, ``expert_actions`` and
    ``init_weights``). ``resume``: the states kept for resuming (``Trainer.state_dict()``'s ``"optimizer"``
    and ``"generator"``, stored as CPU copies), or None in a final checkpoint. ``half`` stores the network's
    floating-point weights as float16 (a final checkpoint: half the size; ``train.round_to_half`` rounds the
    network first, so nothing is lost that it used).

    The weights, expert actions and initial weights are stored as CPU copies whatever their device
    (a network on a GPU is copied, not moved), so the file loads on any machine.
    """
    resume = resume or {}
    ckpt = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "package_version": __version__,
        "method": check_choice("method", agent.method, ALL_METHODS),
        "architecture": architecture(agent.method, agent.preset),
        "preset": agent.preset.to_dict(),
        "data_sha256": str(data_sha256),
        "epoch": int(epoch),
        "seed": None if seed is None else int(seed),
        "model": {
            k: _cpu_copy(v, torch.float16 if half and v.is_floating_point() else None)
            for k, v in agent.network.state_dict().items()
        },
        "expert_actions": _cpu_copy(agent.expert_actions, torch.float32),
        "init_weights": None if agent.init_weights is None else _cpu_copy(agent.init_weights, torch.float32),
        "optimizer": _on_cpu(resume.get("optimizer")),
        "generator": resume.get("generator"),
        "metrics": list(metrics or []),
    }
    return atomic_torch_save(ckpt, path)


def _on_cpu(obj):
    """``obj`` (tensors in dicts, lists, tuples) with every tensor on the CPU: what a checkpoint stores."""
    if isinstance(obj, torch.Tensor):
        return obj.cpu()
    if isinstance(obj, dict):
        return {k: _on_cpu(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return type(obj)(_on_cpu(v) for v in obj)
    return obj


def _read(path: Path) -> dict:
    return read_torch_file(path, "agent checkpoint", "train it again")


def _field(path: Path, ckpt: dict, key: str, types, what: str):
    if key not in ckpt:
        raise ValueError(f"{path} is damaged: it lacks the field '{key}' ({what}): train it again")
    value = ckpt[key]
    if not isinstance(value, types) or (isinstance(value, bool) and types is int):
        raise ValueError(f"{path} is damaged: its field '{key}' must be {what}, got {type(value).__name__}")
    return value


def _check_fields(path: Path, ckpt: dict, resumable: bool) -> None:
    """Every field's type, shape and range (see the module docstring); ValueError naming the file and
    field."""
    bad = lambda msg: ValueError(f"{path} is damaged: {msg}: train it again")  # noqa: E731
    _field(path, ckpt, "architecture", dict, "a dict")
    preset_d = _field(path, ckpt, "preset", dict, "a dict")
    sha = _field(path, ckpt, "data_sha256", str, "a SHA-256 hex string")
    if not re.fullmatch(r"[0-9a-f]{64}", sha):
        raise bad(f"data_sha256 must be 64 hex digits, got {sha[:20]!r}")
    epoch = _field(path, ckpt, "epoch", int, "an integer")
    if epoch < 0:
        raise bad(f"epoch must be >= 0, got {epoch}")
    if ckpt.get("seed") is not None and (
        not isinstance(ckpt["seed"], int) or isinstance(ckpt["seed"], bool) or ckpt["seed"] < 0
    ):
        raise bad(f"seed must be an integer >= 0, got {ckpt['seed']!r}")
    try:
        preset = Preset.from_dict(preset_d)
    except (TypeError, ValueError) as exc:
        raise bad(f"its preset is not valid ({exc})") from None
    if architecture(ckpt["method"], preset) != ckpt["architecture"]:
        raise bad("its preset and its architecture disagree")
    model = _field(path, ckpt, "model", dict, "a state dict")
    try:
        want = network_from_architecture(ckpt["architecture"]).state_dict()
    except (KeyError, TypeError, ValueError) as exc:
        raise bad(f"its architecture cannot be built ({type(exc).__name__}: {exc})") from None
    if set(model) != set(want):
        raise bad(
            f"its weights do not fit its architecture (missing {sorted(set(want) - set(model))[:3]}, "
            f"unexpected {sorted(set(model) - set(want))[:3]})"
        )
    for k, v in model.items():
        dtype_ok = isinstance(v, torch.Tensor) and (
            v.dtype == want[k].dtype or (v.dtype == torch.float16 and want[k].dtype == torch.float32)
        )  # a final checkpoint's float16 weights
        if not dtype_ok or v.shape != want[k].shape:
            got = tuple(v.shape) if isinstance(v, torch.Tensor) else type(v).__name__
            raise bad(
                f"its weights do not fit its architecture: {k} must be {tuple(want[k].shape)}, got {got}"
            )
        if v.is_floating_point() and not torch.isfinite(v).all():
            raise bad(f"its weight {k} holds NaN or inf")
    acts = _field(path, ckpt, "expert_actions", torch.Tensor, "a tensor")
    if acts.ndim != 2 or acts.shape[1] != 2 or len(acts) < 1 or not acts.is_floating_point():
        raise bad(f"expert_actions must be a float tensor of shape (M >= 1, 2), got {tuple(acts.shape)}")
    if not torch.isfinite(acts).all() or acts.abs().max() > 1.0:
        raise bad("expert_actions must be finite and in [-1, 1]")
    w = ckpt.get("init_weights")
    if w is not None:
        if not isinstance(w, torch.Tensor) or w.shape != (len(acts),) or not w.is_floating_point():
            got = tuple(w.shape) if isinstance(w, torch.Tensor) else type(w).__name__
            raise bad(
                f"init_weights must be a float tensor of shape ({len(acts)},), one per expert action, "
                f"got {got}"
            )
        if not torch.isfinite(w).all() or (w < 0).any() or not w.sum() > 0:
            raise bad("init_weights must be finite, >= 0 and not all 0")
    metrics = ckpt.get("metrics", [])
    if not isinstance(metrics, list) or not all(isinstance(m, dict) for m in metrics):
        raise bad("metrics must be a list of dicts")
    if resumable:
        if not isinstance(ckpt.get("optimizer"), dict) or not isinstance(ckpt.get("generator"), torch.Tensor):
            raise ValueError(
                f"{path} has no optimiser and generator states (a final checkpoint?): a run resumes "
                "only from the last.pt its training wrote"
            )
        if len(metrics) < 1 or not isinstance(metrics[-1].get("epoch"), int):
            raise bad("a resumable checkpoint must hold the metrics so far")


def load_checkpoint(
    path, *, method: str | None = None, preset: Preset | None = None, resumable: bool = False
) -> dict:
    """Read a checkpoint with ``weights_only=True`` and check every field before use.

    Args:
        path: the file.
        method, preset: if given, the checkpoint must be of this method and of this preset's
            architecture (e.g. when resuming a run); otherwise any agent checkpoint is accepted.
        resumable: it must hold the optimiser and generator states (a ``last.pt``).
    Raises:
        ValueError (naming the file): truncated, not a checkpoint, another format or package
            version, a missing, mistyped or non-finite field, or another architecture.
    """
    path = Path(path)
    ckpt = _read(path)
    if not isinstance(ckpt, dict) or ckpt.get("format") != FORMAT:
        raise ValueError(f"{path} is not an ibc-tutorial agent checkpoint (no '{FORMAT}' header)")
    if ckpt.get("format_version") != FORMAT_VERSION:
        raise ValueError(
            f"{path} is a checkpoint of format version {ckpt.get('format_version')}; "
            f"this library reads version {FORMAT_VERSION}: train it again"
        )
    if _minor(ckpt.get("package_version", "")) != _minor(__version__):
        raise ValueError(
            f"{path} was written by ibc_tutorial {ckpt.get('package_version')}; this is {__version__}: "
            "train it again with this version"
        )
    if ckpt.get("method") not in ALL_METHODS:
        raise ValueError(
            f"{path} is damaged: its method must be one of {ALL_METHODS}, got {ckpt.get('method')!r}"
        )
    _check_fields(path, ckpt, resumable)
    if method is not None and ckpt["method"] != method:
        raise ValueError(f"{path} is a checkpoint of method {ckpt['method']!r}, expected {method!r}")
    if preset is not None:
        want = architecture(ckpt["method"], preset)
        if ckpt["architecture"] != want:
            diff = {
                k: (ckpt["architecture"].get(k), v)
                for k, v in want.items()
                if ckpt["architecture"].get(k) != v
            }
            raise ValueError(f"{path} holds another architecture: (checkpoint, expected) differ in {diff}")
    return ckpt


def training_seed(ckpt: dict) -> int | None:
    """The seed a checkpoint's agent was trained with (its ``seed``, or, in older files, its metrics'), or
    None."""
    if ckpt.get("seed") is not None:
        return int(ckpt["seed"])
    seeds = {m.get("seed") for m in ckpt.get("metrics", [])}
    return next(iter(seeds)) if len(seeds) == 1 and isinstance(next(iter(seeds)), int) else None


def network_from_checkpoint(ckpt: dict) -> torch.nn.Module:
    """Rebuild the network a checked checkpoint describes and load its weights."""
    if architecture(ckpt["method"], Preset.from_dict(ckpt["preset"])) != ckpt["architecture"]:
        raise ValueError("the checkpoint's preset and architecture disagree: the file was altered")
    net = network_from_architecture(ckpt["architecture"])
    try:
        net.load_state_dict(ckpt["model"], strict=True)
    except RuntimeError as exc:
        raise ValueError(f"the checkpoint's weights do not fit its architecture: {exc}") from None
    net.eval()
    return net


def load_agent(path, *, method: str | None = None, preset: Preset | None = None) -> tuple[Agent, dict]:
    """An ``Agent`` from a checkpoint file (checked as ``load_checkpoint`` does); returns (agent, ckpt)."""
    ckpt = load_checkpoint(path, method=method, preset=preset)
    net = network_from_checkpoint(ckpt)
    agent = Agent(
        ckpt["method"], net, Preset.from_dict(ckpt["preset"]), ckpt["expert_actions"], ckpt["init_weights"]
    )
    return agent, ckpt
