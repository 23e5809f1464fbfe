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
from typing import NamedTuple

import numpy as np

from ibc_tutorial.driving.dataset import DemoLog
from ibc_tutorial.driving.env import MAX_SPEED
from ibc_tutorial.driving.expert import Expert, ExpertConfig
from ibc_tutorial.driving.routes import Route, random_route
from ibc_tutorial.driving.sim import DrivingSim
from ibc_tutorial.driving.stems import EXITS, stem_approaches
from ibc_tutorial.driving.towns import TOWNS, get_town
from ibc_tutorial.utils import check_choice, check_fraction, check_int, check_positive, progress

GIVEN_ROUTE_STREAM = 1_000_033
"""Mixed into the seed of an episode's generator when ``collect`` is given its routes."""
TWIN_STREAM = 1_000_003
"""Mixed into the seed of the stem twins' generators, so that they never share a stream with a route."""
MAX_TWIN_STEPS = 300
"""Most steps of one stem twin episode (30 s)."""
TWIN_GREEN_STEPS = 80
"""Steps for which a twin's stem light stays green from its start (8 s: the approach and the turn)."""


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
    stem_twins: int = 0
    """Twin pairs per stem of the town, after the routes (``episode_plan``): each pair crosses one stem left
    and right from the identical state, so that the stem is a state with two answers (0 = none)."""
    twin_start_m: tuple[float, float] = (10.0, 18.0)
    """Range of the distance before the stem's junction entry at which a twin pair starts (metres, drawn
    uniformly per pair)."""
    twin_after_steps: int = 10
    """Steps a twin episode goes on after the car has left the stem's junction."""

    def __post_init__(self):
        check_choice("town", self.town, TOWNS)
        check_int("routes", self.routes, minimum=0 if self.stem_twins else 1)
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
        check_int("stem_twins", self.stem_twins, minimum=0)
        check_int("twin_after_steps", self.twin_after_steps, minimum=1)
        lo, hi = (check_positive("twin_start_m", v) for v in self.twin_start_m)
        if not 5.0 <= lo <= hi:
            raise ValueError(
                f"twin_start_m must be (low, high) with 5 <= low <= high metres, got {self.twin_start_m}"
            )
        if self.stem_twins and self.routeless:
            raise ValueError("stem_twins needs routes (routeless=False): a twin's turn is set by its route")


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


class EpisodePlan(NamedTuple):
    """How one episode of a collection starts."""

    rng: np.random.Generator
    """The episode's generator, after its route was drawn from it: ``DrivingSim.reset`` draws from it next."""
    route: Route | None
    """The route the expert follows (None when routeless)."""
    offsets: np.ndarray | None
    """(J,) the junctions' light phases (None: drawn by ``reset`` from ``rng``)."""
    record: dict
    """What the log's meta records of it besides its start: ``turns``, and a twin's ``stem`` and ``pair``."""


