"""The steering-only road-following task of the steering-EBM paper, in the town (chapter 10).

**The task.** The paper's models steer only; speed is not their job. Here the longitudinal control
is the PID expert's (``driving.expert``): its speed PID and its stops at red (and stoppable yellow)
lights, with one change, ``longitudinal_config``: the target speed is ``preset.speed`` (6 m/s, the
expert's cruise speed) everywhere, in turns too, and the throttle is not scaled down while
steering. With the expert's own settings the car slows to 4.5 m/s before a turn, so the speed
would tell the model which way the expert was going to go.

**The observation**: the five-channel BEV as the environment renders it (``DrivingEnv``; road,
lane lines, stop lines with their lights), which shows no route, and the speed. The driving
agents' state also holds the previous steer and acceleration; here both entries are set to 0
(``steering_observation``), because the previous steer shows that a turn has begun. So at a side
road the observation is ambiguous: the same picture led the expert straight on most times and
into the side road a few times.

**The data**: town01 routes (``demo_route``) on which, wherever the road goes on past a side road,
the expert takes the side road with probability ``preset.side_road_share`` (15 %) and keeps
straight otherwise; at the stem of a T (no straight exit) it turns left or right with equal
chance. ``side_road_counts`` measures the realised share. As in ``driving.collect``, short
steering perturbations are executed (not labelled), so the data shows how to come back to the
lane. The model's label is the expert's steering command, in [-1, 1] (+1 = right).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from ibc_tutorial.driving.analysis import exit_counts, log_junction_visits
from ibc_tutorial.driving.collect import Recorder
from ibc_tutorial.driving.dataset import DemoDataset, DemoLog
from ibc_tutorial.driving.expert import Expert, ExpertConfig
from ibc_tutorial.driving.routes import Route, random_route, uniform_exit
from ibc_tutorial.driving.sim import DrivingSim
from ibc_tutorial.driving.towns import Town, get_town
from ibc_tutorial.utils import check_int, check_positive, check_probability

DEMO_TOWN = "town01"
"""Where the demonstrations are driven (the paper's data and its test road differ; so do the towns)."""


def longitudinal_config(speed: float = 6.0, steer_noise: float = 0.0) -> ExpertConfig:
    """The expert's settings with one target speed everywhere and an unscaled throttle (see the module
    docstring)."""
    speed = check_positive("speed", speed)
    return replace(
        ExpertConfig(),
        cruise_speed=speed,
        turn_speed=speed,
        min_throttle_scale=1.0,
        steer_noise=check_positive("steer_noise", steer_noise, allow_zero=True),
    )


def steering_observation(obs: dict) -> dict:
    """``{"bev", "state"}`` batch -> the same with the state reduced to the speed: [speed, 0, 0] (B, 3).

    Works on numpy arrays and torch tensors; the BEV is passed on untouched (whatever the
    environment renders)."""
    state = obs["state"]
    if isinstance(state, torch.Tensor):
        out = torch.zeros_like(state, dtype=torch.float32)  # (B, 3)
    else:
        out = np.zeros(np.shape(state), dtype=np.float32)  # (B, 3)
    out[:, 0] = state[:, 0]  # speed (m/s); previous steer and acceleration hidden
    return {"bev": obs["bev"], "state": out}


def demo_route(
    town: Town,
    rng: np.random.Generator,
    side_road_share: float,
    n_turns: int = 64,
    start: tuple[int, float] | None = None,
) -> Route:
    """A route whose turns keep straight past side roads except with probability ``side_road_share``.

    At an approach with a straight exit the turn is "straight", or, with probability
    ``side_road_share``, the other exit (the side road); at an approach without one (the stem of a
    T) left and right are equally likely. Corners take no choice."""
    p = check_probability("side_road_share", side_road_share)

    def keep_straight_mostly(exits: list[str], rng: np.random.Generator) -> str:
        if "straight" in exits:
            side = [e for e in exits if e != "straight"]
            return side[0] if rng.random() < p else "straight"
        return uniform_exit(exits, rng)  # the stem of a T: left or right

    return random_route(town, rng, n_turns, start, choose=keep_straight_mostly)


def collect_demonstrations(
    routes: int,
    minutes: float,
    side_road_share: float,
    *,
    speed: float = 6.0,
    steer_noise: float = 0.3,
    seed: int = 0,
) -> DemoLog:
    """Drive ``routes`` town01 routes of ``minutes`` each (``demo_route``) and log states and actions.

    The label is the expert's action (its steering is what the models learn); the executed action
    carries the steering perturbations. Meta: the settings, each route, how each ended."""
    check_int("routes", routes, minimum=1)
    minutes = check_positive("minutes", minutes)
    check_int("seed", seed, minimum=0)
    sim = DrivingSim(DEMO_TOWN)
    expert = Expert(sim, longitudinal_config(speed, steer_noise), seed=seed)
    rec = Recorder(sim)
    steps = int(round(minutes * 600))  # 10 Hz
    meta_routes, ended = [], []
    for k in range(routes):
        rng = np.random.default_rng([seed, k])
        route = demo_route(sim.town, rng, side_road_share)
        sim.reset(rng, route=route)
        meta_routes.append(
            {"start_lane": route.start_lane, "start_s": route.start_s, "turns": list(route.turns)}
        )
        reason = "completed"
        for _ in range(steps):
            action = expert.act()
            executed = expert.perturb(action)
            rec.record(k, action, executed, expert.current_lane)
            sim.step(float(executed[0]), float(executed[1]))
            if sim.terminated:
                reason = sim.termination_reason
                break
        ended.append({"steps": int(sim.t), "distance_m": round(sim.distance, 1), "end": reason})
    config = {
        "town": DEMO_TOWN,
        "routes": routes,
        "minutes": minutes,
        "side_road_share": side_road_share,
        "speed": speed,
        "steer_noise": steer_noise,
        "seed": seed,
    }
    return rec.log(
        {"config": config, "routes": meta_routes, "episodes": ended, "expert": "longitudinal_config"}
    )


def preset_demonstrations(preset, path) -> DemoLog:
    """The demonstrations a steering preset asks for (``collect_demonstrations`` with its routes,
    minutes, side-road share, speed, steering noise and seed), collected into ``path`` unless that
    file already exists (a resumed study), then loaded from it."""
    path = Path(path)
    if not path.exists():
        demo = collect_demonstrations(
            preset.routes,
            preset.route_minutes,
            preset.side_road_share,
            speed=preset.speed,
            steer_noise=preset.steer_noise,
            seed=preset.collect_seed,
        )
        demo.save(path)
    return DemoLog.load(path)


def side_road_counts(log: DemoLog) -> dict:
    """How often the log's expert passed side roads straight on and took them, and how it left stems.

    Returns ``{"straight": n, "side_road": n, "share": side_road / (straight + side_road),
    "stem": {"left": n, "right": n}}`` counted from the lanes driven (``analysis.exit_counts``)."""
    town = get_town(log.town)
    through, stem = Counter(), Counter()
    for ap, counts in exit_counts(log_junction_visits(log)).items():
        if "straight" in town.approaches[ap].exits:
            through["straight"] += counts.get("straight", 0)
            through["side_road"] += counts.get("left", 0) + counts.get("right", 0)
        else:
            stem.update(counts)
    n = through["straight"] + through["side_road"]
    return {
        "straight": through["straight"],
        "side_road": through["side_road"],
        "share": through["side_road"] / n if n else float("nan"),
        "stem": {"left": stem.get("left", 0), "right": stem.get("right", 0)},
    }


class SteeringBatches:
    """Demonstrations as ``training.Minibatches`` for a steering model.

    ``batch(indices)`` gives ``{"obs": {"bev", "state"}, "actions": (B, 1) steering}`` with the
    state reduced to the speed (``steering_observation``). With ``pairs=True`` the samples are
    the frames t that have a successor t + 1 in the same episode, and each batch also holds
    ``next_obs`` and ``next_actions`` (temporal smoothing, eq. 4 of the steering-EBM paper; the
    paper samples "sequences of two consecutive frames").
    """

    def __init__(self, dataset: DemoDataset, pairs: bool = False):
        self.dataset = dataset
        self.pairs = bool(pairs)
        ep = dataset.log.episode
        self.index = np.flatnonzero(ep[1:] == ep[:-1]) if self.pairs else np.arange(len(dataset))  # (P,)
        if len(self.index) == 0:
            raise ValueError("the demonstrations hold no two consecutive frames of one episode")

    def __len__(self) -> int:
        return len(self.index)

    def _frames(self, rows: np.ndarray) -> tuple[dict, torch.Tensor]:
        obs, actions = self.dataset.batch(rows)  # {"bev": (B, 5, S, S), "state": (B, 3)}, (B, 2)
        return steering_observation(obs), actions[:, :1]  # steering only: (B, 1)

    def batch(self, indices) -> dict:
        rows = self.index[np.asarray(indices, dtype=np.int64).reshape(-1)]  # (B,)
        obs, steer = self._frames(rows)
        out = {"obs": obs, "actions": steer}
        if self.pairs:
            out["next_obs"], out["next_actions"] = self._frames(rows + 1)
        return out
