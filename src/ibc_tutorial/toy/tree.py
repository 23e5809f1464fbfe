"""The tree world: the failure case of Fig. 1 (left) of the steering-EBM paper.

A car drives along the x axis at constant speed; a tree (a disc) stands on the centre
line ahead. Each expert decides, with probability 1/2 and independently of where it
starts, to pass the tree on the right (mode 0, y < 0, steering > 0) or on the left (mode 1,
y > 0, steering < 0): steering +1 turns right, -1 left, and ``y`` points to the left. It
drives along the centre line until ``swerve_start`` m before the tree, then heads for
``pass_offset`` m to its side, and heads back once it is ``return_after`` m past the tree
(a pure-pursuit controller, see ``ToyWorld.expert_steer``, with a little steering noise).

**The observation is the distance to the tree alone** (``obs_lateral=False``): a driver with
no navigation command, whose view ahead looks the same whichever side it will take. So for
one and the same observation the demonstrations hold two modes of action, right and left,
which is the situation of the paper's caption: "If the experts have passed the tree from
left and right with equal frequency in the training data, behavioral cloning with a
unimodal policy and no high-level navigation commands would average the training
trajectories and drive straight into the tree."

``TreeConfig(obs_lateral=True)`` also observes the lateral offset, which reveals the side a car
has started to take; chapter 01 shows that regression then passes the tree, and explains why the
crash needs both an averaging loss and the distance-only observation.

A collision is the car's disc (``car_radius``) overlapping the tree's (``tree_radius``),
checked along each step's segment (``ibc_tutorial.toy.car.segment_circle_contact``).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ibc_tutorial.toy import car
from ibc_tutorial.toy.world import Rollouts, ToyConfig, ToyWorld
from ibc_tutorial.utils import check_positive_fields, check_probability


@dataclass
class TreeConfig(ToyConfig):
    """The tree world's settings (metres); the car's and the expert's are in ``ToyConfig``."""

    heading_max: float = 0.7
    """Direction of travel at full steering (rad): enough for the expert's swerve."""
    tree_x: float = 20.0
    """x of the tree's centre (m); the tree stands on the centre line y = 0."""
    tree_radius: float = 1.5
    """Radius of the tree's disc (m)."""
    car_radius: float = 1.0
    """Radius of the car's disc (m)."""
    pass_offset: float = 4.0
    """Lateral offset (m) the expert's path holds beside the tree."""
    swerve_start_min: float = 10.0
    """Smallest distance before the tree (m, along x) at which an expert decides and starts to swerve."""
    swerve_start_max: float = 10.0
    """Largest such distance: each expert draws its own uniformly in [min, max], independently of its side."""
    return_after: float = 3.0
    """Distance past the tree (m) from which the expert heads back to the centre line."""
    right_prob: float = 0.5
    """Probability that an expert passes on the right (mode 0); it passes on the left otherwise (mode 1)."""


class TreeWorld(ToyWorld):
    """The tree on the road: ``expert_demonstrations``, ``rollout``, ``pass_side``, ``collision_rate``.

    Observation (1,): [distance ahead to the tree along x / 10 m] (with ``obs_lateral=True`` also
    [lateral offset to the right (-y) / 2 m]). Action (1,): steering in [-1, 1], +1 = right,
    heading = -0.7 rad * steer. Modes: 0 = passes on the right (y < 0), 1 = on the left (y > 0).
    """

    anchor_name = "tree"
    mode_names = ("passes right", "passes left")

    def __init__(self, config: TreeConfig | None = None):
        config = TreeConfig() if config is None else config
        super().__init__(config)
        c = config
        check_positive_fields(
            c,
            (
                "tree_radius",
                "car_radius",
                "pass_offset",
                "swerve_start_min",
                "swerve_start_max",
                "return_after",
            ),
        )
        if not c.swerve_start_min <= c.swerve_start_max:
            raise ValueError(
                f"config.swerve_start_min must be <= config.swerve_start_max, got {c.swerve_start_min} and "
                f"{c.swerve_start_max}"
            )
        check_probability("config.right_prob", c.right_prob)

    @property
    def anchor_x(self) -> float:
        return self.config.tree_x

    @property
    def clearance(self) -> float:
        """Distance between the car's and the tree's centres at which they touch (m)."""
        return self.config.car_radius + self.config.tree_radius

    def mode_probs(self) -> torch.Tensor:
        return torch.tensor([self.config.right_prob, 1.0 - self.config.right_prob])

    def sample_plans(self, start: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
        """(E, 3): [mode, lateral offset held away from the tree (m), distance before the tree
        at which the expert starts to swerve (m), uniform in [swerve_start_min, swerve_start_max]]."""
        c = self.config
        base = super().sample_plans(start, generator)  # (E, 2)
        where = c.swerve_start_min + (c.swerve_start_max - c.swerve_start_min) * torch.rand(
            len(start), 1, generator=generator
        )
        return torch.cat([base, where], dim=1)

    def reference_lateral(self, x: torch.Tensor, plan: torch.Tensor) -> torch.Tensor:
        # the offset the expert wants at the look-ahead point x: plan[:, 1] until the car (at
        # x - lookahead) is plan[:, 2] m before the tree, then pass_offset to its side until the
        # car is return_after m past the tree, then plan[:, 1] again
        c = self.config
        car_x = x - c.expert_lookahead
        sign = 2.0 * plan[:, 0] - 1.0  # mode 0 -> -1 (right, y < 0), mode 1 -> +1 (left)
        swerving = (car_x >= c.tree_x - plan[:, 2]) & (car_x <= c.tree_x + c.return_after)
        return torch.where(swerving, sign * c.pass_offset, plan[:, 1])

    def contact_fraction(self, p0: torch.Tensor, p1: torch.Tensor) -> torch.Tensor:
        centre = torch.tensor([self.config.tree_x, 0.0])
        return car.segment_circle_contact(p0, p1, centre, self.clearance)

    def collides(self, positions: torch.Tensor) -> torch.Tensor:
        """(...,) bool: the car's disc at ``positions`` (..., 2) [x, y] overlaps the tree."""
        centre = torch.tensor([self.config.tree_x, 0.0])
        return ((positions[..., :2] - centre) ** 2).sum(-1) < self.clearance**2

    def pass_side(self, rollouts: Rollouts) -> torch.Tensor:
        """(E,) int64: +1 passed on the right (y < 0 where x crosses the tree), -1 on the left
        (y > 0): the sign of the steering that takes a car there. 0 collided (or never reached
        the tree)."""
        s = rollouts.states  # (E, T+1, 3)
        past = s[:, :, 0] >= self.config.tree_x  # (E, T+1)
        reached = past.any(dim=1)
        first = past.float().argmax(dim=1)  # first step at or beyond the tree
        y = s[torch.arange(len(s)), first, 1]
        side = torch.where(y > 0, -1, 1)
        return torch.where(reached & ~rollouts.collided, side, torch.zeros_like(side)).to(torch.long)

    def collision_rate(self, rollouts: Rollouts) -> float:
        """Fraction of the episodes that hit the tree."""
        return float(rollouts.collided.float().mean())
