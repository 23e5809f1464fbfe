"""Gaussian KDE (eq. 4 of the DA-IBC paper), inverse-density weights and weighted sampling."""

import math

import numpy as np
import pytest
import torch
from scipy.stats import gaussian_kde

from ibc_tutorial.kde import inverse_density_weights, kde_density, sample_indices, sampling_probs


def loop_kde(query, data, h):
    """Eq. 4 written out with Python loops: 1/(M h^D) Σ_j Π_d K((q_d − x_jd)/h), K the standard normal pdf."""
    m, d = data.shape
    out = []
    for q in query.tolist():
        total = 0.0
        for x in data.tolist():
            prod = 1.0
            for qd, xd in zip(q, x):
                u = (qd - xd) / h
                prod *= math.exp(-0.5 * u * u) / math.sqrt(2 * math.pi)
            total += prod
        out.append(total / (m * h**d))
    return torch.tensor(out, dtype=torch.float64)


@pytest.mark.parametrize("d", [1, 2, 3])
def test_kde_matches_loop_reference(d):
    g = torch.Generator().manual_seed(d)
    data = torch.randn(40, d, generator=g) * 0.5
    query = torch.rand(25, d, generator=g) * 3 - 1.5
    for h in (0.05, 0.2, 1.0):
        got = kde_density(query, data, h).double()
        torch.testing.assert_close(got, loop_kde(query, data, h), rtol=1e-5, atol=1e-12)


def test_kde_matches_scipy_in_1d():
    rng = np.random.default_rng(0)
    data = np.concatenate([rng.normal(-0.5, 0.1, 300), rng.normal(0.4, 0.3, 700)])
    query = np.linspace(-1.5, 1.5, 301)
    h = 0.2
    # scipy's bandwidth is a factor times the data's standard deviation (ddof=1): factor = h / std
    ref = gaussian_kde(data, bw_method=h / data.std(ddof=1))(query)
    got = kde_density(torch.tensor(query)[:, None], torch.tensor(data)[:, None], h).numpy()
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12)


def test_kde_chunking_gives_the_same_answer_and_float32_in_float32_out():
    g = torch.Generator().manual_seed(1)
    data = torch.rand(1000, 2, generator=g) * 2 - 1
    query = torch.rand(700, 2, generator=g) * 2 - 1
    whole = kde_density(query, data)
    for chunk in (700, 2500, 10**6):  # data split in two; one or two queries per block; all at once
        torch.testing.assert_close(kde_density(query, data, chunk_elements=chunk), whole)
    assert whole.dtype == torch.float32


def test_kde_integrates_to_one_and_far_data_are_exact():
    data = torch.tensor([[0.0], [0.3], [-0.2]])
    grid = torch.linspace(-3, 3, 6001)[:, None]
    dens = kde_density(grid, data, 0.2)
    assert abs(float(dens.sum() * (grid[1, 0] - grid[0, 0])) - 1.0) < 1e-4
    # a single point far from the origin: the density at itself is 1/(h sqrt(2π)) exactly
    far = torch.tensor([[1e4]], dtype=torch.float64)
    assert float(kde_density(far, far, 0.2)) == pytest.approx(1 / (0.2 * math.sqrt(2 * math.pi)), rel=1e-12)


def test_kde_large_inputs_fit_in_memory():
    g = torch.Generator().manual_seed(2)
    data = torch.rand(20000, 2, generator=g)
    query = data[:3000]
    dens = kde_density(query, data, 0.2)
    assert dens.shape == (3000,) and torch.isfinite(dens).all() and (dens > 0).all()


def test_kde_bad_arguments():
    x = torch.zeros(5, 2)
    with pytest.raises(ValueError, match="same number of dimensions"):
        kde_density(torch.zeros(3, 1), x)
    with pytest.raises(ValueError, match="bandwidth"):
        kde_density(x, x, 0.0)
    with pytest.raises(ValueError, match="query"):
        kde_density(torch.zeros(3), x)
    with pytest.raises(ValueError, match="data must hold at least one point"):
        kde_density(x, torch.zeros(0, 2))


def test_inverse_density_weights_sum_to_one_and_rank_rare_actions_higher():
    g = torch.Generator().manual_seed(3)
    common = torch.randn(900, 2, generator=g) * 0.05  # driving straight
    rare = torch.tensor([0.7, 0.2]) + torch.randn(30, 2, generator=g) * 0.05  # a turn
    actions = torch.cat([common, rare])
    w = inverse_density_weights(actions)
    assert w.shape == (930,) and (w > 0).all()
    assert float(w.sum()) == pytest.approx(1.0, abs=1e-6)
    assert w[900:].min() > w[:900].max()
    # proportional to 1 / ĝ(y_i)
    inv = 1 / kde_density(actions, actions).double()
    torch.testing.assert_close(w.double(), inv / inv.sum(), rtol=1e-5, atol=0)


def test_sampling_probs_and_sampler_raise_the_share_of_rare_actions():
    g = torch.Generator().manual_seed(4)
    actions = torch.cat([torch.randn(950, 1, generator=g) * 0.05, 0.8 + torch.randn(50, 1, generator=g) * 0.05])
    rare = torch.zeros(1000, dtype=torch.bool)
    rare[950:] = True
    uni = sampling_probs(actions, weighting="uniform")
    inv = sampling_probs(actions)
    assert float(uni.sum()) == pytest.approx(1.0) and float(inv.sum()) == pytest.approx(1.0, abs=1e-6)
    idx_u = sample_indices(uni, 20000, generator=torch.Generator().manual_seed(0))
    idx_w = sample_indices(inv, 20000, generator=torch.Generator().manual_seed(0))
    share_u, share_w = rare[idx_u].float().mean(), rare[idx_w].float().mean()
    assert abs(float(share_u) - 0.05) < 0.01
    # the inverse density flattens the two clusters to roughly equal shares
    assert 0.35 < float(share_w) < 0.65
    # expected share under the probabilities
    assert abs(float(share_w) - float(inv[950:].sum())) < 0.015


def test_sample_indices_is_the_draw_training_makes():
    probs = torch.tensor([0.1, 0.2, 0.7])
    a = sample_indices(probs, 64, generator=torch.Generator().manual_seed(5))
    b = torch.multinomial(probs, 64, replacement=True, generator=torch.Generator().manual_seed(5))
    assert torch.equal(a, b)
    with pytest.raises(ValueError, match="probs"):
        sample_indices(torch.tensor([-1.0, 2.0]), 3)
    with pytest.raises(ValueError, match="batch_size"):
        sample_indices(probs, 0)
    with pytest.raises(ValueError, match="weighting"):
        sampling_probs(torch.zeros(3, 1), weighting="kde")


def test_training_draws_the_minibatches_sample_indices_describes():
    """``train(..., sample_probs=sampling_probs(...))`` draws its first minibatch exactly as ``sample_indices`` does."""
    from ibc_tutorial.training import TrainConfig, train

    actions = torch.cat([torch.zeros(90, 1), torch.ones(10, 1)])
    probs = sampling_probs(actions, bandwidth=0.2)
    seen = []
    w = torch.nn.Parameter(torch.zeros(1))

    def loss_fn(batch, generator):
        seen.append(batch["index"].clone())
        return ((w - 1) ** 2).sum()

    data = {"index": torch.arange(100), "actions": actions}
    train(torch.nn.ParameterList([w]), loss_fn, data, TrainConfig(steps=1, batch_size=32, seed=7, progress=False), sample_probs=probs)
    assert torch.equal(seen[0], sample_indices(probs, 32, generator=torch.Generator().manual_seed(7)))
