"""Free driving of every shipped agent (and the expert) in town02, recorded for the stem analysis.

The protocol is chapter 09's free driving (the DA-IBC paper's Fig. 5): routeless episodes of
``STEPS`` steps (300 s at 10 Hz) from ``reset(seed=EVAL_SEED + i)``, policy seed 0, in town02;
here for **every** agent of each method (``runs/<method>/seed<k>/final.pt``), not one, and for the
PID expert, whose routeless drive picks a stem's exits at random.

Each drive is written to ``<out>/drives/<method>-seed<k>.npz`` (``expert.npz``) atomically, one file
per agent, so an interrupted run resumes where it stopped. A file holds, per episode ``i``, the
per-state record (``e<i>_lane``, ``_pose``, ``_speed``, ``_red_ahead``, ``_entry_dist``,
``_actions``) and, for an agent, the observations of the states the energy analysis looks at
(``driving.stems.kept_states``: every junction crossing from a stem, from ``LEAD`` states before
its entry, and one state per stop at a red light): ``obs_episode``, ``obs_t``, ``obs_bev``
(the BEV, whose values are 0 or 1 with the agents' "flag" light encoding, bit-packed along its
last axis: ``np.unpackbits(obs_bev, axis=-1)`` restores it) and ``obs_state``.

    ibc-tutorial stems drive --folder book/results/laptop \
        --out book/results/laptop/stems --episodes 5

``replicate`` records the same for every agent from its table's episodes (``recorded_drive``: the
``final_evaluations`` of ``EVAL_SEED``'s starts, with the agent's training seed as its policy seed), into
``runs/<method>/seed<k>/stem_drive.npz`` (``runs/expert/stem_drive.npz``), so that a replication
needs no second drive; ``drive_file`` finds either.

``analyse`` (``experiments.agents.stem_analysis``) then reads these files.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ibc_tutorial.driving.rollout import RolloutRecording
from ibc_tutorial.driving.stems import kept_states
from ibc_tutorial.experiments.agents.checkpoints import load_agent
from ibc_tutorial.experiments.agents.evaluate import EVAL_SEED, EVAL_TOWN, episode_rows, evaluate_agent
from ibc_tutorial.experiments.agents.presets import METHODS
from ibc_tutorial.experiments.agents.replication_folder import STEM_DRIVE, expert_dir, run_dir
from ibc_tutorial.experiments.runs import run_missing_recorded, write_npz
from ibc_tutorial.optimizers.dfo import DFOConfig
from ibc_tutorial.utils import check_int

STEPS = 3000
"""Steps per episode: 300 s at 10 Hz, chapter 09's ``routeless_steps``."""
EPISODES = 5
"""Episodes per agent (the first of chapter 09's ten starts): what 25 minutes of one core allow 16 drivers."""
POLICY_SEED = 0
"""Seed of the agents' DFO draws, as in chapter 09's free driving."""
TRACE = ("lane", "pose", "speed", "red_ahead", "entry_dist", "actions")
"""The per-state record kept of each episode."""


def drivers(folder) -> list[tuple[str, Path | None]]:
    """(name, checkpoint) of every agent under ``folder/runs``, by method then seed, then ("expert", None)."""
    folder = Path(folder)
    out = []
    for m in METHODS:
        for ck in sorted((folder / "runs" / m).glob("seed*/final.pt"), key=lambda p: int(p.parent.name[4:])):
            out.append((f"{m}-{ck.parent.name}", ck))
    if not out:
        raise ValueError(
            f"folder must hold runs/<method>/seed<k>/final.pt checkpoints, found none in {folder}"
        )
    return out + [("expert", None)]


