"""Counter-example samplers: shapes, bounds and statistics against independent references
(chapter 04's experiment around them: ``tests/test_counter_examples.py``)."""

import pytest
import torch
from scipy import stats

from ibc_tutorial.negatives import ExpertSampler, UniformSampler, expert_negatives, uniform_negatives


def test_uniform_shape_bounds_and_distribution():
    g = torch.Generator().manual_seed(0)
    neg = uniform_negatives(64, 100, [-1.0, 0.0], [1.0, 0.5], generator=g)
    assert neg.shape == (64, 100, 2) and neg.dtype == torch.float32
    assert (neg[..., 0] >= -1).all() and (neg[..., 0] <= 1).all()
    assert (neg[..., 1] >= 0).all() and (neg[..., 1] <= 0.5).all()
    # Kolmogorov-Smirnov against U(low, high), each dimension
    assert stats.kstest(neg[..., 0].reshape(-1).numpy(), stats.uniform(loc=-1, scale=2).cdf).pvalue > 1e-3
    assert stats.kstest(neg[..., 1].reshape(-1).numpy(), stats.uniform(loc=0, scale=0.5).cdf).pvalue > 1e-3
    # the two dimensions are independent
    assert abs(float(torch.corrcoef(neg.reshape(-1, 2).T)[0, 1])) < 0.02


def test_uniform_seeded_and_scalar_bounds():
    a = uniform_negatives(4, 5, -1.0, 1.0, generator=torch.Generator().manual_seed(3))
    b = uniform_negatives(4, 5, -1.0, 1.0, generator=torch.Generator().manual_seed(3))
    assert a.shape == (4, 5, 1) and torch.equal(a, b)


def test_expert_mean_and_variance_are_expert_set_plus_sigma_squared():
    g = torch.Generator().manual_seed(1)
    expert = torch.tensor([[0.0, 0.4], [0.1, 0.5], [-0.6, 0.3], [0.7, -0.8], [0.0, 0.45]])
    sigma = 0.2
    neg = expert_negatives(expert, 400, 500, sigma, generator=g).reshape(-1, 2).double()  # 200,000 draws
    mu = expert.double().mean(0)
    var = expert.double().var(0, unbiased=False) + sigma**2  # Var(mixture) = Var(expert set) + σ²
    n = len(neg)
    se_mean = (var / n).sqrt()
    assert ((neg.mean(0) - mu).abs() < 4 * se_mean).all()
    assert ((neg.var(0) - var).abs() / var < 0.02).all()


def test_expert_sigma_zero_draws_with_replacement_from_the_set():
    g = torch.Generator().manual_seed(2)
    expert = torch.tensor([[-0.5], [0.25], [0.9]])
    neg = expert_negatives(expert, 10, 3000, 0.0, generator=g)
    values, counts = torch.unique(neg, return_counts=True)
    torch.testing.assert_close(values, expert[:, 0])
    # chi-square: each expert action drawn with probability 1/M
    assert stats.chisquare(counts.numpy()).pvalue > 1e-3
    # with replacement: more draws per row than actions in the set
    assert neg.shape == (10, 3000, 1)


def test_expert_noise_is_gaussian_with_sigma():
    g = torch.Generator().manual_seed(4)
    neg = expert_negatives(torch.tensor([[0.3]]), 50, 400, 0.15, generator=g)
    assert stats.kstest(neg.reshape(-1).numpy(), stats.norm(loc=0.3, scale=0.15).cdf).pvalue > 1e-3


def test_expert_rows_are_independent_draws():
    g = torch.Generator().manual_seed(5)
    expert = torch.linspace(-1, 1, 50)[:, None]
    neg = expert_negatives(expert, 8, 20, 0.0, generator=g)
    assert not all(torch.equal(neg[0], neg[i]) for i in range(1, 8))


def test_expert_clipping_optional():
    g = torch.Generator().manual_seed(6)
    expert = torch.tensor([[0.95, -1.0]])
    free = expert_negatives(expert, 20, 200, 0.1, generator=g)
    assert (free[..., 0] > 1).any() and (free[..., 1] < -1).any()  # default: not clipped
    clipped = expert_negatives(expert, 20, 200, 0.1, generator=g, low=[-1, -1], high=[1, 1])
    assert (clipped >= -1).all() and (clipped <= 1).all()
    assert (clipped[..., 1] == -1).float().mean() > 0.4  # point mass on the bound, as the docs warn


