"""Closed-loop episodes of a policy, batched over environments: the paper's evaluation protocol.

The DA-IBC paper scores an agent over 10 episodes of 3000 steps in town02 (its Fig. 4). Here
the episodes run side by side, so that a neural policy is called once per step on a batch of
observations rather than once per episode and step:

    results = rollout(policy, town="town02", episodes=10, steps=3000, bev_size=64, seed=0)

``policy`` maps ``{"bev": uint8 (B, 5, S, S), "state": float32 (B, 3)}`` (numpy arrays, B = the
episodes still running) to actions (B, 2); or it is the string ``"expert"`` for the PID expert.
Episode ``i`` starts from ``env.reset(seed=seed + i)``, so two policies evaluated with the same
``seed`` meet the same starts and the same light phases.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ibc_tutorial.driving.env import make_env
from ibc_tutorial.driving.expert import Expert
from ibc_tutorial.utils import check_int, progress


@dataclass
class EpisodeResult:
    """What one closed-loop episode achieved."""

    seed: int
    """The seed its environment was reset with."""
    steps: int
    """Steps driven (less than asked if it was terminated)."""
    distance_m: float
    """Distance driven in metres."""
    red_light_infractions: int
    """Red lights run."""
    score: float
    """The paper's score: distance x 0.7 ** infractions."""
    terminated: bool
    """True if it left the road or hit a building."""
    termination: str
    """"off_road", "building" or "" (drove to the end)."""
    xy: np.ndarray = field(repr=False, default=None)
    """(steps + 1, 2) the car's positions, the start included (if recorded)."""


def rollout(policy: Callable | str, town: str = "town02", episodes: int = 10, steps: int = 3000, bev_size: int = 64,
            seed: int = 0, routeless: bool = True, record_xy: bool = True, show_progress: bool | None = None) -> list[EpisodeResult]:
    """Run ``episodes`` episodes of at most ``steps`` steps side by side; return one result each.

    Actions are clipped to [-1, 1] (a NaN still raises the environment's ValueError).
    """
    episodes = check_int("episodes", episodes, minimum=1)
    steps = check_int("steps", steps, minimum=1)
    seed = check_int("seed", seed, minimum=0)
    if isinstance(policy, str) and policy != "expert":
        raise ValueError(f"policy must be a callable or 'expert', got {policy!r}")
    if not isinstance(policy, str) and not callable(policy):
        raise ValueError(f"policy must be a callable or 'expert', got {type(policy).__name__}")
    envs = [make_env(town, bev_size=bev_size, routeless=routeless, max_steps=steps) for _ in range(episodes)]
    obs, infos = zip(*(env.reset(seed=seed + i) for i, env in enumerate(envs)))
    obs, infos = list(obs), list(infos)
    experts = [Expert(env) for env in envs] if policy == "expert" else None
    tracks = [[(info["x"], info["y"])] for info in infos]
    active = list(range(episodes))
    done_info: dict[int, dict] = {}
    bar = progress(total=steps, desc=f"{episodes} episodes in {town}", enabled=show_progress)
    for _ in range(steps):
        if not active:
            break
        if experts is not None:
            actions = np.stack([experts[i].act() for i in active])
        else:
            batch = {"bev": np.stack([obs[i]["bev"] for i in active]), "state": np.stack([obs[i]["state"] for i in active])}
            actions = np.asarray(policy(batch), dtype=np.float64).reshape(len(active), 2)
            with np.errstate(invalid="ignore"):
                actions = np.where(np.isnan(actions), actions, np.clip(actions, -1.0, 1.0))
        still = []
        for k, i in enumerate(active):
            obs[i], _, terminated, truncated, info = envs[i].step(actions[k])
            if record_xy:
                tracks[i].append((info["x"], info["y"]))
            if terminated or truncated:
                done_info[i] = info
            else:
                still.append(i)
        active = still
        bar.update(1)
    bar.close()
    results = []
    for i in range(episodes):
        info = done_info.get(i) or envs[i].sim.info()
        results.append(EpisodeResult(seed + i, info["step"], info["distance_m"], info["red_light_infractions"], info["score"],
                                     bool(info["termination"]), info["termination"],
                                     np.array(tracks[i]) if record_xy else None))
    return results
