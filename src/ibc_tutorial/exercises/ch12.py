"""Checkers for ``exercises/12_tree_in_the_town.ipynb``: a fork and its gap, two valleys, the minority exit.

- ``check_fork(fn)``: the fork of an episode and its twin (``driving.forks``' rule),
  ``fn(recorded, twin) -> (index, gap)``: the first state at which the two (T, 2) label arrays
  [steer, acceleration] differ and the steering gap there; ``ValueError`` when they never differ.
- ``check_two_sided(fn)``: whether an energy profile over steering keeps both exits of a stem,
  ``fn(steer, profile) -> bool``: two valleys by the book's criterion (``energy_profiles.valleys``:
  within 3 nats of the minimum, a barrier of at least 1 nat), one left and one right of straight.
- ``check_exit_summary(fn)``: a method's stem exits over its agents,
  ``fn(counts) -> {"minority": share, "both": n_agents}`` with ``counts`` a list of (left, right) per
  agent: the pooled minority share (``stats.minority`` of the pooled left share) and the agents that
  took both exits.
- ``check_commit(fn)``: the flow agent's commitment rule (``agents.agent.nearest_previous_steer``),
  ``fn(samples (B, N, 2), previous_steer (B,)) -> (B, 2)``: of N sampled actions, the one whose steering is
  nearest the previous steering (ties: the first).
- ``check_head_passes(fn)``: what one decision costs in head passes (``Preset.network_evaluations``),
  ``fn(dfo_samples, dfo_iters, flow_samples, flow_steps) -> (dfo, flow)``: N x N_iters and N x K.
- ``check_expert_log_q(fn)``: the log-density of DA-IBC's counter-example proposal that ranking NCE
  subtracts (``negatives.ExpertSampler.log_prob``, unclipped), ``fn(candidates (B, K, D), actions (M, D),
  sigma) -> (B, K)``: log (1/M) Σ_m N(y; a_m, σ² I).

Each compares the reader's function with the library's rule on chosen cases and, when they differ, tests
the usual mistakes one by one to name the one made, without giving the answer away.
"""

from __future__ import annotations

import math
import numbers

import numpy as np
import torch

from ibc_tutorial.driving.energy_profiles import BARRIER, DEPTH, boltzmann_sides, valleys
from ibc_tutorial.exercises.core import (
    Feedback,
    close,
    correct,
    hint,
    mistake_hint,
    number_answer,
    run_check,
    tensor_answer,
)
from ibc_tutorial.negatives import ExpertSampler
from ibc_tutorial.policies.flow import network_evaluations as flow_network_evaluations
from ibc_tutorial.stats import minority


# --------------------------------------------------------------------------- 1. the fork and its gap
def _labels(steer, accel) -> np.ndarray:
    return np.stack([np.asarray(steer, dtype=np.float32), np.asarray(accel, dtype=np.float32)], axis=1)


def _fork_case(steer, accel, twin_steer, twin_accel) -> tuple[np.ndarray, np.ndarray]:
    return _labels(steer, accel), _labels(twin_steer, twin_accel)


_TINY = 2.0**-20
"""A difference of about a millionth in steering: float32 tells it apart at 0.25, ``np.isclose`` does not."""

FORK_CASES = [
    # (recorded (T, 2), twin (T, 2)): float32 labels, as a log stores them, identical up to the fork
    _fork_case(  # fork at 3; recorded steers more to the right than the twin; acceleration differs too
        [0.0, 0.01, 0.015, 0.02, 0.3, 0.6, 0.7],
        [0.5, 0.4, 0.3, 0.3, 0.1, 0.0, 0.0],
        [0.0, 0.01, 0.015, -0.085, -0.3, -0.6, -0.7],
        [0.5, 0.4, 0.3, 0.1, 0.05, 0.0, 0.0],
    ),
    _fork_case(  # fork at 5; recorded steers more to the left than the twin
        [0.0, 0.0, -0.01, -0.02, -0.03, -0.06, -0.4, -0.7, -0.7],
        [0.3, 0.3, 0.3, 0.3, 0.3, 0.2, 0.0, -0.1, 0.0],
        [0.0, 0.0, -0.01, -0.02, -0.03, 0.048, 0.4, 0.7, 0.7],
        [0.3, 0.3, 0.3, 0.3, 0.3, 0.45, 0.2, 0.1, 0.0],
    ),
    _fork_case(  # fork at 2 by a millionth in steering; the clear difference comes two states later
        [0.1, 0.2, 0.25, 0.25, 0.3, 0.5],
        [0.4, 0.4, 0.4, 0.4, 0.4, 0.4],
        [0.1, 0.2, 0.25 + _TINY, 0.25, -0.3, -0.5],
        [0.4, 0.4, 0.4, 0.4, 0.4, 0.4],
    ),
    _fork_case(  # fork at 3 in the acceleration only (gap 0); the steering parts one state later
        [0.0, 0.0, 0.01, 0.02, 0.02, 0.2, 0.5],
        [0.6, 0.5, 0.5, 0.5, 0.4, 0.2, 0.1],
        [0.0, 0.0, 0.01, 0.02, -0.09, -0.2, -0.5],
        [0.6, 0.5, 0.5, 0.45, 0.3, 0.2, 0.1],
    ),
]


