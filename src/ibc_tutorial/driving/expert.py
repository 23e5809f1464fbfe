"""The expert: PID control along dense waypoints, obeying the traffic lights.

The DA-IBC paper's expert is "a deterministic agent, guided by a dense point trajectory and a PID
controller" (its sec. 4.1, citing Learning by Cheating) on predefined leaderboard routes, and it says
no more. The book's reconstruction starts from the PID autopilot with which Learning by Cheating
collected its data:

* the path: lanes with waypoints every metre, following a route's turns, or (routeless) a
  random legal exit at each junction;
* steering: a PID on the angle between the car's heading and the direction to a target
  waypoint ``lookahead_m`` ahead (``turn_lookahead_m`` when a turn is near);
* speed: a PID towards ``cruise_speed`` (``turn_speed`` in and just before turns), its
  derivative on the measured speed so that a switch of the target gives no kick; the throttle
  is scaled by ``max(1 - |steer|, 0.25)``;
* lights: a red or yellow stop line of its lane within ``stop_distance_m`` ahead stops the car
  before the line, braking with the constant deceleration that stops it ``stop_margin_m``
  short of the line once that deceleration exceeds ``brake_trigger`` (once begun, the stop runs to its end
  without handing back to the PID, so it never chatters between throttle and brake), and holding full brake
  there; a yellow light that it can no longer stop for (it would need more than full braking) is passed. Red
  lights are never passed.

The action is [steer, throttle - brake] in [-1, 1]^2. Optional perturbations for data
collection (DART-style, [Laskey et al. 2017]) change what is *executed*, not the expert's label:

* steering noise (``steer_noise``): a short constant offset of the steering, so that the data
  hold states off the lane's centre line, each labelled with the expert's correction;
* braking noise (``brake_noise``): the acceleration held at a brake for 1-3 s, at random moments
  (``brake_prob`` per step) and, with chance ``hesitate_prob``, at the moment the expert leaves
  from rest (the light has turned green). The car then slows or stops where the expert would
  have driven on, or waits on at a green light, and the data hold states "slow or at rest, the
  light green", each labelled with the expert's "drive on". Without them nearly every state at
  rest in the data is a wait at a red light, the label "brake"; only the first second after the
  change says "go", and a policy at rest before a green light has almost no example of leaving:
  chapter 08 measures this.

Changes from LBC's starting values (``docs/design.md``), found by driving town02 (largest distance
from the lane's centre line over 4 x 150 s: 1.8 m with LBC's settings, 0.5 m with these):
the steering P gain was raised from 0.75 to 1.5 (this car's front wheels turn at most 0.6 rad,
CARLA's about 1.2 rad, so the same gain turned them half as far), and the lookahead before
turns stays 5 m instead of 7.5 m (the longer one cut the corners); the full brake for a red
light within 9.5 m became a constant-deceleration stop that starts at about the same distance
at cruise speed but ends just before the line (a full brake from 6 m/s stops 7 m short of
it); at yellow the expert stops only if 4 m/s^2 suffice, else it goes on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ibc_tutorial.driving.lights import GREEN, RED, STOP_LINE_THICKNESS
from ibc_tutorial.utils import check_fraction, check_positive, check_probability


@dataclass(frozen=True)
class ExpertConfig:
    """Settings of the expert driver."""

    lookahead_m: float = 5.0
    """Distance along the path to the steering target."""
    turn_lookahead_m: float = 5.0
    """Distance to the steering target when a turn starts within ``turn_preview_m`` (LBC: 7.5)."""
    turn_preview_m: float = 10.0
    """How far ahead a turn slows the car and lengthens the lookahead (metres)."""
    turn_hold_m: float = 0.0
    """0: the steering target follows the path, so a turn is anticipated as soon as the target enters its
    arc, and a tight right turn (7 m radius) steers earlier than a wide left one (11 m). > 0: until the car is
    this close to the start of a turn's arc (the junction entry), the target is held on the straight line
    of its lane, so every turn, left or right, begins at the same place (chapter 08's stem analysis)."""
    steer_gains: tuple[float, float, float] = (1.5, 0.05, 0.0)
    """(P, I, D) of the steering PID on the heading error in radians (LBC: 0.75, 0.05, 0.0)."""
    speed_gains: tuple[float, float, float] = (0.5, 0.025, 0.1)
    """(P, I, D) of the speed PID on the speed error in m/s."""
    cruise_speed: float = 6.0
    """Target speed on straight road (m/s)."""
    turn_speed: float = 4.5
    """Target speed in and just before turns (m/s)."""
    stop_distance_m: float = 9.5
    """A red or yellow stop line of its lane closer than this (from the front bumper) stops the car."""
    stop_margin_m: float = 1.0
    """Where the car aims to stop: this far before the stop line."""
    brake_trigger: float = 2.0
    """Deceleration (m/s^2) needed to stop at the line above which braking begins."""
    yellow_brake: float = 4.0
    """At yellow, stop if this deceleration (m/s^2) suffices to stop before the line, else go on."""
    smooth_speed_control: bool = True
    """False: the book's earlier speed control, kept to measure the change: derivative on the
    error (a kick when the target switches) and stops handed back to the PID (chatter)."""
    min_throttle_scale: float = 0.25
    """Throttle is scaled by max(1 - |steer|, this)."""
    steer_noise: float = 0.0
    """Size of steering perturbations during collection (0 = none)."""
    noise_prob: float = 0.02
    """Chance per step that a perturbation starts."""
    noise_steps: tuple[int, int] = (5, 15)
    """Range of a perturbation's length in steps."""
    brake_noise: float = 0.0
    """Strength of braking perturbations during collection, in [0, 1] (0 = none): the executed acceleration is
    held at -brake_noise x U(0.5, 1) for ``brake_steps`` steps."""
    brake_prob: float = 0.01
    """Chance per step that a braking perturbation starts (when none is running)."""
    brake_steps: tuple[int, int] = (10, 30)
    """Range of a braking perturbation's length in steps (1-3 s at 10 Hz)."""
    hesitate_prob: float = 1.0
    """Chance that a braking perturbation starts when the expert leaves from rest (with ``brake_noise`` > 0).
    """

    def __post_init__(self):
        for name in ("lookahead_m", "turn_lookahead_m", "cruise_speed", "turn_speed", "stop_distance_m"):
            check_positive(f"ExpertConfig.{name}", getattr(self, name))
        check_positive("ExpertConfig.steer_noise", self.steer_noise, allow_zero=True)
        check_positive("ExpertConfig.turn_hold_m", self.turn_hold_m, allow_zero=True)
        check_fraction("ExpertConfig.brake_noise", self.brake_noise)
        for name in ("noise_prob", "brake_prob", "hesitate_prob"):
            check_probability(f"ExpertConfig.{name}", getattr(self, name))
        if len(self.brake_steps) != 2 or not 1 <= self.brake_steps[0] <= self.brake_steps[1]:
            raise ValueError(
                f"ExpertConfig.brake_steps must be (low, high) with 1 <= low <= high, got "
                f"{self.brake_steps!r}"
            )


class PID:
    """A discrete PID controller: ``u = kp e + ki sum(e) dt - kd (y - y_prev) / dt``.

    The derivative acts on the measurement ``y`` ("derivative on measurement"), not on the
    error: a step of the set point (the expert's target speed switching between 6 and 4.5 m/s)
    then gives no derivative kick, while the damping of the measured motion is the same.
    Without a measurement the derivative falls back to the error's, ``kd (e - e_prev) / dt``.
    """

    def __init__(self, kp: float, ki: float, kd: float, dt: float, integral_limit: float = 10.0):
        self.kp, self.ki, self.kd, self.dt = kp, ki, kd, dt
        self.integral_limit = integral_limit
        self.reset()

    def reset(self) -> None:
        self.integral = 0.0
        self.prev: float | None = None

    def step(self, error: float, measurement: float | None = None) -> float:
        """Controller output for the current ``error`` (and the measured value it is the error of)."""
        self.integral = min(max(self.integral + error * self.dt, -self.integral_limit), self.integral_limit)
        now = error if measurement is None else -measurement  # e = r - y: de/dt = -dy/dt at fixed r
        deriv = 0.0 if self.prev is None else (now - self.prev) / self.dt
        self.prev = now
        return self.kp * error + self.ki * self.integral + self.kd * deriv


def stops_for_light(state: int, gap_m: float, speed: float, config: ExpertConfig = ExpertConfig()) -> bool:
    """Whether the expert stops for its lane's light: ``state`` (0 green, 1 yellow, 2 red) with the
    front bumper ``gap_m`` metres before the stop line at ``speed`` m/s.

    Beyond ``config.stop_distance_m`` the light is not yet considered; red stops; green does
    not; yellow stops only if ``speed^2 / (2 gap)`` <= ``config.yellow_brake`` (m/s^2).
    """
    if gap_m > config.stop_distance_m or state == GREEN:
        return False
    if state == RED:
        return True
    return gap_m > 0 and speed * speed / (2 * gap_m) <= config.yellow_brake


def _sim_of(env):
    """The ``DrivingSim`` behind an env (wrapped or not) or a sim itself."""
    from ibc_tutorial.driving.sim import DrivingSim

    if isinstance(env, DrivingSim):
        return env
    sim = getattr(getattr(env, "unwrapped", env), "sim", None)
    if not isinstance(sim, DrivingSim):
        raise ValueError(f"env must be a driving environment or a DrivingSim, got {type(env).__name__}")
    return sim


class Expert:
    """``Expert(env).act()``: the expert's action for the env's current state.

    Follows the env's route if it has one, else picks a random legal exit at each junction.
    Those choices and the steering noise are drawn from a generator seeded by ``seed`` and the
    episode's seed, so an episode started by ``env.reset(seed=...)`` is driven the same way
    every time. It notices a new episode by itself.
    """

    HORIZON_M = 40.0  # path kept ahead of the car

    def __init__(self, env, config: ExpertConfig = ExpertConfig(), seed: int | None = None):
        self.sim = _sim_of(env)
        self.config = config
        self.town = self.sim.town
        self.seed = 0 if seed is None else int(seed)
        self.rng = np.random.default_rng(self.seed)
        dt = self.sim.car.config.control_dt
        self.steer_pid = PID(*config.steer_gains, dt, integral_limit=1.0)
        self.speed_pid = PID(*config.speed_gains, dt, integral_limit=10.0)
        self.car_half = self.sim.car.config.length / 2
        self.max_brake = self.sim.car.config.max_brake
        self._episode = None
        self._passed = 0
        self._noise_left = 0
        self._noise_value = 0.0
        self._brake_left = 0
        self._brake_value = 0.0
        self._last_label_acc = 0.0
        self._braking = False
        self.last: dict = {}

    # ------------------------------------------------------------------ path
    def _start(self) -> None:
        """Plan from where the car is (the route start, or its nearest lane)."""
        sim = self.sim
        x, y, yaw = sim.car.pose
        route = sim.route
        if route is not None and sim.t == 0:
            lane, s = route.start_lane, route.start_s
            idx = int(s // (self.town.lanes[lane].length / len(self.town.lanes[lane].points)))
        else:
            lane, idx, _ = self.town.localize(x, y, yaw)
        if sim.t == 0:
            self.rng = np.random.default_rng([self.seed, sim.episode_seed])
            self._passed = 0  # junction choices the car has driven into
        self._turns = list(route.turns) if route is not None else []
        self._turn_k = self._passed  # re-planning mid-route goes on with the next turn
        pts = self.town.lanes[lane]
        self.xy = pts.points[idx:].copy()
        spacing = pts.length / len(pts.points)
        self.s = np.arange(len(self.xy)) * spacing
        self.lane = np.full(len(self.xy), lane)
        self.turn_wp = np.full(len(self.xy), self.town.lanes[lane].turn != "straight")  # waypoints in turns
        self.choice_wp = np.full(len(self.xy), -1)  # index of the junction choice that led here, -1 if none
        self.stops: list[tuple[float, int]] = []  # (arc length of the junction entry, light id)
        self._end_lane = lane
        self._add_stop(lane, self.s[0] + (len(self.xy)) * spacing)
        self.idx = 0
        self.steer_pid.reset()
        self.speed_pid.reset()
        self._noise_left = 0
        self._brake_left = 0
        self._braking = False
        self._extend()

    def _add_stop(self, lane: int, s_end: float) -> None:
        ap = self.town.approach_of_lane.get(lane)
        if ap is not None and ap in self.town.light_of_approach:
            self.stops.append((s_end, self.town.light_of_approach[ap]))

    def _choose(self, lane: int) -> tuple[int, int]:
        """The lane after ``lane`` and the index of the junction choice it took (-1: no choice)."""
        ap = (
            self.town.approaches[self.town.approach_of_lane[lane]]
            if lane in self.town.approach_of_lane
            else None
        )
        if ap is None or not ap.is_junction:
            return self.town.next_lane(lane), -1
        if self._turn_k < len(self._turns):
            turn = self._turns[self._turn_k]
        else:
            turn = sorted(ap.exits)[int(self.rng.integers(len(ap.exits)))]
        self._turn_k += 1
        return self.town.next_lane(lane, turn), self._turn_k - 1

    def _extend(self) -> None:
        while self.s[-1] - self.s[self.idx] < self.HORIZON_M:
            prev = self.town.lanes[self._end_lane]
            s0 = self.s[-1] + prev.length / len(prev.points)
            nxt_id, choice = self._choose(self._end_lane)
            nxt = self.town.lanes[nxt_id]
            spacing = nxt.length / len(nxt.points)
            self.xy = np.concatenate([self.xy, nxt.points])
            self.s = np.concatenate([self.s, s0 + np.arange(len(nxt.points)) * spacing])
            self.lane = np.concatenate([self.lane, np.full(len(nxt.points), nxt.id)])
            self.turn_wp = np.concatenate([self.turn_wp, np.full(len(nxt.points), nxt.turn != "straight")])
            self.choice_wp = np.concatenate([self.choice_wp, np.full(len(nxt.points), choice)])
            self._add_stop(nxt.id, s0 + nxt.length)
            self._end_lane = nxt.id
        if self.idx > 100:  # forget the path well behind the car
            cut = self.idx - 20
            self.xy, self.s, self.lane = self.xy[cut:], self.s[cut:], self.lane[cut:]
            self.turn_wp, self.choice_wp = self.turn_wp[cut:], self.choice_wp[cut:]
            self.idx -= cut
            self.stops = [st for st in self.stops if st[0] > self.s[0]]

    def _progress(self, x: float, y: float) -> float:
        """Advance ``idx`` to the waypoint nearest the car; return the car's distance to it."""
        lo, hi = self.idx, min(self.idx + 12, len(self.xy))
        d2 = (self.xy[lo:hi, 0] - x) ** 2 + (self.xy[lo:hi, 1] - y) ** 2
        k = int(np.argmin(d2))
        self.idx = lo + k
        if self.choice_wp[self.idx] >= 0:
            self._passed = max(self._passed, int(self.choice_wp[self.idx]) + 1)
        return math.sqrt(float(d2[k]))

    @property
    def current_lane(self) -> int:
        """The lane the car is on, as the expert sees it."""
        return int(self.lane[self.idx]) if self._episode is not None else -1

    # ------------------------------------------------------------------ control
    def act(self) -> np.ndarray:
        """The expert's action (2,) float32 = [steer, acceleration] for the current state."""
        sim, c = self.sim, self.config
        if self._episode != sim.episode:
            self._episode = sim.episode
            self._start()
        x, y, yaw = sim.car.pose
        if self._progress(x, y) > 4.0:  # pushed off its path (e.g. another driver had the wheel)
            self._start()
            self._progress(x, y)
        self._extend()
        s_car = self.s[self.idx]
        # a turn ahead: the path's heading changes within the preview distance
        j = int(np.searchsorted(self.s, s_car + c.turn_preview_m))
        j = min(j, len(self.s) - 1)
        turning = bool(self.turn_wp[self.idx : j + 1].any())
        look = c.turn_lookahead_m if turning else c.lookahead_m
        t = min(int(np.searchsorted(self.s, s_car + look)), len(self.s) - 1)
        tx, ty = self._held_target(s_car, look, t) if c.turn_hold_m > 0 else self.xy[t]
        err = math.atan2(ty - y, tx - x) - yaw
        err = -math.atan2(
            math.sin(err), math.cos(err)
        )  # > 0: target to the right; positive steer turns right
        steer = min(max(self.steer_pid.step(err), -1.0), 1.0)

        speed = sim.car.speed
        target = c.turn_speed if turning else c.cruise_speed
        acc = None
        stop_d = self._stop_distance(s_car, speed)
        if stop_d is not None:
            room = stop_d - c.stop_margin_m
            need = speed * speed / (2 * max(room, 0.05))
            smooth = c.smooth_speed_control
            if room <= 0.5 or (smooth and self._braking and speed < 0.1):
                acc = -1.0  # at the line, or stopped short of it: hold the brake
            elif need >= c.brake_trigger or (smooth and self._braking):
                self._braking = True  # once begun, the constant-deceleration stop runs to its end
                acc = -min(need / self.max_brake, 1.0)
            else:
                target = min(target, math.sqrt(2 * c.brake_trigger * room))
        else:
            self._braking = False
        u = self.speed_pid.step(target - speed, measurement=speed if c.smooth_speed_control else None)
        if acc is None:
            acc = u if u < 0 else u * max(1.0 - abs(steer), c.min_throttle_scale)
        acc = min(max(acc, -1.0), 1.0)
        self.last = {
            "target_speed": target,
            "stop_distance": stop_d,
            "turning": turning,
            "lane": self.current_lane,
        }
        return np.array([steer, acc], dtype=np.float32)

    def _held_target(self, s_car: float, look: float, t: int) -> tuple[float, float]:
        """The steering target with ``turn_hold_m``: on the straight extension of the lane while the next
        turn's arc (its first waypoint, the junction entry) is more than ``turn_hold_m`` ahead; else
        ``xy[t]``."""
        ahead = np.flatnonzero(self.turn_wp[self.idx + 1 : t + 1])
        if not len(ahead):
            return self.xy[t]
        k = self.idx + 1 + int(ahead[0])  # first waypoint of the arc
        if self.turn_wp[k - 1] or self.s[k] - s_car <= self.config.turn_hold_m:
            return self.xy[t]  # already in a turn, or close enough to begin it
        d = self.xy[k] - self.xy[k - 1]
        d = d / max(float(np.hypot(*d)), 1e-9)  # (2,) the lane's direction at the entry
        tx, ty = self.xy[k] + d * (s_car + look - self.s[k])
        return float(tx), float(ty)

    def _stop_distance(self, s_car: float, speed: float) -> float | None:
        """Distance from the front bumper to the stop line it must stop at, or None."""
        lights = self.sim.lights
        for s_entry, light in self.stops:
            if s_entry - s_car < -self.car_half:
                continue  # the rear has crossed: this light no longer applies
            d = s_entry - STOP_LINE_THICKNESS - (s_car + self.car_half)
            if d > self.config.stop_distance_m:
                return None
            return d if stops_for_light(int(lights[light]), d, speed, self.config) else None
        return None

    # ------------------------------------------------------------------ noise
    def perturb(self, action: np.ndarray) -> np.ndarray:
        """The action actually executed during collection: ``action`` with a steering offset and a held brake,
        when one of those perturbations is running (see the module's doc). Each draws from the expert's
        generator only when its size is above 0, so a collection without it is the same as before it
        existed."""
        c = self.config
        out = np.array(action, dtype=np.float32)
        if c.steer_noise > 0:
            if self._noise_left <= 0 and self.rng.random() < c.noise_prob:
                self._noise_left = int(self.rng.integers(c.noise_steps[0], c.noise_steps[1] + 1))
                self._noise_value = float(
                    self.rng.choice([-1.0, 1.0]) * self.rng.uniform(0.5, 1.0) * c.steer_noise
                )
            if self._noise_left > 0:
                self._noise_left -= 1
                out[0] = np.float32(min(max(out[0] + self._noise_value, -1.0), 1.0))
        if c.brake_noise > 0:
            leaving = self.sim.car.speed < 0.1 and action[1] > 0 >= self._last_label_acc  # leaving from rest
            self._last_label_acc = float(action[1])
            if self._brake_left <= 0 and self.rng.random() < (c.hesitate_prob if leaving else c.brake_prob):
                self._brake_left = int(self.rng.integers(c.brake_steps[0], c.brake_steps[1] + 1))
                self._brake_value = -float(self.rng.uniform(0.5, 1.0) * c.brake_noise)
            if self._brake_left > 0:
                self._brake_left -= 1
                out[1] = np.float32(self._brake_value)
        return out
