"""An energy over steering, read as the DA-IBC paper's Fig. 6 reads it: valleys, mass left and right, spread.

At a stem of a T the two right answers are a left and a right turn. An energy-based policy keeps
both if its energy over steering (the lowest over acceleration, on a grid) has two valleys, or at
least Boltzmann mass on both sides of straight; it averaged them if its one valley sits at straight;
it kept one if all the mass is on one side. At a red light one answer is right (stop, straight): the
paper's Fig. 6 shows the low-energy region spread along the steering axis at the junction and
concentrated at the red light. These pure functions read one profile e(s) (nats, over a steering
grid s, increasing, left < 0 < right):

- ``steering_profile``: the profile itself, from energies on a (steering, acceleration) grid;
- ``read_profile``: the one reading of a profile at a state (valleys, mass left of straight, 3-nat range),
  and ``read_grid``, the same from the energies on the grid (every reading of an agent at one state);
- ``valleys``: the valleys within ``depth`` (3) nats of the minimum that a barrier of at least
  ``barrier`` (1) nat separates from every lower one (topographic prominence);
- ``boltzmann_sides``: the mass of p(s) ∝ exp(-e(s)) left and right of straight;
- ``low_range``: the steering within ``depth`` nats of the minimum (its extent and its measure);
- ``beta_shape``: for BC, what its Beta over steering looks like (single-peaked, U-shaped or J-shaped).
"""

from __future__ import annotations

import math

import numpy as np

from ibc_tutorial.utils import check_positive

DEPTH = 3.0
"""Nats above the minimum within which a valley (or a steering value) counts as low."""
BARRIER = 1.0
"""Nats a barrier must rise above the higher of two valleys for them to count as two."""


def steering_profile(energy) -> np.ndarray:
    """The energy over steering of energies on a (steering, acceleration) grid: at each steering value the
    lowest energy over the accelerations, minus the lowest of all (nats, >= 0, 0 at the minimum).

    energy: (..., G accel, G steer), e.g. ``Agent.energy_grid``'s; returns (..., G steer)."""
    e = np.asarray(energy)
    if e.ndim < 2:
        raise ValueError(f"energy must have an acceleration and a steering axis, got shape {e.shape}")
    low = e.min(axis=-2)  # (..., G) the lowest over acceleration
    return low - low.min(axis=-1, keepdims=True)


def _profile(steer, energy) -> tuple[np.ndarray, np.ndarray]:
    s = np.asarray(steer, dtype=float).reshape(-1)
    e = np.asarray(energy, dtype=float).reshape(-1)
    if len(s) != len(e) or len(s) < 2:
        raise ValueError(f"steer and energy must be 1-D of one equal length >= 2, got {len(s)} and {len(e)}")
    if not (np.isfinite(s).all() and np.isfinite(e).all()):
        raise ValueError("steer and energy must be finite")
    if (np.diff(s) <= 0).any():
        raise ValueError("steer must be strictly increasing")
    return s, e


def _climb(v: np.ndarray, i: int, order) -> float:
    """The highest value from point ``i`` (along ``order``) to the first lower point (inf: none)."""
    top = -np.inf
    for j in order:
        if v[j] < v[i] or (v[j] == v[i] and j < i):
            return top
        top = max(top, v[j])
    return np.inf


def valleys(steer, energy, depth: float = DEPTH, barrier: float = BARRIER) -> list[dict]:
    """The separate valleys of a profile: ``[{"steer", "energy", "prominence"}]`` by steering.

    A plateau (a run of equal neighbouring values) counts as one point, at its middle. A valley is
    a local minimum; its prominence is how far it must climb to reach a lower valley, the lower of
    the highest points on the way left and on the way right (a way that meets the grid's edge before
    a lower point costs nothing: infinite). Equal minima are ordered by position, so of two equally
    deep valleys the left one counts as the lower. The global minimum's prominence is infinite. Kept:
    the valleys within ``depth`` nats of the global minimum with a prominence of at least ``barrier``.
    """
    depth = check_positive("depth", depth, allow_zero=True)
    barrier = check_positive("barrier", barrier, allow_zero=True)
    s, e = _profile(steer, energy)
    # collapse plateaus: (first index, last index, value) of each run of equal values
    cut = np.flatnonzero(np.diff(e) != 0) + 1
    starts = np.r_[0, cut]
    ends = np.r_[cut - 1, len(e) - 1]
    v = e[starts]  # (P,)
    n = len(v)
    lower_left = np.r_[np.inf, v[:-1]]
    lower_right = np.r_[v[1:], np.inf]
    minima = np.flatnonzero((v < lower_left) & (v < lower_right))
    floor = v.min()
    out = []
    for i in minima:
        if v[i] > floor + depth:
            continue
        prominence = min(_climb(v, i, range(i - 1, -1, -1)), _climb(v, i, range(i + 1, n))) - v[i]
        if prominence >= barrier:
            mid = 0.5 * (s[starts[i]] + s[ends[i]])
            out.append({"steer": float(mid), "energy": float(v[i]), "prominence": float(prominence)})
    return out


