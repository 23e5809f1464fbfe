"""Gaussian KDE (eq. 4 of the DA-IBC paper), inverse-density weights (eq. 5) and their numerical range."""

import math

import numpy as np
import pytest
import torch
from scipy.stats import gaussian_kde

from ibc_tutorial.kde import inverse_density_weights, kde_density


def loop_kde(query, data, h):
    """Eq. 4 written out with Python loops: 1/(M h^D) Σ_j Π_d K((q_d − x_jd)/h), K the standard normal pdf."""
    m, d = data.shape
    out = []
    for q in query.tolist():
        total = 0.0
        for x in data.tolist():
            prod = 1.0
            for qd, xd in zip(q, x, strict=True):
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


def test_inverse_density_weights_raise_the_share_of_rare_actions_in_minibatches():
    """Drawn with probabilities w_i (as the training loop draws minibatches), rare actions are seen far more
    often."""
    g = torch.Generator().manual_seed(4)
    actions = torch.cat(
        [torch.randn(950, 1, generator=g) * 0.05, 0.8 + torch.randn(50, 1, generator=g) * 0.05]
    )
    rare = torch.zeros(1000, dtype=torch.bool)
    rare[950:] = True
    inv = inverse_density_weights(actions)
    assert float(inv.sum()) == pytest.approx(1.0, abs=1e-6)
    idx_u = torch.multinomial(
        torch.full((1000,), 1e-3), 20000, replacement=True, generator=torch.Generator().manual_seed(0)
    )
    idx_w = torch.multinomial(inv, 20000, replacement=True, generator=torch.Generator().manual_seed(0))
    share_u, share_w = rare[idx_u].float().mean(), rare[idx_w].float().mean()
    assert abs(float(share_u) - 0.05) < 0.01
    # the inverse density flattens the two clusters to roughly equal shares
    assert 0.35 < float(share_w) < 0.65
    # expected share under the probabilities
    assert abs(float(share_w) - float(inv[950:].sum())) < 0.015


def test_empty_inputs_are_refused():
    x = torch.zeros(5, 2)
    with pytest.raises(ValueError, match="query must hold at least one point"):
        kde_density(torch.zeros(0, 2), x)
    with pytest.raises(ValueError, match="actions must hold at least one point"):
        inverse_density_weights(torch.zeros(0, 2))
    with pytest.raises(ValueError, match="at least one dimension"):
        kde_density(torch.zeros(3, 0), torch.zeros(5, 0))


# ---------------------------------------------------------------- numerical range (tiny or huge h, many D)
def test_tiny_bandwidth_gives_exact_densities_or_names_the_bandwidth():
    g = torch.Generator().manual_seed(5)
    data = torch.rand(20, 1, generator=g)
    query = torch.rand(10, 1, generator=g)
    # no query coincides with a data point: every kernel is e^(−huge), the density is 0 (it was NaN)
    assert torch.equal(kde_density(query, data, 1e-200), torch.zeros(10))
    assert torch.equal(
        kde_density(query[:, :1].expand(10, 2).contiguous(), data.expand(20, 2).contiguous(), 1e-200),
        torch.zeros(10),
    )
    # at the data points themselves: 1 / (M h √(2π)) per coincident point, exact in float64 ...
    dens = kde_density(data.double(), data.double(), 1e-200)
    torch.testing.assert_close(
        dens,
        torch.full((20,), 1 / (20 * 1e-200 * math.sqrt(2 * math.pi)), dtype=torch.float64),
        rtol=1e-12,
        atol=0,
    )
    # ... and beyond float32's range: a clear error naming the bandwidth
    with pytest.raises(ValueError, match="bandwidth"):
        kde_density(data, data, 1e-200)
    # the weights are all equal (each point sees only itself), not NaN
    torch.testing.assert_close(inverse_density_weights(data, 1e-200), torch.full((20,), 0.05))


def test_far_queries_underflow_gracefully_in_log_space():
    """Kernels below float64's range (e^−800) can still give a representable density when h is small."""
    h = 1e-100
    data = torch.tensor([[0.0]], dtype=torch.float64)
    u = torch.tensor(
        [10.0, 40.0, 45.0], dtype=torch.float64
    )  # distances in units of h: u²/2 = 50, 800, 1012.5
    got = kde_density((u * h)[:, None], data, h)
    exact = [
        math.exp(-0.5 * float(v) ** 2 - math.log(h * math.sqrt(2 * math.pi))) for v in u
    ]  # 8e-124, 1.4e-247, 0
    assert got[1] > 0 and got[2] == 0  # e^−800 underflows, e^−800 / (h √(2π)) does not
    torch.testing.assert_close(got, torch.tensor(exact, dtype=torch.float64), rtol=1e-9, atol=0)


def test_many_dimensions_give_finite_weights():
    x = torch.rand(10, 50, generator=torch.Generator().manual_seed(6))
    # each ĝ(y_i) ≈ 1 / (M h^50 (2π)^25) ~ 1e79 overflows float32 (the weights were NaN)
    w = inverse_density_weights(x, 0.01)
    assert torch.isfinite(w).all()
    torch.testing.assert_close(
        w, torch.full((10,), 0.1)
    )  # the points are far apart in units of h: equal weights
    with pytest.raises(ValueError, match="bandwidth"):
        kde_density(x, x, 0.01)
    assert torch.isfinite(kde_density(x.double(), x.double(), 0.01)).all()
    # a spread of densities in float64 ranks rare points higher, as in low dimensions
    pts = torch.cat([torch.zeros(5, 50), torch.ones(1, 50)]).double()
    w = inverse_density_weights(pts, 0.01)
    assert w[5] > w[:5].max() and float(w.sum()) == pytest.approx(1.0)