def recorded_drive(
    agent,
    episodes: int,
    steps: int,
    seed: int = EVAL_SEED,
    policy_seed: int = POLICY_SEED,
    keep_obs: bool = True,
):
    """Drive ``agent`` (an ``Agent``, or "expert") for ``episodes`` batched routeless town02 episodes of
    ``steps`` steps, recording what the stem analysis reads; returns ``(results, arrays)``: the
    ``EpisodeResult`` of each episode (as ``evaluate_agent`` returns them: the recording changes no
    episode) and the arrays of its drive file (see the module's docstring). ``replicate`` records its
    table's episodes so, for every agent. ``keep_obs=False`` keeps the per-state record only (no
    observations: a BEV drawn with the "intensity" lights is not 0/1 and cannot be bit-packed)."""
    is_agent = not isinstance(agent, str) and keep_obs
    packed: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

    def keep(t: int, running: list[int], batch: dict) -> None:
        bev = batch["bev"]  # (B, 5, S, S) float32, 0 or 1 with the "flag" encoding
        if not ((bev == 0.0) | (bev == 1.0)).all():
            raise ValueError("the BEV holds values other than 0 and 1: it cannot be bit-packed")
        bits = np.packbits(bev.astype(np.uint8), axis=-1)  # (B, 5, S, S / 8)
        for k, i in enumerate(running):
            packed[(i, t)] = (bits[k], batch["state"][k].astype(np.float32))

    results = evaluate_agent(
        agent,
        EVAL_TOWN,
        episodes,
        steps,
        seed=seed,
        policy_seed=policy_seed,
        record=RolloutRecording(xy=False, steps=True, on_step=keep if is_agent else None),
    )
    arrays: dict[str, np.ndarray] = {}
    obs_ep, obs_t, obs_bev, obs_state = [], [], [], []
    for i, r in enumerate(results):
        tr = r.trace
        for k in TRACE:
            arrays[f"e{i}_{k}"] = np.asarray(tr[k])
        if is_agent:
            for t in kept_states(EVAL_TOWN, tr["lane"], tr["speed"], tr["red_ahead"], tr["entry_dist"]):
                if (i, t) in packed:  # the last state of an episode was never shown to the policy
                    obs_ep.append(i)
                    obs_t.append(t)
                    obs_bev.append(packed[(i, t)][0])
                    obs_state.append(packed[(i, t)][1])
    if is_agent:
        arrays["obs_episode"] = np.array(obs_ep, dtype=np.int16)
        arrays["obs_t"] = np.array(obs_t, dtype=np.int32)
        arrays["obs_bev"] = np.stack(obs_bev) if obs_bev else np.zeros((0,), np.uint8)
        arrays["obs_state"] = np.stack(obs_state) if obs_state else np.zeros((0, 3), np.float32)
    arrays["rows"] = np.array(json.dumps(episode_rows(results)))
    return results, arrays


DFO_OVERRIDES = {"select": "select", "samples": "n_samples", "iters": "n_iters"}
"""``run_drives``' ``dfo`` keys and the ``DFOConfig`` fields they set (``--dfo-select`` etc.)."""


def with_dfo(agent, dfo: dict | None):
    """``agent`` acting with its ``DFOConfig`` changed by ``dfo`` ({"select": "sample", "samples": 2048,
    "iters": 5}, any of them; the counterfactuals of chapter 08); BC and the expert are returned as they are.
    """
    if not dfo or isinstance(agent, str) or agent.dfo_config is None:
        return agent
    unknown = sorted(set(dfo) - set(DFO_OVERRIDES))
    if unknown:
        raise ValueError(f"dfo must hold some of {sorted(DFO_OVERRIDES)}, got {unknown}")
    agent.dfo_config = replace(agent.dfo_config, **{DFO_OVERRIDES[k]: v for k, v in dfo.items()})
    return agent


def drive(
    checkpoint: Path | None,
    episodes: int,
    steps: int,
    seed: int = EVAL_SEED,
    dfo: dict | None = None,
    policy_seed: int = POLICY_SEED,
) -> dict:
    """Drive one agent (``checkpoint``; None: the expert) for ``episodes`` free-driving episodes, an energy
    agent's DFO changed by ``dfo`` (``with_dfo``), its DFO draws seeded with ``policy_seed``.

    Returns the arrays of its drive file (see the module's docstring)."""
    agent = "expert" if checkpoint is None else with_dfo(load_agent(checkpoint)[0], dfo)
    return recorded_drive(agent, episodes, steps, seed, policy_seed)[1]


def table_policy_seed(name: str) -> int:
    """The policy seed ``replicate`` drives driver ``name``'s table episodes with: an agent's training seed
    (``<method>-seed<k>``: k), the expert's ``POLICY_SEED``."""
    if name == "expert":
        return POLICY_SEED
    method, _, seed = name.rpartition("-seed")
    if method not in METHODS or not seed.isdigit():
        raise ValueError(
            f"name must be 'expert' or '<method>-seed<k>' with a method of {METHODS}, got {name!r}"
        )
    return int(seed)


