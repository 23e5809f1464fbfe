"""Checkers for ``exercises/13_other_families.ipynb``: a flow policy's sampling and training target, and
ranking NCE's logits.

- ``check_euler_sample(fn)``: K Euler steps of dy/dt = v(y, t) from t = 0 to 1,
  ``fn(velocity, y0 (N, D), n_steps) -> (N, D)``, ``velocity(y (N, D), t: float) -> (N, D)``: y ← y + v(y,
  k/K) / K for k = 0..K−1, nothing clipped (``policies.flow.FlowPolicy.sample`` clips only at the end).
- ``check_flow_pair(fn)``: the conditional flow-matching pair of a straight path,
  ``fn(y0 (N, D), y1 (N, D), t (N,)) -> (y_t, u)``: y_t = (1 − t) y0 + t y1 and u = y1 − y0 (Lipman et al.
  2023, eqs. 20-23 with σ_min = 0).
- ``check_ranking_logits(fn)``: ranking NCE's logits, ``fn(pos_energy (B,), neg_energy (B, N), pos_log_q
  (B,), neg_log_q (B, N)) -> (B, 1 + N)``: −E − log q, the expert first (``losses.ranking_nce``).

Each compares the reader's function with the reference on chosen cases and, when they differ, tests the
usual mistakes one by one to name the one made, without giving the answer away.
"""

from __future__ import annotations

import torch

from ibc_tutorial.exercises.core import Feedback, close, correct, hint, mistake_hint, run_check, tensor_answer


# --------------------------------------------------------------------------- 1. Euler steps
def _euler(velocity, y0: torch.Tensor, k: int, *, t_of=lambda i, k: i / k, h=None, steps=None, clip=False):
    """Euler integration with one of the usual mistakes switched on (the reference with none)."""
    y = y0.clone()
    for i in range(k if steps is None else steps):
        y = y + velocity(y, t_of(i, k)) * (1.0 / k if h is None else h)
        if clip:
            y = y.clamp(-1.0, 1.0)
    return y


def _time_field(y, t):  # v = t: the time of each step matters
    return torch.full_like(y, float(t))


def _decay_field(y, t):  # v = −2 y: the step size matters
    return -2.0 * y


def _there_and_back_field(y, t):  # v = 3, then −3 from t = 1/2: out of the box and back
    return torch.full_like(y, 3.0 if t < 0.5 else -3.0)


def _push_field(y, t):  # v = 3: carries every sample out of the box
    return torch.full_like(y, 3.0)


EULER_CASES = [
    (_decay_field, torch.tensor([[1.0, -0.5], [0.3, 0.2]]), 3),
    (_time_field, torch.tensor([[0.0], [0.5], [-0.2]]), 4),
    (_there_and_back_field, torch.tensor([[0.0, -0.5, 0.2]]), 2),
    (_push_field, torch.tensor([[0.0, -0.5, 0.2]]), 2),
    (_decay_field, torch.tensor([[0.8]]), 1),
]
"""(velocity, y0 (N, D), K): the step count and size, the time, the box and a single step each tell a
mistake."""


def check_euler_sample(fn) -> Feedback:
    """Check ``fn(velocity, y0, n_steps)``: K Euler steps from t = 0 to t = 1."""

    def check() -> Feedback:
        for velocity, y0, k in EULER_CASES:
            out = tensor_answer(fn(velocity, y0.clone(), k), "euler_sample", tuple(y0.shape), " (like y0)")
            if isinstance(out, Feedback):
                return out
            want = _euler(velocity, y0, k)
            if close(out, want):
                continue
            mistakes = [
                (
                    _euler(velocity, y0, k, t_of=lambda i, k: (i + 1) / k),
                    "the time at which each step reads the velocity: an Euler step uses the velocity at "
                    "the time where it starts, t = 0 first.",
                ),
                (
                    _euler(velocity, y0, k, h=1.0),
                    "the size of each step: K steps cover the time from 0 to 1.",
                ),
                (_euler(velocity, y0, k, steps=k + 1), "how many steps you take: K, from t = 0 to t = 1."),
                (_euler(velocity, y0, k, steps=k - 1), "how many steps you take: K, from t = 0 to t = 1."),
                (
                    _euler(velocity, y0, k).clamp(-1, 1),
                    "the box: return the samples as the last step leaves "
                    "them, unclipped (the library clips them itself).",
                ),
                (
                    _euler(velocity, y0, k, clip=True),
                    "the box: nothing is clipped here (the library clips "
                    "the samples once, after the last step).",
                ),
                (y0 + velocity(y0, 0.0), "the number of steps: one step of size 1 is K = 1 only."),
            ]
            return mistake_hint(out, mistakes, atol=1e-5) or hint(
                f"with K = {k} your samples differ from K Euler steps of dy/dt = v(y, t) from t = 0 to t = 1."
            )
        return correct("K Euler steps, each reading the velocity where it starts, and nothing clipped.")

    return run_check(check, "`euler_sample`")


