"""The Gymnasium environment: drive a town from the bird's-eye view, as the DA-IBC paper's agents do.

Observation (the paper's sec. 3.1): ``{"bev": float32 (5, S, S), "state": float32 (3,)}``: the BEV's
road channels are 0/1 and its light channels 0.3 / 0.6 / 1.0 for green / yellow / red (``driving.bev``),
with state = [speed in m/s, previous steer, previous acceleration]. Action: ``Box(-1, 1, (2,))``
= [steer, acceleration (negative brakes)], at 10 Hz. **Steering sign, the whole book's: +1 turns
right, -1 turns left** (CARLA's convention; the world frame is right-handed, so a right turn
decreases the heading). The reward of a
step is the increase of the paper's score, distance x 0.7 ** red-light infractions, so an
episode's return is its score. Terminated when the car leaves the drivable area or touches a
building; truncated after ``max_steps``.

``make_env("town02", bev_size=64)`` or ``gymnasium.make("ibc_tutorial/Town02-v0", bev_size=64)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gymnasium
import numpy as np
from gymnasium import spaces

from ibc_tutorial.driving.bev import LIGHT_ENCODINGS, BEVRenderer, check_bev_size, get_raster
from ibc_tutorial.driving.car import CarConfig
from ibc_tutorial.driving.lights import LightTiming
from ibc_tutorial.driving.routes import Route, random_route
from ibc_tutorial.driving.sim import DrivingSim
from ibc_tutorial.driving.towns import TOWNS
from ibc_tutorial.utils import check_choice, check_int

RESET_OPTIONS = ("route", "start", "light_offsets", "max_steps")
"""Keys ``reset(options=...)`` accepts."""
MAX_SPEED = 30.0
"""Upper bound of the speed entry of the observation (m/s); the car tops out near 20 m/s."""


@dataclass(frozen=True)
class EnvConfig:
    """Settings of a driving environment."""

    town: str = "town01"
    """"town01" (the paper's training town) or "town02" (its evaluation town)."""
    bev_size: int = 192
    """Side of the BEV in pixels: 192 (the paper's) or 96, 64, 48, 32 (same field, OR-pooled)."""
    routeless: bool = True
    """True: no route (the agents' setting; the expert takes random exits). False: each episode
    draws a route (a start and a list of turns) that the expert follows."""
    max_steps: int = 3000
    """Steps (0.1 s each) before the episode is truncated (the paper evaluates over 3000)."""
    car: CarConfig = field(default_factory=CarConfig)
    """The car's physical parameters."""
    lights: LightTiming = field(default_factory=LightTiming)
    """The traffic lights' timing."""
    light_encoding: str = "intensity"
    """How the BEV draws the lights (``bev.LIGHT_ENCODINGS``): by state, or as one "must stop" bit."""

    def __post_init__(self):
        check_choice("town", self.town, TOWNS)
        check_bev_size(self.bev_size)
        check_choice("light_encoding", self.light_encoding, LIGHT_ENCODINGS)
        check_int("max_steps", self.max_steps, minimum=1)
        if not isinstance(self.routeless, bool):
            raise ValueError(f"routeless must be True or False, got {self.routeless!r}")


class DrivingEnv(gymnasium.Env):
    """A town, its traffic lights and one car driven from a five-channel bird's-eye view."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        town: str = "town01",
        bev_size: int = 192,
        routeless: bool = True,
        max_steps: int = 3000,
        render_mode: str | None = None,
        config: EnvConfig | None = None,
        light_encoding: str = "intensity",
    ):
        self.config = (
            config
            if config is not None
            else EnvConfig(town, bev_size, routeless, max_steps, light_encoding=light_encoding)
        )
        if render_mode is not None:
            check_choice("render_mode", render_mode, self.metadata["render_modes"])
        self.render_mode = render_mode
        c = self.config
        self.sim = DrivingSim(c.town, c.car, c.lights)
        self.town = self.sim.town
        self.renderer = BEVRenderer(get_raster(c.town), c.bev_size, c.light_encoding)
        self._full_renderer = (
            self.renderer if c.bev_size == 192 else BEVRenderer(get_raster(c.town), 192, c.light_encoding)
        )
        S = c.bev_size
        self.observation_space = spaces.Dict(
            {
                "bev": spaces.Box(0.0, 1.0, (5, S, S), dtype=np.float32),
                "state": spaces.Box(
                    np.array([0.0, -1.0, -1.0], dtype=np.float32),
                    np.array([MAX_SPEED, 1.0, 1.0], dtype=np.float32),
                    dtype=np.float32,
                ),
            }
        )
        self.action_space = spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.route: Route | None = None
        self._max_steps = c.max_steps
        self._done = True
        self._last_score = 0.0

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode; ``options`` may hold "route" (a ``Route``), "start" ((lane, s): where the
        car starts), "light_offsets" ((J,) phase of each junction's cycle in steps) and "max_steps"
        (this episode's length). Anything not given is drawn from the seeded generator."""
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - set(RESET_OPTIONS)
        if unknown:
            raise ValueError(f"options may hold {RESET_OPTIONS}, got {sorted(unknown)}")
        route = options.get("route")
        if route is not None and not isinstance(route, Route):
            raise ValueError(f"options['route'] must be a Route, got {type(route).__name__}")
        start = options.get("start")
        if start is not None:
            start = self._check_start(start)
        if route is None and not self.config.routeless:
            route = random_route(self.town, self.np_random, start=start)
        self.route = route
        self._max_steps = check_int(
            "options['max_steps']", options.get("max_steps", self.config.max_steps), minimum=1
        )
        lane, s = (None, None) if start is None else start
        offsets = options.get("light_offsets")
        if offsets is not None:
            offsets = np.asarray(offsets)
            if offsets.shape != (self.town.n_junctions,) or offsets.dtype.kind not in "iu":
                raise ValueError(
                    f"options['light_offsets'] must be {self.town.n_junctions} integers, got {offsets!r}"
                )
        self.sim.reset(self.np_random, lane=lane, s=s, route=route, offsets=offsets)
        self._done = False
        self._last_score = 0.0
        return self._observation(), self.sim.info()

    def step(self, action):
        if self._done:
            raise RuntimeError("the episode has ended: call reset() before step()")
        a = self._check_action(action)
        sim = self.sim
        sim.step(a[0], a[1])
        terminated = sim.terminated
        truncated = (not terminated) and sim.t >= self._max_steps
        self._done = terminated or truncated
        info = sim.info()
        reward = info["score"] - self._last_score
        self._last_score = info["score"]
        return self._observation(), float(reward), terminated, truncated, info

    def render(self):
        """An RGB picture (192, 192, 3) of the car's surroundings: the BEV in colour with the car drawn."""
        from ibc_tutorial.driving.render import bev_to_rgb, draw_ego

        x, y, yaw = self.sim.car.pose
        return draw_ego(
            bev_to_rgb(self._full_renderer.render(x, y, yaw, self.sim.light_history())), self.sim.car.config
        )

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def _check_action(action) -> tuple[float, float]:
        try:
            a = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"action must be 2 numbers [steer, acceleration], got {action!r}") from None
        if a.shape != (2,):
            raise ValueError(f"action must have shape (2,) = [steer, acceleration], got shape {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"action must be finite, got {a.tolist()}")
        if np.abs(a).max() > 1.0 + 1e-6:
            raise ValueError(f"action entries must lie in [-1, 1], got {a.tolist()}")
        a = np.clip(a, -1.0, 1.0)
        return float(a[0]), float(a[1])

    def _check_start(self, start) -> tuple[int, float]:
        try:
            lane, s = start
            lane, s = int(lane), float(s)
        except (TypeError, ValueError):
            raise ValueError(
                f"options['start'] must be (road lane id, arc length in m), got {start!r}"
            ) from None
        if lane not in self.town.road_lanes or not 0 <= s <= self.town.lanes[lane].length:
            raise ValueError(
                f"options['start'] must name a road lane of {self.town.name} and a position on it, got "
                f"{start!r}"
            )
        return lane, s

    def _observation(self) -> dict:
        x, y, yaw = self.sim.car.pose
        bev = self.renderer.render(x, y, yaw, self.sim.light_history())
        steer, acc = self.sim.prev_action
        state = np.array([min(self.sim.car.speed, MAX_SPEED), steer, acc], dtype=np.float32)
        return {"bev": bev, "state": state}


ENV_IDS = {"town01": "ibc_tutorial/Town01-v0", "town02": "ibc_tutorial/Town02-v0"}
"""Gymnasium ids of the two towns."""


def register_envs() -> None:
    """Register ``ENV_IDS`` with Gymnasium (once; importing ``ibc_tutorial.driving`` does it)."""
    for town, env_id in ENV_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(
                id=env_id, entry_point="ibc_tutorial.driving.env:DrivingEnv", kwargs={"town": town}
            )


def make_env(
    town: str = "town01",
    bev_size: int = 192,
    routeless: bool = True,
    max_steps: int = 3000,
    seed: int | None = None,
    render_mode: str | None = None,
    light_encoding: str = "intensity",
    *,
    config: EnvConfig | None = None,
) -> DrivingEnv:
    """A driving environment (see ``DrivingEnv``), made through its Gymnasium id so that it carries
    its spec, without Gymnasium's wrappers; if ``seed`` is given it is reset with it once.

    ``config``, if given, is the whole setting (its town, BEV size, car, lights, ...) and the
    arguments ``town`` to ``max_steps`` and ``light_encoding`` are not used."""
    if config is not None and not isinstance(config, EnvConfig):
        raise ValueError(f"config must be an EnvConfig or None, got {type(config).__name__}")
    if config is None:
        check_choice("town", town, TOWNS)
        settings = dict(
            bev_size=bev_size, routeless=routeless, max_steps=max_steps, light_encoding=light_encoding
        )
    else:
        town, settings = config.town, dict(config=config)
    if render_mode is not None:
        check_choice("render_mode", render_mode, DrivingEnv.metadata["render_modes"])
    register_envs()
    env = gymnasium.make(
        ENV_IDS[town], render_mode=render_mode, disable_env_checker=True, **settings
    ).unwrapped
    if seed is not None:
        check_int("seed", seed, minimum=0)
        env.reset(seed=seed)
    return env
