"""What a model does at a side-road junction, beyond the swerve thresholds: the sweep's measures.

At the states of a side-road pass, from ``evaluate.SECTION_BEFORE_M`` (15 m) before the junction to
its entry, a model that keeps the side road's mode in mind puts some of its probability on steering
towards the side road, even if its argmin (or argmax, or mean) keeps straight. Two pure measures:

- ``side_road_mass``: the share of the Boltzmann mass exp(−E) over the steering grid (for an EBM;
  for the classifier and the MDN, E = −log p of their density, so the mass is their probability)
  on steering values more than ``threshold`` beyond the expert's steer, towards the side road;
- ``section_whiteness``: W (eq. 2 of the steering-EBM paper, as ``metrics.whiteness``) of the commands
  over the junction sections only: whether argmin jitters between the two modes where there are two.

Steering is +1 right, −1 left; a side road on the left (``side`` = +1, as ``Reference.sections``)
lies towards negative steering.
"""

from __future__ import annotations

import math

import numpy as np

from ibc_tutorial.utils import check_positive

MASS_THRESHOLD = 0.3
"""Steering beyond the expert's by more than this, towards the side road, counts as the side road's mode
(0.3 of the ±1 range: 75° of the paper's steering wheel; the expert's lane keeping on a straight road
stays within ±0.05)."""


def side_road_mass(scores, grid, expert_steer, side: int, threshold: float = MASS_THRESHOLD) -> np.ndarray:
    """(T,) per state, the share of exp(−scores) on steering towards the side road beyond ``threshold``.

    Args:
        scores: (T, G) energies over ``grid`` (lower = preferred; −log p for a density).
        grid: (G,) the steering values the scores are of.
        expert_steer: (T,) or a number: the expert's steering at each state.
        side: +1 if the side road is on the left (towards negative steering), −1 if on the right.
        threshold: how far beyond the expert's steer a value must lie to count, >= 0.
    Returns:
        (T,) shares in [0, 1]: sum over g with −side·(g − expert) > threshold of softmax(−scores)_g.
    """
    threshold = check_positive("threshold", threshold, allow_zero=True)
    if side not in (1, -1):
        raise ValueError(f"side must be +1 (side road on the left) or -1 (on the right), got {side!r}")
    e = np.asarray(scores, dtype=np.float64)
    g = np.asarray(grid, dtype=np.float64).reshape(-1)
    if e.ndim != 2 or e.shape[1] != len(g) or not len(g):
        raise ValueError(f"scores must have shape (T, G) with G = len(grid) = {len(g)}, got {e.shape}")
    if not np.isfinite(e).all():
        raise ValueError("scores must be finite")
    x = np.broadcast_to(np.asarray(expert_steer, dtype=np.float64), (e.shape[0],))  # (T,)
    p = np.exp(-(e - e.min(axis=1, keepdims=True)))  # (T, G), stable
    p /= p.sum(axis=1, keepdims=True)
    towards = (-side) * (g[None, :] - x[:, None]) > threshold  # (T, G)
    return (p * towards).sum(axis=1)


def section_whiteness(steer, in_section, dt: float) -> float:
    """W (1/s) of ``steer`` over the steps where ``in_section`` holds, pooled over its runs.

    Args:
        steer: (T,) commands, one per step.
        in_section: (T,) bool, True at the steps inside a junction section; a change is counted only
            between two consecutive steps that are both inside (a run of one step has none).
        dt: seconds between decisions.
    Returns:
        sqrt(mean over the counted changes of (δsteer / dt)²); NaN if no change is counted.
    """
    dt = check_positive("dt", dt)
    s = np.asarray(steer, dtype=np.float64).reshape(-1)
    m = np.asarray(in_section, dtype=bool).reshape(-1)
    if s.shape != m.shape:
        raise ValueError(f"steer and in_section must have the same length, got {s.shape} and {m.shape}")
    both = m[1:] & m[:-1]  # (T-1,) changes inside a section
    if not both.any():
        return float("nan")
    d = np.diff(s)[both]
    return math.sqrt(float(np.mean((d / dt) ** 2)))


def pooled_whiteness(values: list[tuple[float, int]]) -> float:
    """Ws of several stretches, each with its number of changes, pooled as ``metrics.whiteness`` pools
    (root of the change-weighted mean square); NaN if there are no changes."""
    n = sum(k for w, k in values if k > 0 and not math.isnan(w))
    if not n:
        return float("nan")
    return math.sqrt(sum(k * w * w for w, k in values if k > 0 and not math.isnan(w)) / n)
