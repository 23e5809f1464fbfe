"""InfoNCE (eqs. 2-3 of the DA-IBC paper; eq. 5 with weights) against independent references."""

import math

import pytest
import torch
import torch.nn.functional as F

from ibc_tutorial.losses import info_nce


def reference_per_sample(pos, neg):
    """-log p̃_i through torch's cross-entropy: logits -E, the expert at class 0."""
    logits = torch.cat([-pos[:, None], -neg], dim=1).double()
    return F.cross_entropy(logits, torch.zeros(len(pos), dtype=torch.long), reduction="none")


def test_matches_cross_entropy_unweighted():
    g = torch.Generator().manual_seed(0)
    pos, neg = torch.randn(16, generator=g), torch.randn(16, 9, generator=g)
    torch.testing.assert_close(
        info_nce(pos, neg).double(), reference_per_sample(pos, neg).mean(), rtol=1e-6, atol=1e-6
    )


def test_matches_cross_entropy_weighted():
    g = torch.Generator().manual_seed(1)
    pos, neg = torch.randn(16, generator=g), torch.randn(16, 9, generator=g)
    w = torch.rand(16, generator=g) * 3
    want = (w.double() * reference_per_sample(pos, neg)).mean()  # mean over batch of w_i (-log p̃_i)
    torch.testing.assert_close(info_nce(pos, neg, w).double(), want, rtol=1e-6, atol=1e-6)
    # F.cross_entropy's class weights do something else (a weighted mean), so compare to the sum form too
    torch.testing.assert_close(
        info_nce(pos, neg, w).double() * 16, (w.double() * reference_per_sample(pos, neg)).sum()
    )


def test_matches_explicit_softmax_of_eq_3():
    pos = torch.tensor([0.5, -1.0])
    neg = torch.tensor([[1.0, 2.0, 0.0], [0.0, 0.0, -1.0]])
    p0 = math.exp(-0.5) / (math.exp(-0.5) + math.exp(-1) + math.exp(-2) + math.exp(0))
    p1 = math.exp(1.0) / (math.exp(1.0) + 1 + 1 + math.exp(1.0))
    assert abs(float(info_nce(pos, neg)) - (-(math.log(p0) + math.log(p1)) / 2)) < 1e-6


@pytest.mark.parametrize("scale", [1e3, 5e3, -3e3])
def test_stable_at_large_energies(scale):
    g = torch.Generator().manual_seed(2)
    pos = scale + torch.randn(8, generator=g) * 10
    neg = scale + torch.randn(8, 32, generator=g) * 10
    got = info_nce(pos, neg)
    assert torch.isfinite(got)
    want = reference_per_sample(pos.double(), neg.double()).mean()
    torch.testing.assert_close(got.double(), want, rtol=1e-4, atol=1e-3)
    # shifting every energy by a constant changes nothing (softmax invariance)
    torch.testing.assert_close(got, info_nce(pos - scale, neg - scale), rtol=1e-4, atol=1e-3)


def test_gradients_finite_at_large_energies():
    pos = torch.full((4,), 2000.0, requires_grad=True)
    neg = torch.full((4, 10), 3000.0, requires_grad=True)
    info_nce(pos, neg).backward()
    assert torch.isfinite(pos.grad).all() and torch.isfinite(neg.grad).all()


def test_limits():
    pos = torch.zeros(3)
    assert abs(float(info_nce(pos, torch.zeros(3, 7))) - math.log(8)) < 1e-6  # all equal: log(N + 1)
    assert float(info_nce(pos - 50, torch.zeros(3, 7))) < 1e-6  # expert far lower: loss -> 0
    assert float(info_nce(torch.zeros(2), torch.zeros(2, 3), torch.zeros(2))) == 0.0


def test_gradient_lowers_expert_and_raises_negatives():
    pos = torch.zeros(2, requires_grad=True)
    neg = torch.zeros(2, 5, requires_grad=True)
    info_nce(pos, neg).backward()
    assert (pos.grad > 0).all() and (neg.grad < 0).all()  # descent lowers E(expert), raises E(negatives)


def test_bad_input():
    with pytest.raises(ValueError, match="pos_energy"):
        info_nce(torch.zeros(3, 1), torch.zeros(3, 4))
    with pytest.raises(ValueError, match="neg_energy"):
        info_nce(torch.zeros(3), torch.zeros(2, 4))
    with pytest.raises(ValueError, match="neg_energy"):
        info_nce(torch.zeros(3), torch.zeros(3, 0))
    with pytest.raises(ValueError, match="weights"):
        info_nce(torch.zeros(3), torch.zeros(3, 4), torch.ones(2))
    with pytest.raises(ValueError, match="weights"):
        info_nce(torch.zeros(3), torch.zeros(3, 4), -torch.ones(3))
    with pytest.raises(ValueError, match="finite"):
        info_nce(torch.tensor([float("nan")]), torch.zeros(1, 4))


def test_empty_batch_is_refused_not_nan():
    with pytest.raises(ValueError, match=r"pos_energy must hold at least one sample \(B >= 1\)"):
        info_nce(torch.zeros(0), torch.zeros(0, 4))
    with pytest.raises(ValueError, match="at least one sample"):
        info_nce(torch.zeros(0), torch.zeros(0, 4), torch.zeros(0))
