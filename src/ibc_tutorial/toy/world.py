"""What the tree world and the side-road world share: the settings of the car and its
start, the expert's controller, the batched closed-loop rollout, and the two records it
produces (``Demonstrations`` of the expert, ``Rollouts`` of any policy).

A *policy* is any callable ``policy(obs) -> actions`` with ``obs`` a tensor of torch's default dtype
(B, obs_dim) and ``actions`` a tensor (B, 1) of steering in [-1, 1], **+1 turning right and
-1 left** (the book's convention; see ``ibc_tutorial.toy.car``). A rollout calls it once
per step on all B episodes at once. A policy that returns NaN, the wrong shape or a value
outside [-1, 1] gets a ``ValueError`` saying what was expected: nothing is clipped silently.

The expert (both worlds) is a pure-pursuit controller: it looks ``expert_lookahead`` metres
ahead along x and steers the car's heading at the point of its reference path there (the
expert sees the whole state, the policy only its observation). The reference path depends on
the expert's *mode*, drawn once per episode, independently of the start state: this is what
puts two modes of action into the data for one and the same observation.

Units: metres, radians, seconds. ``x`` runs along the road in the direction of travel, ``y``
to the left (a right-handed frame), so a positive steering command makes ``y`` decrease. The
same ``seed`` gives the same start states to ``rollout``, ``expert_rollouts`` and
``expert_demonstrations``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch

from ibc_tutorial.toy import car
from ibc_tutorial.utils import check_int, check_positive, check_positive_fields, check_tensor

ToyPolicy = Callable[[torch.Tensor], torch.Tensor]
"""A closed-loop policy in a toy world: ``policy(obs (B, obs_dim)) -> actions (B, 1)`` in [-1, 1],
+1 = full right, on tensor batches (an explicit policy's controller, a ``GridArgminPolicy``, a
``dfo_policy``). The town's is ``driving.rollout.DrivingPolicy``, on numpy dict batches."""


@dataclass
class ToyConfig:
    """Settings shared by both toy worlds (lengths in metres, angles in radians, times in seconds)."""

    speed: float = 5.0
    """Constant forward speed of the car (m/s)."""
    dt: float = 0.1
    """Time step (s): the car moves speed * dt = 0.5 m per step."""
    heading_max: float = 0.6
    """Direction of travel at full steering |steer| = 1 (rad, relative to the road; steer = +1
    gives heading -heading_max, to the right)."""
    horizon: int = 80
    """Steps per episode (the car covers a little less than speed * dt * horizon metres along x)."""
    start_lateral_range: float = 0.2
    """The start's lateral offset y (m) is uniform in [-range, range]: close to the centre line (both
    worlds)."""
    expert_holds_start_offset: bool = False
    """True: the expert's path runs at its own start offset (a driver who keeps where it is in
    the lane); False (both worlds): it runs along the centre line y = 0, the tree expert's away from the
    tree, the side-road experts back to the main road's (lane keeping)."""
    expert_lookahead: float = 5.0
    """Distance ahead (m, along x) of the point on its path that the expert aims at."""
    expert_noise_std: float = 0.05
    """Standard deviation of the Gaussian noise added to the expert's steering (then clipped)."""
    obs_distance_scale: float = 10.0
    """Observations divide the distance along x (m) by this, so that they are of order 1."""
    obs_lateral: bool = False
    """Whether the observation includes the lateral offset; False (both worlds): the distance to the landmark
    alone (the tree world's module docstring says why)."""
    obs_lateral_scale: float = 2.0
    """Observations divide the lateral offset (m, to the right of the centre line: -y) by this."""
    obs_prev_action: bool = False
    """Whether the observation ends with the steering applied at the previous step (0 at the
    start): the memory the DA-IBC agent has, whose state includes its previous action (sec. 3.1
    of the DA-IBC paper). The car's heading is that action (``heading = -heading_max * steer``,
    see ``ibc_tutorial.toy.car``), so it is read off the state; expert demonstrations record it
    like every other observation."""
    obs_noise_std: float = 0.0
    """Standard deviation of Gaussian noise added to every component of the observation (in the
    scaled units of ``observe``), independently at every step: sensor jitter, as consecutive
    camera frames differ a little (the setting of the steering-EBM paper's Table 1). It is added
    to what a policy sees in ``rollout`` and to what demonstrations record; the car, the expert
    (which steers from the true state) and the collision test use the true state. The noise has
    its own generator, seeded from the episodes' ``seed`` + ``OBS_NOISE_SEED_OFFSET``, so the
    start states and the expert's own noise are the same as without it. 0 = noiseless."""