def _fork_ref(recorded, twin, *, steer_only=False, tolerant=False) -> tuple[int, float]:
    a, b = (recorded[:, :1], twin[:, :1]) if steer_only else (recorded, twin)
    differ = ~np.isclose(a, b) if tolerant else a != b
    i = int(np.flatnonzero(differ.any(axis=1))[0])
    return i, float(abs(float(recorded[i, 0]) - float(twin[i, 0])))


FORK_HINTS = {
    "last identical": "that is the last state at which the two labels agree; the fork is where they part.",
    "tolerant": "a difference of a millionth is still a difference: before the fork an episode and its twin "
    "are equal bit for bit (the simulator and the expert are deterministic), so compare exactly, without a "
    "tolerance or rounding.",
    "steer only": "a label is [steer, acceleration]: the two labels can part in the acceleration first, and "
    "the fork is there even if the steering is still equal.",
    "norm": "the label gap is the distance between the two labels in steering only, not in the whole action.",
    "signed": "the label gap is a distance: it does not depend on which of the two is the recorded episode.",
}


def _index_answer(out) -> tuple[int, float] | Feedback:
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        return hint(f"fork must return a pair (index, gap), got {type(out).__name__} {out!r}.")
    index, gap = out
    if isinstance(index, (bool, np.bool_)) or not isinstance(index, numbers.Integral):
        return hint(f"the index fork returns must be a whole number (an int), got {type(index).__name__}.")
    gap = number_answer(gap, "fork's gap")
    if isinstance(gap, Feedback):
        return gap
    return int(index), gap


def check_fork(fn) -> Feedback:
    """Check ``fn(recorded, twin)``: the first index at which the labels differ (any component) and
    ``|recorded[i, 0] - twin[i, 0]|`` there; ``ValueError`` for labels that never differ."""

    def check() -> Feedback:
        for recorded, twin in FORK_CASES:
            out = _index_answer(fn(recorded.copy(), twin.copy()))
            if isinstance(out, Feedback):
                return out
            index, gap = out
            ref_index, ref_gap = _fork_ref(recorded, twin)
            if index == ref_index and close(gap, ref_gap, rtol=1e-5, atol=1e-7):
                continue
            if index == ref_index - 1:
                return hint(FORK_HINTS["last identical"])
            if index == _fork_ref(recorded, twin, tolerant=True)[0] != ref_index:
                return hint(FORK_HINTS["tolerant"])
            if index == _fork_ref(recorded, twin, steer_only=True)[0] != ref_index:
                return hint(FORK_HINTS["steer only"])
            if index == ref_index:
                d = recorded[index].astype(float) - twin[index].astype(float)
                if close(gap, float(np.linalg.norm(d)), rtol=1e-5, atol=1e-7):
                    return hint(FORK_HINTS["norm"])
                if ref_gap > 0 and close(gap, -ref_gap, rtol=1e-5, atol=1e-7):
                    return hint(FORK_HINTS["signed"])
                return hint(
                    f"your index is right for these labels, but the gap {gap:.6f} is not: the label gap is "
                    "the difference in steering between the two labels at the fork."
                )
            return hint(
                f"for labels that part at one state your index is {index}: look for the first state at which "
                "the two labels differ."
            )
        same = FORK_CASES[0][0]
        try:
            out = fn(same.copy(), same.copy())
        except ValueError:
            return correct(
                "That is how driving.forks finds each stem crossing's fork and its label gap in the data."
            )
        except (IndexError, StopIteration) as exc:  # the first of no differing states
            return hint(
                f"for an episode and a twin that never differ your code raised {type(exc).__name__}: "
                "there is no fork; say so with a ValueError."
            )
        return hint(
            f"for an episode and a twin that never differ your function returned {out!r}: there is no fork; "
            "raise a ValueError."
        )

    return run_check(check, "`fork`")


