"""Checkers of exercises/13_other_families.ipynb: solution -> correct, stub -> not attempted,
typical mistakes -> a hint naming the mistake, code that raises -> a hint (never an exception).

The reference solutions are ``ibc_tutorial.exercises.solutions.ch13_*``."""

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from ibc_tutorial.exercises import ch13
from ibc_tutorial.exercises.solutions import ch13_euler_sample, ch13_flow_pair, ch13_ranking_logits
from ibc_tutorial.losses import ranking_nce
from ibc_tutorial.policies import FlowPolicy

CHECKS = [
    (ch13.check_euler_sample, ch13_euler_sample),
    (ch13.check_flow_pair, ch13_flow_pair),
    (ch13.check_ranking_logits, ch13_ranking_logits),
]


@pytest.mark.parametrize("check, solution", CHECKS)
def test_solution_stub_and_crash(check, solution, stub_and_crash):
    assert check(solution).status == "correct"
    stub_and_crash(check)
    assert check(lambda *a: "a lot").status == "hint"


# --------------------------------------------------------------------------- 1. Euler steps
def _euler(t_of=lambda k, n: k / n, h=None, steps=lambda n: n, clip=False, end_clip=False):
    def fn(velocity, y0, n_steps):
        y = y0
        for k in range(steps(n_steps)):
            y = y + velocity(y, t_of(k, n_steps)) * (1 / n_steps if h is None else h)
            y = y.clamp(-1, 1) if clip else y
        return y.clamp(-1, 1) if end_clip else y

    return fn


@pytest.mark.parametrize(
    "mistake, words",
    [
        (_euler(t_of=lambda k, n: (k + 1) / n), "where it starts"),
        (_euler(h=1.0), "size of each step"),
        (_euler(steps=lambda n: n + 1), "how many steps"),
        (_euler(clip=True), "nothing is clipped"),
        (_euler(end_clip=True), "unclipped"),
        (lambda v, y0, n: y0 + 0.1, "differ"),
        (lambda v, y0, n: y0[:1], "like y0"),
    ],
)
def test_euler_mistakes(mistake, words):
    fb = ch13.check_euler_sample(mistake)
    assert fb.status == "hint" and words in fb.message, fb.message


@settings(max_examples=20, deadline=None)
@given(st.integers(1, 12), st.integers(0, 1000))
def test_the_euler_solution_is_the_flow_policys_sampling(k, seed):
    # the library's FlowPolicy.sample runs the same steps (before its clip at the end)
    torch.manual_seed(seed)
    policy = FlowPolicy.for_vectors(1, 1, hidden=8)
    obs = torch.zeros(1, 1)
    g = torch.Generator().manual_seed(seed)
    y0 = torch.randn(1, 5, 1, generator=torch.Generator().manual_seed(seed))
    z = policy.embed(obs)
    with torch.no_grad():
        ours = ch13_euler_sample(lambda y, t: policy.velocity_from_embedding(z, y, t), y0, k)
        theirs = policy.sample(obs, 5, k, generator=g)
    assert torch.allclose(ours.clamp(-1, 1), theirs, atol=1e-5)


# --------------------------------------------------------------------------- 2. the flow-matching pair
@pytest.mark.parametrize(
    "mistake, words",
    [
        (lambda y0, y1, t: (t[:, None] * y0 + (1 - t[:, None]) * y1, y1 - y0), "where the path starts"),
        (lambda y0, y1, t: ((1 - t[:, None]) * y0 + t[:, None] * y1, y0 - y1), "direction of u"),
        (
            lambda y0, y1, t: ((1 - t[:, None]) * y0 + t[:, None] * y1, t[:, None] * (y1 - y0)),
            "same at every t",
        ),
        (lambda y0, y1, t: (1 - t) * y0 + t * y1, "raised"),  # t not broadcast per row: shapes clash
        (lambda y0, y1, t: y0, "pair"),
    ],
)
def test_flow_pair_mistakes(mistake, words):
    fb = ch13.check_flow_pair(mistake)
    assert fb.status == "hint" and words in fb.message, fb.message


# --------------------------------------------------------------------------- 3. ranking NCE's logits
def _logits(sign_e=-1, sign_q=-1, q_on_expert=True):
    def fn(pe, ne, plq, nlq):
        e = torch.cat([pe[:, None], ne], dim=1)
        q = torch.cat([plq[:, None] * q_on_expert, nlq], dim=1)
        return sign_e * e + sign_q * q

    return fn


@pytest.mark.parametrize(
    "mistake, words",
    [
        (_logits(sign_q=1), "sign of log q"),
        (_logits(sign_q=0), "InfoNCE"),
        (_logits(sign_e=1), "sign of the energy"),
        (_logits(q_on_expert=False), "expert's candidate"),
        (lambda *a: torch.log_softmax(ch13_ranking_logits(*a), dim=1), "log-softmax"),
        (lambda pe, ne, plq, nlq: -ne - nlq, "(B, 1 + N"),
    ],
)
def test_ranking_mistakes(mistake, words):
    fb = ch13.check_ranking_logits(mistake)
    assert fb.status == "hint" and words in fb.message, fb.message


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 4), st.integers(1, 6), st.integers(0, 10_000))
def test_the_logits_give_the_librarys_ranking_nce(b, n, seed):
    g = torch.Generator().manual_seed(seed)
    pe, ne = torch.randn(b, generator=g), torch.randn(b, n, generator=g)
    plq, nlq = torch.randn(b, generator=g), torch.randn(b, n, generator=g)
    logits = ch13_ranking_logits(pe, ne, plq, nlq)
    ours = (torch.logsumexp(logits, dim=1) - logits[:, 0]).mean()
    assert torch.allclose(ours, ranking_nce(pe, ne, plq, nlq), atol=1e-5)
