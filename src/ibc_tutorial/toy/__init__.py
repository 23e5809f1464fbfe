"""The small worlds of Part I, after Fig. 1 of the steering-EBM paper, and the junction world
of Part II.

- ``TreeWorld`` (``tree.py``): experts pass a tree on the right or on the left, 50/50.
- ``SideRoadWorld`` (``side_road.py``): experts keep straight, or sometimes take a side road
  that branches off to the right.
- ``Demonstrations``, ``Rollouts``, ``check_policy_actions`` and the shared closed loop (``world.py``).
- the car's kinematics and the collision geometry (``car.py``).
- ``JunctionWorld`` (``junction.py``): observations of the road ahead (cruise, a T-junction, a
  red light) and the expert's (steer, acceleration) actions, without a closed loop: the
  counter-example experiments of chapters 04-06.

**Steering convention (the whole book): steer = +1 turns right, -1 turns left** (CARLA's,
the simulator of the DA-IBC paper). Positions are in a right-handed frame, ``x`` along the
road and ``y`` to the left, so a positive steering command makes the heading and ``y``
decrease.

A policy is any callable ``policy(obs (B, obs_dim)) -> actions (B, 1)`` in [-1, 1];
in the tree and side-road worlds the observation is the distance ahead to the landmark / 10 m
(obs_dim = 1), optionally with the lateral offset (``obs_lateral=True``, obs_dim = 2).
"""

from ibc_tutorial.toy import car
from ibc_tutorial.toy.junction import SITUATIONS, JunctionConfig, JunctionWorld
from ibc_tutorial.toy.side_road import SideRoadConfig, SideRoadWorld
from ibc_tutorial.toy.tree import TreeConfig, TreeWorld
from ibc_tutorial.toy.world import (
    Demonstrations,
    Rollouts,
    ToyConfig,
    ToyPolicy,
    ToyWorld,
    check_policy_actions,
)

__all__ = [
    "TreeWorld",
    "TreeConfig",
    "SideRoadWorld",
    "SideRoadConfig",
    "JunctionWorld",
    "JunctionConfig",
    "SITUATIONS",
    "ToyWorld",
    "ToyConfig",
    "Demonstrations",
    "Rollouts",
    "ToyPolicy",
    "check_policy_actions",
    "car",
]
