"""A 2-D driving world after the DA-IBC paper's CARLA set-up (its secs. 3 and 4.1).

Modules, one concern each:

- ``lanes``    lane geometry, dense 1 m waypoints, approaches and their legal exits
- ``towns``    the layouts of town01 and town02, built into a ``Town``
- ``lights``   traffic-light timing, stop lines, the red-light rule
- ``car``      the pymunk car with kinematic-bicycle steering
- ``bev``      the town raster and the five-channel bird's-eye view
- ``sim``      one control step: car, lights, infractions, termination
- ``routes``   routes as a start and a list of junction choices
- ``expert``   the PID expert that follows waypoints and obeys the lights
- ``env``      the Gymnasium environment (registered as ``ibc_tutorial/Town01-v0`` and ``-Town02-v0``)
- ``dataset``  the demonstration log and the torch ``Dataset`` that renders its BEVs
- ``collect``  driving the expert to record demonstrations (``ibc-tutorial collect``)
- ``rollout``  the one loop over environments: closed-loop episodes of a ``DrivingPolicy``, batched
               (scores, trajectories, per-step records)
- ``analysis`` where a car went: junction passes, exits per approach, road coverage
- ``render``   RGB pictures
"""

from ibc_tutorial.driving.bev import CHANNELS, SUPPORTED_SIZES, BEVRenderer, get_raster, get_renderer
from ibc_tutorial.driving.car import Car, CarConfig
from ibc_tutorial.driving.env import ENV_IDS, DrivingEnv, EnvConfig, make_env, register_envs
from ibc_tutorial.driving.expert import PID, Expert, ExpertConfig, stops_for_light
from ibc_tutorial.driving.lights import GREEN, RED, YELLOW, LightSchedule, LightTiming
from ibc_tutorial.driving.rollout import DrivingPolicy, EpisodeResult, RolloutRecording, rollout
from ibc_tutorial.driving.routes import Route, random_route
from ibc_tutorial.driving.sim import DrivingSim, score
from ibc_tutorial.driving.towns import TOWNS, Town, get_town

register_envs()

__all__ = [
    "CHANNELS",
    "SUPPORTED_SIZES",
    "BEVRenderer",
    "get_raster",
    "get_renderer",
    "Car",
    "CarConfig",
    "DrivingEnv",
    "EnvConfig",
    "make_env",
    "PID",
    "Expert",
    "ExpertConfig",
    "stops_for_light",
    "GREEN",
    "YELLOW",
    "RED",
    "LightSchedule",
    "LightTiming",
    "Route",
    "random_route",
    "EpisodeResult",
    "DrivingPolicy",
    "RolloutRecording",
    "rollout",
    "DrivingSim",
    "score",
    "TOWNS",
    "Town",
    "get_town",
    "ENV_IDS",
    "register_envs",
]