def read_profile(steer, low, marg) -> dict:
    """The one reading of an energy over steering at a state, used by every chapter that reads one (the stem
    analysis of chapters 09 and 12, the command readings of chapter 11, the forks and stem approaches of
    chapter 12).

    ``steer`` (G,) the grid's steering values (straight exactly 0: ``optimizers.grid.symmetric_axis``),
    ``low`` (G,) the lowest energy over acceleration at each (``steering_profile``) and ``marg`` (G,) the
    marginal over acceleration, -log sum_a exp(-E) (nats; each minus anything constant). Returns
    ``valleys`` (how many, by ``valleys``: within ``DEPTH`` nats of the minimum, a barrier of at least
    ``BARRIER``), ``valley_steer`` (where), ``two_sided`` (two valleys, one left and one right of straight),
    ``argmin_steer``, ``left_mass`` (the Boltzmann mass left of straight of the marginal, ``boltzmann_sides``)
    and ``left_mass_low`` (of the lowest), and the 3-nat range of ``low`` (``range_extent``,
    ``range_measure``: ``low_range``)."""
    s = np.asarray(steer, dtype=float)
    low = np.asarray(low, dtype=float)
    low = low - low.min()
    marg = np.asarray(marg, dtype=float)
    vs = valleys(s, low)
    r = low_range(s, low)
    return {
        "valleys": len(vs),
        "valley_steer": [v["steer"] for v in vs],
        "two_sided": any(v["steer"] < 0 for v in vs) and any(v["steer"] > 0 for v in vs),
        "argmin_steer": float(s[np.argmin(low)]),
        "left_mass_low": boltzmann_sides(s, low)["left"],
        "left_mass": boltzmann_sides(s, marg - marg.min())["left"],
        "range_extent": r["extent"],
        "range_measure": r["measure"],
    }


def read_grid(steer, energy) -> dict:
    """``read_profile`` of energies on an (acceleration, steering) grid at one state, with the profile itself.

    ``steer`` (G,) the grid's steering values (straight exactly 0), ``energy`` (A accel, G steer), e.g.
    ``Agent.energy_grid``'s. Returns ``read_profile``'s entries and ``profile`` (G,): the lowest energy over
    acceleration minus its minimum (``steering_profile``, in ``energy``'s dtype); the marginal read beside
    it is -log sum_a exp(-E)."""
    e = np.asarray(energy)
    low = steering_profile(e)  # (G,)
    marg = -np.logaddexp.reduce(-e, axis=-2)  # (G,) the marginal over acceleration
    return {"profile": low, **read_profile(steer, low, marg)}


def boltzmann_sides(steer, energy, temperature: float = 1.0) -> dict[str, float]:
    """Mass of p(s) ∝ exp(-e(s) / temperature) over the grid: ``{"left", "right"}`` (sum 1).

    Left is s < 0, right s > 0; a grid value at straight gives half its mass to each. Straight is any
    value within a millionth of the grid's spacing of 0, so that a float32 grid whose middle value is
    -1.5e-8 (``torch.linspace(-1, 1, 41)`` with AVX2 kernels) reads as one with an exact 0
    (``optimizers.grid.symmetric_axis``).
    """
    temperature = check_positive("temperature", temperature)
    s, e = _profile(steer, energy)
    p = np.exp(-(e - e.min()) / temperature)
    p = p / p.sum()
    straight = np.abs(s) <= 1e-6 * (s[-1] - s[0]) / (len(s) - 1)
    zero = 0.5 * p[straight].sum()
    return {
        "left": float(p[(s < 0) & ~straight].sum() + zero),
        "right": float(p[(s > 0) & ~straight].sum() + zero),
    }


