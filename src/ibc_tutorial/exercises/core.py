"""The feedback type and the safe-call wrapper shared by all exercise checkers."""

from __future__ import annotations

import math
import traceback
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

NOT_ATTEMPTED = "not attempted"
CORRECT = "correct"
HINT = "hint"
MARKS = {CORRECT: "✓", HINT: "→", NOT_ATTEMPTED: "○"}
"""The mark before each answer in a notebook: text glyphs that the common fonts (DejaVu, Liberation) have,
so they render without an emoji font."""


class NotAttempted(Exception):
    """Raised inside a checker when the reader's answer is still the stub."""


@dataclass(frozen=True)
class Feedback:
    """A checker's answer: ``status`` is one of "not attempted", "correct", "hint"."""

    status: str
    """"not attempted", "correct" or "hint"."""
    message: str
    """One or two sentences for the reader."""

    def __repr__(self) -> str:  # what a notebook cell prints
        return f"[{self.status}] {self.message}"

    def _repr_markdown_(self) -> str:
        mark = MARKS.get(self.status, "")
        return f"{mark} **{self.status}**: {self.message}"

    @property
    def correct(self) -> bool:
        return self.status == CORRECT


def not_attempted(what: str = "this exercise") -> Feedback:
    return Feedback(
        NOT_ATTEMPTED,
        f"Replace the `raise NotImplementedError` in {what} with your code, run the cell that "
        "defines your function, then run this checker cell.",
    )


def correct(message: str = "Well done.") -> Feedback:
    return Feedback(CORRECT, message)


def hint(message: str) -> Feedback:
    return Feedback(HINT, message)


def run_check(check: Callable[[], Feedback], what: str = "this exercise") -> Feedback:
    """Run ``check`` and turn anything the reader's code raises into feedback.

    A ``NotImplementedError`` (the stub) or ``NotAttempted`` means "not attempted"; any other
    exception becomes a hint naming the exception, never a traceback in the reader's face.
    """
    try:
        return check()
    except (NotImplementedError, NotAttempted):
        return not_attempted(what)
    except Exception as exc:  # the reader's code failed: tell them how, do not raise
        last = traceback.extract_tb(exc.__traceback__)[-1]
        return hint(f"your code raised {type(exc).__name__}: {exc} (line {last.lineno} of {last.name}).")


def tensor_answer(out, name: str, shape: tuple, what: str = "") -> torch.Tensor | Feedback:
    """The reader's ``out`` as a finite tensor of ``shape`` (detached), or a hint saying what is wrong.

    ``what`` is appended to the shape hint, e.g. "(one value per point)".
    """
    if not isinstance(out, torch.Tensor):
        return hint(f"{name} must return a torch.Tensor of shape {shape}, got {type(out).__name__}.")
    if tuple(out.shape) != shape:
        return hint(f"{name} must return a tensor of shape {shape}{what}, got {tuple(out.shape)}.")
    if not torch.isfinite(out).all():
        return hint(f"{name} returned NaN or inf values.")
    return out.detach()


def scalar_answer(out, name: str, advice: str) -> torch.Tensor | Feedback:
    """The reader's ``out`` as a scalar tensor, or the hint that says why it is not one; ``advice`` ends
    the hint for a tensor of another shape (how to reduce it)."""
    if not isinstance(out, torch.Tensor):
        return hint(f"{name} must return a torch.Tensor (a scalar), got {type(out).__name__}.")
    if out.ndim != 0:
        return hint(
            f"{name} must return a scalar (0-dimensional tensor), got shape {tuple(out.shape)}: {advice}"
        )
    return out


def mistake_hint(out, mistakes, rtol: float = 1e-4, atol: float = 1e-4) -> Feedback | None:
    """The hint "close, but check ..." for the first ``(value, what)`` of ``mistakes`` that ``out`` is
    ``close`` to (within ``rtol`` and ``atol``), or None when it is close to none of them."""
    for value, what in mistakes:
        if close(out, value, rtol=rtol, atol=atol):
            return hint(f"close, but check {what}")
    return None


def unnormalised_hint(out, ref, what: str, rtol: float = 1e-3, atol: float = 1e-4) -> Feedback | None:
    """The hint "right proportions, but not summing to 1" when ``out`` rescaled to sum to 1 is ``close``
    to ``ref`` (which sums to 1), else None; ``what`` says what the values are ("shares of ...")."""
    if close(out / out.sum(), ref, rtol=rtol, atol=atol):
        return hint(f"the proportions are right; make them sum to 1 ({what}).")
    return None


def close(a, b, rtol: float = 1e-4, atol: float = 1e-4) -> bool:
    """Whether the reader's ``a`` and the reference ``b`` (tensors, arrays or numbers) have the same
    shape and are finite and equal within ``rtol`` and ``atol`` (compared in float64)."""
    a = torch.as_tensor(a, dtype=torch.float64)
    b = torch.as_tensor(b, dtype=torch.float64)
    return (
        a.shape == b.shape
        and bool(torch.isfinite(a).all())
        and bool(torch.allclose(a, b, rtol=rtol, atol=atol))
    )


def number_answer(value, name: str) -> float | Feedback:
    """A reader's function's return value as a finite float, or the hint that says why it is not one
    (``name`` is the function's name in the exercise). True and False are refused: they are not numbers."""
    if isinstance(value, (bool, np.bool_)):
        return hint(f"{name} must return a number, got {type(value).__name__}.")
    try:
        v = float(value)
    except (TypeError, ValueError):
        return hint(f"{name} must return a number, got {type(value).__name__}.")
    if not math.isfinite(v):
        return hint(f"{name} returned {v} for an ordinary input.")
    return v
