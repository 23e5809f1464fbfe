"""The steering-EBM paper's variants (eqs. 3-5) and the measures of ``ibc_tutorial.metrics`` (eq. 2)."""

import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from scipy.special import softmax as scipy_softmax

from ibc_tutorial.losses import grid_cross_entropy, info_nce, soft_targets, temporal_smoothing
from ibc_tutorial.metrics import expert_rank, grid_nll, whiteness
from ibc_tutorial.optimizers import ActionOptimizer
from ibc_tutorial.optimizers.grid import GridOptimizer, action_grid, symmetric_axis


# --------------------------------------------------------------------------- soft targets (eq. 5)
def test_soft_targets_match_scipy_and_fall_with_distance():
    grid = action_grid(41)  # (41, 1)
    gt = torch.tensor([[0.1], [-0.65]])
    T = 0.01
    p = soft_targets(grid, gt, T)
    assert p.shape == (2, 41)
    for i in range(2):
        want = scipy_softmax(-((grid[:, 0].numpy() - gt[i, 0].numpy()) ** 2) / T)
        np.testing.assert_allclose(p[i].numpy(), want, rtol=1e-5, atol=1e-7)
        d = (grid[:, 0] - gt[i, 0]).abs()
        order = torch.argsort(d)
        assert (p[i][order][1:] <= p[i][order][:-1] + 1e-7).all()  # falls with distance: the intended sign
        assert int(p[i].argmax()) == int(d.argmin())


def test_soft_targets_limits_and_2d():
    grid = action_grid(5, 2)  # (25, 2)
    gt = torch.tensor([[0.5, -0.5]])
    sharp = soft_targets(grid, gt, 1e-6)
    hot = torch.zeros(25)
    hot[int(((grid - gt) ** 2).sum(1).argmin())] = 1
    torch.testing.assert_close(sharp[0], hot)
    flat = soft_targets(grid, gt, 1e6)
    torch.testing.assert_close(flat[0], torch.full((25,), 1 / 25), atol=1e-5, rtol=0)
    per_sample = soft_targets(grid.expand(1, -1, -1), gt, 0.3)
    torch.testing.assert_close(per_sample, soft_targets(grid, gt, 0.3))
    with pytest.raises(ValueError, match="temperature"):
        soft_targets(grid, gt, 0.0)


# --------------------------------------------------------------------------- grid cross-entropy (eq. 3)
def test_grid_cross_entropy_matches_torch_with_probability_targets():
    g = torch.Generator().manual_seed(0)
    e = torch.randn(6, 12, generator=g) * 3
    t = torch.softmax(torch.randn(6, 12, generator=g), 1)
    torch.testing.assert_close(grid_cross_entropy(e, t), F.cross_entropy(-e, t))


def test_grid_cross_entropy_checks_on_its_inputs_device():
    """The targets check builds its constant on the targets' device, not torch's default one: with the default
    device set to another one (meta), a CPU call gives the same number and the same refusals."""
    g = torch.Generator().manual_seed(0)
    e = torch.randn(4, 6, generator=g)
    t = torch.softmax(torch.randn(4, 6, generator=g), 1)
    want = grid_cross_entropy(e, t)
    bad = e.clone()
    bad[1, 2] = float("inf")
    with torch.device("meta"):
        got = grid_cross_entropy(e, t)
        with pytest.raises(ValueError, match="targets must be non-negative with rows summing to 1"):
            grid_cross_entropy(e, 2 * t)
        with pytest.raises(ValueError, match="energies must be finite"):
            grid_cross_entropy(bad, t)
    assert got.device.type == "cpu" and torch.equal(got, want)


def test_one_hot_grid_cross_entropy_is_info_nce_with_the_grid_as_counter_examples():
    g = torch.Generator().manual_seed(1)
    e = torch.randn(5, 9, generator=g)
    hot = torch.zeros(5, 9)
    hot[:, 0] = 1
    torch.testing.assert_close(grid_cross_entropy(e, hot), info_nce(e[:, 0], e[:, 1:]))


def test_grid_cross_entropy_rejects_bad_targets():
    with pytest.raises(ValueError, match="targets"):
        grid_cross_entropy(torch.zeros(2, 3), torch.ones(2, 3))
    with pytest.raises(ValueError, match="targets"):
        grid_cross_entropy(torch.zeros(2, 3), torch.ones(2, 4) / 4)


