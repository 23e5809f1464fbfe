"""The Gymnasium environment: API, errors, reproducibility, termination, red-light infractions."""

import importlib
import math
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import ibc_tutorial.driving as drv
from ibc_tutorial.driving import Expert, make_env
from ibc_tutorial.driving.lights import RED, STOP_LINE_THICKNESS


@pytest.mark.parametrize("town, size", [("town01", 64), ("town02", 192)])
def test_gymnasium_checker_passes(town, size):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(make_env(town, bev_size=size))
        check_env(gymnasium.make(drv.ENV_IDS[town], bev_size=size, render_mode="rgb_array").unwrapped)


def test_registered_ids_and_reimport_is_silent():
    assert set(drv.ENV_IDS.values()) <= set(gymnasium.registry)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        importlib.reload(drv)
    env = gymnasium.make("ibc_tutorial/Town02-v0", bev_size=32, max_steps=5)
    obs, info = env.reset(seed=0)
    assert obs["bev"].shape == (5, 32, 32) and env.unwrapped.town.name == "town02"


def test_observation_and_info():
    env = make_env("town02", bev_size=64)
    obs, info = env.reset(seed=3)
    assert obs["bev"].dtype == np.float32 and set(np.unique(obs["bev"][:2])) <= {0, 1}
    assert set(np.unique(obs["bev"][2:])) <= {0.0, np.float32(0.3), np.float32(0.6), 1.0}  # light levels
    assert env.observation_space.contains(obs)
    assert obs["state"].dtype == np.float32 and obs["state"].shape == (3,)
    assert obs["bev"][0, 40 // 3 + 64 - 64 // 3 * 3 - 1 :, :].any()  # road under and around the car
    total = 0.0
    for _ in range(30):
        obs, reward, term, trunc, info = env.step(np.array([0.0, 0.6], dtype=np.float32))
        total += reward
    for key in ("distance_m", "red_light_infractions", "score", "x", "y", "yaw"):
        assert key in info
    assert info["score"] == pytest.approx(info["distance_m"] * 0.7 ** info["red_light_infractions"])
    assert total == pytest.approx(info["score"])  # the return is the paper's score
    assert obs["state"][0] == pytest.approx(info["speed"], rel=1e-6)
    assert np.allclose(obs["state"][1:], [0.0, 0.6])
    img = env.render()
    assert img.shape == (192, 192, 3) and img.dtype == np.uint8


@pytest.mark.parametrize(
    "action, match",
    [
        ([np.nan, 0.0], "finite"),
        ([0.0, 0.0, 0.0], "shape"),
        ([0.0, 1.5], r"\[-1, 1\]"),
        ([-2.0, 0.0], r"\[-1, 1\]"),
        ("go", "action"),
        (None, "action"),
    ],
)
def test_bad_actions_are_refused(action, match):
    env = make_env("town02", bev_size=32, seed=0)
    with pytest.raises(ValueError, match=match):
        env.step(action)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(town="town03"), "town"),
        (dict(bev_size=100), "bev_size"),
        (dict(bev_size=64.0), "bev_size"),
        (dict(max_steps=0), "max_steps"),
        (dict(routeless="yes"), "routeless"),
        (dict(render_mode="human"), "render_mode"),
    ],
)
def test_bad_arguments_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        make_env(**kwargs)


def test_bad_reset_options_are_refused():
    env = make_env("town02", bev_size=32)
    with pytest.raises(ValueError, match="options may hold"):
        env.reset(seed=0, options={"speed": 3})
    with pytest.raises(ValueError, match="start"):
        env.reset(seed=0, options={"start": (10_000, 0.0)})
    with pytest.raises(ValueError, match="light_offsets"):
        env.reset(seed=0, options={"light_offsets": [1, 2]})
    env.reset(seed=0, options={"max_steps": 1})
    env.step([0.0, 0.0])
    with pytest.raises(RuntimeError, match="reset"):
        env.step([0.0, 0.0])


def run(env, seed, actions):
    obs, info = env.reset(seed=seed)
    out = [(obs, info)]
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        out.append((obs, info))
        if term or trunc:
            break
    return out