def test_huge_bandwidth_gives_flat_densities():
    # h = 1e200 raised OverflowError (h ** D); the density is 1 / (h^D (2π)^(D/2)): tiny, or 0 below float64
    data = torch.rand(5, 1, dtype=torch.float64)
    torch.testing.assert_close(
        kde_density(data, data, 1e200),
        torch.full((5,), 1 / (1e200 * math.sqrt(2 * math.pi)), dtype=torch.float64),
    )
    assert torch.equal(kde_density(torch.rand(4, 2), torch.rand(5, 2), 1e200), torch.zeros(4))
    torch.testing.assert_close(inverse_density_weights(torch.rand(4, 2), 1e200), torch.full((4,), 0.25))


def test_normal_inputs_take_the_plain_path():
    """The log-space fallback leaves ordinary inputs untouched: the result is eq. 4 summed directly."""
    g = torch.Generator().manual_seed(7)
    data = torch.rand(300, 2, generator=g, dtype=torch.float64)
    query = torch.rand(50, 2, generator=g, dtype=torch.float64)
    h = 0.2
    sq = ((query[:, None, :] - data[None, :, :]) ** 2).sum(-1) / h**2  # (Q, M)
    direct = torch.exp(-0.5 * sq).sum(1) / (300 * h**2 * 2 * math.pi)
    torch.testing.assert_close(kde_density(query, data, h), direct, rtol=1e-12, atol=0)


# ----------------------------------------------------------------------------- boundary correction
def loop_kde_reflected(query, data, h, low, high):
    """The reflection estimator (Schuster 1985) written out with scipy: per dimension the kernel
    of x_d plus those of its mirror images 2 low − x_d and 2 high − x_d, multiplied over d."""
    from scipy.stats import norm

    m = len(data)
    out = []
    for q in query.tolist():
        total = 0.0
        for x in data.tolist():
            prod = 1.0
            for qd, xd in zip(q, x, strict=True):
                prod *= sum(norm.pdf((qd - c) / h) / h for c in (xd, 2 * low - xd, 2 * high - xd))
            total += prod
        out.append(total / m)
    return torch.tensor(out, dtype=torch.float64)


@pytest.mark.parametrize("d", [1, 2])
def test_reflected_kde_matches_scipy_written_out(d):
    g = torch.Generator().manual_seed(d)
    data = torch.rand(30, d, generator=g, dtype=torch.float64) * 2 - 1
    data[:5, -1] = -1.0  # actions exactly on the edge, as full braking is
    query = torch.rand(12, d, generator=g, dtype=torch.float64) * 2 - 1
    ref = loop_kde_reflected(query, data, 0.2, -1.0, 1.0)
    out = kde_density(query, data, 0.2, bounds=(-1.0, 1.0))
    assert torch.allclose(out, ref, rtol=1e-10, atol=0)
    # per-dimension bounds give the same answer; far from the edges nothing changes
    out_seq = kde_density(query, data, 0.2, bounds=([-1.0] * d, [1.0] * d))
    assert torch.allclose(out_seq, out, rtol=1e-12, atol=0)
    centre = torch.zeros(1, d, dtype=torch.float64)
    assert torch.allclose(
        kde_density(centre, centre, 0.1, bounds=(-1.0, 1.0)), kde_density(centre, centre, 0.1), rtol=1e-9
    )
    # float32 in, float32 out, as without bounds
    assert kde_density(query.float(), data.float(), 0.2, bounds=(-1.0, 1.0)).dtype == torch.float32


def test_reflected_kde_integrates_to_one_inside_the_box_and_plain_kde_does_not():
    data = torch.tensor([[-1.0], [-1.0], [-0.9], [0.0], [0.95]], dtype=torch.float64)
    x = torch.linspace(-1, 1, 20001, dtype=torch.float64)[:, None]
    dx = 2 / 20000
    plain = float(torch.trapezoid(kde_density(x, data, 0.2), dx=dx))
    reflected = float(torch.trapezoid(kde_density(x, data, 0.2, bounds=(-1, 1)), dx=dx))
    assert abs(reflected - 1) < 1e-6
    assert plain < 0.8  # two points on the edge lose half their mass, two more lose some


def test_reflected_weights_do_not_inflate_edge_actions():
    # actions spread evenly over the box [-1, 1]: the true density is flat, so every action should
    # get the same weight; the plain KDE loses the kernel mass past the edges and gives actions
    # on an edge about twice the weight of those in the middle
    a = torch.linspace(-1, 1, 801, dtype=torch.float64)[:, None]  # (801, 1)
    edge = a[:, 0].abs() > 0.99  # within h/20 of an edge
    middle = a[:, 0].abs() < 0.5
    w_plain = inverse_density_weights(a, 0.2)
    w_reflected = inverse_density_weights(a, 0.2, bounds=(-1.0, 1.0))
    ratio_plain = float(w_plain[edge].mean() / w_plain[middle].mean())
    ratio_reflected = float(w_reflected[edge].mean() / w_reflected[middle].mean())
    assert 1.8 < ratio_plain < 2.1
    assert abs(ratio_reflected - 1) < 0.02
    assert abs(float(w_reflected.sum()) - 1) < 1e-12
    # the default is unchanged: eq. 4 as the paper writes it
    assert torch.equal(inverse_density_weights(a, 0.2, bounds=None), w_plain)


def test_reflected_kde_bad_bounds():
    data = torch.zeros(3, 2)
    for bad in [(1.0, -1.0), (0.0,), (-1.0, [1.0, 1.0, 1.0]), (float("nan"), 1.0), 5]:
        with pytest.raises(ValueError, match="bounds"):
            kde_density(data, data, 0.2, bounds=bad)
        with pytest.raises(ValueError, match="bounds"):
            inverse_density_weights(data, 0.2, bounds=bad)