# --------------------------------------------------------------------------- 2. two valleys, one each side
STEER = np.linspace(-1.0, 1.0, 161)
"""The chapter's reading grid over steering (0.0125 apart, straight exactly 0)."""


def _wells(steer, *wells) -> np.ndarray:
    """A profile made of parabolas ``(centre, floor, curvature)``: the lowest of them, minus its minimum."""
    s = np.asarray(steer, dtype=float)
    e = np.min([k * (s - m) ** 2 + d for m, d, k in wells], axis=0)
    return e - e.min()


TWO_SIDED_CASES = [
    # (what the profile shows, steer, profile)
    ("one broad valley at straight", STEER, _wells(STEER, (0.0, 0.0, 3.0))),
    ("two valleys, both left of straight", STEER, _wells(STEER, (-0.7, 0.0, 30.0), (-0.2, 0.5, 30.0))),
    ("a valley left and one right", STEER, _wells(STEER, (-0.4, 0.0, 30.0), (0.4, 1.0, 30.0))),
    ("a valley left and one right 4 nats up", STEER, _wells(STEER, (-0.4, 0.0, 30.0), (0.4, 4.0, 30.0))),
    ("two minima, left and right, 0.5 nat apart", STEER, _wells(STEER, (-0.2, 0.0, 12.5), (0.2, 0.0, 12.5))),
    ("a valley at straight and one right", STEER, _wells(STEER, (0.0, 0.0, 30.0), (0.5, 1.0, 30.0))),
    ("a valley at straight and one left", STEER, _wells(STEER, (0.0, 0.8, 30.0), (-0.5, 0.0, 30.0))),
    (
        "three valleys: left, straight and right",
        STEER,
        _wells(STEER, (-0.6, 0.5, 30.0), (0.0, 0.0, 30.0), (0.6, 1.5, 30.0)),
    ),
    (
        "a valley left and a deeper one right, on a coarser grid",
        np.linspace(-1.0, 1.0, 81),
        _wells(np.linspace(-1.0, 1.0, 81), (-0.3, 2.0, 30.0), (0.5, 0.0, 30.0)),
    ),
]


def _local_minima(steer, profile) -> list[float]:
    e = np.asarray(profile, dtype=float)
    inner = np.flatnonzero((e[1:-1] < e[:-2]) & (e[1:-1] < e[2:])) + 1
    ends = [0] if e[0] < e[1] else []
    ends += [len(e) - 1] if e[-1] < e[-2] else []
    return [float(steer[i]) for i in sorted([*inner, *ends])]


_RULES = {"book": (DEPTH, BARRIER), "no depth": (1e9, BARRIER), "no barrier": (DEPTH, 0.0)}
"""(depth, barrier) of the book's valley rule and of the rule with one of its two parts left out."""


def _two_sided_ref(steer, profile, *, rule="book", left=np.less, right=np.greater) -> bool:
    if rule == "local minima":
        at = _local_minima(steer, profile)
    else:
        depth, barrier = _RULES[rule]
        at = [v["steer"] for v in valleys(steer, profile, depth=depth, barrier=barrier)]
    return bool(any(left(s, 0.0) for s in at) and any(right(s, 0.0) for s in at))


