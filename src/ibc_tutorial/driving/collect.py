"""Collecting demonstrations: the expert drives routes and every step's state and action is logged.

Like the DA-IBC paper's dataset (its sec. 4.1): ten routes in town01, recorded at 10 Hz, the
shortest 2.5 minutes and about 3.5 minutes on average, about 21,000 samples in all. A route
here is a random start and a random list of junction choices (``routes.random_route``), and
the durations are spread evenly between ``min_minutes`` and ``max_minutes``. Small steering
perturbations (``steer_noise``) and, optionally, held brakes (``brake_noise``) widen the states
seen; the label is always the expert's own action (``driving.expert``). Routeless collection
(random exits chosen on the way) is offered too.

    ibc-tutorial collect --town town01 --routes 10 --seed 0 --out data/town01.npz

(The command line checks ``--out`` before driving, and never overwrites an existing file unless
``--force`` is given: ``ibc_tutorial.cli``.)
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ibc_tutorial.driving.dataset import DemoLog
from ibc_tutorial.driving.env import MAX_SPEED
from ibc_tutorial.driving.expert import Expert, ExpertConfig
from ibc_tutorial.driving.routes import random_route
from ibc_tutorial.driving.sim import DrivingSim
from ibc_tutorial.driving.towns import TOWNS
from ibc_tutorial.utils import check_choice, check_fraction, check_int, check_positive, progress


@dataclass(frozen=True)
class CollectConfig:
    """What to collect."""

    town: str = "town01"
    """Town to drive (the paper collects in town01)."""
    routes: int = 10
    """Number of routes (episodes); the paper has 10."""
    seed: int = 0
    """Seeds the routes, their durations, the light phases and the steering noise."""
    min_minutes: float = 2.5
    """Shortest route duration (the paper's shortest route: 1480 samples, 2.5 min)."""
    max_minutes: float = 4.5
    """Longest route duration; with 2.5 this averages 3.5 min, the paper's mean (2129 samples)."""
    routeless: bool = False
    """True: no fixed route, the expert picks a random exit at each junction on the way."""
    steer_noise: float = 0.3
    """Size of the expert's steering perturbations during collection (0 = none)."""
    brake_noise: float = 0.0
    """Strength of the expert's braking perturbations during collection, in [0, 1] (0 = none;
    ``ExpertConfig``)."""
    turn_hold_m: float = 0.0
    """The expert's ``ExpertConfig.turn_hold_m``: > 0 makes every turn begin this far before the junction
    entry, left and right alike (0: turns anticipated along the path, the right turns earlier)."""

    def __post_init__(self):
        check_choice("town", self.town, TOWNS)
        check_int("routes", self.routes, minimum=1)
        check_int("seed", self.seed, minimum=0)
        check_positive("min_minutes", self.min_minutes)
        check_positive("max_minutes", self.max_minutes)
        if self.max_minutes < self.min_minutes:
            raise ValueError(
                f"max_minutes must be >= min_minutes, got {self.max_minutes} < {self.min_minutes}"
            )
        check_positive("steer_noise", self.steer_noise, allow_zero=True)
        check_fraction("CollectConfig.brake_noise", self.brake_noise)
        check_positive("turn_hold_m", self.turn_hold_m, allow_zero=True)


class Recorder:
    """Accumulates the rows of a ``DemoLog`` from a running ``DrivingSim``."""

    def __init__(self, sim: DrivingSim):
        self.sim = sim
        self.rows: dict[str, list] = {
            k: []
            for k in (
                "pose",
                "speed",
                "prev_action",
                "action",
                "executed",
                "lights",
                "episode",
                "step",
                "lane",
            )
        }

    def record(self, episode: int, action, executed, lane: int) -> None:
        """Log the sim's current state with the action chosen in it (call before ``sim.step``)."""
        sim, r = self.sim, self.rows
        r["pose"].append(sim.car.pose)
        r["speed"].append(min(sim.car.speed, MAX_SPEED))
        r["prev_action"].append(sim.prev_action)
        r["action"].append(np.asarray(action, dtype=np.float32))
        r["executed"].append(np.asarray(executed, dtype=np.float32))
        r["lights"].append(sim.lights.copy())
        r["episode"].append(episode)
        r["step"].append(sim.t)
        r["lane"].append(lane)

    def log(self, meta: dict | None = None) -> DemoLog:
        n_lights = self.sim.town.n_lights
        r = self.rows
        arrays = {k: np.array(v) for k, v in r.items()}
        if not r["pose"]:
            arrays = {
                "pose": np.zeros((0, 3)),
                "speed": np.zeros(0),
                "prev_action": np.zeros((0, 2)),
                "action": np.zeros((0, 2)),
                "executed": np.zeros((0, 2)),
                "lights": np.zeros((0, n_lights)),
                "episode": np.zeros(0),
                "step": np.zeros(0),
                "lane": np.zeros(0),
            }
        return DemoLog(self.sim.town.name, meta=meta or {}, **arrays)


def collect(config: CollectConfig = CollectConfig(), show_progress: bool | None = None) -> DemoLog:
    """Drive the expert over ``config.routes`` episodes and return the log."""
    c = config
    sim = DrivingSim(c.town)
    expert = Expert(
        sim,
        ExpertConfig(steer_noise=c.steer_noise, brake_noise=c.brake_noise, turn_hold_m=c.turn_hold_m),
        seed=c.seed,
    )
    rng = np.random.default_rng(c.seed)
    # durations spread evenly over [min, max] (stratified: one draw per 1/routes of the range, shuffled),
    # so the total stays close to routes x the mean duration: 600 steps per minute at 10 Hz
    lo, hi = c.min_minutes * 600, c.max_minutes * 600
    steps = np.round(lo + (hi - lo) * (rng.permutation(c.routes) + rng.random(c.routes)) / c.routes).astype(
        int
    )
    rec = Recorder(sim)
    routes, ended = [], []
    bar = progress(total=int(steps.sum()), desc=f"collecting {c.town}", enabled=show_progress)
    for k in range(c.routes):
        ep_rng = np.random.default_rng([c.seed, k])
        route = None if c.routeless else random_route(sim.town, ep_rng)
        sim.reset(ep_rng, route=route)
        if route is None:
            lane, s = sim.start
            routes.append({"start_lane": int(lane), "start_s": float(s), "turns": None})
        else:
            routes.append(
                {"start_lane": route.start_lane, "start_s": route.start_s, "turns": list(route.turns)}
            )
        reason = "completed"
        for _ in range(int(steps[k])):
            action = expert.act()
            executed = expert.perturb(action)
            rec.record(k, action, executed, expert.current_lane)
            sim.step(float(executed[0]), float(executed[1]))
            bar.update(1)
            if sim.terminated:
                reason = sim.termination_reason
                break
        ended.append(
            {
                "steps": int(sim.t),
                "distance_m": round(sim.distance, 1),
                "red_light_infractions": sim.infractions,
                "end": reason,
            }
        )
    bar.close()
    # what was collected and how; no wall time (the command prints it): identical collections, identical logs
    meta = {"config": asdict(c), "expert": asdict(expert.config), "routes": routes, "episodes": ended}
    return rec.log(meta)