def test_reset_is_reproducible():
    actions = np.random.default_rng(1).uniform(-0.3, 1, (40, 2))
    a = run(make_env("town01", bev_size=64), 7, actions)
    b = run(make_env("town01", bev_size=64), 7, actions)
    assert len(a) == len(b)
    for (oa, ia), (ob, ib) in zip(a, b, strict=True):
        assert np.array_equal(oa["bev"], ob["bev"]) and np.array_equal(oa["state"], ob["state"]) and ia == ib
    c = run(make_env("town01", bev_size=64), 8, actions)
    assert (c[0][1]["x"], c[0][1]["y"]) != (a[0][1]["x"], a[0][1]["y"])


def test_truncated_at_max_steps():
    env = make_env("town02", bev_size=32, max_steps=5)
    env.reset(seed=0)
    flags = [env.step([0.0, -1.0])[2:4] for _ in range(5)]
    assert flags[-1] == (False, True) and all(f == (False, False) for f in flags[:-1])


def test_termination_off_road_and_at_buildings():
    env = make_env("town02", bev_size=32)
    town = env.town
    south = next(
        ln for ln in town.lanes if ln.kind == "road" and np.allclose(ln.start, [9, -2])
    )  # eastbound, outer edge on its right
    for steer, reason in [(1.0, "off_road"), (-1.0, "building")]:
        env.reset(seed=0, options={"start": (south.id, 20.0)})
        for t in range(100):
            obs, r, term, trunc, info = env.step([steer if t < 8 else 0.0, 1.0])
            if term:
                break
        assert term and info["termination"] == reason
        assert info["collision"] == (reason == "building")


def red_light_setup(env, light_id=0, metres_before=30.0):
    """Reset with the car ``metres_before`` the stop line of ``light_id``, that light red from t = 0."""
    line = env.town.stop_lines[light_id]
    lane = env.town.approaches[line.approach].lane
    s = env.town.lanes[lane].length - metres_before
    offsets = env.sim.schedule.offsets_red_from_start(light_id)
    return env.reset(seed=0, options={"start": (lane, s), "light_offsets": offsets})


def test_running_a_red_light_is_counted_once():
    env = make_env("town02", bev_size=32)
    red_light_setup(env, 0)
    line = env.town.stop_lines[0]
    e, d = np.array(line.entry), np.array(line.direction)
    counted_at = []
    for t in range(80):
        assert env.sim.lights[0] == RED
        obs, r, term, trunc, info = env.step([0.0, 0.5])
        if info["ran_red_light"]:
            counted_at.append(t)
            rear = np.array(env.sim.car.rear())
            assert 0 <= (rear - e) @ d < 1.0  # counted as the rear crossed the line, not the front
        if term:
            break
    assert info["red_light_infractions"] == 1 and len(counted_at) == 1
    assert info["score"] == pytest.approx(0.7 * info["distance_m"])


def test_stopping_at_a_red_light_is_not_an_infraction():
    env = make_env("town02", bev_size=32)
    line = env.town.stop_lines[0]
    e, d = np.array(line.entry), np.array(line.direction)
    red_light_setup(env, 0)
    expert = Expert(env)
    gaps, states = [], []
    for _ in range(500):
        obs, r, term, trunc, info = env.step(expert.act())
        front = np.array([info["x"], info["y"]]) + 2.3 * np.array(
            [math.cos(info["yaw"]), math.sin(info["yaw"])]
        )
        gaps.append((e - STOP_LINE_THICKNESS * d - front) @ d)  # front bumper to the stop line's near edge
        states.append(env.sim.lights[0])
        assert not term
    states, gaps = np.array(states), np.array(gaps)
    assert info["red_light_infractions"] == 0
    green = int(np.argmax(states != RED))  # the light's first green
    assert green > 250 and (states[:green] == RED).all()
    assert 0.0 <= gaps[:green].min() < 2.5  # it waited just before the line while red
    assert env.sim.monitor.last_crossed == 0 and info["distance_m"] > 60  # and drove on after the green
