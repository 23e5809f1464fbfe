"""Losses of the explicit policies against independent references (torch.distributions, by hand)."""

import math

import pytest
import torch

from ibc_tutorial.losses import (
    BETA_EPS,
    action_to_bin,
    beta_nll,
    bin_centers,
    classification_loss,
    mdn_nll,
    regression_loss,
)


def _random_beta_params(gen, b=64, d=2):
    # concentrations across both regimes: U-shaped (< 1) and peaked (> 1)
    alpha = torch.exp(torch.empty(b, d).uniform_(-2.0, 2.5, generator=gen))
    beta = torch.exp(torch.empty(b, d).uniform_(-2.0, 2.5, generator=gen))
    return alpha, beta


@pytest.mark.parametrize("d", [1, 2, 3])
def test_beta_nll_matches_torch_beta_inside_interval(d):
    gen = torch.Generator().manual_seed(d)
    alpha, beta = _random_beta_params(gen, d=d)
    actions = torch.empty(64, d).uniform_(-0.999, 0.999, generator=gen)
    ref = (
        -torch.distributions.Beta(alpha.double(), beta.double())
        .log_prob((actions.double() + 1) / 2)
        .sum(1)
        .mean()
    )
    got = beta_nll(alpha, beta, actions)
    assert got.shape == ()
    torch.testing.assert_close(got.double(), ref, rtol=1e-4, atol=1e-4)


def test_beta_nll_single_sample_by_hand():
    # Beta(2, 3) at y' = 0.25 (y = -0.5): f = 12 * 0.25 * 0.75**2
    got = beta_nll(torch.tensor([[2.0]]), torch.tensor([[3.0]]), torch.tensor([[-0.5]]))
    assert float(got) == pytest.approx(-math.log(12 * 0.25 * 0.75**2), rel=1e-5)


def test_beta_nll_sums_dimensions_and_averages_batch():
    gen = torch.Generator().manual_seed(3)
    alpha, beta = _random_beta_params(gen, b=5, d=2)
    actions = torch.empty(5, 2).uniform_(-0.9, 0.9, generator=gen)
    per = [
        beta_nll(alpha[i : i + 1, j : j + 1], beta[i : i + 1, j : j + 1], actions[i : i + 1, j : j + 1])
        for i in range(5)
        for j in range(2)
    ]
    torch.testing.assert_close(beta_nll(alpha, beta, actions), torch.stack(per).sum() / 5)


def test_beta_nll_finite_with_finite_gradients_at_the_bounds():
    gen = torch.Generator().manual_seed(1)
    alpha, beta = _random_beta_params(gen, b=32, d=2)
    alpha.requires_grad_(True)
    beta.requires_grad_(True)
    actions = torch.tensor([[-1.0, 1.0], [1.0, -1.0]]).repeat(16, 1)
    loss = beta_nll(alpha, beta, actions)
    loss.backward()
    assert torch.isfinite(loss)
    assert torch.isfinite(alpha.grad).all() and torch.isfinite(beta.grad).all()
    # the documented clamp: evaluated at y' = BETA_EPS and 1 - BETA_EPS
    y = ((actions + 1) / 2).clamp(BETA_EPS, 1 - BETA_EPS).double()
    ref = -torch.distributions.Beta(alpha.detach().double(), beta.detach().double()).log_prob(y).sum(1).mean()
    torch.testing.assert_close(loss.detach().double(), ref, rtol=1e-4, atol=1e-4)


def test_beta_nll_gradient_with_respect_to_actions_is_finite_at_bounds():
    actions = torch.tensor([[-1.0], [1.0], [0.0]], requires_grad=True)
    loss = beta_nll(torch.full((3, 1), 0.5), torch.full((3, 1), 0.5), actions)
    loss.backward()
    assert torch.isfinite(actions.grad).all()


@pytest.mark.parametrize(
    "alpha, beta, actions, match",
    [
        (torch.ones(4, 2), torch.ones(4, 2), torch.zeros(4), "actions"),
        (torch.ones(4, 1), torch.ones(4, 2), torch.zeros(4, 2), "alpha"),
        (torch.ones(4, 2), torch.ones(3, 2), torch.zeros(4, 2), "beta"),
        (-torch.ones(4, 2), torch.ones(4, 2), torch.zeros(4, 2), "alpha must be > 0"),
        (torch.ones(4, 2), torch.zeros(4, 2), torch.zeros(4, 2), "beta must be > 0"),
        (torch.ones(4, 2), torch.ones(4, 2), torch.full((4, 2), 1.5), r"\[-1, 1\]"),
        (torch.full((4, 2), float("nan")), torch.ones(4, 2), torch.zeros(4, 2), "alpha must be finite"),
    ],
)
def test_beta_nll_rejects_bad_input(alpha, beta, actions, match):
    with pytest.raises(ValueError, match=match):
        beta_nll(alpha, beta, actions)


