"""What chapter 12 reads of a flow agent at a state, where it reads an energy agent's valleys.

A flow-matching policy (``policies.flow.FlowPolicy``) has no energy to read: it *draws* actions. Its
reading at a state is therefore the distribution of its own samples, ``READ_SAMPLES`` of them drawn as the
agent draws them at a decision (the preset's K Euler steps from N(0, I) noise, the action box clipped only
at the end; seeded, ``READ_SEED``), and of those the steering:

- ``left_mass``: the share of the samples left of straight (steer < 0; one exactly at 0 counts half), the
  analogue of an energy agent's Boltzmann mass left of straight (both are the model's p(y | x) on that side);
- ``valleys``, ``two_sided``, ``argmin_steer``: the same reading of a profile as an energy agent's
  (``driving.energy_profiles.read_profile``: valleys within ``DEPTH`` = 3 nats of the lowest, separated by a
  barrier of at least ``BARRIER`` = 1 nat), applied to the samples' density as an energy, -log p̂(steer), p̂
  a Gaussian KDE of the steering samples with bandwidth ``BANDWIDTH`` on the same steering grid. "Two valleys,
  one each side of straight" thus means the same for both: two separated modes of p(steer | x), the smaller
  within a factor e³ ≈ 20 of the larger, one left and one right;
- ``mean_steer`` and ``samples`` (the steering of every sample).

There is no energy of the fork's two labels (an energy agent's ``label_energy``).

**A caveat.** Samples clipped to the box pile up exactly at full lock (steer ±1): a flow that sends some
samples beyond the box shows a narrow valley there, on either side, which the valley count includes (the
agent would indeed steer at full lock with them). A barely trained flow, its samples spread over the whole
box, may thus read as "two-sided" at the box's edges; ``valley_steer`` is not kept, but ``samples`` and
``profile`` are, to check where a valley lies.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ibc_tutorial.driving.energy_profiles import read_profile
from ibc_tutorial.policies.encoders import to_tensor_obs
from ibc_tutorial.utils import check_int, check_positive

READ_SAMPLES = 1024
"""Samples of the flow agent's steering per state read (1,024: about 25 within a bandwidth of a mode of a
tenth of the mass spread over 0.4, so that counting noise moves -log p̂ by about 0.2 nats, well under the
``BARRIER`` of 1 nat)."""
READ_SEED = 0
"""Seed of the noise of the samples read (the same for every agent and state batch order)."""
BANDWIDTH = 0.05
"""Steering bandwidth of the KDE whose -log is read as a profile: an eighth of the forks' label gap (about
0.4), so that the two answers' modes stay apart, and wide enough that ``READ_SAMPLES`` make it smooth."""


def sample_profile(steer_grid: np.ndarray, samples: np.ndarray, bandwidth: float = BANDWIDTH) -> np.ndarray:
    """-log p̂ on ``steer_grid`` (G,) of a Gaussian KDE of ``samples`` (n,), minus its minimum: (G,) in nats,
    finite everywhere (computed as a log-sum-exp)."""
    h = check_positive("bandwidth", bandwidth)
    s = np.asarray(samples, dtype=float).ravel()
    if s.size == 0:
        raise ValueError("samples must hold at least one value")
    g = np.asarray(steer_grid, dtype=float)
    z = -0.5 * ((g[:, None] - s[None, :]) / h) ** 2  # (G, n)
    top = z.max(axis=1, keepdims=True)  # (G, 1)
    log_p = top[:, 0] + np.log(np.exp(z - top).sum(axis=1)) - math.log(s.size * h * math.sqrt(2 * math.pi))
    e = -log_p  # (G,)
    return e - e.min()


def left_share(samples: np.ndarray) -> float:
    """Share of ``samples`` left of straight (< 0), one exactly at 0 counting half."""
    s = np.asarray(samples, dtype=float).ravel()
    return float(((s < 0).sum() + 0.5 * (s == 0).sum()) / s.size)


@torch.no_grad()
def read_flow_states(
    agent,
    bev: np.ndarray,
    state: np.ndarray,
    steer_grid: np.ndarray,
    chunk: int = 16,
    n_samples: int = READ_SAMPLES,
) -> dict:
    """Readings of a flow ``agent`` at N states (``bev`` (N, 5, S, S), ``state`` (N, 3)) on ``steer_grid``
    (G,) (see the module docstring). Returns arrays of N: ``valleys``, ``two_sided``, ``left_mass``,
    ``argmin_steer``, ``mean_steer``, ``profile`` (N, G) and ``samples`` (N, n_samples) of steering."""
    if getattr(agent, "method", None) != "flow":
        raise ValueError(
            f"agent must be a flow agent, got {getattr(agent, 'method', type(agent).__name__)!r}"
        )
    if len(bev) != len(state):
        raise ValueError(f"bev and state must hold the same states, got {len(bev)} and {len(state)}")
    check_int("chunk", chunk, minimum=1)
    check_int("n_samples", n_samples, minimum=1)
    gen = torch.Generator().manual_seed(READ_SEED)
    grid = np.asarray(steer_grid, dtype=float)
    out = {
        k: []
        for k in ("valleys", "two_sided", "left_mass", "argmin_steer", "mean_steer", "profile", "samples")
    }
    for a in range(0, len(state), chunk):
        obs = to_tensor_obs({"bev": bev[a : a + chunk], "state": state[a : a + chunk]}, agent.device)
        y = agent.network.sample(obs, n_samples, agent.preset.flow_steps, generator=gen)  # (B, n, 2)
        for steer in y[..., 0].double().cpu().numpy():  # (n,) each
            p = sample_profile(grid, steer)
            r = read_profile(grid, p, p)  # the one reading of a profile, as for an energy agent
            for k in ("valleys", "two_sided", "argmin_steer"):
                out[k].append(r[k])
            out["left_mass"].append(left_share(steer))
            out["mean_steer"].append(float(steer.mean()))
            out["profile"].append(p.astype(np.float32))
            out["samples"].append(steer.astype(np.float32))
    return {k: np.array(v) for k, v in out.items()}
