"""DFO, Algorithm 1 of the DA-IBC paper, on analytic energies with known modes."""

import math

import pytest
import torch

from ibc_tutorial.inference import dfo, dfo_batch, dfo_init_weights, dfo_policy, dfo_trace, initial_samples
from ibc_tutorial.kde import kde_density

TAU = 0.01  # valley width: E = (y − c)² / TAU


def two_valleys(offset=0.0):
    """1-D energy with floors at y = −0.5 (energy 0) and y = +0.5 (energy ``offset``): (N, 1) -> (N,)."""

    def energy(y):
        y = y[:, 0]
        return torch.minimum((y + 0.5) ** 2 / TAU, (y - 0.5) ** 2 / TAU + offset)

    return energy


def symmetric_experts(n=200, seed=0):
    g = torch.Generator().manual_seed(seed)
    half = torch.randn(n // 2, 1, generator=g) * 0.05
    return torch.cat([half - 0.5, -half + 0.5])  # exactly mirror-symmetric


SMALL = dict(n_samples=512)


@pytest.mark.parametrize("init", ["uniform", "kde", "inverse-kde"])
def test_equal_valleys_both_reached_with_sample(init):
    g = torch.Generator().manual_seed(0)
    experts = symmetric_experts()
    actions = torch.stack([dfo(two_valleys(), experts, init=init, generator=g, **SMALL) for _ in range(200)])  # (200, 1)
    right = (actions[:, 0] > 0).float().mean()
    assert 0.35 < float(right) < 0.65
    # and every answer lies in a valley (closer to a floor than to the ridge at 0)
    assert ((actions.abs() - 0.5).abs() < 0.25).all()


@pytest.mark.parametrize("init", ["uniform", "kde", "inverse-kde"])
def test_unequal_valleys_argmax_lands_on_the_deeper_floor(init):
    g = torch.Generator().manual_seed(1)
    experts = symmetric_experts()
    for _ in range(30):
        a = dfo(two_valleys(offset=1.0), experts, init=init, select="argmax", generator=g, **SMALL)
        assert abs(float(a[0]) + 0.5) < 0.03


def test_sample_follows_the_sharpened_distribution_on_unequal_valleys():
    """After k energy evaluations the population follows roughly p(y|x)^k: the shallow valley fades with n_iters."""
    g = torch.Generator().manual_seed(2)
    experts = symmetric_experts()
    share = {}
    for k in (1, 5):
        acts = torch.stack([dfo(two_valleys(offset=0.3), experts, init="uniform", n_iters=k, generator=g, **SMALL) for _ in range(300)])
        share[k] = float((acts[:, 0] > 0).float().mean())
    # equal widths: p(shallow) = e^{-k·0.3} / (1 + e^{-k·0.3}); k = 1: 0.43, k = 5: 0.18
    assert abs(share[1] - 1 / (1 + math.exp(0.3))) < 0.08
    assert share[5] < share[1] - 0.1


def test_results_inside_bounds_even_when_the_minimum_is_outside():
    # energy falling towards y = +2, outside [−1, 1]: noise pushes samples out, they are clamped
    energy = lambda y: 50 * ((y - 2.0) ** 2).sum(-1)
    experts = torch.tensor([[0.9], [0.5], [-0.9]])
    g = torch.Generator().manual_seed(3)
    tr = dfo_trace(energy, experts, low=-1.0, high=1.0, init="uniform", select="argmax", generator=g, **SMALL)
    for s in tr.samples:
        assert s.min() >= -1.0 and s.max() <= 1.0
    assert (tr.samples[-1] == 1.0).float().mean() > 0.2  # clamped onto the bound, not redrawn
    assert float(tr.action[0]) == 1.0
    # per-dimension bounds in 2-D
    e2 = lambda y: ((y - torch.tensor([5.0, -5.0])) ** 2).sum(-1)
    a = dfo(e2, torch.zeros(4, 2), low=[-1.0, -0.5], high=[1.0, 0.5], select="argmax", generator=g, **SMALL)
    assert torch.allclose(a, torch.tensor([1.0, -0.5]))


def test_reproducible_with_a_generator_and_trace_matches_dfo():
    experts = symmetric_experts()
    kw = dict(n_samples=256, init="uniform")
    a1 = dfo(two_valleys(), experts, generator=torch.Generator().manual_seed(7), **kw)
    a2 = dfo(two_valleys(), experts, generator=torch.Generator().manual_seed(7), **kw)
    tr = dfo_trace(two_valleys(), experts, generator=torch.Generator().manual_seed(7), **kw)
    assert torch.equal(a1, a2) and torch.equal(a1, tr.action)
    assert len(tr.samples) == 5 and tr.energy_evaluations == 256 * 5
    assert tr.sigmas[:4] == [0.5, 0.25, 0.125, 0.0625] and math.isnan(tr.sigmas[4])
    for p, e in zip(tr.probs, tr.energies):
        torch.testing.assert_close(p, torch.softmax(-e, 0))
    # the population shrinks onto the floors: spread around the nearest floor falls
    spread = [float(((s.abs() - 0.5) ** 2).mean()) for s in tr.samples]
    assert spread[-1] < spread[0] / 5


def test_single_is_batched_with_b_equal_1_and_rows_are_independent():
    experts = symmetric_experts()
    a = dfo(two_valleys(), experts, n_samples=128, generator=torch.Generator().manual_seed(9))
    b = dfo_batch(lambda y: two_valleys()(y[0])[None], experts, 1, n_samples=128, generator=torch.Generator().manual_seed(9))
    assert torch.equal(a, b[0])
    # B = 3 observations, each with its own single valley at c_b
    centres = torch.tensor([-0.6, 0.1, 0.7])
    energy = lambda y: (y[..., 0] - centres[:, None]) ** 2 / TAU  # (B, N, 1) -> (B, N)
    acts = dfo_batch(energy, experts, 3, n_samples=512, select="argmax", generator=torch.Generator().manual_seed(0))
    assert acts.shape == (3, 1)
    torch.testing.assert_close(acts[:, 0], centres, atol=0.02, rtol=0)


def test_initialisations_follow_their_weights():
    g = torch.Generator().manual_seed(4)
    experts = torch.cat([torch.randn(900, 1, generator=g) * 0.05, 0.7 + torch.randn(100, 1, generator=g) * 0.05])
    gk = kde_density(experts, experts).double()
    for init, w in (("kde", gk / gk.sum()), ("inverse-kde", (1 / gk) / (1 / gk).sum())):
        torch.testing.assert_close(dfo_init_weights(experts, init).double(), w, rtol=1e-5, atol=0)
        y = initial_samples(experts, 2, 20000, init=init, generator=g)  # (2, N, 1)
        assert y.shape == (2, 20000, 1)
        rare = float((y > 0.35).float().mean())
        assert abs(rare - float(w[900:].sum())) < 0.02
    assert dfo_init_weights(experts, "uniform") is None
    u = initial_samples(experts, 1, 20000, init="uniform", low=-1.0, high=1.0, generator=g)
    assert abs(float(u.mean())) < 0.03 and u.min() >= -1 and u.max() <= 1
    # the text's weights spread the samples over the clusters; the algorithm's concentrate them
    y_inv = initial_samples(experts, 1, 20000, init="inverse-kde", generator=g)
    y_kde = initial_samples(experts, 1, 20000, init="kde", generator=g)
    assert (y_inv > 0.35).float().mean() > 0.3 > 0.1 > (y_kde > 0.35).float().mean()


def test_bad_arguments_get_clear_errors():
    experts = symmetric_experts()
    e = two_valleys()
    with pytest.raises(ValueError, match="n_samples"):
        dfo(e, experts, n_samples=0)
    with pytest.raises(ValueError, match="low must be < high"):
        dfo(e, experts, low=1.0, high=1.0)
    with pytest.raises(ValueError, match="low must be < high"):
        dfo(e, experts, low=0.5, high=-0.5)
    with pytest.raises(ValueError, match="action dimension"):
        dfo(e, experts, low=[-1.0, -1.0], high=[1.0, 1.0])  # D = 1 actions, D = 2 bounds
    with pytest.raises(ValueError, match="energy_fn must map actions"):
        dfo(lambda y: y.sum(-1)[:, None], experts, n_samples=8)  # (N, 1) instead of (N,)
    with pytest.raises(ValueError, match="energy_fn must map actions"):
        dfo(lambda y: torch.zeros(3), experts, n_samples=8)
    with pytest.raises(ValueError, match="NaN"):
        dfo(lambda y: torch.full((len(y),), float("nan")), experts, n_samples=8)
    with pytest.raises(ValueError, match="n_iters"):
        dfo(e, experts, n_iters=0)
    with pytest.raises(ValueError, match="init"):
        dfo(e, experts, init="kde-inverse")
    with pytest.raises(ValueError, match="select"):
        dfo(e, experts, select="max")
    with pytest.raises(ValueError, match="expert_actions must have 2 dimensions"):
        dfo(e, torch.zeros(5))
    with pytest.raises(ValueError, match="inside"):
        dfo(e, torch.tensor([[1.5]]))
    with pytest.raises(ValueError, match="init_weights"):
        dfo(e, experts, init_weights=torch.ones(3))
    with pytest.raises(ValueError, match="sigma_init"):
        dfo(e, experts, sigma_init=-0.1)
    with pytest.raises(ValueError, match="one energy per candidate"):
        dfo_batch(lambda y: torch.zeros(2, 5), experts, 3, n_samples=8)


class _QuadraticModel(torch.nn.Module):
    """A stand-in with the EnergyModel interface: E(x, y) = (y − x)² / TAU."""

    def embed(self, obs):
        return obs  # (B, 1)

    def energy_from_embedding(self, z, actions):
        return ((actions - z[:, None, :]) ** 2).sum(-1) / TAU  # (B, N)


def test_dfo_policy_acts_on_a_batch_of_observations():
    experts = torch.linspace(-0.9, 0.9, 50)[:, None]
    policy = dfo_policy(_QuadraticModel(), experts, n_samples=512, select="argmax", generator=torch.Generator().manual_seed(0))
    obs = torch.tensor([[-0.3], [0.0], [0.8]])
    acts = policy(obs)
    assert acts.shape == (3, 1)
    torch.testing.assert_close(acts, obs, atol=0.02, rtol=0)