def test_grid_cross_entropy_refuses_empty_batches_and_grids():
    with pytest.raises(ValueError, match=r"energies must hold at least one sample \(B >= 1\)"):
        grid_cross_entropy(torch.zeros(0, 3), torch.zeros(0, 3))
    with pytest.raises(ValueError, match="at least one candidate"):
        grid_cross_entropy(torch.zeros(2, 0), torch.zeros(2, 0))


# --------------------------------------------------------------------------- the grid itself
def test_action_grid_is_the_cartesian_product_in_any_dimension():
    axis = torch.linspace(-1, 1, 5)
    torch.testing.assert_close(action_grid(5), axis[:, None])
    g2 = action_grid(5, 2)  # (25, 2), first dimension slowest
    assert g2.shape == (25, 2) and torch.equal(g2[7], torch.stack([axis[1], axis[2]]))
    g3 = action_grid(4, 3, low=0.0, high=3.0)  # (64, 3): D = 3 is allowed now
    assert g3.shape == (64, 3)
    assert torch.equal(g3[0], torch.zeros(3)) and torch.equal(g3[-1], torch.full((3,), 3.0))
    assert torch.equal(
        g3[1 * 16 + 2 * 4 + 3], torch.tensor([1.0, 2.0, 3.0])
    )  # row i·n² + j·n + k = (a_i, a_j, a_k)
    assert len(torch.unique(g3, dim=0)) == 64
    with pytest.raises(ValueError, match="low must be < high"):
        action_grid(5, low=1.0, high=-1.0)
    with pytest.raises(ValueError, match="n_per_dim"):
        action_grid(1)
    with pytest.raises(ValueError, match="action_dim"):
        action_grid(5, 0)


class _Quadratic:
    """E(x, y) = |y − x|²: the argmin is the observation itself."""

    def embed(self, obs):
        return obs  # (B, D)

    def energy_from_embedding(self, z, actions):
        if actions.ndim == 2:
            actions = actions.expand(len(z), -1, -1)  # (B, G, D)
        return ((actions - z[:, None, :]) ** 2).sum(-1)  # (B, G)