OBS_NOISE_SEED_OFFSET = 7919
"""Added to a rollout's ``seed`` to seed the generator of its observation noise."""


@dataclass
class Demonstrations:
    """Expert data from ``world.expert_demonstrations``: M = E * T samples of E episodes of T steps."""

    obs: torch.Tensor
    """(M, obs_dim) observations (torch default dtype: float32, or float64 in the toy chapters),
    with the sensor noise of ``config.obs_noise_std`` when it is > 0."""
    actions: torch.Tensor
    """(M, 1) steering the expert applied (noise included), in [-1, 1], +1 = right."""
    episode: torch.Tensor
    """(M,) int64 episode index of each sample."""
    step: torch.Tensor
    """(M,) int64 time step of each sample within its episode."""
    mode: torch.Tensor
    """(M,) int64 the expert's mode in that episode (the world's ``mode_names``: tree 0 passes
    right, 1 passes left; side road 0 keeps straight, 1 takes the side road)."""
    states: torch.Tensor
    """(E, T+1, 3) [x m, y m, heading rad] (default dtype) of each expert episode."""
    episode_mode: torch.Tensor
    """(E,) int64 the mode of each episode."""

    def __len__(self) -> int:
        return len(self.obs)

    def training_data(self) -> dict[str, torch.Tensor]:
        """``{"obs": (M, obs_dim), "actions": (M, 1)}``: what ``ibc_tutorial.training.train`` takes."""
        return {"obs": self.obs, "actions": self.actions}


@dataclass
class Rollouts:
    """Closed-loop episodes of one policy from ``world.rollout``: E episodes of T steps."""

    states: torch.Tensor
    """(E, T+1, 3) [x m, y m, heading rad] (default dtype); an episode that collided stays where it hit."""
    actions: torch.Tensor
    """(E, T, 1) steering the policy returned, +1 = right (after a collision: returned, not applied)."""
    obs: torch.Tensor
    """(E, T, obs_dim) observations the policy was given."""
    collided: torch.Tensor
    """(E,) bool: the episode ended in a collision (tree world: hit the tree; side road: left the road)."""
    collision_step: torch.Tensor
    """(E,) int64 the step during which the collision happened, -1 where none did."""
    alive: torch.Tensor = field(repr=False)
    """(E, T) bool: the step was driven (False after a collision)."""

    def __len__(self) -> int:
        return len(self.states)


def check_policy_actions(actions, batch: int) -> torch.Tensor:
    """Return ``actions`` in the default dtype (B, 1), or raise ValueError saying what a policy
    must return."""
    if not isinstance(actions, torch.Tensor):
        raise ValueError(
            f"policy must return a torch.Tensor of shape ({batch}, 1), got {type(actions).__name__}"
        )
    if actions.shape != (batch, 1):
        raise ValueError(f"policy must return actions of shape ({batch}, 1), got {tuple(actions.shape)}")
    if not actions.is_floating_point():
        raise ValueError(f"policy must return floating-point actions, got dtype {actions.dtype}")
    if not torch.isfinite(actions).all():
        raise ValueError("policy must return finite actions in [-1, 1], got NaN or inf")
    if (actions.abs() > 1.0).any():
        worst = float(actions.abs().max())
        raise ValueError(
            f"policy must return actions in [-1, 1] (they are not clipped), got |action| up to {worst:.3g}"
        )
    return actions.detach().to(torch.get_default_dtype())


def _as_1d(name: str, value) -> torch.Tensor:
    dtype = torch.get_default_dtype()
    t = torch.as_tensor(
        np.asarray(value, dtype=np.float64) if not isinstance(value, torch.Tensor) else value, dtype=dtype
    )
    t = t.reshape(-1)
    if not torch.isfinite(t).all():
        raise ValueError(f"{name} must be finite, got {value!r}")
    return t


