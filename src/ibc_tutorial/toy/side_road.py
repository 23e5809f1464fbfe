"""The side-road world: Fig. 1 (right) of the steering-EBM paper.

A straight road along the x axis; at ``branch_x`` a side road branches off to the right
(towards -y, as ``y`` points to the left) at ``side_angle_deg``, so taking it needs positive
steering (+1 turns right, -1 left). Most experts keep straight (mode 0, probability
``straight_prob``); the others take the side road (mode 1). Their choice is drawn per
episode, independently of the start, and nothing in the observation shows it. The paper
saw unimodal regression models "swerve slightly (the red trajectory) towards the side road
... minor because side roads are rarely taken in our training data": ``swerve`` measures
that, as the largest move towards the side road (to the right, from 5 m before the branch
point on) of the episodes that stay on the main road.

As in the tree world, the policy observes the distance to the branch point alone, and the
straight experts keep to the centre line (``expert_holds_start_offset=False``).

The car's centre must stay on the drivable area: within ``road_half_width`` of the main
road's centre line, or of the side road's (beyond the branch point). Leaving it is this
world's collision.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from ibc_tutorial.toy.world import Rollouts, ToyConfig, ToyWorld
from ibc_tutorial.utils import check_positive_fields, check_probability


@dataclass
class SideRoadConfig(ToyConfig):
    """The side-road world's settings (metres, degrees); the car's and the expert's are in ``ToyConfig``."""

    branch_x: float = 20.0
    """x where the side road's centre line leaves the main road's (m)."""
    side_angle_deg: float = 30.0
    """Angle between the side road and the main road (degrees), opening to the right (-y)."""
    road_half_width: float = 2.0
    """How far the car's centre may be from a road's centre line (m) before it has left the road."""
    straight_prob: float = 0.8
    """Probability that an expert keeps straight (mode 0); it takes the side road otherwise (mode 1)."""
    horizon: int = 64
    """Steps per episode: the car ends about 12 m past the branch point."""
    corner_length: float = 6.0
    """Length (m, along x) over which the side-road expert's path bends from the main road into the side road.
    """
    swerve_from: float = 5.0
    """``swerve`` looks at the part of each episode from this far (m) before the branch point on."""


