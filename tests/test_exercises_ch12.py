"""Checkers of exercises/12_tree_in_the_town.ipynb: solution -> correct, stub -> not attempted,
typical mistakes -> a hint naming the mistake, code that raises -> a hint (never an exception).

The reference solutions are ``ibc_tutorial.exercises.solutions.ch12_*``."""

import math

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from ibc_tutorial.driving.energy_profiles import boltzmann_sides, valleys
from ibc_tutorial.exercises import ch12
from ibc_tutorial.exercises.solutions import (
    ch12_commit,
    ch12_exit_summary,
    ch12_expert_log_q,
    ch12_fork,
    ch12_head_passes,
    ch12_two_sided,
)
from ibc_tutorial.experiments.agents.agent import nearest_previous_steer
from ibc_tutorial.experiments.agents.presets import Preset
from ibc_tutorial.negatives import ExpertSampler
from ibc_tutorial.stats import minority

CHECKS = [
    (ch12.check_fork, ch12_fork),
    (ch12.check_two_sided, ch12_two_sided),
    (ch12.check_exit_summary, ch12_exit_summary),
    (ch12.check_commit, ch12_commit),
    (ch12.check_head_passes, ch12_head_passes),
    (ch12.check_expert_log_q, ch12_expert_log_q),
]


@pytest.mark.parametrize("check, solution", CHECKS)
def test_solution_stub_and_crash(check, solution, stub_and_crash):
    assert check(solution).status == "correct"
    stub_and_crash(check)
    assert check(lambda *a: "a lot").status == "hint"


# --------------------------------------------------------------------------- 1. fork
def _fork(differ=lambda r, t: np.any(r != t, axis=1), shift=0, gap=lambda r, t: abs(r[0] - t[0])):
    """A reader's fork: the first state where ``differ`` holds, moved by ``shift``, with ``gap`` of the
    two labels there."""

    def fn(recorded, twin):
        i = int(np.flatnonzero(differ(recorded, twin))[0]) + shift
        return i, float(gap(recorded[i], twin[i]))

    return fn


def _no_value_error(recorded, twin):
    differ = np.flatnonzero(np.any(recorded != twin, axis=1))
    if not len(differ):
        return -1, 0.0
    return ch12_fork(recorded, twin)


@pytest.mark.parametrize(
    "mistake, words",
    [
        (_fork(shift=-1), "last state"),  # the last identical state
        (_fork(gap=lambda r, t: np.linalg.norm(r - t)), "steering only"),
        (_fork(gap=lambda r, t: r[0] - t[0]), "which of the two"),
        (_fork(gap=lambda r, t: t[0] - r[0]), "which of the two"),
        (_fork(differ=lambda r, t: ~np.isclose(r, t).all(axis=1)), "without a tolerance"),
        (_fork(differ=lambda r, t: np.any(np.round(r, 3) != np.round(t, 3), axis=1)), "without a tolerance"),
        (_fork(differ=lambda r, t: r[:, 0] != t[:, 0]), "acceleration first"),
        (_fork(shift=1), "first state at which"),
        (_fork(gap=lambda r, t: 0.1), "the gap"),
        (lambda r, t: (int(np.flatnonzero(np.any(r != t, axis=1))[0]), None), "number"),
        (lambda r, t: (2.0, 0.1), "whole number"),
        (lambda r, t: 3, "pair"),
        (_no_value_error, "raise a ValueError"),
        (_fork(), "with a ValueError"),  # the first of no differing states: an IndexError
    ],
)
def test_fork_mistakes(mistake, words):
    fb = ch12.check_fork(mistake)
    assert fb.status == "hint" and words in fb.message, fb.message


@given(
    st.integers(2, 30).flatmap(
        lambda t: st.tuples(st.just(t), st.integers(0, t - 1), st.integers(0, 1), st.floats(1e-6, 2.0))
    )
)
def test_fork_solution_finds_the_first_differing_state(case):
    t, at, column, delta = case
    recorded = np.random.default_rng(t).uniform(-1, 1, (t, 2)).astype(np.float32)
    twin = recorded.copy()
    twin[at, column] = np.float32(recorded[at, column] + delta)
    if recorded[at, column] == twin[at, column]:  # delta lost in float32 rounding: no fork to find
        with pytest.raises(ValueError):
            ch12_fork(recorded, twin)
        return
    twin[at + 1 :] = -twin[at + 1 :]  # what follows the fork differs too
    index, gap = ch12_fork(recorded, twin)
    assert index == at
    assert gap == (abs(recorded[at, 0] - twin[at, 0]) if column == 0 else 0.0)


# --------------------------------------------------------------------------- 2. two valleys
def _sides(at, left=np.less, right=np.greater):
    return any(left(s, 0) for s in at) and any(right(s, 0) for s in at)


def _local_minima(s, p):
    i = np.flatnonzero(np.r_[True, p[1:] < p[:-1]] & np.r_[p[:-1] < p[1:], True])
    return s[i]