def _mistakes_two_sided() -> dict[str, list[bool]]:
    """Each usual mistake's answers on ``TWO_SIDED_CASES``."""

    def each(f):
        return [bool(f(s, p)) for _, s, p in TWO_SIDED_CASES]

    return {
        "count": each(lambda s, p: len(valleys(s, p)) >= 2),
        "exactly two": each(lambda s, p: len(valleys(s, p)) == 2 and _two_sided_ref(s, p)),
        "local minima": each(lambda s, p: _two_sided_ref(s, p, rule="local minima")),
        "no depth": each(lambda s, p: _two_sided_ref(s, p, rule="no depth")),
        "no barrier": each(lambda s, p: _two_sided_ref(s, p, rule="no barrier")),
        "zero left": each(lambda s, p: _two_sided_ref(s, p, left=np.less_equal)),
        "zero right": each(lambda s, p: _two_sided_ref(s, p, right=np.greater_equal)),
        "zero both": each(lambda s, p: _two_sided_ref(s, p, left=np.less_equal, right=np.greater_equal)),
        "mass": each(lambda s, p: min(boltzmann_sides(s, p).values()) >= 0.2),
    }


TWO_SIDED_HINTS = {
    "count": "two valleys on the same side of straight are two ways of turning the same way: the question "
    "is whether both exits are kept, so where the valleys lie matters, not only how many there are.",
    "exactly two": "a third valley (at straight, say) does not undo a valley left and one right: do not ask "
    "for exactly two.",
    "local minima": "every dip of a profile is not a valley: the book keeps only those low enough (the depth "
    "rule) and separated from a lower one by a high enough barrier (the barrier rule).",
    "no depth": "a valley far above the minimum is one the policy almost never picks: apply the depth rule.",
    "no barrier": "two minima that a small bump separates are one valley with a wrinkle: apply the barrier "
    "rule.",
    "zero left": "a valley at straight (steer 0) is neither left nor right: do not count it as left.",
    "zero right": "a valley at straight (steer 0) is neither left nor right: do not count it as right.",
    "zero both": "a valley at straight (steer 0) is neither left nor right: do not count it on either side.",
    "mass": "mass on both sides of straight is not two valleys: one broad valley at straight has it too. "
    "Find the valleys.",
}


def check_two_sided(fn) -> Feedback:
    """Check ``fn(steer, profile)``: a valley (``energy_profiles.valleys``, its defaults) left of straight
    and one right of it."""

    def check() -> Feedback:
        answers = []
        for what, steer, profile in TWO_SIDED_CASES:
            out = fn(steer.copy(), profile.copy())
            if not isinstance(out, (bool, np.bool_)):
                return hint(f"two_sided must return True or False, got {type(out).__name__} for {what}.")
            answers.append(bool(out))
        refs = [_two_sided_ref(s, p) for _, s, p in TWO_SIDED_CASES]
        if answers == refs:
            return correct(
                "That is the reading the chapter counts at every fork and stem approach: two valleys, "
                "one each side of straight."
            )
        for name, mistake in _mistakes_two_sided().items():
            if answers == mistake:
                return hint(TWO_SIDED_HINTS[name])
        if all(answers) or not any(answers):
            return hint(f"your function answers {answers[0]} for every profile: read the profile's valleys.")
        wrong = next(w for (w, _, _), a, r in zip(TWO_SIDED_CASES, answers, refs, strict=True) if a != r)
        return hint(
            f"for a profile with {wrong} your answer is not the book's: find its valleys (within 3 nats of "
            "the minimum, a barrier of at least 1 nat), then where they lie."
        )

    return run_check(check, "`two_sided`")


# --------------------------------------------------------------------------- 3. the minority exit
EXIT_CASES = [
    [(3, 1), (0, 5), (2, 2)],
    [(5, 0), (0, 5)],  # one agent always left, another always right: the method takes both exits
    [(4, 1), (6, 0), (0, 0), (1, 1)],  # an agent that crossed no stem
]


def _summary_ref(counts, *, share="pooled", both="both") -> dict:
    left, right = sum(c[0] for c in counts), sum(c[1] for c in counts)
    crossed = [c for c in counts if c[0] + c[1] > 0]
    if share == "pooled":
        s = float(minority(left / (left + right)))
    elif share == "mean":
        s = float(np.mean([min(c) / sum(c) for c in crossed]))
    elif share == "minima":
        s = sum(min(c) for c in counts) / (left + right)
    else:  # the share of one exit, not the less taken one
        s = {"left": left, "right": right}[share] / (left + right)
    n = sum((c[0] > 0 and c[1] > 0) if both == "both" else (c[0] + c[1] > 0) for c in counts)
    return {"minority": s, "both": n}


