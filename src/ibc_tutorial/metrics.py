"""Generic measures of commands and of energy models.

- ``whiteness``: smoothness of a command sequence, eq. 2 of the steering-EBM paper.
- ``grid_nll``: negative log-likelihood of held-out expert actions under an energy model,
  with the normalising constant Z(x) summed over a fine grid instead of estimated from
  counter-examples (so models trained with different counter-examples compare fairly).
- ``expert_rank``: the share of candidates an energy model ranks above the expert's action.
- ``swerve_rate``: the share of passes of a side road with a swerve towards it, a slight swerve
  counting half (Table 2 of the steering-EBM paper).
- ``crashes_per_km``: crashes (VISTA's, in the steering-EBM paper) per kilometre driven.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ibc_tutorial.utils import check_positive, check_tensor


def whiteness(commands, dt: float, *, per_episode: bool = False):
    """Whiteness of a command sequence, eq. 2 of the steering-EBM paper:

        W = sqrt( (1/D) Σ_i (δP_i / δt)² )

    where δP_i is the change of the command between consecutive decisions, D the number of
    changes and δt the time between decisions. W is the root-mean-square rate of change of
    the command: 0 for a constant command, large for a jerky one. The unit is the command's
    unit per second (the paper's steering angles give °/s; the book's steering in [-1, 1]
    gives 1/s).

    Args:
        commands: a tensor or array of shape (T,) (one sequence), (E, T) (E episodes) or
            (E, T, D) (D command dimensions); time is the first axis of a 1-D input, else the
            second. Differences are taken within each episode only.
        dt: δt, seconds between decisions.
        per_episode: return one W per episode (an (E,) array) instead of W pooled over all
            episodes' changes.
    Returns:
        a float, or an (E,) float array.
    """
    dt = check_positive("dt", dt)
    x = commands.detach().cpu().numpy() if isinstance(commands, torch.Tensor) else np.asarray(commands)
    if x.ndim not in (1, 2, 3) or not np.issubdtype(x.dtype, np.number):
        raise ValueError(
            f"commands must be numeric with shape (T,), (E, T) or (E, T, D), got shape {x.shape}"
        )
    x = x.astype(np.float64)
    if x.ndim == 1:
        x = x[None]  # (1, T)
    if x.shape[1] < 2:
        raise ValueError(
            f"commands must hold at least 2 decisions per episode, got shape {np.shape(commands)}"
        )
    if not np.isfinite(x).all():
        raise ValueError("commands must be finite, got NaN or inf")
    rate = np.diff(x, axis=1) / dt  # (E, T-1[, D]): δP_i / δt
    sq = rate.reshape(len(rate), -1) ** 2  # (E, D_e)
    if per_episode:
        return np.sqrt(sq.mean(axis=1))
    return float(np.sqrt(sq.mean()))


def grid_nll(pos_energy: torch.Tensor, grid_energy: torch.Tensor, cell_volume: float) -> torch.Tensor:
    """Per-sample NLL of the expert actions under p(y|x) = exp(-E(x, y)) / Z(x), Z on a grid.

        Z(x) ≈ Σ_g exp(-E(x, a_g)) · ΔA,     -log p(y|x) = E(x, y) + log Σ_g exp(-E(x, a_g)) + log ΔA

    with a_g the points of a regular grid covering the action box and ΔA the volume of one
    grid cell (a Riemann sum). This is a density: it can be compared with the NLL of any other
    density over the same box (e.g. the expert's own, or the uniform one, log of the box's
    volume), and it does not depend on the counter-examples a model was trained with.

    Args:
        pos_energy: (B,) energies of the held-out expert actions, E(x_i, y_i).
        grid_energy: (B, G) energies of the G grid points for the same observations.
        cell_volume: ΔA, e.g. (2 / (n - 1))² for an n × n grid over [-1, 1]².
    Returns:
        (B,) NLL in nats.
    """
    check_tensor("pos_energy", pos_energy, ndim=1)
    check_tensor("grid_energy", grid_energy, shape=(len(pos_energy), None))
    cell_volume = check_positive("cell_volume", cell_volume)
    return pos_energy + torch.logsumexp(-grid_energy, dim=1) + math.log(cell_volume)


def expert_rank(pos_energy: torch.Tensor, cand_energy: torch.Tensor) -> torch.Tensor:
    """Share of candidates with a lower energy than the expert's action: (B,) in [0, 1].

    0 means the expert's action beats every candidate (the model would choose it, or something
    at least as good); 0.5 means it is no better than a typical candidate.

    Args:
        pos_energy: (B,) energies of the expert actions.
        cand_energy: (B, G) energies of G candidates (e.g. a uniform grid over the box).
    """
    check_tensor("pos_energy", pos_energy, ndim=1)
    check_tensor("cand_energy", cand_energy, shape=(len(pos_energy), None))
    return (cand_energy < pos_energy[:, None]).float().mean(dim=1)


def swerve_rate(toward_side_road, *, slight: float, clear: float, per_pass: bool = False):
    """Swerve rate as Table 2 of the steering-EBM paper defines it: the share of passes of a side
    road in which the car swerved towards it, "slight swerves [...] counted as half a swerve".

    Each pass p contributes its peak offset towards the side road, m_p = max_t d_p(t), scored

        1    if m_p >= clear            (a swerve)
        1/2  if slight <= m_p < clear   (a slight swerve)
        0    if m_p < slight            (no swerve),

    and the rate is the mean score. The paper judged its nine passes by eye and says slight
    swerves "are difficult to set a threshold for"; a measured trace needs the two thresholds
    stated, so they are arguments: ``slight`` above the drift of drivers who keep straight
    (so that noise is not a swerve), ``clear`` a movement a passenger would call a swerve.

    Args:
        toward_side_road: (P, T) one trace per pass: the lateral offset (m) towards the side road,
            relative to where the car was when the road section began (positive = towards it);
            NaN marks time steps outside the section (each pass needs one finite value).
        slight: threshold (m) of a slight swerve, > 0.
        clear: threshold (m) of a full swerve, >= slight.
        per_pass: return the (P,) scores (0, 0.5 or 1) instead of their mean.
    Returns:
        a float in [0, 1], or a (P,) float array.
    """
    slight = check_positive("slight", slight)
    clear = check_positive("clear", clear)
    if clear < slight:
        raise ValueError(f"clear must be >= slight, got clear={clear} < slight={slight}")
    x = (
        toward_side_road.detach().cpu().numpy()
        if isinstance(toward_side_road, torch.Tensor)
        else np.asarray(toward_side_road)
    )
    if x.ndim != 2 or len(x) == 0 or not np.issubdtype(x.dtype, np.number):
        raise ValueError(f"toward_side_road must be numeric with shape (P, T), P >= 1, got shape {x.shape}")
    x = x.astype(np.float64)
    if np.isinf(x).any() or np.isnan(x).all(axis=1).any():
        raise ValueError("toward_side_road must be finite, with at least one non-NaN value per pass")
    peak = np.nanmax(x, axis=1)  # (P,)
    score = np.where(peak >= clear, 1.0, np.where(peak >= slight, 0.5, 0.0))  # (P,)
    return score if per_pass else float(score.mean())


def crashes_per_km(crashes, distance_m) -> float:
    """Crashes per kilometre driven: ``sum(crashes) / (sum(distance_m) / 1000)``.

    The steering-EBM paper counts VISTA crashes per session of about 20 minutes; over routes of
    different lengths the count per distance compares. Several runs are pooled: their crashes
    and distances are summed first (not their rates averaged, which would weigh a short run
    like a long one).

    Args:
        crashes: a count, or a sequence of counts (non-negative integers).
        distance_m: the distance driven (m), or a sequence of them (one per count); the total
            must be > 0.
    Returns:
        a float >= 0.
    """
    c = np.atleast_1d(np.asarray(crashes))
    d = np.atleast_1d(np.asarray(distance_m, dtype=np.float64))
    if c.ndim != 1 or c.shape != d.shape or not np.issubdtype(c.dtype, np.number):
        raise ValueError(
            f"crashes and distance_m must be numbers or equally long sequences, got shapes "
            f"{np.shape(crashes)} and {np.shape(distance_m)}"
        )
    if not np.isfinite(c).all() or (c < 0).any() or (c != np.round(c)).any():
        raise ValueError(f"crashes must be non-negative integers, got {c.tolist()}")
    if not np.isfinite(d).all() or (d < 0).any() or d.sum() <= 0:
        raise ValueError(f"distance_m must be finite, >= 0 and sum to more than 0, got {d.tolist()}")
    return float(c.sum() / (d.sum() / 1000.0))