def _at(s, p, **kwargs):
    return [v["steer"] for v in valleys(s, p, **kwargs)]


@pytest.mark.parametrize(
    "mistake, words",
    [
        (lambda s, p: len(valleys(s, p)) >= 2, "where the valleys lie"),
        (lambda s, p: len(valleys(s, p)) == 2 and _sides(_at(s, p)), "exactly two"),
        (lambda s, p: _sides(_local_minima(s, p)), "every dip"),
        (lambda s, p: _sides(_at(s, p, depth=100.0)), "depth rule"),
        (lambda s, p: _sides(_at(s, p, barrier=0.0)), "barrier rule"),
        (lambda s, p: _sides(_at(s, p), left=np.less_equal), "count it as left"),
        (lambda s, p: _sides(_at(s, p), right=np.greater_equal), "count it as right"),
        (lambda s, p: _sides(_at(s, p), np.less_equal, np.greater_equal), "on either side"),
        (lambda s, p: min(boltzmann_sides(s, p).values()) >= 0.2, "Find the valleys"),
        (lambda s, p: True, "every profile"),
        (lambda s, p: float(s[np.argmin(p)]) > 0, "not the book's"),
        (lambda s, p: int(_sides(_at(s, p))), "True or False"),
    ],
)
def test_two_sided_mistakes(mistake, words):
    fb = ch12.check_two_sided(mistake)
    assert fb.status == "hint" and words in fb.message, fb.message


def test_two_sided_mistakes_are_told_apart_by_the_cases():
    refs = [ch12_two_sided(s, p) for _, s, p in ch12.TWO_SIDED_CASES]
    answers = [tuple(v) for v in ch12._mistakes_two_sided().values()]
    assert len(set(answers)) == len(answers) and tuple(refs) not in answers


# --------------------------------------------------------------------------- 3. the minority exit
def _summary(share="pooled", both=lambda c: c[0] > 0 and c[1] > 0):
    def fn(counts):
        left, right = sum(c[0] for c in counts), sum(c[1] for c in counts)
        if share == "mean":
            s = float(np.mean([min(c) / sum(c) for c in counts if sum(c)]))
        elif share == "minima":
            s = sum(min(c) for c in counts) / (left + right)
        elif share == "left":
            s = left / (left + right)
        else:
            s = min(left, right) / (left + right)
        return {"minority": s, "both": sum(bool(both(c)) for c in counts)}

    return fn


@pytest.mark.parametrize(
    "mistake, words",
    [
        (_summary(share="mean"), "pool the crossings"),
        (_summary(share="minima"), "neither agent does"),
        (_summary(share="left"), "share of left exits"),
        (_summary(both=lambda c: c[0] + c[1] > 0), "not necessarily"),
        (_summary(both=lambda c: c[0] > 0 or c[1] > 0), "not necessarily"),
        (_summary(both=lambda c: c[0] > 0), "which exits each took"),
        (lambda counts: {"minority": 0.3, "both": 1}, "the less taken exit"),
        (lambda counts: {**ch12_exit_summary(counts), "both": True}, "number of agents"),
        (lambda counts: {"minority": "few", "both": 1}, "number"),
        (lambda counts: [0.3, 1], "keys"),
    ],
)
def test_exit_summary_mistakes(mistake, words):
    fb = ch12.check_exit_summary(mistake)
    assert fb.status == "hint" and words in fb.message, fb.message


@given(st.lists(st.tuples(st.integers(0, 20), st.integers(0, 20)), min_size=1, max_size=8))
def test_exit_summary_solution_matches_the_library_and_its_bounds(counts):
    left, right = sum(c[0] for c in counts), sum(c[1] for c in counts)
    if left + right == 0:
        return
    out = ch12_exit_summary(counts)
    assert out["minority"] == pytest.approx(float(minority(left / (left + right))), abs=1e-12)
    assert 0.0 <= out["minority"] <= 0.5
    assert 0 <= out["both"] <= len(counts)
    assert out["minority"] > 0 or out["both"] == 0  # an agent that took both exits makes a minority


# --------------------------------------------------------------------------- 4. commit
def _pick(samples, score):
    return samples[torch.arange(len(samples)), score.argmin(dim=1)]


@pytest.mark.parametrize(
    "mistake, words",
    [
        (lambda s, p: _pick(s, s[..., 0].abs()), "not the one nearest straight"),
        (lambda s, p: s.mean(dim=1), "mean of the samples"),
        (lambda s, p: _pick(s, -(s[..., 0] - p[:, None]).abs()), "not the farthest"),
        (lambda s, p: _pick(s, (s - p[:, None, None]).norm(dim=-1)), "acceleration is not part"),
        (lambda s, p: _pick(s, (s.sum(-1) - p[:, None]).abs()), "first component"),
        (lambda s, p: s[:, 0], "keep one of the N samples whole"),
        (lambda s, p: s[:, 0, 0], "shape (4, 2)"),
    ],
)
def test_commit_mistakes(mistake, words):
    fb = ch12.check_commit(mistake)
    assert fb.status == "hint" and words in fb.message, fb.message