def test_mdn_nll_matches_mixture_same_family():
    gen = torch.Generator().manual_seed(0)
    b, k, d = 50, 3, 2
    logits = torch.randn(b, k, generator=gen)
    means = torch.randn(b, k, d, generator=gen)
    stds = torch.exp(torch.randn(b, k, d, generator=gen) * 0.5)
    actions = torch.randn(b, d, generator=gen)
    mix = torch.distributions.MixtureSameFamily(
        torch.distributions.Categorical(logits=logits),
        torch.distributions.Independent(torch.distributions.Normal(means, stds), 1),
    )
    torch.testing.assert_close(mdn_nll(logits, means, stds, actions), -mix.log_prob(actions).mean())


def test_mdn_nll_one_component_is_gaussian_nll():
    means = torch.tensor([[[0.2]]])
    stds = torch.tensor([[[0.5]]])
    got = mdn_nll(torch.zeros(1, 1), means, stds, torch.tensor([[0.7]]))
    want = 0.5 * 1.0**2 + math.log(0.5) + 0.5 * math.log(2 * math.pi)
    assert float(got) == pytest.approx(want, rel=1e-5)


def test_mdn_nll_rejects_bad_input():
    with pytest.raises(ValueError, match="stds must be > 0"):
        mdn_nll(torch.zeros(2, 3), torch.zeros(2, 3, 1), torch.zeros(2, 3, 1), torch.zeros(2, 1))
    with pytest.raises(ValueError, match="means"):
        mdn_nll(torch.zeros(2, 3), torch.zeros(2, 2, 1), torch.ones(2, 3, 1), torch.zeros(2, 1))


def test_bins_and_classification_loss_match_cross_entropy():
    centers = bin_centers(4)
    torch.testing.assert_close(centers, torch.tensor([-0.75, -0.25, 0.25, 0.75]))
    actions = torch.tensor([[-1.0, 1.0], [-0.3, 0.1], [0.5, 0.0]])
    torch.testing.assert_close(action_to_bin(actions, 4), torch.tensor([[0, 3], [1, 2], [3, 2]]))
    gen = torch.Generator().manual_seed(0)
    logits = torch.randn(3, 2, 4, generator=gen)
    target = action_to_bin(actions, 4)
    ref = torch.nn.functional.cross_entropy(logits.reshape(-1, 4), target.reshape(-1), reduction="sum") / 3
    torch.testing.assert_close(classification_loss(logits, actions), ref)
    with pytest.raises(ValueError, match="logits"):
        classification_loss(torch.zeros(3, 1, 4), actions)


def test_regression_loss_mae_and_mse():
    pred = torch.tensor([[0.5, -0.5], [0.0, 0.0]])
    act = torch.tensor([[0.0, 0.0], [1.0, -1.0]])
    assert float(regression_loss(pred, act, "mae")) == pytest.approx((1.0 + 2.0) / 2)
    assert float(regression_loss(pred, act, "mse")) == pytest.approx((0.5 + 2.0) / 2)
    with pytest.raises(ValueError, match="kind"):
        regression_loss(pred, act, "huber")


def test_empty_batches_are_refused_not_nan():
    empty = torch.zeros(0, 2)
    with pytest.raises(ValueError, match=r"actions must hold at least one sample \(B >= 1\)"):
        beta_nll(torch.ones(0, 2), torch.ones(0, 2), empty)
    with pytest.raises(ValueError, match="at least one sample"):
        regression_loss(empty, empty)
    with pytest.raises(ValueError, match="at least one sample"):
        classification_loss(torch.zeros(0, 2, 4), empty)
    with pytest.raises(ValueError, match="at least one sample"):
        mdn_nll(torch.zeros(0, 3), torch.zeros(0, 3, 2), torch.ones(0, 3, 2), empty)
    # helpers that are not means over a batch still accept it
    assert action_to_bin(empty, 4).shape == (0, 2)
