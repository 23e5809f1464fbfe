"""Demonstrations: a compact log of states and actions, and a torch ``Dataset`` that renders BEVs.

The DA-IBC paper stores 21k BEV images (30 GB, its sec. 4.1); here a step is stored as the
state the BEV is rendered from (pose, speed, previous action, the state of every light) and
the expert's action, a few dozen bytes, and the BEV is rendered when a sample is drawn, at
any supported size. So the paper-sized dataset is a file of about a megabyte.

File format (``.npz``, written atomically): the arrays of ``DemoLog`` plus ``format`` (the
string ``FORMAT``), ``version`` (``VERSION``), ``meta`` (JSON: town, how it was collected) and
``checksum`` (``DemoLog.checksum``: SHA-256 of every array's dtype, shape and bytes). A file
that is truncated, altered, of another format or of another version is refused with a
``ValueError`` naming it and saying so; so is one whose values could not have been recorded
(``check_values``): non-finite or off-map poses, light codes or lane indices out of range,
actions outside [-1, 1], incomplete meta.
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from ibc_tutorial.driving.bev import HISTORY_LAGS, PAD, BEVRenderer, check_bev_size, get_raster
from ibc_tutorial.driving.commands import log_commands
from ibc_tutorial.driving.env import MAX_SPEED
from ibc_tutorial.driving.lights import RED
from ibc_tutorial.driving.towns import TOWNS, get_town
from ibc_tutorial.utils import atomic_write_bytes, check_choice, progress

FORMAT = "ibc_tutorial.demonstrations"
"""The ``format`` entry of every demonstration file."""
VERSION = 1
"""The ``version`` entry; files of another version are refused."""

ARRAYS = {  # name -> (dtype, trailing shape; "L" = number of lights)
    "pose": (np.float64, (3,)),
    "speed": (np.float32, ()),
    "prev_action": (np.float32, (2,)),
    "action": (np.float32, (2,)),
    "executed": (np.float32, (2,)),
    "lights": (np.uint8, ("L",)),
    "episode": (np.int32, ()),
    "step": (np.int32, ()),
    "lane": (np.int16, ()),
}


@dataclass
class DemoLog:
    """N recorded steps of the expert, in episodes stored one after the other."""

    town: str
    """The town driven ("town01" or "town02")."""
    pose: np.ndarray
    """(N, 3) float64 car pose (x, y, yaw) when the step's observation was made."""
    speed: np.ndarray
    """(N,) float32 forward speed (m/s), as in the observation's state."""
    prev_action: np.ndarray
    """(N, 2) float32 action executed at the step before (zeros at an episode's start)."""
    action: np.ndarray
    """(N, 2) float32 the expert's action: the label (steer, acceleration)."""
    executed: np.ndarray
    """(N, 2) float32 the action executed (the label plus any collection noise)."""
    lights: np.ndarray
    """(N, L) uint8 state of every light (0 green, 1 yellow, 2 red)."""
    episode: np.ndarray
    """(N,) int32 episode index (the route's number)."""
    step: np.ndarray
    """(N,) int32 step within the episode (0, 1, 2, ...)."""
    lane: np.ndarray
    """(N,) int16 the lane the expert was following."""
    meta: dict = field(default_factory=dict)
    """How the log was collected (JSON-serialisable)."""

    def __post_init__(self):
        check_choice("town", self.town, TOWNS)
        n = len(self.pose)
        n_lights = get_town(self.town).n_lights
        for name, (dtype, shape) in ARRAYS.items():
            arr = np.asarray(getattr(self, name))
            want = (n,) + tuple(n_lights if s == "L" else s for s in shape)
            if arr.shape != want:
                raise ValueError(f"DemoLog.{name} must have shape {want}, got {arr.shape}")
            setattr(self, name, arr.astype(dtype, copy=False))
        if n:
            new = np.ones(n, dtype=bool)
            new[1:] = self.episode[1:] != self.episode[:-1]
            expected = np.where(new, 0, np.concatenate([[0], self.step[:-1] + 1]))
            if (self.step != expected).any():
                raise ValueError(
                    "DemoLog episodes must be stored step by step: step 0, 1, 2, ... within each episode"
                )

    def __len__(self) -> int:
        return len(self.pose)

    @property
    def n_episodes(self) -> int:
        return int(len(np.unique(self.episode)))

    def states(self) -> np.ndarray:
        """(N, 3) float32 [speed, previous steer, previous acceleration]: the observation's state."""
        return np.concatenate([np.minimum(self.speed, MAX_SPEED)[:, None], self.prev_action], axis=1).astype(
            np.float32
        )

    def history_rows(self, index: np.ndarray) -> np.ndarray:
        """(B, 3) rows holding the light states 15, 8 and 0 steps before each sample (clamped at its episode's
        start)."""
        index = np.asarray(index, dtype=np.int64)
        back = np.minimum(np.array(HISTORY_LAGS)[None, :], self.step[index][:, None])  # (B, 3)
        return index[:, None] - back

    def light_history(self, index: np.ndarray) -> np.ndarray:
        """(B, 3, L) uint8 light states (0 green, 1 yellow, 2 red) at the BEV's three history lags."""
        return self.lights[self.history_rows(index)]

    def episodes(self) -> list[slice]:
        """The rows of each episode, in order."""
        starts = np.flatnonzero(self.step == 0)
        ends = np.append(starts[1:], len(self))
        return [slice(int(a), int(b)) for a, b in zip(starts, ends, strict=True)]

    # ------------------------------------------------------------------ files
    def checksum(self) -> str:
        """SHA-256 (hex) of the log's content: every array's name, dtype, shape and bytes.

        The demonstrations' identity: two identical collections have the same checksum whenever
        and wherever they were made (the file's bytes differ: the archive records when it was
        written). Agent checkpoints record it as ``data_sha256``.
        """
        h = hashlib.sha256()
        for name in ARRAYS:
            arr = np.ascontiguousarray(getattr(self, name))
            h.update(f"{name}:{arr.dtype.str}:{arr.shape};".encode())
            h.update(arr.tobytes())
        return h.hexdigest()

    def save(self, path) -> Path:
        """Write the log to ``path`` (.npz) atomically."""
        buf = io.BytesIO()
        meta = dict(self.meta, town=self.town)
        np.savez_compressed(
            buf,
            format=np.array(FORMAT),
            version=np.array(VERSION),
            meta=np.array(json.dumps(meta)),
            checksum=np.array(self.checksum()),
            **{k: getattr(self, k) for k in ARRAYS},
        )
        return atomic_write_bytes(path, buf.getvalue())

    @classmethod
    def load(cls, path) -> DemoLog:
        """Read a log written by ``save``; ValueError if the file is damaged, foreign or of
        another version."""
        path = Path(path)
        if not path.is_file():
            raise ValueError(f"no demonstration file at {path}")
        if not zipfile.is_zipfile(path):
            raise ValueError(
                f"{path} is truncated or damaged, or not a demonstration file: it is not an .npz archive"
            )
        try:
            with np.load(path, allow_pickle=False) as z:
                files = set(z.files)
                if "format" not in files or str(z["format"]) != FORMAT:
                    raise _Refused(f"{path} is not an ibc-tutorial demonstration file (no '{FORMAT}' header)")
                if int(z["version"]) != VERSION:
                    raise _Refused(
                        f"{path} is a demonstration file of version {int(z['version'])}; "
                        f"this library reads version {VERSION}: collect it again"
                    )
                missing = [k for k in list(ARRAYS) + ["meta", "checksum"] if k not in files]
                if missing:
                    raise _Refused(f"{path} is damaged: it lacks {missing}")
                meta = json.loads(str(z["meta"]))
                arrays = {k: z[k] for k in ARRAYS}
                stored = str(z["checksum"])
        except _Refused as exc:
            raise ValueError(str(exc)) from None
        except Exception as exc:  # a damaged archive member: zlib, zip, format or JSON errors
            raise ValueError(
                f"{path} is truncated or damaged and cannot be read ({type(exc).__name__}: "
                f"{' '.join(str(exc).split())}): collect it again"
            ) from None
        if not isinstance(meta, dict) or not isinstance(meta.get("town"), str) or meta["town"] not in TOWNS:
            raise ValueError(f"{path} is damaged: its meta must be a dict naming the town (one of {TOWNS})")
        for name, (dtype, _shape) in ARRAYS.items():
            if arrays[name].dtype != np.dtype(dtype):
                raise ValueError(
                    f"{path} is damaged: {name} must be {np.dtype(dtype).name}, got {arrays[name].dtype.name}"
                )
        try:
            log = cls(meta.pop("town"), meta=meta, **arrays)
        except ValueError as exc:
            raise ValueError(f"{path} is damaged: {exc}") from None
        if log.checksum() != stored:
            raise ValueError(f"{path} is damaged: its checksum does not match its contents")
        try:
            log.check_values()
        except ValueError as exc:
            raise ValueError(f"{path} holds invalid demonstrations: {exc}: collect it again") from None
        return log

    def check_values(self) -> None:
        """ValueError unless every value could have been recorded: finite poses on the town's map (its
        roads' extent plus the BEV's margin), speeds in [-MAX_SPEED, MAX_SPEED], actions in [-1, 1], light
        codes 0-2, lane indices of the town, episode indices >= 0, and the meta of a collection."""
        town = get_town(self.town)
        x0, y0, x1, y1 = town.extent
        if len(self) == 0:
            raise ValueError("the log holds no samples")
        if not np.isfinite(self.pose).all():
            raise ValueError("pose holds NaN or inf")
        x, y = self.pose[:, 0], self.pose[:, 1]
        off = (x < x0 - PAD) | (x > x1 + PAD) | (y < y0 - PAD) | (y > y1 + PAD)
        if off.any():
            k = int(np.flatnonzero(off)[0])
            raise ValueError(
                f"pose {k} ({x[k]:.1f}, {y[k]:.1f}) lies off {self.town}'s map "
                f"(x in [{x0 - PAD:.0f}, {x1 + PAD:.0f}], y in [{y0 - PAD:.0f}, {y1 + PAD:.0f}] m)"
            )
        if not np.isfinite(self.speed).all() or (np.abs(self.speed) > MAX_SPEED).any():
            raise ValueError(f"speed must be finite and within ±{MAX_SPEED} m/s")
        for name in ("action", "executed", "prev_action"):
            v = getattr(self, name)
            if not np.isfinite(v).all() or (np.abs(v) > 1.0).any():
                raise ValueError(f"{name} must be finite and in [-1, 1]")
        if (self.lights > RED).any():
            raise ValueError(
                f"lights must be codes 0 (green), 1 (yellow) or 2 (red), got {int(self.lights.max())}"
            )
        if (self.lane < 0).any() or (self.lane >= len(town.lanes)).any():
            raise ValueError(
                f"lane must index {self.town}'s {len(town.lanes)} lanes, got "
                f"{int(self.lane.min())}..{int(self.lane.max())}"
            )
        if (self.episode < 0).any():
            raise ValueError("episode indices must be >= 0")
        missing = [k for k in ("config", "episodes") if k not in self.meta]
        if missing:
            raise ValueError(f"its meta lacks {missing}")