def test_samplers_use_the_minibatch():
    g = torch.Generator().manual_seed(7)
    actions = torch.tensor([[0.2, 0.1], [0.2, 0.1]])
    neg = ExpertSampler(0.0)(actions, 6, g)
    assert neg.shape == (2, 6, 2) and (neg == torch.tensor([0.2, 0.1])).all()
    u = UniformSampler(-1.0, 1.0)(actions, 6, g)
    assert u.shape == (2, 6, 2) and (u.abs() <= 1).all()
    u2 = UniformSampler([-1.0, 0.0], [1.0, 1.0])(actions, 3, g)
    assert (u2[..., 1] >= 0).all()
    with pytest.raises(ValueError, match="columns"):
        UniformSampler([-1.0, 0, 0], [1.0, 1, 1])(actions, 3, g)


def test_bad_input():
    with pytest.raises(ValueError, match="low"):
        uniform_negatives(2, 3, 1.0, -1.0)
    with pytest.raises(ValueError, match="n_neg"):
        uniform_negatives(2, 0, -1.0, 1.0)
    with pytest.raises(ValueError, match="same length"):
        uniform_negatives(2, 3, [-1.0, -1.0], [1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="sigma"):
        expert_negatives(torch.zeros(3, 1), 2, 3, -0.1)
    with pytest.raises(ValueError, match="expert_actions"):
        expert_negatives(torch.zeros(3), 2, 3, 0.1)
    with pytest.raises(ValueError, match="expert_actions"):
        expert_negatives(torch.zeros(0, 2), 2, 3, 0.1)
    with pytest.raises(ValueError, match="together"):
        expert_negatives(torch.zeros(3, 1), 2, 3, 0.1, low=-1.0)
    with pytest.raises(ValueError, match="batch_size"):
        expert_negatives(torch.zeros(3, 1), 0, 3, 0.1)


def test_expert_clipping_per_dimension_bounds():
    g = torch.Generator().manual_seed(1)
    expert = torch.tensor([[0.9, 0.4], [-0.9, 0.1]])
    neg = expert_negatives(expert, 50, 40, 0.3, generator=g, low=[-1.0, 0.0], high=[1.0, 0.5])
    assert (neg[..., 0] >= -1).all() and (neg[..., 0] <= 1).all()
    assert (neg[..., 1] >= 0).all() and (neg[..., 1] <= 0.5).all()
    assert (neg[..., 1] == 0.5).any() and (neg[..., 1] == 0.0).any()


def test_check_box_is_the_one_check_of_action_bounds():
    from ibc_tutorial.utils import check_box

    lo, hi = check_box(-1.0, [1.0, 0.5])  # a single number stands for every dimension
    assert torch.equal(lo, torch.tensor([-1.0, -1.0])) and torch.equal(hi, torch.tensor([1.0, 0.5]))
    assert check_box(0.0, 1.0, 3)[0].shape == (3,)
    for low, high, d, match in [
        (1.0, -1.0, None, "low must be < high"),
        ([-1.0, 0.5], [1.0, 0.0], None, "low must be < high"),
        (float("nan"), 1.0, None, "low must be finite"),
        ([], 1.0, None, "low must hold"),
        ("a", 1.0, None, "low must be a number"),
        ([-1.0, -1.0], 1.0, 3, "D = 3"),
    ]:
        with pytest.raises(ValueError, match=match):
            check_box(low, high, d)
    with pytest.raises(ValueError, match="bounds: low must be < high"):
        check_box(1.0, 0.0, name="bounds")


def test_info_nce_objective_needs_a_sampler():
    from ibc_tutorial.negatives import NegativeSampler
    from ibc_tutorial.objectives import info_nce_objective

    assert isinstance(UniformSampler(), NegativeSampler) and isinstance(ExpertSampler(0.1), NegativeSampler)
    with pytest.raises(ValueError, match="sampler must be a NegativeSampler"):
        info_nce_objective(torch.nn.Linear(1, 1), "uniform", 8)