class ToyWorld:
    """Base class of ``TreeWorld`` and ``SideRoadWorld``: subclasses give the landmark's x
    (``anchor_x``), the expert's reference path, the mode probabilities and the collision test.

    The observation is ``[distance ahead to the landmark along x, lateral offset, previous
    action]``: the distance divided by ``obs_distance_scale``, the lateral offset (only when
    ``config.obs_lateral``) by ``obs_lateral_scale``, and the steering applied at the previous
    step (only when ``config.obs_prev_action``; 0 at the start), and nothing about the expert's
    plan. The heading is the last action (see ``ibc_tutorial.toy.car``), so the previous action
    is read off the state's heading.

    The *lateral offset* (observed, and the ``lateral`` argument of ``states_at`` / ``obs_at``)
    is measured **to the right** of the centre line, -y, signed like the steering: a car at a
    positive offset is where positive steering takes it.
    """

    action_dim = 1
    n_modes = 2
    anchor_name = "landmark"
    mode_names: tuple[str, ...] = ("mode 0", "mode 1")
    """What each of the expert's modes does, indexed by ``Demonstrations.mode``."""

    def __init__(self, config: ToyConfig):
        c = config
        check_positive_fields(
            c, ("speed", "dt", "heading_max", "expert_lookahead", "obs_distance_scale", "obs_lateral_scale")
        )
        check_positive_fields(
            c, ("start_lateral_range", "expert_noise_std", "obs_noise_std"), allow_zero=True
        )
        check_int("config.horizon", c.horizon, minimum=1)
        if not c.heading_max < math.pi / 2:
            raise ValueError(
                f"config.heading_max must be < pi/2 (the car drives forward), got {c.heading_max}"
            )
        self.config = c

    @property
    def obs_dim(self) -> int:
        """1 ([distance]), plus 1 with ``config.obs_lateral`` (the lateral offset), plus 1 with
        ``config.obs_prev_action`` (the previous action)."""
        return 1 + int(self.config.obs_lateral) + int(self.config.obs_prev_action)

    # ------------------------------------------------------------------ to implement
    @property
    def anchor_x(self) -> float:
        """x (m) of the landmark the observation measures its distance to."""
        raise NotImplementedError

    def mode_probs(self) -> torch.Tensor:
        """(n_modes,) probabilities of the expert's modes."""
        raise NotImplementedError

    def reference_lateral(self, x: torch.Tensor, plan: torch.Tensor) -> torch.Tensor:
        """The expert's path: lateral offset y (m) it wants at ``x`` (B,), given its ``plan`` (B, P)."""
        raise NotImplementedError

    def contact_fraction(self, p0: torch.Tensor, p1: torch.Tensor) -> torch.Tensor:
        """Fraction in [0, 1] of the move ``p0 -> p1`` (B, 2) at which the car collides; inf if
        it does not."""
        raise NotImplementedError

    def sample_plans(self, start: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
        """The experts' plans (E, P) for episodes starting at ``start`` (E, 3): column 0 the mode
        (drawn from ``mode_probs``, independently of the start), column 1 the lateral offset the
        expert's path runs at away from the landmark (see ``expert_holds_start_offset``);
        subclasses may add columns (e.g. where the tree expert starts to swerve)."""
        n = len(start)
        modes = torch.multinomial(self.mode_probs(), n, replacement=True, generator=generator).to(
            torch.get_default_dtype()
        )
        base = start[:, 1] if self.config.expert_holds_start_offset else torch.zeros(n)
        return torch.stack([modes, base], dim=1)  # (E, 2)

    # ------------------------------------------------------------------ observations
    def observe(self, states: torch.Tensor) -> torch.Tensor:
        """Observation of ``states`` (..., 3) -> (..., obs_dim) in the default dtype: [distance ahead to the
        landmark along x / obs_distance_scale, lateral offset to the right (-y) / obs_lateral_scale
        (if observed), previous action = -heading / heading_max (if observed)]."""
        c = self.config
        parts = [(self.anchor_x - states[..., 0]) / c.obs_distance_scale]
        if c.obs_lateral:
            parts.append(-states[..., 1] / c.obs_lateral_scale)
        if c.obs_prev_action:
            parts.append(-states[..., 2] / c.heading_max)  # the steering that set this heading
        return torch.stack(parts, dim=-1).to(torch.get_default_dtype())

    def physical(self, obs: torch.Tensor) -> torch.Tensor:
        """Undo the scaling of ``observe``: (..., obs_dim) -> [distance to the landmark m, lateral
        offset to the right m (if observed), previous action (if observed, unscaled)]."""
        check_tensor("obs", obs)
        if obs.ndim == 0 or obs.shape[-1] != self.obs_dim:
            raise ValueError(f"obs must end in dimension {self.obs_dim}, got shape {tuple(obs.shape)}")
        c = self.config
        scale = [c.obs_distance_scale] + [c.obs_lateral_scale] * c.obs_lateral + [1.0] * c.obs_prev_action
        return obs * torch.tensor(scale, dtype=obs.dtype)

    def states_at(self, distance, lateral=0.0, prev_action=0.0) -> torch.Tensor:
        """States (N, 3) at ``distance`` m before the landmark (along x) and ``lateral`` m to the
        right of the centre line (y = -lateral), with the heading that steering ``prev_action``
        (in [-1, 1]) gives, straight ahead by default; numbers or 1-D sequences (broadcast together)."""
        prev = _as_1d("prev_action", prev_action)
        if (prev.abs() > 1).any():
            raise ValueError(f"prev_action must be in [-1, 1], got {prev_action!r}")
        d, right, prev = torch.broadcast_tensors(
            _as_1d("distance", distance), _as_1d("lateral", lateral), prev
        )
        heading = -self.config.heading_max * prev
        return torch.stack([self.anchor_x - d, -right, heading], dim=-1)  # (N, 3)

    def obs_at(self, distance, lateral=0.0, prev_action=0.0) -> torch.Tensor:
        """Observations (N, obs_dim) ``distance`` m before the landmark, ``lateral`` m to the right
        of the centre line (on it by default), after steering ``prev_action`` (0 by default):
        e.g. to plot a policy's action there."""
        return self.observe(self.states_at(distance, lateral, prev_action))

    def in_window(
        self, obs: torch.Tensor, distance: tuple[float, float], max_abs_lateral: float = 0.5
    ) -> torch.Tensor:
        """(M,) bool: which observations ``obs`` (M, obs_dim) lie ``distance`` = (low, high) m
        before the landmark with |lateral offset| <= ``max_abs_lateral`` m (if it is observed)."""
        lo, hi = distance
        if not lo < hi:
            raise ValueError(f"distance must be a (low, high) pair with low < high, got {distance!r}")
        check_positive("max_abs_lateral", max_abs_lateral)
        p = self.physical(obs)
        inside = (p[..., 0] >= lo) & (p[..., 0] <= hi)
        return inside & (p[..., 1].abs() <= max_abs_lateral) if self.config.obs_lateral else inside

    # ------------------------------------------------------------------ dynamics and expert
    def step(self, states: torch.Tensor, steer: torch.Tensor) -> torch.Tensor:
        """One step of the car (see ``ibc_tutorial.toy.car.step``): (B, 3), (B, 1) -> (B, 3)."""
        c = self.config
        return car.step(states, steer, speed=c.speed, heading_max=c.heading_max, dt=c.dt)

    def initial_states(self, n_episodes: int, generator: torch.Generator) -> torch.Tensor:
        """Start states (E, 3): x = 0, y uniform in [-start_lateral_range, start_lateral_range], heading 0."""
        n = check_int("n_episodes", n_episodes, minimum=1)
        y = self.config.start_lateral_range * (1.0 - 2.0 * torch.rand(n, generator=generator))
        return torch.stack([torch.zeros(n), y, torch.zeros(n)], dim=-1)

    def expert_steer(
        self, states: torch.Tensor, plan: torch.Tensor, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """The expert's steering (B, 1) at ``states`` (B, 3) following ``plan`` (B, P): pure
        pursuit, i.e. head for the point of its path ``expert_lookahead`` m ahead, plus Gaussian
        noise when a ``generator`` is given, clipped to [-1, 1] (+1 = right)."""
        c = self.config
        x, y = states[:, 0], states[:, 1]
        target_y = self.reference_lateral(x + c.expert_lookahead, plan)  # (B,)
        wanted = torch.atan2(target_y - y, torch.full_like(y, c.expert_lookahead))  # heading (rad, > 0 left)
        steer = -wanted / c.heading_max  # heading = -heading_max * steer (see toy.car)
        if generator is not None and c.expert_noise_std > 0:
            steer = steer + c.expert_noise_std * torch.randn(steer.shape, generator=generator)
        return steer.clamp(-1.0, 1.0)[:, None]  # (B, 1)

    # ------------------------------------------------------------------ closed loop
    def _simulate(
        self, act: Callable[[torch.Tensor, torch.Tensor], torch.Tensor], start: torch.Tensor, seed: int
    ) -> Rollouts:
        """Drive all episodes from ``start`` (E, 3) for ``horizon`` steps with ``act(obs, states) -> (E, 1)``;
        ``seed`` seeds the observation noise (``config.obs_noise_std``)."""
        e, t_max = len(start), self.config.horizon
        noise_std = self.config.obs_noise_std
        noise_gen = torch.Generator().manual_seed(seed + OBS_NOISE_SEED_OFFSET) if noise_std > 0 else None
        states = torch.empty(e, t_max + 1, 3)
        actions = torch.empty(e, t_max, 1)
        obs_all = torch.empty(e, t_max, self.obs_dim)
        alive = torch.zeros(e, t_max, dtype=torch.bool)
        collision_step = torch.full((e,), -1, dtype=torch.long)
        s = start.to(torch.get_default_dtype()).clone()
        states[:, 0] = s
        done = torch.zeros(e, dtype=torch.bool)
        for t in range(t_max):
            obs = self.observe(s)  # (E, obs_dim)
            if noise_gen is not None:  # sensor jitter: what the policy sees, not the state
                obs = obs + noise_std * torch.randn(obs.shape, generator=noise_gen)
            a = check_policy_actions(act(obs, s), e)  # (E, 1)
            nxt = self.step(s, a)
            frac = self.contact_fraction(s[:, :2], nxt[:, :2])  # (E,)
            hit = torch.isfinite(frac) & ~done
            if hit.any():  # stop the car where it touched
                f = frac.clamp(0, 1)[:, None]
                contact = torch.cat([s[:, :2] + f * (nxt[:, :2] - s[:, :2]), nxt[:, 2:]], dim=-1)
                nxt = torch.where(hit[:, None], contact, nxt)
                collision_step[hit] = t
            nxt = torch.where(done[:, None], s, nxt)
            obs_all[:, t], actions[:, t], alive[:, t] = obs, a, ~done
            done = done | hit
            s = nxt
            states[:, t + 1] = s
        return Rollouts(
            states=states,
            actions=actions,
            obs=obs_all,
            collided=collision_step >= 0,
            collision_step=collision_step,
            alive=alive,
        )

    def rollout(
        self, policy: ToyPolicy, n_episodes: int, seed: int, *, initial_states: torch.Tensor | None = None
    ) -> Rollouts:
        """Run ``policy`` in closed loop on ``n_episodes`` episodes at once, started from the
        start distribution drawn with ``seed`` (or from ``initial_states`` (E, 3) when given).

        The same ``seed`` gives the same starts as ``expert_rollouts`` and ``expert_demonstrations``
        (and, with ``config.obs_noise_std`` > 0, the same observation noise at each step)."""
        if not callable(policy):
            raise ValueError(
                f"policy must be callable as policy(obs) -> actions, got {type(policy).__name__}"
            )
        n = check_int("n_episodes", n_episodes, minimum=1)
        check_int("seed", seed, minimum=0)
        if initial_states is None:
            start = self.initial_states(n, torch.Generator().manual_seed(seed))
        else:
            start = check_tensor("initial_states", initial_states, shape=(n, 3)).to(torch.get_default_dtype())

        def act(obs, _states):
            with torch.no_grad():
                return policy(obs)

        return self._simulate(act, start, seed)

    def expert_rollouts(self, n_episodes: int, seed: int) -> tuple[Rollouts, torch.Tensor]:
        """The expert's episodes as ``Rollouts`` (to compare with a policy's) and their modes (E,) int64."""
        n = check_int("n_episodes", n_episodes, minimum=1)
        check_int("seed", seed, minimum=0)
        gen = torch.Generator().manual_seed(seed)
        start = self.initial_states(n, gen)
        plans = self.sample_plans(start, gen)  # (E, P)
        ro = self._simulate(lambda obs, s: self.expert_steer(s, plans, gen), start, seed)
        return ro, plans[:, 0].to(torch.long)

    def expert_demonstrations(self, n_episodes: int, seed: int) -> Demonstrations:
        """Drive ``n_episodes`` expert episodes (mode drawn per episode from ``mode_probs``,
        independently of the start) and return their samples; reproducible from ``seed``."""
        ro, modes = self.expert_rollouts(n_episodes, seed)
        n, t_max = len(modes), self.config.horizon
        keep = ro.alive.reshape(-1)  # (E*T,)
        return Demonstrations(
            obs=ro.obs.reshape(-1, self.obs_dim)[keep],
            actions=ro.actions.reshape(-1, 1)[keep],
            episode=torch.arange(n).repeat_interleave(t_max)[keep],
            step=torch.arange(t_max).repeat(n)[keep],
            mode=modes.repeat_interleave(t_max)[keep],
            states=ro.states,
            episode_mode=modes,
        )
