"""Langevin MCMC inference (the original IBC paper) and its polynomial step-size schedule."""

import pytest
import torch

from ibc_tutorial.inference import langevin, langevin_batch, langevin_trace, polynomial_schedule


def test_polynomial_schedule_matches_the_ibc_formula():
    n = 25
    rates = [polynomial_schedule(k, n) for k in range(n)]
    assert rates[0] == pytest.approx(1e-1) and rates[-1] == pytest.approx(1e-5)
    for k, r in enumerate(rates):  # (init − final)(1 − k/(n−1))^2 + final
        assert r == pytest.approx((1e-1 - 1e-5) * (1 - k / 24) ** 2 + 1e-5)
    assert all(a > b for a, b in zip(rates, rates[1:]))
    assert polynomial_schedule(0, 1) == pytest.approx(1e-1)
    with pytest.raises(ValueError, match="step"):
        polynomial_schedule(25, 25)


def test_langevin_descends_to_a_quadratic_minimum():
    energy = lambda y: ((y - torch.tensor([0.3, -0.4])) ** 2).sum(-1) * 20  # (N, 2) -> (N,)
    g = torch.Generator().manual_seed(0)
    experts = torch.zeros(3, 2)
    tr = langevin_trace(energy, experts, n_samples=256, n_iters=50, noise_scale=0.0, generator=g)
    final = tr.samples[-1]
    assert (final - torch.tensor([0.3, -0.4])).abs().max() < 0.02
    torch.testing.assert_close(tr.action, torch.tensor([0.3, -0.4]), atol=0.02, rtol=0)
    assert tr.energy_evaluations == 256 * 51 and tr.gradient_evaluations == 256 * 50
    assert len(tr.samples) == 51 and len(tr.step_sizes) == 50


def test_one_step_is_the_reference_update():
    """y ← clip(y − clip(ε(½ dE/dy + noise·n), ±0.1·half-range), low, high) with n ~ N(0, I)."""
    c = torch.tensor([0.5])
    energy = lambda y: ((y - c) ** 2).sum(-1)  # dE/dy = 2 (y − c)
    experts = torch.zeros(2, 1)
    g1 = torch.Generator().manual_seed(3)
    tr = langevin_trace(energy, experts, n_samples=64, n_iters=1, step_init=0.05, noise_scale=1.0, generator=g1)
    y0, y1 = tr.samples
    g2 = torch.Generator().manual_seed(3)
    _ = torch.rand(1, 64, 1, generator=g2)  # the uniform initialisation
    noise = torch.randn(1, 64, 1, generator=g2)[0]
    delta = (0.05 * (0.5 * 2 * (y0 - c) + noise)).clamp(-0.1, 0.1)
    torch.testing.assert_close(y1, (y0 - delta).clamp(-1, 1))


def test_langevin_stays_in_bounds_and_is_reproducible():
    energy = lambda y: -5 * y.sum(-1)  # pulls towards +inf
    experts = torch.zeros(2, 1)
    kw = dict(n_samples=128, n_iters=30, step_init=0.5, delta_clip=1.0)
    tr = langevin_trace(energy, experts, generator=torch.Generator().manual_seed(1), **kw)
    assert all(s.min() >= -1 and s.max() <= 1 for s in tr.samples)
    a = langevin(energy, experts, generator=torch.Generator().manual_seed(1), **kw)
    assert torch.equal(a, tr.action) and float(a) == 1.0


def test_langevin_batch_and_errors():
    centres = torch.tensor([[-0.5], [0.6]])
    energy = lambda y: 20 * ((y - centres[:, None, :]) ** 2).sum(-1)  # (B, N, 1) -> (B, N)
    acts = langevin_batch(energy, torch.zeros(2, 1), 2, n_samples=128, n_iters=60, generator=torch.Generator().manual_seed(2))
    torch.testing.assert_close(acts, centres, atol=0.05, rtol=0)
    e = lambda y: (y**2).sum(-1)
    with pytest.raises(ValueError, match="n_samples"):
        langevin(e, torch.zeros(2, 1), n_samples=0)
    with pytest.raises(ValueError, match="low must be < high"):
        langevin(e, torch.zeros(2, 1), low=1.0, high=-1.0)
    with pytest.raises(ValueError, match="step_init"):
        langevin(e, torch.zeros(2, 1), step_init=0.0)
    with pytest.raises(ValueError, match="action dimension"):
        langevin(e, torch.zeros(2, 1), low=[-1, -1, -1], high=1.0)