def low_range(steer, energy, depth: float = DEPTH) -> dict[str, float]:
    """The steering within ``depth`` nats of the minimum: ``{"low", "high", "extent", "measure"}``.

    ``low`` and ``high`` are the most leftward and rightward such grid values, ``extent`` = high - low
    (0 if one grid value); ``measure`` counts the low grid values times the grid's mean spacing (it
    leaves out the gaps between separate valleys).
    """
    depth = check_positive("depth", depth, allow_zero=True)
    s, e = _profile(steer, energy)
    low = s[e <= e.min() + depth]
    spacing = (s[-1] - s[0]) / (len(s) - 1)
    return {
        "low": float(low.min()),
        "high": float(low.max()),
        "extent": float(low.max() - low.min()),
        "measure": float(len(low) * spacing),
    }


def beta_shape(alpha: float, beta: float) -> dict:
    """What a Beta(α, β) over steering (rescaled to [-1, 1]) looks like: shape, mean, mode.

    ``shape``: "single-peaked" (α > 1 and β > 1: an interior peak), "U-shaped" (α < 1 and β < 1: the
    density rises toward both ends, the two full turns), "J-shaped" (the density rises toward one end
    only) or "flat" (α = β = 1). ``mean`` = 2 α / (α + β) - 1; ``mode`` the interior peak (None unless
    single-peaked); ``mass_left`` the probability of steering left of straight.
    """
    a = check_positive("alpha", alpha)
    b = check_positive("beta", beta)
    if a > 1 and b > 1:
        shape = "single-peaked"
    elif a < 1 and b < 1:
        shape = "U-shaped"
    elif a == 1 and b == 1:
        shape = "flat"
    else:
        shape = "J-shaped"
    return {
        "shape": shape,
        "mean": 2 * a / (a + b) - 1,
        "mode": 2 * (a - 1) / (a + b - 2) - 1 if shape == "single-peaked" else None,
        "mass_left": beta_cdf(0.5, a, b),
    }


def beta_density(steer, alpha: float, beta: float) -> np.ndarray:
    """The density of a Beta(α, β) rescaled to steering in [-1, 1], at ``steer`` (per unit of steering:
    half the density on [0, 1] at (s + 1) / 2); 0 at the bounds where it is finite there."""
    a, b = check_positive("alpha", alpha), check_positive("beta", beta)
    s = np.asarray(steer, dtype=float)
    if not np.isfinite(s).all() or (np.abs(s) > 1).any():
        raise ValueError("steer must hold finite values in [-1, 1]")
    x = (s + 1.0) / 2.0
    log_b = math.lgamma(a) + math.lgamma(b) - math.lgamma(a + b)
    with np.errstate(divide="ignore"):
        log_p = (a - 1) * np.log(x) + (b - 1) * np.log1p(-x) - log_b
    return np.exp(log_p) / 2.0


def beta_cdf(x: float, a: float, b: float) -> float:
    """The regularised incomplete beta function I_x(a, b): P(Z <= x) for Z ~ Beta(a, b), 0 <= x <= 1.

    By its continued fraction (modified Lentz), on the side where it converges fast
    (x < (a + 1) / (a + b + 2), else 1 - I_{1-x}(b, a)); relative error below 1e-12.
    """
    a, b = check_positive("a", a), check_positive("b", b)
    if not 0.0 <= x <= 1.0:
        raise ValueError(f"x must be in [0, 1], got {x!r}")
    if x in (0.0, 1.0):
        return float(x)
    if x > (a + 1) / (a + b + 2):
        return 1.0 - beta_cdf(1.0 - x, b, a)
    from math import exp, lgamma, log

    front = exp(a * log(x) + b * log(1 - x) - (lgamma(a) + lgamma(b) - lgamma(a + b))) / a
    tiny = 1e-300
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1)
    d = 1.0 / (d if abs(d) > tiny else tiny)
    f = d
    for m in range(1, 500):
        for num in (
            m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)),
            -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1)),
        ):
            d = 1.0 + num * d
            d = 1.0 / (d if abs(d) > tiny else tiny)
            c = 1.0 + num / c
            c = c if abs(c) > tiny else tiny
            f *= c * d
        if abs(c * d - 1.0) < 1e-14:
            break
    return float(front * f)