@given(st.integers(0, 10_000), st.integers(1, 6), st.integers(1, 12))
def test_commit_solution_is_the_agents_rule(seed, b, n):
    g = torch.Generator().manual_seed(seed)
    samples, previous = torch.randn(b, n, 2, generator=g), torch.randn(b, generator=g)
    assert torch.equal(ch12_commit(samples, previous), nearest_previous_steer(samples, previous))


# --------------------------------------------------------------------------- 5. head passes
@pytest.mark.parametrize(
    "mistake, words",
    [
        (lambda n, i, m, k: (n, m * k), "evaluates the energy at all N samples"),
        (lambda n, i, m, k: (n + i, m * k), "iterations multiply"),
        (lambda n, i, m, k: (n * i + 1, m * k + 1), "encoder runs once"),
        (lambda n, i, m, k: (n * i, m), "evaluates the velocity at all N"),
        (lambda n, i, m, k: (n * i, k), "not one"),
        (lambda n, i, m, k: (n * i, m + k), "steps multiply"),
        (lambda n, i, m, k: (n * i, m * (k + 1)), "drawing the noise takes none"),
        (lambda n, i, m, k: (m * k, n * i), "DFO's count first"),
        (lambda n, i, m, k: (float(n * i), m * k), "whole numbers"),
        (lambda n, i, m, k: n * i, "a pair"),
    ],
)
def test_head_passes_mistakes(mistake, words):
    fb = ch12.check_head_passes(mistake)
    assert fb.status == "hint" and words in fb.message, fb.message


@given(st.integers(1, 4096), st.integers(1, 10), st.integers(1, 64), st.integers(1, 20))
def test_head_passes_solution_is_the_presets_accounting(n, i, m, k):
    preset = Preset(name="t", dfo_samples=n, dfo_iters=i, flow_samples=m, flow_steps=k)
    heads = (preset.network_evaluations("da-ibc")["head"], preset.network_evaluations("flow")["head"])
    assert ch12_head_passes(n, i, m, k) == heads


# --------------------------------------------------------------------------- 6. the proposal's log q
def _comp(y, a, sigma, var=False):
    s2 = sigma if var else sigma**2
    sq = (y[:, :, None, :] - a[None, None, :, :]).square().sum(-1)
    return -0.5 * sq / s2 - 0.5 * y.shape[-1] * math.log(2 * math.pi * s2)  # (B, K, M)


def _own(y, a, sigma):
    idx = torch.arange(len(y))
    return _comp(y, a, sigma)[idx, :, idx]


@pytest.mark.parametrize(
    "mistake, words",
    [
        (_own, "not only around its own row"),
        (lambda y, a, s: torch.logsumexp(_comp(y, a, s), dim=-1), "weight 1/M"),
        (
            lambda y, a, s: ch12_expert_log_q(y, a, s) + 0.5 * y.shape[-1] * math.log(2 * math.pi * s**2),
            "normalising constant",
        ),
        (lambda y, a, s: torch.logsumexp(_comp(y, a, s, var=True), dim=-1) - math.log(len(a)), "variance is"),
        (lambda y, a, s: ch12_expert_log_q(y, a, s).exp(), "not q"),
        (lambda y, a, s: ch12_expert_log_q(y, a, s) + 1.0, "not the mixture's"),
        (lambda y, a, s: ch12_expert_log_q(y, a, s)[:, 0], "shape"),
    ],
)
def test_expert_log_q_mistakes(mistake, words):
    fb = ch12.check_expert_log_q(mistake)
    assert fb.status == "hint" and words in fb.message, fb.message


@given(st.integers(0, 10_000), st.integers(1, 5), st.integers(1, 4), st.integers(1, 3), st.floats(0.05, 2.0))
def test_expert_log_q_solution_is_the_samplers(seed, b, k, d, sigma):
    g = torch.Generator().manual_seed(seed)
    actions = torch.rand(b, d, generator=g, dtype=torch.float64) * 2 - 1
    candidates = actions[:, None, :] + torch.randn(b, k, d, generator=g, dtype=torch.float64)
    ref = ExpertSampler(sigma).log_prob(candidates, actions)
    assert torch.allclose(ch12_expert_log_q(candidates, actions, sigma), ref, rtol=1e-9, atol=1e-9)


def test_head_passes_first_case_is_the_chapters_study():
    """The praise quotes the first case as the chapter's agents' settings: their stored head counts agree."""
    import json
    from pathlib import Path

    summary = Path(__file__).parents[1] / "book/results/two-answers/analysis/summary.json"
    methods = json.loads(summary.read_text())["study"]["methods"]
    dfo, flow = ch12_head_passes(*ch12.HEAD_PASS_CASES[0])
    assert methods["da-ibc"]["network_evaluations_per_decision"]["head"] == dfo
    assert methods["flow"]["network_evaluations_per_decision"]["head"] == flow