def episode_plan(sim: DrivingSim, config: CollectConfig, k: int) -> EpisodePlan:
    """Episode ``k`` of the collection ``config``, driven on ``sim``.

    Episodes ``0 .. routes - 1`` are the routes (``routes.random_route`` from a random start). The stem
    twins follow (``stem_twins`` > 0): for each stem of the town in turn and each pair ``p``, two episodes
    that start ``twin_start_m`` before the stem's junction entry at cruising speed, the stem's light green
    for ``TWIN_GREEN_STEPS`` (a wait at a red light would add nothing to the question and triple a twin's
    length; the routes hold the waits), and that differ only in the turn taken at the stem: left in the
    first, right in the second. A twin's generator is seeded by the stem and the pair, not by the side, so
    both twins draw the same start, light phases, later turns and steering noise: their states are
    identical until the expert's labels first differ (the fork, ``driving.forks``)."""
    town = sim.town
    if k < config.routes:
        rng = np.random.default_rng([config.seed, k])
        if config.routeless:
            return EpisodePlan(rng, None, None, {"turns": None})
        route = random_route(town, rng)
        return EpisodePlan(rng, route, None, {"turns": list(route.turns)})
    i = k - config.routes
    stems = stem_approaches(town)
    if not 0 <= i < 2 * config.stem_twins * len(stems):
        raise ValueError(f"k must be an episode of this collection (< {n_episodes(config)}), got {k}")
    stem, pair, side = stems[i // (2 * config.stem_twins)], (i // 2) % config.stem_twins, EXITS[i % 2]
    rng = np.random.default_rng([config.seed, TWIN_STREAM, stem, pair])
    ap = town.approaches[stem]
    lane = town.lanes[ap.lane]
    lo, hi = config.twin_start_m
    s = max(lane.length - (lo + (hi - lo) * float(rng.random())), 0.0)
    # the turns after the stem, for either exit, drawn by both twins alike (so both generators end equal)
    later = {
        e: random_route(town, rng, n_turns=7, start=(town.next_lane(ap.lane, e), 0.0)).turns for e in EXITS
    }
    offsets = sim.schedule.offsets_green_from_start(town.light_of_approach[stem], TWIN_GREEN_STEPS, rng)
    route = Route(ap.lane, s, (side, *later[side]))
    return EpisodePlan(
        rng, route, offsets, {"turns": list(route.turns), "stem": int(stem), "pair": int(pair)}
    )


def n_episodes(config: CollectConfig) -> int:
    """How many episodes the collection ``config`` drives: its routes, then two per stem twin pair."""
    return config.routes + 2 * config.stem_twins * len(stem_approaches(get_town(config.town)))


def episode_steps(config: CollectConfig) -> np.ndarray:
    """(routes,) the step budget of each route: durations spread evenly over [min, max] minutes
    (stratified: one draw per 1/routes of the range, shuffled), so that the total stays close to routes x the
    mean duration, 600 steps per minute at 10 Hz."""
    rng = np.random.default_rng(config.seed)
    lo, hi = config.min_minutes * 600, config.max_minutes * 600
    n = config.routes
    return np.round(lo + (hi - lo) * (rng.permutation(n) + rng.random(n)) / n).astype(int)


def drive_episode(
    sim: DrivingSim,
    expert: Expert,
    rng: np.random.Generator,
    route: Route | None,
    steps: int,
    *,
    offsets: np.ndarray | None = None,
    speed: float = 0.0,
    after_stem: int | None = None,
    on_step=None,
) -> dict:
    """One expert episode: ``sim.reset(rng, route=route, offsets=offsets, speed=speed)``, then up to
    ``steps`` steps of the expert's action (``on_step(action, executed)`` is called before each
    ``sim.step``, with the sim in the state the action was chosen in). With ``after_stem``, the episode
    ends that many steps after the car has left the first stem it crossed (the stem twins). Returns how it
    ended: ``steps``, ``distance_m``, ``red_light_infractions`` and ``end`` ("completed", or the sim's
    termination reason)."""
    sim.reset(rng, route=route, offsets=offsets, speed=speed)
    stems = set(stem_approaches(sim.town))
    stage, left_at = 0, None  # 0 before the stem, 1 on it, 2 in its junction, 3 left it
    reason = "completed"
    for t in range(int(steps)):
        action = expert.act()
        executed = expert.perturb(action)
        if on_step is not None:
            on_step(action, executed)
        sim.step(float(executed[0]), float(executed[1]))
        if sim.terminated:
            reason = sim.termination_reason
            break
        if after_stem is not None:
            tw, lane = sim.town, expert.current_lane
            on_road = tw.lanes[lane].kind == "road"
            if stage == 0 and tw.approach_of_lane.get(lane) in stems:
                stage = 1
            elif stage == 1 and not on_road:
                stage = 2
            elif stage == 2 and on_road:
                stage, left_at = 3, t
            if left_at is not None and t - left_at >= after_stem:
                break
    return {
        "steps": int(sim.t),
        "distance_m": round(sim.distance, 1),
        "red_light_infractions": sim.infractions,
        "end": reason,
    }


def make_expert(sim: DrivingSim, config: CollectConfig) -> Expert:
    """The expert of the collection ``config`` (its perturbations and turn timing), on ``sim``."""
    return Expert(
        sim,
        ExpertConfig(
            steer_noise=config.steer_noise, brake_noise=config.brake_noise, turn_hold_m=config.turn_hold_m
        ),
        seed=config.seed,
    )


def collect(
    config: CollectConfig = CollectConfig(), show_progress: bool | None = None, routes: list | None = None
) -> DemoLog:
    """Drive the expert over the episodes of ``config`` (``episode_plan``) and return the log.

    ``routes``: ``config.routes`` routes to drive instead of the random ones (e.g.
    ``command_balance.balanced_routes``); each episode's lights and noise then come from its own stream."""
    c = config
    if routes is not None and (len(routes) != c.routes or not all(isinstance(r, Route) for r in routes)):
        raise ValueError(f"routes must be a list of {c.routes} Route (config.routes), got {routes!r:.80}")
    sim = DrivingSim(c.town)
    expert = make_expert(sim, c)
    steps = episode_steps(c)
    n = n_episodes(c)
    rec = Recorder(sim)
    records, ended = [], []
    bar = progress(total=n, desc=f"collecting {c.town}", enabled=show_progress)
    for k in range(n):
        twin = k >= c.routes
        if routes is not None and not twin:
            r = routes[k]
            plan = EpisodePlan(
                np.random.default_rng([c.seed, GIVEN_ROUTE_STREAM, k]), r, None, {"turns": list(r.turns)}
            )
        else:
            plan = episode_plan(sim, c, k)

        def record(action, executed, k=k):
            rec.record(k, action, executed, expert.current_lane)

        ended.append(
            drive_episode(
                sim,
                expert,
                plan.rng,
                plan.route,
                MAX_TWIN_STEPS if twin else int(steps[k]),
                offsets=plan.offsets,
                speed=expert.config.cruise_speed if twin else 0.0,
                after_stem=c.twin_after_steps if twin else None,
                on_step=record,
            )
        )
        lane, s = sim.start
        records.append({"start_lane": int(lane), "start_s": float(s), **plan.record})
        bar.update(1)
    bar.close()
    # what was collected and how; no wall time (the command prints it): identical collections, identical logs
    meta = {"config": asdict(c), "expert": asdict(expert.config), "routes": records, "episodes": ended}
    return rec.log(meta)