@pytest.mark.parametrize("n", [2, 3, 21, 41, 81, 201, 1000])
def test_symmetric_axis_is_exact_on_every_cpu(n):
    exact = [(2 * i - (n - 1)) / (n - 1) for i in range(n)]  # Python floats, no vector kernels
    for dtype in (torch.float32, torch.float64):
        v = symmetric_axis(n, dtype)
        assert v.dtype == dtype and v.shape == (n,)
        assert torch.equal(v, torch.tensor(exact, dtype=dtype))
        assert torch.equal(v, -v.flip(0)) and v[0] == -1 and v[-1] == 1
        if n % 2:
            assert v[n // 2] == 0 and not torch.signbit(v[n // 2])


def test_symmetric_axis_rejects_bad_input():
    with pytest.raises(ValueError, match="n"):
        symmetric_axis(1)
    with pytest.raises(ValueError, match="dtype"):
        symmetric_axis(5, torch.int64)


def test_grid_optimizer_finds_the_argmin_in_three_dimensions():
    opt = GridOptimizer(action_grid(11, 3))  # (1331, 3), spacing 0.2
    assert isinstance(opt, ActionOptimizer)
    obs = torch.tensor([[0.2, -0.4, 1.0], [-1.0, 0.0, 0.6]])
    torch.testing.assert_close(opt.infer(_Quadratic(), obs), obs)


# --------------------------------------------------------------------------- temporal smoothing (eq. 4)
def test_temporal_smoothing_is_alpha_times_mean_euclidean_norm():
    a = torch.tensor([[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]])
    b = torch.tensor([[1.0, 0.0, 3.0], [3.0, 4.0, 0.0]])
    assert float(temporal_smoothing(a, b, alpha=1.0)) == pytest.approx((2.0 + 5.0) / 2)
    assert float(temporal_smoothing(a, b, alpha=0.5)) == pytest.approx(0.5 * 3.5)
    mask = torch.tensor([True, False, True])  # the masked column (e.g. the ground truth) is ignored
    assert float(temporal_smoothing(a, b, mask=mask)) == pytest.approx((0.0 + 3.0) / 2)
    assert float(temporal_smoothing(a, a)) == 0.0


def test_temporal_smoothing_gradient_finite_when_equal():
    a = torch.zeros(2, 4, requires_grad=True)
    temporal_smoothing(a, torch.zeros(2, 4)).backward()
    assert torch.isfinite(a.grad).all()


def test_temporal_smoothing_bad_mask():
    with pytest.raises(ValueError, match="mask"):
        temporal_smoothing(torch.zeros(2, 3), torch.zeros(2, 3), mask=torch.ones(3))
    with pytest.raises(ValueError, match="alpha"):
        temporal_smoothing(torch.zeros(2, 3), torch.zeros(2, 3), alpha=-1)
    with pytest.raises(ValueError, match="at least one sample"):
        temporal_smoothing(torch.zeros(0, 3), torch.zeros(0, 3))


# --------------------------------------------------------------------------- whiteness (eq. 2)
def test_whiteness_analytic_cases():
    t = np.arange(0, 10, 0.1)
    assert whiteness(np.full(50, 0.3), 0.1) == 0.0
    assert whiteness(0.5 * t, 0.1) == pytest.approx(0.5)  # a ramp: constant rate 0.5 per s
    alternating = np.array([1.0, -1.0] * 20)
    assert whiteness(alternating, 0.1) == pytest.approx(20.0)  # |δP| = 2 every 0.1 s
    # eq. 2 written out
    x = np.random.default_rng(0).normal(size=30)
    assert whiteness(x, 0.05) == pytest.approx(math.sqrt(np.mean((np.diff(x) / 0.05) ** 2)))


def test_whiteness_episodes_are_not_joined():
    eps = np.stack([np.zeros(10), np.ones(10)])  # each constant: the jump between episodes is not a change
    assert whiteness(eps, 0.1) == 0.0
    three_d = torch.tensor(np.stack([np.arange(5.0), 2 * np.arange(5.0)])[..., None])  # (E, T, 1)
    np.testing.assert_allclose(whiteness(three_d, 1.0, per_episode=True), [1.0, 2.0])
    assert whiteness(three_d, 1.0) == pytest.approx(math.sqrt((1 + 4) / 2))


def test_whiteness_bad_input():
    with pytest.raises(ValueError, match="dt"):
        whiteness(np.zeros(5), 0.0)
    with pytest.raises(ValueError, match="commands"):
        whiteness(np.zeros(1), 0.1)
    with pytest.raises(ValueError, match="commands"):
        whiteness(np.array([0.0, np.nan]), 0.1)


# --------------------------------------------------------------------------- grid NLL and rank
def test_grid_nll_of_a_gaussian_energy_matches_torch_distributions():
    mu, s = torch.tensor([0.2, -0.4]), torch.tensor([0.1, 0.25])
    grid = action_grid(2001)[:, 0]  # (G,)
    y = torch.tensor([0.25, 0.1])
    energy = lambda a: 0.5 * ((a - mu[:, None]) / s[:, None]) ** 2  # E = -log N + const  # noqa: E731
    got = grid_nll(energy(y[:, None])[:, 0], energy(grid[None, :].expand(2, -1)), cell_volume=2 / 2000)
    normal = torch.distributions.Normal(mu, s)
    inside = normal.cdf(torch.tensor(1.0)) - normal.cdf(torch.tensor(-1.0))  # the box truncates the Gaussian
    want = -normal.log_prob(y) + torch.log(inside)
    torch.testing.assert_close(got, want, atol=1e-3, rtol=0)


def test_grid_nll_of_flat_energy_is_log_volume():
    got = grid_nll(torch.zeros(3), torch.zeros(3, 21 * 21), cell_volume=(2 / 20) ** 2)
    # 441 points of a 21 x 21 grid each holding 0.01 of area: Z = 4.41, a little more than the box's 4
    torch.testing.assert_close(got, torch.full((3,), math.log(4.41)))


def test_expert_rank():
    r = expert_rank(torch.tensor([0.0, 5.0]), torch.tensor([[1.0, 2.0, -1.0, 3.0], [0.0, 1.0, 2.0, 3.0]]))
    torch.testing.assert_close(r, torch.tensor([0.25, 1.0]))
