"""Agent checkpoints: the network's weights with everything needed to trust and reuse them.

A checkpoint is a ``torch.save`` of a plain dict (tensors, numbers, strings, lists, dicts), so
it loads with ``torch.load(..., weights_only=True)``: no pickled code runs. It holds

- ``format`` / ``format_version``: what the file is (``FORMAT``, ``FORMAT_VERSION``);
- ``package_version``: the ``ibc_tutorial`` version that wrote it;
- ``method``, ``architecture`` (``agent.architecture``: the network's class and sizes) and the
  whole ``preset``;
- ``data_sha256``: the SHA-256 of the demonstrations' content (``DemoLog.checksum``: every
  recorded step's state and action, not the file's bytes, which carry the time it was written);
- ``epoch``, ``model`` (the state dict), the expert actions and DFO initial weights the agent
  acts with, and, for resuming, ``optimizer`` and ``generator`` states (``training.Trainer``)
  and the metrics so far.

It is written atomically (``utils.atomic_torch_save``). ``load_checkpoint`` refuses, with a
``ValueError`` that says why, a file that is not a checkpoint, one of another format version or
of another package version (major.minor), and one whose architecture differs from the one asked
for (or whose weights do not fit it).
"""

from __future__ import annotations

from pathlib import Path

import torch

from ibc_tutorial import __version__
from ibc_tutorial.experiments.agents.agent import Agent, architecture, network_from_architecture
from ibc_tutorial.experiments.agents.presets import METHODS, Preset
from ibc_tutorial.utils import atomic_torch_save, check_choice

FORMAT = "ibc_tutorial.agent"
"""The ``format`` entry of every agent checkpoint."""
FORMAT_VERSION = 1
"""The layout version of the checkpoint dict; another one is refused."""


def _minor(version: str) -> str:
    return ".".join(str(version).split(".")[:2])


def save_checkpoint(path, *, method: str, preset: Preset, network: torch.nn.Module, data_sha256: str, epoch: int,
                    expert_actions: torch.Tensor, init_weights: torch.Tensor | None = None,
                    optimizer: dict | None = None, generator: torch.Tensor | None = None,
                    metrics: list | None = None) -> Path:
    """Write an agent checkpoint atomically (see the module docstring for its contents).

    ``optimizer`` and ``generator`` are the states kept for resuming (``Trainer.state_dict()``'s
    ``"optimizer"`` and ``"generator"``), or None in a final checkpoint.
    """
    ckpt = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "package_version": __version__,
        "method": check_choice("method", method, METHODS),
        "architecture": architecture(method, preset),
        "preset": preset.to_dict(),
        "data_sha256": str(data_sha256),
        "epoch": int(epoch),
        "model": {k: v.detach().clone() for k, v in network.state_dict().items()},
        "expert_actions": expert_actions.detach().float().clone(),
        "init_weights": None if init_weights is None else init_weights.detach().float().clone(),
        "optimizer": optimizer,
        "generator": generator,
        "metrics": list(metrics or []),
    }
    return atomic_torch_save(ckpt, path)


def load_checkpoint(path, *, method: str | None = None, preset: Preset | None = None) -> dict:
    """Read a checkpoint with ``weights_only=True`` and check it.

    Args:
        path: the file.
        method, preset: if given, the checkpoint must be of this method and of this preset's
            architecture (e.g. when resuming a run); otherwise any agent checkpoint is accepted.
    Raises:
        ValueError: not a checkpoint, another format or package version, or another architecture.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"no checkpoint at {path}")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        raise ValueError(f"{path} is not a readable agent checkpoint ({type(exc).__name__}: {exc})") from None
    if not isinstance(ckpt, dict) or ckpt.get("format") != FORMAT:
        raise ValueError(f"{path} is not an ibc-tutorial agent checkpoint (no '{FORMAT}' header)")
    if ckpt.get("format_version") != FORMAT_VERSION:
        raise ValueError(f"{path} is a checkpoint of format version {ckpt.get('format_version')}; "
                         f"this library reads version {FORMAT_VERSION}: train it again")
    if _minor(ckpt.get("package_version", "")) != _minor(__version__):
        raise ValueError(f"{path} was written by ibc_tutorial {ckpt.get('package_version')}; this is {__version__}: "
                         "train it again with this version")
    if method is not None and ckpt["method"] != method:
        raise ValueError(f"{path} is a checkpoint of method {ckpt['method']!r}, expected {method!r}")
    if preset is not None:
        want = architecture(ckpt["method"], preset)
        if ckpt["architecture"] != want:
            diff = {k: (ckpt["architecture"].get(k), v) for k, v in want.items() if ckpt["architecture"].get(k) != v}
            raise ValueError(f"{path} holds another architecture: (checkpoint, expected) differ in {diff}")
    return ckpt


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
    agent = Agent(ckpt["method"], net, Preset.from_dict(ckpt["preset"]), ckpt["expert_actions"], ckpt["init_weights"])
    return agent, ckpt
