"""The car: one pymunk dynamic body with kinematic-bicycle steering.

pymunk integrates the body's position and handles collisions with the buildings; the body's
*velocity function* (called by pymunk once per physics step) replaces pymunk's free motion by a
car's:

* longitudinal: ``v <- max(0, v + (a - drag(v)) dt)`` with ``a = 3 m/s^2 x acc`` when
  ``acc >= 0`` and ``a = 8 m/s^2 x acc`` when braking; braking stops the car, it never reverses;
* yaw rate of the kinematic bicycle: ``omega = -v tan(delta_max steer) / L`` (positive steer
  turns right, CARLA's convention; angles are counter-clockwise, so a right turn is negative);
* lateral slip removed up to a friction limit: while the sideways speed (the heading has
  turned under the velocity) is below ``mu g dt`` the tyres hold and carry the speed round;
  above it the car skids and the sideways speed shrinks by ``mu g dt`` per step.

The physics runs at 20 Hz with 2 substeps per 10 Hz control step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pymunk

from ibc_tutorial.utils import check_int, check_positive

CAR_COLLISION_TYPE = 1
"""pymunk collision type of the car's shape."""
BUILDING_COLLISION_TYPE = 2
"""pymunk collision type of the buildings' shapes."""


@dataclass(frozen=True)
class CarConfig:
    """Physical parameters of the car (a mid-size saloon; ``docs/design.md``)."""

    mass: float = 1500.0
    """Mass in kg."""
    length: float = 4.6
    """Body length in metres."""
    width: float = 2.0
    """Body width in metres."""
    wheelbase: float = 2.9
    """Distance between the axles in metres (the L of the kinematic bicycle)."""
    max_steer_rad: float = 0.6
    """Front-wheel angle at steer = +-1 (radians)."""
    max_accel: float = 3.0
    """Acceleration at acc = +1 (m/s^2)."""
    max_brake: float = 8.0
    """Deceleration at acc = -1 (m/s^2)."""
    lateral_grip: float = 0.9 * 9.81
    """Largest sideways deceleration the tyres give, mu g (m/s^2)."""
    rolling_drag: float = 0.1
    """Constant resistance while moving (m/s^2)."""
    air_drag: float = 0.0075
    """Quadratic resistance coefficient (1/m): drag = rolling + air v^2 (3 m/s^2 at 20 m/s)."""
    physics_hz: int = 20
    """Physics steps per second."""
    substeps: int = 2
    """Physics steps per control step (so control runs at physics_hz / substeps = 10 Hz)."""

    def __post_init__(self):
        for name in (
            "mass",
            "length",
            "width",
            "wheelbase",
            "max_steer_rad",
            "max_accel",
            "max_brake",
            "lateral_grip",
        ):
            check_positive(f"CarConfig.{name}", getattr(self, name))
        for name in ("rolling_drag", "air_drag"):
            check_positive(f"CarConfig.{name}", getattr(self, name), allow_zero=True)
        check_int("CarConfig.physics_hz", self.physics_hz, minimum=1)
        check_int("CarConfig.substeps", self.substeps, minimum=1)

    @property
    def control_dt(self) -> float:
        """Seconds per control step (0.1 s)."""
        return self.substeps / self.physics_hz


class Car:
    """The car's pymunk body and its controls; ``step`` advances one control step."""

    def __init__(self, space: pymunk.Space, config: CarConfig = CarConfig()):
        self.config = config
        self.space = space
        c = config
        self.body = pymunk.Body(c.mass, pymunk.moment_for_box(c.mass, (c.length, c.width)))
        self.shape = pymunk.Poly.create_box(self.body, (c.length, c.width))
        self.shape.collision_type = CAR_COLLISION_TYPE
        self.shape.friction = 0.5
        self.body.velocity_func = self._velocity
        space.add(self.body, self.shape)
        self.steer = 0.0
        self.acc = 0.0
        self._tan_delta = 0.0

    # ------------------------------------------------------------------ state
    def reset(self, x: float, y: float, yaw: float, speed: float = 0.0) -> None:
        """Place the car at (x, y) heading ``yaw`` (radians) with forward ``speed`` (m/s),
        controls at rest."""
        self.body.position = (x, y)
        self.body.angle = yaw
        self.body.velocity = (speed * math.cos(yaw), speed * math.sin(yaw))
        self.body.angular_velocity = 0.0
        self.space.reindex_shapes_for_body(self.body)
        self.set_controls(0.0, 0.0)

    @property
    def pose(self) -> tuple[float, float, float]:
        """(x, y, yaw) of the body's centre, yaw in radians counter-clockwise from east."""
        p = self.body.position
        return p.x, p.y, self.body.angle

    @property
    def speed(self) -> float:
        """Forward speed in m/s (never negative: the car does not reverse)."""
        v = self.body.velocity
        a = self.body.angle
        return max(0.0, v.x * math.cos(a) + v.y * math.sin(a))

    def rear(self) -> tuple[float, float]:
        """Position of the middle of the rear bumper."""
        x, y, a = self.pose
        h = self.config.length / 2
        return x - h * math.cos(a), y - h * math.sin(a)

    # ------------------------------------------------------------------ dynamics
    def _velocity(self, body: pymunk.Body, gravity, damping, dt: float) -> None:
        c = self.config
        a = body.angle
        ca, sa = math.cos(a), math.sin(a)
        vx, vy = body.velocity
        v_long = vx * ca + vy * sa
        v_lat = -vx * sa + vy * ca  # to the left
        grip = c.lateral_grip * dt
        if abs(v_lat) <= grip:
            # the tyres hold: the heading turned under the velocity since the last step, and the
            # wheels carry the speed round with it (a kinematic bicycle loses no speed in a turn)
            v_long = math.copysign(math.hypot(v_long, v_lat), v_long)
            v_lat = 0.0
        else:  # skidding: friction removes at most mu g dt of sideways speed
            v_lat -= math.copysign(grip, v_lat)
        accel = self.acc * (c.max_accel if self.acc >= 0 else c.max_brake)
        drag = (c.rolling_drag if v_long > 0 else 0.0) + c.air_drag * v_long * v_long
        v_long = max(0.0, v_long + (accel - drag) * dt)  # braking stops the car, never reverses it
        body.velocity = (v_long * ca - v_lat * sa, v_long * sa + v_lat * ca)
        # kinematic bicycle: omega = v tan(delta) / L, positive steer turns right (clockwise)
        body.angular_velocity = -v_long * self._tan_delta / c.wheelbase

    def set_controls(self, steer: float, acc: float) -> None:
        """Hold ``steer`` and ``acc`` (both in [-1, 1]) until the next call."""
        self.steer = float(steer)
        self.acc = float(acc)
        self._tan_delta = math.tan(self.config.max_steer_rad * self.steer)  # tan of the front-wheel angle
