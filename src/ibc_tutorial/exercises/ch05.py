"""Checkers for ``exercises/05_kde_weighting.ipynb``.

- ``check_kde_1d(fn)``: eq. 4 of the DA-IBC paper by hand, ``fn(x (Q,), data (M,), h) -> (Q,)``.
- ``check_inverse_weights(fn)``: the weights of eq. 5, ``fn(actions (M, D), h) -> (M,)`` summing to 1.
- ``check_choose_bandwidth(fn)``: the chapter's finding, a bandwidth chosen by the rare share of
  weighted minibatches under a floor on the weights' effective sample size,
  ``fn(actions (M, D), rare (M,), candidates, min_ess) -> float``.

Each compares the reader's function with an independent reference (a float64 evaluation of the
formula) and, when they differ, tries the usual mistakes one by one to name the one made.
"""

from __future__ import annotations

import math

import torch

from ibc_tutorial.exercises.core import (
    Feedback,
    close,
    correct,
    hint,
    mistake_hint,
    run_check,
    tensor_answer,
    unnormalised_hint,
)
from ibc_tutorial.kde import inverse_density_weights


def _tensor(out, name: str, shape: tuple) -> torch.Tensor | Feedback:
    """The answer as float64, or a hint (``core.tensor_answer``)."""
    out = tensor_answer(out, name, shape, " (one value per point)")
    return out if isinstance(out, Feedback) else out.to(torch.float64)


# --------------------------------------------------------------------------- eq. 4 by hand
def _kde_ref(
    x: torch.Tensor,
    data: torch.Tensor,
    h: float,
    *,
    kernel_const=True,
    divide_h=True,
    divide_m=True,
    half=True,
) -> torch.Tensor:
    """Eq. 4 in float64, with switches that reproduce the usual mistakes."""
    u = (x.double()[:, None] - data.double()[None, :]) / h  # (Q, M)
    k = torch.exp(-(0.5 if half else 1.0) * u**2)
    if kernel_const:
        k = k / math.sqrt(2 * math.pi)
    total = k.sum(dim=1)
    if divide_m:
        total = total / len(data)
    if divide_h:
        total = total / h
    return total


def check_kde_1d(fn) -> Feedback:
    """Check ``fn(x (Q,), data (M,), h) -> (Q,)`` against eq. 4 with the Gaussian kernel."""

    def check() -> Feedback:
        g = torch.Generator().manual_seed(0)
        data = torch.cat(
            [0.05 * torch.randn(40, generator=g), 0.7 + 0.05 * torch.randn(8, generator=g)]
        )  # (48,)
        x = torch.linspace(-1, 1, 21)
        h = 0.2
        out = _tensor(fn(x.clone(), data.clone(), h), "kde_1d", (21,))
        if isinstance(out, Feedback):
            return out
        ref = _kde_ref(x, data, h)
        if not close(out, ref, atol=1e-12):
            mistakes = [
                (
                    _kde_ref(x, data, h, divide_h=False),
                    "the factor 1/(N h) of eq. 4: the 1/h is missing, so the estimate does not integrate "
                    "to 1.",
                ),
                (
                    _kde_ref(x, data, h, divide_m=False),
                    "the factor 1/(N h) of eq. 4: divide by the number of data points N too (ĝ is an "
                    "average of kernels).",
                ),
                (
                    _kde_ref(x, data, h, kernel_const=False),
                    "the kernel K(u): the Gaussian density has a constant in front of the exponential.",
                ),
                (
                    _kde_ref(x, data, h, half=False),
                    "the kernel K(u): look again at the exponent of the standard Gaussian density.",
                ),
                (
                    _kde_ref(x, data, h * h),
                    "how the bandwidth enters: u = (x − x_j) / h, with h itself, not h².",
                ),
            ]
            if (mistake := mistake_hint(out, mistakes, atol=1e-12)) is not None:
                return mistake
            i = int((out - ref).abs().argmax())
            return hint(
                f"at x = {float(x[i]):.2f} your density is {float(out[i]):.4g} where eq. 4 gives "
                f"{float(ref[i]):.4g}; compute one value by hand and compare."
            )
        # another bandwidth and sizes: nothing hard-coded
        data2, x2 = torch.tensor([-0.3, 0.1, 0.2]), torch.tensor([0.0, 0.5])
        out2 = _tensor(fn(x2, data2, 0.5), "kde_1d", (2,))
        if isinstance(out2, Feedback):
            return out2
        if not close(out2, _kde_ref(x2, data2, 0.5), atol=1e-12):
            return hint(
                "correct for h = 0.2 and 48 data points, but not for h = 0.5 and 3: avoid hard-coding the "
                "bandwidth or the number of points."
            )
        return correct(
            "Your density matches eq. 4: an average of Gaussian bumps of width h, each of area 1/N."
        )

    return run_check(check, "`kde_1d`")


