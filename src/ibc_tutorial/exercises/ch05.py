"""Checkers for ``exercises/05_kde_weighting.ipynb``.

- ``check_kde_1d(fn)``: eq. 4 of the DA-IBC paper by hand, ``fn(x (Q,), data (M,), h) -> (Q,)``.
- ``check_inverse_weights(fn)``: the weights of eq. 5, ``fn(actions (M, D), h) -> (M,)`` summing to 1.

Each compares the reader's function with an independent reference (a float64 evaluation of the
formula) and, when they differ, tries the usual mistakes one by one to name the one made.
"""

from __future__ import annotations

import math

import torch

from ibc_tutorial.exercises.core import Feedback, correct, hint, run_check


def _tensor(out, name: str, shape: tuple) -> torch.Tensor | Feedback:
    if not isinstance(out, torch.Tensor):
        return hint(f"{name} must return a torch.Tensor of shape {shape}, got {type(out).__name__}.")
    if tuple(out.shape) != shape:
        return hint(f"{name} must return a tensor of shape {shape} (one value per point), got {tuple(out.shape)}.")
    if not torch.isfinite(out).all():
        return hint(f"{name} returned NaN or inf values.")
    return out.detach().to(torch.float64)


def _close(a: torch.Tensor, b: torch.Tensor, rtol: float = 1e-4) -> bool:
    return bool(torch.allclose(a.double(), b.double(), rtol=rtol, atol=1e-12))


# --------------------------------------------------------------------------- eq. 4 by hand
def _kde_ref(x: torch.Tensor, data: torch.Tensor, h: float, *, kernel_const=True, divide_h=True, divide_m=True, half=True) -> torch.Tensor:
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
        data = torch.cat([0.05 * torch.randn(40, generator=g), 0.7 + 0.05 * torch.randn(8, generator=g)])  # (48,)
        x = torch.linspace(-1, 1, 21)
        h = 0.2
        out = _tensor(fn(x.clone(), data.clone(), h), "kde_1d", (21,))
        if isinstance(out, Feedback):
            return out
        ref = _kde_ref(x, data, h)
        if not _close(out, ref):
            mistakes = [
                (_kde_ref(x, data, h, divide_h=False), "the factor 1/(N h) of eq. 4: the 1/h is missing, so the estimate does not integrate to 1."),
                (_kde_ref(x, data, h, divide_m=False), "the factor 1/(N h) of eq. 4: divide by the number of data points N too (ĝ is an average of kernels)."),
                (_kde_ref(x, data, h, kernel_const=False), "the kernel K(u): the Gaussian density has a constant in front of the exponential."),
                (_kde_ref(x, data, h, half=False), "the kernel K(u): look again at the exponent of the standard Gaussian density."),
                (_kde_ref(x, data, h * h), "how the bandwidth enters: u = (x − x_j) / h, with h itself, not h²."),
            ]
            for value, what in mistakes:
                if _close(out, value):
                    return hint(f"close, but check {what}")
            i = int((out - ref).abs().argmax())
            return hint(f"at x = {float(x[i]):.2f} your density is {float(out[i]):.4g} where eq. 4 gives {float(ref[i]):.4g}; compute one value by hand and compare.")
        # another bandwidth and sizes: nothing hard-coded
        data2, x2 = torch.tensor([-0.3, 0.1, 0.2]), torch.tensor([0.0, 0.5])
        out2 = _tensor(fn(x2, data2, 0.5), "kde_1d", (2,))
        if isinstance(out2, Feedback):
            return out2
        if not _close(out2, _kde_ref(x2, data2, 0.5)):
            return hint("correct for h = 0.2 and 48 data points, but not for h = 0.5 and 3: avoid hard-coding the bandwidth or the number of points.")
        return correct("Your density matches eq. 4: an average of Gaussian bumps of width h, each of area 1/N.")

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
        if not _close(out, ref, rtol=1e-3):
            if abs(float(out.sum()) - 1) > 1e-3:
                if _close(out / out.sum(), ref, rtol=1e-3):
                    return hint("the weights are proportional to the right values, but they must sum to 1 (they become sampling probabilities).")
                return hint(f"your weights sum to {float(out.sum()):.4g}: normalise them so that they sum to 1.")
            if _close(out, g / g.sum(), rtol=1e-3):
                return hint("your weights grow with the density: eq. 5 gives *rare* actions (low density) the large weights.")
            if out[90:].mean() <= out[:90].mean():
                return hint("the 10 rare actions should get larger weights than the 90 common ones; yours do not.")
            return hint("your weights sum to 1 and favour the rare actions, but they are not proportional to 1/ĝ(y_i) with ĝ the KDE of eq. 4 at bandwidth h (over all D dimensions).")
        out2 = _tensor(fn(actions.clone(), 0.5), "inverse_weights", (100,))
        if isinstance(out2, Feedback):
            return out2
        g2 = _density(actions, 0.5)
        if not _close(out2, (1 / g2) / (1 / g2).sum(), rtol=1e-3):
            return hint("correct for h = 0.2 but not for h = 0.5: use the bandwidth you are given.")
        return correct("Your weights are w_i ∝ 1/ĝ(y_i), summing to 1: rare actions weigh more.")

    return run_check(check, "`inverse_weights`")