# --------------------------------------------------------------------------- 2. the flow-matching pair
_Y0 = torch.tensor([[0.5, -1.2], [2.0, 0.3], [-0.7, 0.9]])  # (3, 2) noise
_Y1 = torch.tensor([[0.6, -0.6], [-0.9, 0.8], [0.1, 0.1]])  # (3, 2) expert actions
_T = torch.tensor([0.25, 0.5, 0.9])  # (3,) times


def check_flow_pair(fn) -> Feedback:
    """Check ``fn(y0, y1, t) -> (y_t, u)``: the point of the straight path at t and its velocity."""

    def check() -> Feedback:
        out = fn(_Y0.clone(), _Y1.clone(), _T.clone())
        if not isinstance(out, tuple) or len(out) != 2:
            return hint("flow_pair must return a pair (y_t, u) of tensors shaped like y0.")
        y_t = tensor_answer(out[0], "flow_pair's y_t", tuple(_Y0.shape), " (like y0)")
        if isinstance(y_t, Feedback):
            return y_t
        u = tensor_answer(out[1], "flow_pair's u", tuple(_Y0.shape), " (like y0)")
        if isinstance(u, Feedback):
            return u
        t = _T[:, None]
        want_yt, want_u = (1 - t) * _Y0 + t * _Y1, _Y1 - _Y0
        if not close(y_t, want_yt):
            return mistake_hint(
                y_t,
                [
                    (
                        t * _Y0 + (1 - t) * _Y1,
                        "where the path starts: at t = 0 it is the noise y0, at t = 1 the expert's action.",
                    ),
                ],
            ) or hint("y_t is not the point of the straight path from y0 to y1 at time t (one t per row).")
        if not close(u, want_u):
            return mistake_hint(
                u,
                [
                    (_Y0 - _Y1, "the direction of u: the path runs from the noise to the expert's action."),
                    (_Y1 - want_yt, "u: along a straight path the velocity is the same at every t."),
                    (want_u * t, "u: along a straight path the velocity is the same at every t."),
                ],
            ) or hint("u is not the velocity of the straight path from y0 to y1.")
        return correct("the straight path and its constant velocity: the regression target of flow matching.")

    return run_check(check, "`flow_pair`")


# --------------------------------------------------------------------------- 3. ranking NCE's logits
_POS_E = torch.tensor([0.3, -1.0])  # (2,)
_NEG_E = torch.tensor([[1.0, 0.2, -0.4], [2.0, 0.5, 0.0]])  # (2, 3)
_POS_LQ = torch.tensor([0.8, 1.1])  # (2,)
_NEG_LQ = torch.tensor([[-0.5, 0.9, 0.1], [-2.0, 0.4, 1.3]])  # (2, 3)


def check_ranking_logits(fn) -> Feedback:
    """Check ``fn(pos_energy, neg_energy, pos_log_q, neg_log_q) -> (B, 1 + N)``: −E − log q, expert first."""

    def check() -> Feedback:
        out = tensor_answer(
            fn(_POS_E.clone(), _NEG_E.clone(), _POS_LQ.clone(), _NEG_LQ.clone()),
            "ranking_logits",
            (2, 4),
            " (B, 1 + N: the expert first)",
        )
        if isinstance(out, Feedback):
            return out
        energy = torch.cat([_POS_E[:, None], _NEG_E], dim=1)  # (B, 1 + N)
        log_q = torch.cat([_POS_LQ[:, None], _NEG_LQ], dim=1)
        want = -energy - log_q
        if close(out, want):
            return correct(
                "−E − log q for every candidate, the expert's included: exp(−E) learns p, not p/q."
            )
        neg_only = torch.cat([-_POS_E[:, None], -_NEG_E - _NEG_LQ], dim=1)
        mistakes = [
            (-energy + log_q, "the sign of log q: a candidate that q proposes often must be penalised."),
            (-energy, "log q: without it these are InfoNCE's logits, whose optimum is exp(−E) ∝ p / q."),
            (energy - log_q, "the sign of the energy: a low energy is a likely action."),
            (neg_only, "the expert's candidate: it was drawn too, and its log q is subtracted as well."),
            (
                torch.cat([-_NEG_E - _NEG_LQ, -_POS_E[:, None] - _POS_LQ[:, None]], dim=1),
                "the order: the expert first.",
            ),
            (torch.log_softmax(want, dim=1), "what to return: the logits themselves, not their log-softmax."),
        ]
        return mistake_hint(out, mistakes) or hint("these are not −E − log q of the 1 + N candidates.")

    return run_check(check, "`ranking_logits`")