SHARE_HINTS = {
    "mean": "an agent with 2 crossings would weigh as much as one with 20: pool the crossings over the "
    "agents.",
    "minima": "the minority is the method's less taken exit over all its crossings: an agent always left and "
    "another always right make a method that takes both exits, though neither agent does.",
    "left": "that is the share of left exits; the minority is the less taken exit's share.",
    "right": "that is the share of right exits; the minority is the less taken exit's share.",
}


def _summary_answer(out) -> dict | Feedback:
    if not isinstance(out, dict) or set(out) != {"minority", "both"}:
        return hint('exit_summary must return a dict with the keys "minority" and "both".')
    share = number_answer(out["minority"], 'exit_summary\'s "minority"')
    if isinstance(share, Feedback):
        return share
    n = out["both"]
    if isinstance(n, (bool, np.bool_)) or not isinstance(n, numbers.Integral):
        return hint(f'"both" must be a number of agents (an int), got {type(n).__name__}.')
    return {"minority": share, "both": int(n)}


def check_exit_summary(fn) -> Feedback:
    """Check ``fn(counts)``: ``{"minority": min(L, R) / (L + R) pooled over the agents, "both": agents with
    left > 0 and right > 0}``."""

    def check() -> Feedback:
        for counts in EXIT_CASES:
            out = _summary_answer(fn([tuple(c) for c in counts]))
            if isinstance(out, Feedback):
                return out
            ref = _summary_ref(counts)
            if not close(out["minority"], ref["minority"], rtol=1e-6, atol=1e-9):
                for share, words in SHARE_HINTS.items():
                    if close(out["minority"], _summary_ref(counts, share=share)["minority"], 1e-6, 1e-9):
                        return hint(words)
                return hint(
                    f"for the counts {counts} your minority share is {out['minority']:.4f}: the share of "
                    "the less taken exit, over every stem crossing of the method's agents."
                )
            if out["both"] != ref["both"]:
                if out["both"] == _summary_ref(counts, both="crossed")["both"]:
                    return hint(
                        "an agent that crossed a stem has not necessarily taken both exits: count the agents "
                        "that took each exit at least once."
                    )
                return hint(
                    f"for the counts {counts} your number of agents that took both exits is {out['both']}: "
                    "go through the agents one by one and check which exits each took."
                )
        return correct(
            "That is the chapter's pooled minority share (its interval resamples agents, then episodes) and "
            "its count of agents that kept both exits in closed loop."
        )

    return run_check(check, "`exit_summary`")


