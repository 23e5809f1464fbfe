"""The small worlds of Part I, after Fig. 1 of the steering-EBM paper.

- ``TreeWorld`` (``tree.py``): experts pass a tree on the left or on the right, 50/50.
- ``SideRoadWorld`` (``side_road.py``): experts keep straight, or sometimes take a side road.
- ``Demonstrations``, ``Rollouts``, ``check_policy_actions`` and the shared closed loop (``world.py``).
- the car's kinematics and the collision geometry (``car.py``).

A policy is any callable ``policy(obs (B, obs_dim) float32) -> actions (B, 1)`` in [-1, 1];
in both worlds the observation is the distance ahead to the landmark / 10 m (obs_dim = 1),
optionally with the lateral offset (``obs_lateral=True``, obs_dim = 2).
"""

from ibc_tutorial.toy.side_road import SideRoadConfig, SideRoadWorld
from ibc_tutorial.toy.tree import TreeConfig, TreeWorld
from ibc_tutorial.toy import car
from ibc_tutorial.toy.world import Demonstrations, Policy, Rollouts, ToyConfig, ToyWorld, check_policy_actions

__all__ = [
    "TreeWorld",
    "TreeConfig",
    "SideRoadWorld",
    "SideRoadConfig",
    "ToyWorld",
    "ToyConfig",
    "Demonstrations",
    "Rollouts",
    "Policy",
    "check_policy_actions",
    "car",
]