# --------------------------------------------------------------------------- inverse-density weights (eq. 5)
def _actions() -> torch.Tensor:
    g = torch.Generator().manual_seed(1)
    common = 0.05 * torch.randn(90, 2, generator=g) + torch.tensor([0.0, 0.3])
    rare = 0.05 * torch.randn(10, 2, generator=g) + torch.tensor([0.7, 0.1])
    return torch.cat([common, rare])  # (100, 2)


def _density(actions: torch.Tensor, h: float) -> torch.Tensor:
    """ĝ at each action (product Gaussian kernel, eq. 4 in D dimensions), float64."""
    u = (actions.double()[:, None, :] - actions.double()[None, :, :]) / h  # (M, M, D)
    d = actions.shape[1]
    k = torch.exp(-0.5 * (u**2).sum(-1)) / (2 * math.pi) ** (d / 2)
    return k.sum(1) / (len(actions) * h**d)


def check_inverse_weights(fn) -> Feedback:
    """Check ``fn(actions (M, D), h) -> (M,)``: weights ∝ 1/ĝ(y_i) summing to 1."""

    def check() -> Feedback:
        actions = _actions()
        out = _tensor(fn(actions.clone(), 0.2), "inverse_weights", (100,))
        if isinstance(out, Feedback):
            return out
        g = _density(actions, 0.2)
        ref = (1 / g) / (1 / g).sum()
        if not close(out, ref, rtol=1e-3, atol=1e-12):
            if abs(float(out.sum()) - 1) > 1e-3:
                if (
                    fb := unnormalised_hint(out, ref, "they become sampling probabilities", atol=1e-12)
                ) is not None:
                    return fb
                return hint(
                    f"your weights sum to {float(out.sum()):.4g}: normalise them so that they sum to 1."
                )
            if close(out, g / g.sum(), rtol=1e-3, atol=1e-12):
                return hint(
                    "your weights grow with the density: eq. 5 gives *rare* actions (low density) the "
                    "large weights."
                )
            if out[90:].mean() <= out[:90].mean():
                return hint(
                    "the 10 rare actions should get larger weights than the 90 common ones; yours do not."
                )
            return hint(
                "your weights sum to 1 and favour the rare actions, but they are not proportional to "
                "1/ĝ(y_i) with ĝ the KDE of eq. 4 at bandwidth h (over all D dimensions)."
            )
        out2 = _tensor(fn(actions.clone(), 0.5), "inverse_weights", (100,))
        if isinstance(out2, Feedback):
            return out2
        g2 = _density(actions, 0.5)
        if not close(out2, (1 / g2) / (1 / g2).sum(), rtol=1e-3, atol=1e-12):
            return hint("correct for h = 0.2 but not for h = 0.5: use the bandwidth you are given.")
        return correct("Your weights are w_i ∝ 1/ĝ(y_i), summing to 1: rare actions weigh more.")

    return run_check(check, "`inverse_weights`")


# -------------------------------------------------------------- choosing a bandwidth by effective sample size
_CANDIDATES = (0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 1.0)
_MIN_ESS = (200.0, 160.0)
"""The floors the checker asks about: they choose different bandwidths."""


def _driving_like() -> tuple[torch.Tensor, torch.Tensor]:
    """(M, 2) actions like the chapter's (cruising, two turns, a braking band) and (M,) bool rare."""
    g = torch.Generator().manual_seed(5)
    d = torch.float64
    cruise = torch.tensor([0.0, 0.35], dtype=d) + 0.05 * torch.randn(900, 2, generator=g, dtype=d)
    left = torch.tensor([-0.7, 0.1], dtype=d) + 0.02 * torch.randn(25, 2, generator=g, dtype=d)
    right = torch.tensor([0.7, 0.1], dtype=d) + 0.02 * torch.randn(25, 2, generator=g, dtype=d)
    v = torch.rand(50, 1, generator=g, dtype=d)
    brake = torch.cat([0.02 * torch.randn(50, 1, generator=g, dtype=d), -0.2 - 0.6 * v], dim=1)
    actions = torch.cat([cruise, left, right, brake])  # (1000, 2)
    return actions, torch.arange(len(actions)) >= 900