class SideRoadWorld(ToyWorld):
    """A main road and a side road branching right: ``expert_demonstrations``, ``rollout``, ``swerve``.

    Observation (1,): [distance ahead to the branch point along x / 10 m] (with ``obs_lateral=True``
    also [lateral offset to the right (-y) / 2 m]). Action (1,): steering in [-1, 1], +1 = right,
    heading = -0.6 rad * steer. Modes: 0 = keeps straight, 1 = takes the side road (to the right).
    """

    anchor_name = "branch"
    mode_names = ("keeps straight", "takes the side road")

    def __init__(self, config: SideRoadConfig | None = None):
        config = SideRoadConfig() if config is None else config
        super().__init__(config)
        c = config
        check_positive_fields(c, ("branch_x", "road_half_width", "corner_length", "swerve_from"))
        if not 0.0 < c.side_angle_deg < 90.0:
            raise ValueError(f"config.side_angle_deg must be in (0, 90), got {c.side_angle_deg}")
        check_probability("config.straight_prob", c.straight_prob)

    @property
    def anchor_x(self) -> float:
        return self.config.branch_x

    @property
    def side_direction(self) -> torch.Tensor:
        """(2,) unit vector along the side road, away from the branch point: (cos a, -sin a), to the right."""
        a = math.radians(self.config.side_angle_deg)
        return torch.tensor([math.cos(a), -math.sin(a)])

    def mode_probs(self) -> torch.Tensor:
        return torch.tensor([self.config.straight_prob, 1.0 - self.config.straight_prob])

    def side_road_lateral(self, x: torch.Tensor) -> torch.Tensor:
        """y (m) of the side road's centre line at ``x`` (0 before the branch, negative beyond: to
        the right)."""
        return -math.tan(math.radians(self.config.side_angle_deg)) * (x - self.config.branch_x).clamp_min(0.0)

    def reference_lateral(self, x: torch.Tensor, plan: torch.Tensor) -> torch.Tensor:
        # side-road expert: a path that bends smoothly (a quadratic over corner_length centred on
        # the branch point) from the main road's centre line onto the side road's, to the right
        c = self.config
        k = -math.tan(math.radians(c.side_angle_deg))  # dy/dx of the side road (< 0)
        u = (x - c.branch_x + c.corner_length / 2).clamp(0.0, c.corner_length)
        bend = k * u * u / (2 * c.corner_length) + k * (x - c.branch_x - c.corner_length / 2).clamp_min(0.0)
        return torch.where(plan[:, 0] == 1, bend, plan[:, 1])

    def on_main_road(self, positions: torch.Tensor) -> torch.Tensor:
        """(...,) bool: the point ``positions`` (..., 2) is within ``road_half_width`` of the main road's
        centre line."""
        return positions[..., 1].abs() <= self.config.road_half_width

    def on_side_road(self, positions: torch.Tensor) -> torch.Tensor:
        """(...,) bool: the point is within ``road_half_width`` of the side road's centre line, beyond the
        branch."""
        rel = positions[..., :2] - torch.tensor([self.config.branch_x, 0.0])
        u = self.side_direction
        along = rel[..., 0] * u[0] + rel[..., 1] * u[1]
        across = -rel[..., 0] * u[1] + rel[..., 1] * u[0]
        return (along >= 0) & (across.abs() <= self.config.road_half_width)

    def on_road(self, positions: torch.Tensor) -> torch.Tensor:
        """(...,) bool: the point is on the drivable area (main road or side road)."""
        return self.on_main_road(positions) | self.on_side_road(positions)

    def contact_fraction(self, p0: torch.Tensor, p1: torch.Tensor) -> torch.Tensor:
        # leaving the road is checked at the end of each 0.5 m step
        off = ~self.on_road(p1)
        return torch.where(off, torch.ones(len(p1)), torch.full((len(p1),), float("inf")))

    def took_side_road(self, rollouts: Rollouts) -> torch.Tensor:
        """(E,) bool: the episode ended on the side road, off the main road, without leaving the road."""
        end = rollouts.states[:, -1, :2]
        return ~rollouts.collided & self.on_side_road(end) & ~self.on_main_road(end)

    def stayed_on_main_road(self, rollouts: Rollouts) -> torch.Tensor:
        """(E,) bool: the episode ended on the main road without leaving the road."""
        return ~rollouts.collided & self.on_main_road(rollouts.states[:, -1, :2])

    def swerve(self, rollouts: Rollouts) -> torch.Tensor:
        """(E,) float: how far (m) each episode that stayed on the main road moved towards the side
        road (to the right, -y), from where it was ``swerve_from`` m before the branch point on:
        y at that point minus the smallest y after it, at least 0. NaN for the episodes that did
        not stay on the main road.

        Measuring from the episode's own offset there (not from y = 0) separates the swerve from
        a car that merely drives a little off-centre all along."""
        trace = self.swerve_traces(rollouts)  # (E, T+1), NaN before the section
        dev = torch.nan_to_num(trace, nan=0.0).max(dim=1).values.clamp_min(0.0)  # never got there: 0
        return torch.where(self.stayed_on_main_road(rollouts), dev, torch.full_like(dev, float("nan")))

    def swerve_traces(self, rollouts: Rollouts) -> torch.Tensor:
        """(E, T+1) float: each episode's offset (m) towards the side road (to the right, -y) from
        ``swerve_from`` m before the branch point on, relative to where it was there: y at the
        section's first state minus y; NaN before the section. The input of
        ``ibc_tutorial.metrics.swerve_rate``; ``swerve`` is its largest value."""
        s = rollouts.states  # (E, T+1, 3)
        near = s[:, :, 0] >= self.config.branch_x - self.config.swerve_from  # (E, T+1)
        first = near.float().argmax(dim=1)  # first state of the section (0 if it is never reached)
        y0 = s[torch.arange(len(s)), first, 1]  # (E,)
        return torch.where(near, y0[:, None] - s[:, :, 1], torch.full_like(s[:, :, 1], float("nan")))
