"""The simulation core shared by the Gymnasium environment and the data collector.

One control step (``docs/design.md``, the data flow): action -> car (pymunk, 2 physics substeps) -> pose ->
lights advance -> red-light infractions checked -> off-road and building collisions checked.
No observation is rendered here: the environment renders the BEV, the collector stores only
the state it is rendered from.
"""

from __future__ import annotations

import math

import numpy as np
import pymunk

from ibc_tutorial.driving.bev import HISTORY_LAGS, get_raster
from ibc_tutorial.driving.car import BUILDING_COLLISION_TYPE, CAR_COLLISION_TYPE, Car, CarConfig
from ibc_tutorial.driving.lights import LightSchedule, LightTiming, RedLightMonitor
from ibc_tutorial.driving.routes import random_start
from ibc_tutorial.driving.towns import get_town
from ibc_tutorial.utils import check_positive

SCORE_PENALTY = 0.7
"""Factor applied to the distance per red-light infraction (CARLA leaderboard; the DA-IBC paper's score)."""


def score(distance_m: float, infractions: int) -> float:
    """The DA-IBC paper's episode score: distance driven x 0.7 ** (red-light infractions)."""
    return float(distance_m) * SCORE_PENALTY ** int(infractions)


class DrivingSim:
    """A town, its lights and one car; ``step`` advances one 0.1 s control step."""

    def __init__(self, town: str = "town01", car: CarConfig | None = None, timing: LightTiming | None = None):
        car = CarConfig() if car is None else car  # the defaults: CarConfig(), LightTiming()
        timing = LightTiming() if timing is None else timing
        self.town = get_town(town)
        self.raster = get_raster(town)
        self.space = pymunk.Space()
        for poly in self.town.buildings:
            shape = pymunk.Poly(self.space.static_body, [tuple(p) for p in poly])
            shape.collision_type = BUILDING_COLLISION_TYPE
            self.space.add(shape)
        self.space.on_collision(CAR_COLLISION_TYPE, BUILDING_COLLISION_TYPE, begin=self._on_building)
        self.car = Car(self.space, car)
        self.dt = 1.0 / car.physics_hz
        self._lags = np.array(HISTORY_LAGS)
        self.schedule = LightSchedule(self.town.stop_lines, self.town.n_junctions, timing)
        self.monitor = RedLightMonitor(self.town.stop_lines)
        self.offsets = np.zeros(self.town.n_junctions, dtype=np.int64)
        self.t = 0
        self.distance = 0.0
        self.prev_action = (0.0, 0.0)
        self.collided = False
        self.ran_lights: list[int] = []
        self.lights = self.schedule.states(0, self.offsets)
        self.route = None
        self.episode = 0
        self.episode_seed = 0

    def _on_building(self, arbiter, space, data) -> None:
        self.collided = True

    # ------------------------------------------------------------------ episode
    def reset(
        self,
        rng: np.random.Generator,
        lane: int | None = None,
        s: float | None = None,
        offsets: np.ndarray | None = None,
        route=None,
        speed: float = 0.0,
    ) -> None:
        """Start an episode: random light phases, the car on ``lane`` at arc length ``s`` (both random when
        None), or at the start of ``route`` (a ``routes.Route``) if given, at rest or moving forward at
        ``speed`` (m/s; the stem twins of ``driving.collect`` start at cruising speed)."""
        check_positive("speed", speed, allow_zero=True)
        if route is not None:
            lane, s = route.start_lane, route.start_s
        self.route = route
        self.episode += 1
        self.episode_seed = int(rng.integers(2**31))  # seeds the routeless expert's choices
        self.offsets = (
            self.schedule.random_offsets(rng) if offsets is None else np.asarray(offsets, dtype=np.int64)
        )
        if lane is None:
            lane, s = random_start(self.town, rng)
        ln = self.town.lanes[lane]
        s = float(np.clip(0.0 if s is None else s, 0.0, ln.length))
        (p,), (h,) = ln.sample(np.array([s]))
        self.car.reset(float(p[0]), float(p[1]), float(h), speed=float(speed))
        self.start = (lane, s)
        self.t = 0
        self.distance = 0.0
        self.prev_action = (0.0, 0.0)
        self.collided = False
        self.ran_lights = []
        self.monitor.reset()
        self._table = self.schedule.table(self.offsets)  # (period, L): light states by step
        self.lights = self._table[0]
        self._off_road = not self.raster.is_drivable(float(p[0]), float(p[1]))

    # ------------------------------------------------------------------ step
    def step(self, steer: float, acc: float) -> None:
        """Apply (steer, acc) for one control step (``CarConfig.substeps`` physics steps)."""
        car = self.car
        x0, y0, _ = car.pose
        rear0 = car.rear()
        car.set_controls(steer, acc)
        for _ in range(car.config.substeps):
            self.space.step(self.dt)
        x1, y1, _ = car.pose
        self.distance += math.hypot(x1 - x0, y1 - y0)
        self.t += 1
        self.lights = self._table[self.t % len(self._table)]
        self.ran_lights = self.monitor.update(rear0, car.rear(), self.lights)
        self.prev_action = (float(steer), float(acc))
        self._off_road = not self.raster.is_drivable(x1, y1)

    # ------------------------------------------------------------------ queries
    @property
    def infractions(self) -> int:
        """Red lights run in this episode."""
        return self.monitor.count

    @property
    def off_road(self) -> bool:
        """True if the car's centre has left the drivable area (checked after each step)."""
        return self._off_road

    @property
    def terminated(self) -> bool:
        """True after leaving the road or touching a building."""
        return self.collided or self.off_road

    @property
    def termination_reason(self) -> str:
        """ "building", "off_road" or "" (still driving)."""
        return "building" if self.collided else ("off_road" if self.off_road else "")

    @property
    def score(self) -> float:
        return score(self.distance, self.infractions)

    def lights_at(self, t) -> np.ndarray:
        """Light states (L,) at step ``t`` of this episode (or (T, L) for T steps)."""
        return self._table[np.asarray(t) % len(self._table)]

    def light_history(self, t: int | None = None) -> np.ndarray:
        """(3, L) uint8 light states (0 green, 1 yellow, 2 red) at the BEV's three history lags."""
        t = self.t if t is None else t
        steps = np.maximum(t - self._lags, 0) % len(self._table)  # clamped at the episode start
        return self._table[steps]

    def info(self) -> dict:
        """What ``env.step`` reports in ``info``."""
        x, y, yaw = self.car.pose
        return {
            "distance_m": self.distance,
            "red_light_infractions": self.infractions,
            "score": self.score,
            "x": x,
            "y": y,
            "yaw": yaw,
            "speed": self.car.speed,
            "step": self.t,
            "ran_red_light": bool(self.ran_lights),
            "collision": self.collided,
            "off_road": self.off_road,
            "termination": self.termination_reason,
        }