class _Refused(Exception):
    """Internal: a readable file that is not a valid demonstration log."""


class DemoDataset(torch.utils.data.Dataset):
    """Samples ``({"bev": (5, S, S) float32, "state": (3,)}, action (2,))`` of a demonstration log.

    The BEV is rendered on demand from the stored pose and light states, exactly as the
    environment renders its observation (so a sample equals what the env showed the expert).

    Args:
        source: a ``DemoLog`` or the path of a file written by ``DemoLog.save``.
        bev_size: side of the rendered BEV (one of ``bev.SUPPORTED_SIZES``).
        light_encoding: how the BEV draws the lights (``bev.LIGHT_ENCODINGS``; "intensity", the book's).
        cache: render every sample once, now, and keep the views packed one byte per pixel
            (N x S x S bytes: 86 MB for the paper-sized dataset at 64 x 64, 775 MB at 192), so
            that later epochs only unpack them.
        commands: also give every sample's route command, ``obs["command"]`` (int64 index into
            ``driving.commands.COMMANDS``), computed from the log (``driving.commands.log_commands``).
    """

    def __init__(
        self,
        source,
        bev_size: int = 192,
        cache: bool = False,
        light_encoding: str = "intensity",
        commands: bool = False,
    ):
        self.log = source if isinstance(source, DemoLog) else DemoLog.load(source)
        self.bev_size = check_bev_size(bev_size)
        self.renderer = BEVRenderer(get_raster(self.log.town), self.bev_size, light_encoding)
        self.states = torch.from_numpy(self.log.states())  # (N, 3) float32
        self.actions = torch.from_numpy(self.log.action.copy())  # (N, 2) float32
        if not isinstance(commands, bool):
            raise ValueError(f"commands must be True or False, got {commands!r}")
        self.commands = torch.from_numpy(log_commands(self.log)) if commands else None  # (N,) int64
        self._packed = None
        if cache:
            packed = np.empty((len(self.log), self.bev_size, self.bev_size), dtype=np.uint8)  # (N, S, S)
            for a in progress(range(0, len(self.log), 512), desc="rendering BEVs"):
                idx = np.arange(a, min(a + 512, len(self.log)))
                packed[idx] = self.renderer.packed_batch(self.log.pose[idx], self.log.light_history(idx))
            self._packed = packed

    def _packed_of(self, index: np.ndarray) -> np.ndarray:
        if self._packed is not None:
            return self._packed[index]
        return self.renderer.packed_batch(self.log.pose[index], self.log.light_history(index))

    def __len__(self) -> int:
        return len(self.log)

    def _bev(self, packed: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(self.renderer.unpack(packed))  # (..., 5, S, S) float32

    def __getitem__(self, i):
        n = len(self)
        if isinstance(i, (bool, np.bool_)) or not isinstance(i, (int, np.integer)) or not -n <= int(i) < n:
            raise IndexError(f"index must be an integer in [-{n}, {n}), got {i!r}")
        i = int(i) % n
        packed = self._packed_of(np.array([i]))[0]
        obs = {"bev": self._bev(packed), "state": self.states[i]}
        if self.commands is not None:
            obs["command"] = self.commands[i]
        return obs, self.actions[i]

    def batch(self, indices) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
        """Stacked samples: ``({"bev": (B, 5, S, S), "state": (B, 3)}, actions (B, 2))``."""
        idx = torch.as_tensor(indices, dtype=torch.long).reshape(-1)
        if len(idx) and (idx.min() < 0 or idx.max() >= len(self)):
            raise IndexError(f"indices must lie in [0, {len(self)})")
        packed = self._packed_of(idx.numpy())
        obs = {"bev": self._bev(packed), "state": self.states[idx]}
        if self.commands is not None:
            obs["command"] = self.commands[idx]  # (B,) int64
        return obs, self.actions[idx]

    def __getitems__(self, indices):
        """Batched fetch for ``torch.utils.data.DataLoader`` (renders the batch in one call)."""
        obs, act = self.batch(indices)
        return [({key: v[k] for key, v in obs.items()}, act[k]) for k in range(len(act))]