def _bandwidth_table(actions: torch.Tensor, rare: torch.Tensor) -> dict[float, tuple[float, float]]:
    """{h: (share of rare samples in weighted minibatches, effective sample size 1/Σ w²)}."""

    out = {}
    for h in _CANDIDATES:
        w = inverse_density_weights(actions, h).double()  # (M,) summing to 1
        out[h] = (float(w[rare].sum()), float(1 / (w**2).sum()))
    return out


def _reference_choice(table: dict, min_ess: float) -> float | None:
    ok = [h for h, (_, ess) in table.items() if ess >= min_ess]
    return max(ok, key=lambda h: table[h][0]) if ok else None


def check_choose_bandwidth(fn) -> Feedback:
    """Check ``fn(actions (M, D), rare (M,) bool, candidates, min_ess) -> float``: among the candidate
    bandwidths whose weights keep an effective sample size 1/Σ w_i² of at least ``min_ess``, the one
    whose weighted minibatches hold the largest share of rare samples."""

    def check() -> Feedback:
        actions, rare = _driving_like()
        table = _bandwidth_table(actions, rare)
        for min_ess in _MIN_ESS:
            ref = _reference_choice(table, min_ess)
            out = fn(actions.clone(), rare.clone(), list(_CANDIDATES), min_ess)
            try:
                if isinstance(out, (str, bytes)) or out is None:
                    raise TypeError
                h = float(out)
            except (TypeError, ValueError, RuntimeError):
                return hint(
                    "choose_bandwidth must return one bandwidth (a number from `candidates`), got "
                    f"{type(out).__name__}."
                )
            if h not in _CANDIDATES:
                if 0 <= h < len(_CANDIDATES) and float(h).is_integer():
                    return hint("return the bandwidth itself, not its index in `candidates`.")
                return hint(
                    f"choose_bandwidth returned {h:g}, which is not one of the candidates "
                    f"{list(_CANDIDATES)}."
                )
            if h == ref:
                continue
            share, ess = table[h]
            best_any = max(_CANDIDATES, key=lambda c: table[c][0])
            if h == best_any and ess < min_ess:
                return hint(
                    f"h = {h:g} brings the most rare samples into minibatches ({share:.0%}), but its "
                    "weights' effective sample size is "
                    f"only {ess:.0f} < {min_ess:.0f}: a few stray actions take over. Keep only the "
                    "bandwidths whose 1/Σ w² reaches min_ess."
                )
            if h == max(_CANDIDATES, key=lambda c: table[c][1]):
                return hint(
                    f"h = {h:g} has the largest effective sample size, because its weights are nearly "
                    f"uniform: its minibatches hold only {share:.0%} rare samples, and candidates with more "
                    "pass the test too. Among the bandwidths that pass (1 / Σ w_i² of the weights normalised "
                    "to sum to 1, at least min_ess), take the one with the largest rare share."
                )
            if ess < min_ess:
                return hint(
                    f"h = {h:g} has an effective sample size of {ess:.0f}, below min_ess = {min_ess:.0f}: "
                    "compute it as 1 / Σ w_i² of the normalised weights."
                )
            other = [m for m in _MIN_ESS if m != min_ess and _reference_choice(table, m) == h]
            if other:
                return hint(
                    f"h = {h:g} is the choice for min_ess = {other[0]:.0f}, not for min_ess = {min_ess:.0f}: "
                    "use the min_ess you are given."
                )
            return hint(
                f"h = {h:g} passes the effective-sample-size test, but a candidate whose minibatches hold "
                f"more rare samples than its {share:.0%} passes it too. Check both halves of the choice: the "
                "test (1 / Σ w_i² of the weights normalised to sum to 1: computed otherwise, it can drop a "
                "candidate that passes) and the share compared, Σ w_i over the rare samples."
            )
        return correct(
            "Right: the narrowest bandwidths let a few stray actions take over (low effective sample "
            "size), the widest make the weights "
            "nearly uniform (few rare samples); the choice is in between, and it moves with min_ess and "
            "with the data."
        )

    return run_check(check, "`choose_bandwidth`")
