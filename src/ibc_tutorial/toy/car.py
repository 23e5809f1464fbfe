"""The car of the toy worlds: a point on the plane moving forward at constant speed.

State: ``(x, y, heading)`` in metres and radians, in a right-handed frame: ``x`` along the
road, ``y`` to the left, the heading counter-clockwise from +x (a positive heading points the
car to the left). The only action is the steering command ``steer`` in [-1, 1], **+1 turning
right, -1 left** (the book's convention, CARLA's): it sets the direction of travel relative to
the road, ``heading = -steer * heading_max``, a car that follows its wheels at once, with no
yaw inertia (the first-order simplification of a kinematic car). This is the simplest car for
which the steering-EBM paper's Fig. 1 makes sense: the speed is given and the policy only
steers, as in that paper's experiments ("the models controlled only the car's steering").

Because the heading is the action just applied, the state that matters to the future is
the position ``(x, y)``; the observations of the toy worlds are built from it alone.

One step of length ``dt``::

    heading' = -heading_max * steer        (steer > 0: heading < 0, to the right)
    x'       = x + speed * cos(heading') * dt
    y'       = y + speed * sin(heading') * dt
"""

from __future__ import annotations

import torch

from ibc_tutorial.utils import check_positive, check_tensor


def step(
    states: torch.Tensor, steer: torch.Tensor, *, speed: float, heading_max: float, dt: float
) -> torch.Tensor:
    """Advance ``states`` (B, 3) by one step of steering ``steer`` (B, 1) or (B,); returns (B, 3)."""
    check_tensor("states", states, ndim=2, shape=(None, 3))
    check_positive("speed", speed)
    check_positive("heading_max", heading_max)
    check_positive("dt", dt)
    steer = steer.reshape(-1)  # (B,)
    if steer.shape[0] != states.shape[0]:
        raise ValueError(
            f"steer must hold one action per state ({states.shape[0]}), got shape {tuple(steer.shape)}"
        )
    heading = -heading_max * steer  # (B,): +1 = full right = the heading turned clockwise
    x = states[:, 0] + speed * torch.cos(heading) * dt
    y = states[:, 1] + speed * torch.sin(heading) * dt
    return torch.stack([x, y, heading], dim=-1)  # (B, 3)


def segment_circle_contact(
    p0: torch.Tensor, p1: torch.Tensor, centre: torch.Tensor, radius: float
) -> torch.Tensor:
    """Fraction ``s`` in [0, 1] of the way from ``p0`` to ``p1`` (both (B, 2)) at which a point
    moving on that segment enters the open disc of ``radius`` around ``centre`` (2,); ``inf``
    where it never does.

    A point starting inside the disc has contact at ``s = 0``. Touching the circle is not a
    contact (as for two discs that only touch): a segment tangent to it, or starting on it
    and moving away, has none. Checking the whole segment (not only its end points) means a
    fast car cannot jump over a thin obstacle between steps.
    """
    check_positive("radius", radius)
    d = p1 - p0  # (B, 2)
    f = p0 - centre  # (B, 2)
    a = (d * d).sum(-1)  # (B,)
    b = 2.0 * (f * d).sum(-1)
    c = (f * f).sum(-1) - radius**2
    inside = c < 0
    disc = b * b - 4 * a * c
    safe_a = torch.where(a > 0, a, torch.ones_like(a))
    s = (-b - torch.sqrt(disc.clamp_min(0.0))) / (2 * safe_a)  # first root of |f + s d|^2 = r^2
    hit = (disc > 0) & (a > 0) & (s >= 0) & (s <= 1)  # disc = 0: tangent, it only touches
    out = torch.full_like(a, float("inf"))
    out = torch.where(hit, s, out)
    return torch.where(inside, torch.zeros_like(out), out)  # (B,)