@dataclass(frozen=True)
class DriveProtocol:
    """What every drive of one ``stems drive`` folder shares: recorded in its ``provenance.json`` as the
    folder's ``protocol``, which a later invocation must repeat (so that a folder never mixes two)."""

    episodes: int = EPISODES
    """Episodes per driver, from ``reset(seed=EVAL_SEED + i)``."""
    steps: int = STEPS
    """Steps per episode (10 Hz)."""
    dfo: dict | None = None
    """The energy agents' DFO changed (``with_dfo``: keys of ``DFO_OVERRIDES``), or None: as trained."""
    table_seeds: bool = False
    """True: each agent's DFO draws seeded with its training seed (``table_policy_seed``), as the table's
    episodes that ``replicate`` records, so that the drives repeat those episodes (e.g. on another CPU);
    False: ``POLICY_SEED`` for every agent."""

    def __post_init__(self) -> None:
        check_int("episodes", self.episodes, minimum=1)
        check_int("steps", self.steps, minimum=1)
        if self.dfo is not None:
            if not isinstance(self.dfo, dict):
                raise ValueError(f"dfo must be a dict or None, got {type(self.dfo).__name__}")
            unknown = sorted(set(self.dfo) - set(DFO_OVERRIDES))
            if unknown:
                raise ValueError(f"dfo must hold some of {sorted(DFO_OVERRIDES)}, got {unknown}")
            # the values: checked now, by the config they set, not when the first agent drives
            replace(DFOConfig(), **{DFO_OVERRIDES[k]: v for k, v in self.dfo.items()})
        if not isinstance(self.table_seeds, bool):
            raise ValueError(f"table_seeds must be True or False, got {self.table_seeds!r}")

    def policy_seed(self, name: str) -> int:
        """The seed of driver ``name``'s DFO draws."""
        return table_policy_seed(name) if self.table_seeds else POLICY_SEED

    def record(self) -> dict:
        """The protocol as ``provenance.json`` records it."""
        out = {
            "episodes": self.episodes,
            "steps": self.steps,
            "town": EVAL_TOWN,
            "seed": EVAL_SEED,
            "policy_seed": "training seed" if self.table_seeds else POLICY_SEED,
        }
        if self.dfo:
            out["dfo"] = dict(sorted(self.dfo.items()))
        return out


def run_drives(
    folder, out, protocol: DriveProtocol = DriveProtocol(), *, only=None, log=print, command: str = ""
) -> list[str]:
    """Drive each agent of ``folder``, and the expert, without a file in ``out/drives``; the names driven.

    ``protocol``: the episodes, an energy agent's DFO and the policy seeds (``DriveProtocol``), the same for
    every invocation on one ``out``; ``only``: these driver names alone; ``command``: the command line,
    recorded in ``out/provenance.json`` (``ibc-tutorial stems drive``)."""
    if not isinstance(protocol, DriveProtocol):
        raise ValueError(f"protocol must be a DriveProtocol, got {type(protocol).__name__}")
    out = Path(out)

    def drive_one(name, ck, path):
        drive_arrays = drive(
            ck, protocol.episodes, protocol.steps, dfo=protocol.dfo, policy_seed=protocol.policy_seed(name)
        )
        write_npz(path, drive_arrays)

    path_of = lambda name: out / "drives" / f"{name}.npz"  # noqa: E731
    return run_missing_recorded(
        drivers(folder), out, protocol.record(), path_of, drive_one, only=only, log=log, command=command
    )


def drive_file(folder, out, name: str) -> Path | None:
    """The drive file of driver ``name`` (``<method>-seed<k>`` or "expert"): ``out/drives/<name>.npz`` if
    there, else the one a replication recorded in its run folder (``replication_folder.STEM_DRIVE``), else
    None."""
    own = Path(out) / "drives" / f"{name}.npz"
    if own.exists():
        return own
    if name == "expert":
        rec = expert_dir(folder) / STEM_DRIVE
    else:
        method, seed = name.rsplit("-seed", 1)
        rec = run_dir(folder, method, int(seed)) / STEM_DRIVE
    return rec if rec.exists() else None


def load_drive(path) -> dict:
    """A drive file: ``{"rows", "episodes": [{lane, pose, ...}], "obs": {episode, t, bev, state} or None}``"""
    with np.load(path) as z:
        rows = json.loads(str(z["rows"]))
        eps = [{k: z[f"e{i}_{k}"] for k in TRACE} for i in range(len(rows))]
        obs = None
        if "obs_t" in z.files:
            obs = {"episode": z["obs_episode"], "t": z["obs_t"], "bev": z["obs_bev"], "state": z["obs_state"]}
    return {"rows": rows, "episodes": eps, "obs": obs}


def unpack_bev(bits: np.ndarray) -> np.ndarray:
    """(N, 5, S, S) float32 BEVs from the bit-packed (N, 5, S, S / 8) of a drive file."""
    return np.unpackbits(bits, axis=-1).astype(np.float32)
