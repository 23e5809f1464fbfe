"""The car: kinematic-bicycle turning, bounded acceleration, braking without reversing, grip."""

import math

import numpy as np
import pymunk
import pytest

from ibc_tutorial.driving.car import Car, CarConfig

NO_DRAG = CarConfig(rolling_drag=0.0, air_drag=0.0)


def drive(config, controls, speed=0.0, yaw=0.0):
    """Run a car alone in an empty space; return poses and speeds after each control step."""
    space = pymunk.Space()
    car = Car(space, config)
    car.reset(0.0, 0.0, yaw, speed)
    poses, speeds = [], []
    for steer, acc in controls:
        car.set_controls(steer, acc)
        for _ in range(config.substeps):
            space.step(1.0 / config.physics_hz)
        poses.append(car.pose)
        speeds.append(car.speed)
    return np.array(poses), np.array(speeds)


def test_acceleration_is_bounded_and_linear_without_drag():
    _, v = drive(NO_DRAG, [(0.0, 1.0)] * 20)
    assert np.allclose(v, 3.0 * 0.1 * np.arange(1, 21))  # 3 m/s^2 at full throttle
    _, v = drive(NO_DRAG, [(0.0, 0.5)] * 10)
    assert np.isclose(v[-1], 1.5)


def test_braking_stops_without_reversing():
    poses, v = drive(NO_DRAG, [(0.0, -1.0)] * 20, speed=8.0)
    assert np.isclose(v[4], 8.0 - 8.0 * 0.5)  # 8 m/s^2 of braking
    assert (v >= 0).all() and v[-1] == 0.0
    assert np.all(np.diff(poses[:, 0]) >= -1e-12)  # never rolls backwards
    assert poses[-1, 0] == pytest.approx(8.0**2 / (2 * 8.0), abs=0.25)  # v^2 / 2a


def test_drag_gives_a_top_speed():
    c = CarConfig()
    _, v = drive(c, [(0.0, 1.0)] * 600)
    top = math.sqrt((c.max_accel - c.rolling_drag) / c.air_drag)
    assert v[-1] == pytest.approx(top, rel=0.02)


@pytest.mark.parametrize("steer", [0.3, 1.0, -0.5])
def test_turning_circle_is_the_kinematic_bicycles(steer):
    c = NO_DRAG
    poses, v = drive(c, [(steer, 0.0)] * 400, speed=3.0)
    assert np.allclose(v, 3.0)  # turning costs no speed while the tyres hold
    radius = c.wheelbase / math.tan(c.max_steer_rad * abs(steer))
    # a circle through the poses: fit its centre from the last 60 points
    xy = poses[-60:, :2]
    A = np.c_[2 * xy, np.ones(len(xy))]
    cx, cy, k = np.linalg.lstsq(A, (xy**2).sum(1), rcond=None)[0]
    fitted = math.sqrt(k + cx**2 + cy**2)
    assert fitted == pytest.approx(radius, rel=0.02)
    # positive steer turns right (clockwise: yaw decreases)
    assert np.sign(poses[-1, 2] - poses[0, 2]) == -np.sign(steer)


def test_lateral_slip_is_removed_up_to_the_grip():
    c = NO_DRAG
    space = pymunk.Space()
    car = Car(space, c)
    car.reset(0.0, 0.0, 0.0, 0.0)
    car.body.velocity = (0.0, 2.0)  # pure sideways motion
    space.step(0.05)
    assert car.body.velocity.y == pytest.approx(2.0 - c.lateral_grip * 0.05)
    for _ in range(3):  # 2 m/s of slip needs 5 steps of 0.44 m/s
        space.step(0.05)
    assert car.body.velocity.y == pytest.approx(2.0 - 4 * c.lateral_grip * 0.05)
    space.step(0.05)  # the rest is within grip: the tyres hold and turn it into forward speed
    assert car.body.velocity.y == pytest.approx(0.0, abs=1e-9)


def test_config_is_validated():
    with pytest.raises(ValueError, match="wheelbase"):
        CarConfig(wheelbase=0.0)
    with pytest.raises(ValueError, match="substeps"):
        CarConfig(substeps=0)
