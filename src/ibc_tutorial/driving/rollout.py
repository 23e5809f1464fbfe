"""Closed-loop episodes of a policy, batched over environments: the one loop over the driving environment.

The DA-IBC paper scores an agent over 10 episodes of 3000 steps in town02 (its Fig. 4). Here
the episodes run side by side, so that a neural policy is called once per step on a batch of
observations rather than once per episode and step:

    results = rollout(policy, EnvConfig("town02", bev_size=64, max_steps=3000), episodes=10, seed=0)

``policy`` is a ``DrivingPolicy`` (below), or the string ``"expert"`` for the PID expert. Each
episode runs in an environment of the given ``EnvConfig`` for at most its ``max_steps`` steps;
episode ``i`` starts from ``env.reset(seed=seed + i)``, so two policies evaluated with the same
``seed`` meet the same starts and the same light phases.

The same loop serves three uses, chosen by a ``RolloutRecording``: scores only (the
evaluation), the car's positions (``xy``: the free-driving trajectories), and a per-step record
of where the car was and what it saw (``steps``, optionally with the observations: ``obs``),
from which the Fig. 6 moments (a junction, a red light) are picked. The demonstrations are collected by
``driving.collect`` on the simulator itself, not here: the expert drives fixed routes there,
with steering perturbations, which the Gymnasium environment does not model.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ibc_tutorial.driving.env import DrivingEnv, EnvConfig, make_env
from ibc_tutorial.driving.expert import Expert
from ibc_tutorial.driving.lights import GREEN
from ibc_tutorial.utils import check_int, progress

DrivingPolicy = Callable[[dict[str, np.ndarray]], np.ndarray]
"""A closed-loop policy in the town, the one form every driving policy of the book takes:
``policy({"bev": float32 (B, 5, S, S), "state": float32 (B, 3)}) -> actions (B, 2)`` on numpy
batches (B = the episodes still running), actions (steer, acceleration) in [-1, 1]
(``experiments.agents.Agent.policy(seed)`` makes one from a trained agent). On routes with commands
(``route_following.drive_routes``) the batch also holds ``"command"``, (B,) int64."""

StepHook = Callable[[int, list[int], dict[str, np.ndarray]], None]
"""``on_step(t, episodes, batch)``: see ``RolloutRecording.on_step``."""

TRACE_KEYS = ("pose", "speed", "lane", "red_ahead", "entry_dist")
"""Per-state entries of ``EpisodeResult.trace`` (besides ``actions``, ``bev`` and ``state``)."""


@dataclass(frozen=True)
class RolloutRecording:
    """What ``rollout`` keeps of each episode besides its score, and who may watch it run."""

    xy: bool = True
    """Keep the car's positions, the start included, in ``EpisodeResult.xy``."""
    steps: bool = False
    """Keep the per-step record (pose, speed, lane, lights ahead, actions) in ``EpisodeResult.trace``."""
    obs: bool = False
    """With ``steps``, keep the observations (``bev``, ``state``) in the trace too."""
    on_step: StepHook | None = None
    """Called as ``on_step(t, episodes, batch)`` before the policy acts at step t (0-based), with
    the indices of the running episodes (the rows of ``batch``) and the observations the policy
    is about to see; it must not change them (not called for the expert)."""

    def __post_init__(self) -> None:
        for name in ("xy", "steps", "obs"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be True or False, got {getattr(self, name)!r}")
        if self.obs and not self.steps:
            raise ValueError("obs needs steps=True (the observations are kept in the per-step record)")
        if self.on_step is not None and not callable(self.on_step):
            raise ValueError(f"on_step must be callable or None, got {type(self.on_step).__name__}")


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
    trace: dict = field(repr=False, default=None)
    """With ``RolloutRecording.steps``: arrays over the T + 1 states (the start included): ``pose`` (T+1, 3),
    ``speed`` (T+1,), ``lane`` (T+1,) (the lane whose waypoint is nearest, heading aligned),
    ``red_ahead`` (T+1,) (the light of the approach the car is on shows red or yellow),
    ``entry_dist`` (T+1,) (metres to that approach's junction entry, inf off approaches),
    ``actions`` (T, 2); with ``RolloutRecording.obs`` also ``bev`` (T+1, 5, S, S) and ``state`` (T+1, 3)."""


class _Trace:
    """The per-step record of one episode (see ``EpisodeResult.trace``)."""

    def __init__(self, env: DrivingEnv, keep_obs: bool):
        self.env, self.keep_obs = env, keep_obs
        self.rows: dict[str, list] = {k: [] for k in TRACE_KEYS + ("actions", "bev", "state")}

    def note(self, obs: dict, info: dict) -> None:
        tw, r = self.env.town, self.rows
        x, y, yaw = info["x"], info["y"], info["yaw"]
        lane, _, _ = tw.localize(x, y, yaw)
        ap = tw.approach_of_lane.get(lane)
        red, dist = False, float("inf")
        if ap is not None and ap in tw.light_of_approach:
            light = tw.light_of_approach[ap]
            red = bool(self.env.sim.light_history()[2, light] != GREEN)  # red or yellow now
            dist = float(np.hypot(*(np.asarray(tw.stop_lines[light].entry) - (x, y))))
        r["pose"].append((x, y, yaw))
        r["speed"].append(info["speed"])
        r["lane"].append(lane)
        r["red_ahead"].append(red)
        r["entry_dist"].append(dist)
        if self.keep_obs:
            r["bev"].append(obs["bev"])
            r["state"].append(obs["state"])

    def arrays(self) -> dict[str, np.ndarray]:
        out = {k: np.asarray(self.rows[k]) for k in TRACE_KEYS}
        out["pose"] = out["pose"].astype(np.float64)
        out["actions"] = np.asarray(self.rows["actions"], dtype=np.float64).reshape(-1, 2)
        if self.keep_obs:
            out["bev"], out["state"] = np.stack(self.rows["bev"]), np.stack(self.rows["state"])
        return out


def rollout(
    policy: DrivingPolicy | str,
    env: EnvConfig,
    episodes: int = 10,
    seed: int = 0,
    *,
    record: RolloutRecording = RolloutRecording(),
    show_progress: bool | None = None,
) -> list[EpisodeResult]:
    """Run ``episodes`` episodes of at most ``env.max_steps`` steps side by side; return one result each.

    Actions are clipped to [-1, 1] (a NaN still raises the environment's ValueError).

    Args:
        policy: a ``DrivingPolicy`` or "expert".
        env: the environments' settings (town, BEV size and light encoding, routes or none,
            ``max_steps`` the length of an episode).
        episodes: how many episodes, side by side.
        seed: episode ``i`` starts from ``reset(seed=seed + i)``.
        record: what to keep besides the scores (``RolloutRecording``: positions by default).
        show_progress: a progress bar over the steps (None: tqdm's default, silent under ``TQDM_DISABLE``).
    """
    episodes = check_int("episodes", episodes, minimum=1)
    seed = check_int("seed", seed, minimum=0)
    if isinstance(policy, str) and policy != "expert":
        raise ValueError(f"policy must be a callable or 'expert', got {policy!r}")
    if not isinstance(policy, str) and not callable(policy):
        raise ValueError(f"policy must be a callable or 'expert', got {type(policy).__name__}")
    if not isinstance(env, EnvConfig):
        raise ValueError(f"env must be an EnvConfig, got {type(env).__name__}")
    if not isinstance(record, RolloutRecording):
        raise ValueError(f"record must be a RolloutRecording, got {type(record).__name__}")
    town, steps, on_step = env.town, env.max_steps, record.on_step
    envs = [make_env(config=env) for _ in range(episodes)]
    obs, infos = zip(*(e.reset(seed=seed + i) for i, e in enumerate(envs)), strict=True)
    obs, infos = list(obs), list(infos)
    experts = [Expert(env) for env in envs] if policy == "expert" else None
    tracks = [[(info["x"], info["y"])] for info in infos]
    traces = [_Trace(e, record.obs) for e in envs] if record.steps else None
    if traces:
        for i in range(episodes):
            traces[i].note(obs[i], infos[i])
    active = list(range(episodes))
    done_info: dict[int, dict] = {}
    bar = progress(total=steps, desc=f"{episodes} episodes in {town}", enabled=show_progress)
    for t in range(steps):
        if not active:
            break
        if experts is not None:
            actions = np.stack([experts[i].act() for i in active])  # (B, 2)
        else:
            batch = {
                "bev": np.stack([obs[i]["bev"] for i in active]),  # (B, 5, S, S) float32
                "state": np.stack([obs[i]["state"] for i in active]),
            }  # (B, 3) float32
            if on_step is not None:
                on_step(t, list(active), batch)
            actions = np.asarray(policy(batch), dtype=np.float64).reshape(len(active), 2)
            with np.errstate(invalid="ignore"):
                actions = np.where(np.isnan(actions), actions, np.clip(actions, -1.0, 1.0))
        still = []
        for k, i in enumerate(active):
            obs[i], _, terminated, truncated, info = envs[i].step(actions[k])
            if record.xy:
                tracks[i].append((info["x"], info["y"]))
            if traces:
                traces[i].rows["actions"].append(actions[k])
                traces[i].note(obs[i], info)
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
        results.append(
            EpisodeResult(
                seed + i,
                info["step"],
                info["distance_m"],
                info["red_light_infractions"],
                info["score"],
                bool(info["termination"]),
                info["termination"],
                np.array(tracks[i]) if record.xy else None,
                traces[i].arrays() if traces else None,
            )
        )
    return results