# --------------------------------------------------------------------------- 4. the flow agent's commitment
def _commit_case(seed: int, b: int, n: int) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    steer = torch.cat(
        [
            -0.6 + 0.15 * torch.randn(b, n // 2, generator=g),
            0.6 + 0.15 * torch.randn(b, n - n // 2, generator=g),
        ],
        dim=1,
    )  # (B, N): two clusters, one per exit
    accel = 0.3 + 0.2 * torch.randn(b, n, generator=g)  # (B, N)
    previous = torch.tensor([0.5, -0.45, 0.05, -0.1][:b]) if b <= 4 else 0.4 * torch.randn(b, generator=g)
    return torch.stack([steer, accel], dim=-1), previous  # (B, N, 2), (B,)


COMMIT_CASES = [_commit_case(0, 4, 16), _commit_case(1, 4, 7), _commit_case(2, 9, 32)]


def _pick(samples: torch.Tensor, score: torch.Tensor) -> torch.Tensor:
    """The sample of lowest ``score`` (B, N) per row: (B, 2)."""
    return samples[torch.arange(len(samples)), score.argmin(dim=1)]


def _commit_mistakes(samples: torch.Tensor, previous: torch.Tensor) -> list[tuple[torch.Tensor, str]]:
    s = samples[..., 0]  # (B, N)
    mean = samples.mean(dim=1)  # (B, 2)
    return [
        (
            _pick(samples, s.abs()),
            "the steering nearest the *previous* steering, not the one nearest straight.",
        ),
        (
            mean,
            "the mean of the samples lies between the two exits, straight into the wall: keep one sample.",
        ),
        (
            _pick(samples, -(s - previous[:, None]).abs()),
            "the nearest steering (the smallest gap), not the farthest.",
        ),
        (
            _pick(samples, (samples - previous[:, None, None]).norm(dim=-1)),
            "only the steering against the previous steering: the acceleration is not part of the distance.",
        ),
        (
            _pick(samples, (samples.sum(-1) - previous[:, None]).abs()),
            "only the steering (the first component) against the previous steering.",
        ),
    ]


def check_commit(fn) -> Feedback:
    """Check ``fn(samples, previous_steer)``: per row, the sample whose steering is nearest the previous
    steering (``nearest_previous_steer``)."""

    def check() -> Feedback:
        for samples, previous in COMMIT_CASES:
            b = len(samples)
            out = tensor_answer(
                fn(samples.clone(), previous.clone()), "commit", (b, 2), " (one action per row)"
            )
            if isinstance(out, Feedback):
                return out
            if close(out, _pick(samples, (samples[..., 0] - previous[:, None]).abs()), rtol=0, atol=1e-7):
                continue
            found = mistake_hint(out, _commit_mistakes(samples, previous), rtol=0, atol=1e-6)
            if found is not None:
                return found
            return hint(
                "for some rows your action is not the sample whose steering is nearest the previous "
                "steering: keep one of the N samples whole (steering and acceleration), chosen by "
                "|steer − previous|."
            )
        return correct(
            "That is how the town flow agent commits: at a stem its samples can fall in two clusters, one "
            "per exit, and the previous steering picks the side the car has begun to take."
        )

    return run_check(check, "`commit`")


# --------------------------------------------------------------------------- 5. head passes per decision
HEAD_PASS_CASES = [(512, 3, 16, 4), (16384, 5, 16, 4), (1024, 3, 8, 10), (256, 2, 32, 1)]
"""(dfo_samples, dfo_iters, flow_samples, flow_steps): the settings of chapter 12's two-answers study
(``book/results/two-answers``), the presets' defaults, then two others."""


def _head_passes_ref(n_dfo: int, iters: int, n_flow: int, steps: int) -> tuple[int, int]:
    return n_dfo * iters, flow_network_evaluations(n_flow, steps)["head"]


def _head_pass_mistakes(n_dfo, iters, n_flow, steps) -> list[tuple[str, tuple[int, int] | None, int | None]]:
    """(words, DFO count, flow count) of each usual mistake; None where that part is not the mistake."""
    return [
        ("DFO: each of its N_iters iterations evaluates the energy at all N samples.", (n_dfo, None), None),
        ("DFO: the iterations multiply the samples, they do not add to them.", (n_dfo + iters, None), None),
        (
            "count head passes only: the encoder runs once per decision, apart from the head.",
            (n_dfo * iters + 1, None),
            n_flow * steps + 1,
        ),
        ("the flow: each of its K Euler steps evaluates the velocity at all N samples.", None, n_flow),
        ("the flow: all N samples need the velocity at every Euler step, not one.", None, steps),
        ("the flow: the steps multiply the samples, they do not add to them.", None, n_flow + steps),
        (
            "the flow: K Euler steps take K velocity evaluations per sample; drawing the noise takes none.",
            None,
            n_flow * (steps + 1),
        ),
    ]


def check_head_passes(fn) -> Feedback:
    """Check ``fn(dfo_samples, dfo_iters, flow_samples, flow_steps)``: ``(N x N_iters, N x K)``."""

    def check() -> Feedback:
        for case in HEAD_PASS_CASES:
            out = fn(*case)
            if not isinstance(out, (tuple, list)) or len(out) != 2:
                return hint(f"head_passes must return a pair (dfo, flow), got {type(out).__name__} {out!r}.")
            for v in out:
                if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Integral):
                    return hint(f"head passes are counted in whole numbers (ints), got {type(v).__name__}.")
            dfo, flow = int(out[0]), int(out[1])
            ref_dfo, ref_flow = _head_passes_ref(*case)
            if (dfo, flow) == (ref_dfo, ref_flow):
                continue
            for words, wrong_dfo, wrong_flow in _head_pass_mistakes(*case):
                if (wrong_dfo is not None and dfo == wrong_dfo[0]) or (
                    wrong_flow is not None and flow == wrong_flow
                ):
                    return hint(words)
            if (dfo, flow) == (ref_flow, ref_dfo):
                return hint("the pair is (dfo, flow): DFO's count first.")
            part = "DFO's" if dfo != ref_dfo else "the flow's"
            return hint(f"for {case} {part} count is not right: count the head evaluations of one decision.")
        n, iters, m, k = HEAD_PASS_CASES[0]
        dfo, flow = _head_passes_ref(n, iters, m, k)
        return correct(
            f"With the settings of the chapter's agents (DFO: {n} samples, {iters} iterations; the flow: {m} "
            f"samples, {k} steps) DFO evaluates its head {dfo} times per decision, the flow {flow} times: "
            f"the ratio of {dfo // flow} that the chapter prints, for the same one encoder pass."
        )

    return run_check(check, "`head_passes`")


# --------------------------------------------------------------------------- 6. the proposal's log-density
def _log_q_case(seed: int, b: int, k: int, d: int, sigma: float) -> tuple[torch.Tensor, torch.Tensor, float]:
    g = torch.Generator().manual_seed(seed)
    actions = torch.rand(b, d, generator=g, dtype=torch.float64) * 2 - 1  # (M, D), M = B
    near = actions[:, None, :] + sigma * torch.randn(b, k, d, generator=g, dtype=torch.float64)
    return near, actions, sigma  # (B, K, D), (M, D), σ


LOG_Q_CASES = [_log_q_case(0, 5, 6, 2, 0.2), _log_q_case(1, 3, 4, 1, 0.5), _log_q_case(2, 4, 3, 3, 0.1)]


def _log_q_ref(
    y: torch.Tensor, a: torch.Tensor, sigma: float, *, const=True, mean=True, var=False, own=False
) -> torch.Tensor:
    s2 = sigma if var else sigma**2
    sq = (y[:, :, None, :] - a[None, None, :, :]).square().sum(-1)  # (B, K, M)
    log_comp = -0.5 * sq / s2
    if const:
        log_comp = log_comp - y.shape[-1] * (0.5 * math.log(2 * math.pi * s2))
    if own:  # each row's own expert action only
        idx = torch.arange(len(y))
        return log_comp[idx, :, idx]
    return torch.logsumexp(log_comp, dim=-1) - (math.log(a.shape[0]) if mean else 0.0)  # (B, K)


def check_expert_log_q(fn) -> Feedback:
    """Check ``fn(candidates, actions, sigma)``: ``ExpertSampler(sigma).log_prob(candidates, actions)``."""

    def check() -> Feedback:
        for y, a, sigma in LOG_Q_CASES:
            shape = tuple(y.shape[:2])
            out = tensor_answer(
                fn(y.clone(), a.clone(), sigma), "expert_log_q", shape, " (one per candidate)"
            )
            if isinstance(out, Feedback):
                return out
            ref = ExpertSampler(sigma).log_prob(y, a)
            if close(out, ref, rtol=1e-5, atol=1e-5):
                continue
            found = mistake_hint(
                out,
                [
                    (
                        _log_q_ref(y, a, sigma, own=True),
                        "every candidate's density under the whole mixture: "
                        "the sampler draws each counter-example around one of the minibatch's M expert "
                        "actions, not only around its own row's.",
                    ),
                    (
                        _log_q_ref(y, a, sigma, mean=False),
                        "the mixture's weights: each of the M Gaussians has weight 1/M.",
                    ),
                    (
                        _log_q_ref(y, a, sigma, const=False),
                        "the Gaussian's normalising constant, "
                        "−(D/2) log(2πσ²): ranking NCE needs q's density, not just its shape.",
                    ),
                    (_log_q_ref(y, a, sigma, var=True), "σ is the standard deviation: the variance is σ²."),
                    (_log_q_ref(y, a, sigma).exp(), "the log: ranking NCE subtracts log q, not q."),
                ],
                rtol=1e-5,
                atol=1e-5,
            )
            if found is not None:
                return found
            return hint(
                "your log-densities are not the mixture's: log q(y) = log (1/M) Σ_m N(y; a_m, σ² I), summed "
                "over the M expert actions in a numerically safe way (torch.logsumexp)."
            )
        return correct(
            "That is the log q ranking NCE subtracts from each logit, the expert's as well as the "
            "counter-examples' (losses.ranking_nce): the same mixture for every row of a minibatch."
        )

    return run_check(check, "`expert_log_q`")
