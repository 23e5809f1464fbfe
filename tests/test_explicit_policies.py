"""The four explicit policies: shapes, ranges, modes of acting, densities, and that they learn."""

import pytest
import torch

from ibc_tutorial.policies import BetaPolicy, ClassifierPolicy, MDNPolicy, MLPEncoder, RegressionPolicy
from ibc_tutorial.training import TrainConfig, train

POLICIES = {
    "regression": lambda d: RegressionPolicy.for_vectors(3, d, hidden=16),
    "beta": lambda d: BetaPolicy.for_vectors(3, d, hidden=16),
    "classifier": lambda d: ClassifierPolicy.for_vectors(3, d, hidden=16, n_bins=32),
    "mdn": lambda d: MDNPolicy.for_vectors(3, d, hidden=16, n_components=3),
}


@pytest.mark.parametrize("name", list(POLICIES))
@pytest.mark.parametrize("d", [1, 2])
def test_act_shape_range_and_modes(name, d):
    torch.manual_seed(0)
    policy = POLICIES[name](d)
    obs = torch.randn(20, 3) * 5
    for mode in policy.modes:
        a = policy.act(obs, mode=mode, generator=torch.Generator().manual_seed(1))
        assert a.shape == (20, d)
        assert torch.isfinite(a).all()
        assert (a >= -1).all() and (a <= 1).all()
    assert policy.act(obs).shape == (20, d)  # default mode
    with pytest.raises(ValueError, match="mode"):
        policy.act(obs, mode="nonsense")
    loss = policy.loss(obs, torch.rand(20, d) * 2 - 1)
    assert loss.shape == () and torch.isfinite(loss)
    ctrl = policy.controller(generator=torch.Generator().manual_seed(0))
    out = ctrl(obs)
    assert out.shape == (20, d) and not out.requires_grad


@pytest.mark.parametrize("name", ["beta", "classifier", "mdn"])
def test_sampling_is_seeded(name):
    torch.manual_seed(0)
    policy = POLICIES[name](2)
    obs = torch.randn(50, 3)
    a1 = policy.act(obs, mode="sample", generator=torch.Generator().manual_seed(5))
    torch.randn(3)  # disturb the global RNG: must not matter
    a2 = policy.act(obs, mode="sample", generator=torch.Generator().manual_seed(5))
    torch.testing.assert_close(a1, a2)


def test_beta_samples_follow_the_beta_and_leave_the_global_rng_alone():
    """``torch.distributions.Beta`` draws under a forked global RNG seeded from the generator."""
    from scipy import stats

    policy = BetaPolicy.for_vectors(3, 1, hidden=16)
    with torch.no_grad():  # one fixed Beta(2, 5) for every observation
        policy.head.weight.zero_()
        inv_softplus = lambda v: torch.log(torch.expm1(torch.tensor(v)))  # noqa: E731
        c = policy.min_concentration + policy.eps
        policy.head.bias.copy_(torch.stack([inv_softplus(2.0 - c), inv_softplus(5.0 - c)]))
    state = torch.random.get_rng_state()
    a = policy.act(
        torch.zeros(4000, 3), mode="sample", generator=torch.Generator().manual_seed(0)
    )  # (4000, 1)
    assert torch.equal(torch.random.get_rng_state(), state)  # the global generator did not move
    z = ((a[:, 0] + 1) / 2).double().numpy()
    assert stats.kstest(z, stats.beta(2.0, 5.0).cdf).pvalue > 1e-3
    b = policy.act(torch.zeros(4000, 3), mode="sample", generator=torch.Generator().manual_seed(1))
    assert not torch.equal(a, b)


@pytest.mark.parametrize("name", ["beta", "classifier", "mdn"])
def test_action_density_integrates_to_about_one(name):
    torch.manual_seed(0)
    policy = POLICIES[name](2)
    values = torch.linspace(-1, 1, 4001)
    dens = policy.action_density(torch.randn(4, 3) * 0.1, values)
    assert dens.shape == (4, 4001, 2)
    mass = torch.trapezoid(dens, values, dim=1)  # (4, 2)
    if name == "mdn":  # Gaussians may leave [-1, 1]
        assert (mass <= 1.001).all() and (mass > 0.2).all()
    else:
        torch.testing.assert_close(mass, torch.ones_like(mass), atol=2e-2, rtol=0)


def test_regression_has_no_density():
    policy = POLICIES["regression"](1)
    assert not policy.has_density
    with pytest.raises(NotImplementedError):
        policy.action_density(torch.zeros(1, 3), torch.linspace(-1, 1, 5))


def test_beta_head_parameterisation_and_mode():
    torch.manual_seed(0)
    policy = BetaPolicy.for_vectors(3, 2, hidden=16)
    alpha, beta = policy(torch.randn(30, 3))
    assert (alpha >= 1).all() and (beta >= 1).all()
    free = BetaPolicy.for_vectors(3, 2, hidden=16, min_concentration=0.0)
    with torch.no_grad():
        free.head.bias.fill_(-5.0)  # softplus(-5) ≈ 0.007: U-shaped
    alpha, beta = free(torch.zeros(2, 3))
    assert (alpha < 1).all() and (beta < 1).all()
    # mode of a peaked Beta is the argmax of its density
    with torch.no_grad():
        policy.head.weight.zero_()
        policy.head.bias.copy_(
            torch.tensor([1.0, 3.0, 2.0, 0.5])
        )  # α-1 = softplus(1, 3); β-1 = softplus(2, .5)
    obs = torch.zeros(1, 3)
    values = torch.linspace(-1, 1, 20001)
    dens = policy.action_density(obs, values)[0]  # (G, 2)
    torch.testing.assert_close(policy.act(obs, mode="mode")[0], values[dens.argmax(0)], atol=2e-4, rtol=0)
    alpha, beta = policy(obs)
    torch.testing.assert_close(policy.act(obs, mode="mean"), 2 * alpha / (alpha + beta) - 1)


def test_classifier_acts_at_bin_centres_and_mdn_paper_mode():
    clf = ClassifierPolicy.for_vectors(3, 1, hidden=8, n_bins=4)
    with torch.no_grad():
        clf.head.weight.zero_()
        clf.head.bias.copy_(torch.tensor([0.0, 0.0, 5.0, 0.0]))
    assert float(clf.act(torch.zeros(1, 3), mode="argmax")) == pytest.approx(0.25)
    mdn = MDNPolicy.for_vectors(3, 1, hidden=8, n_components=2)
    with torch.no_grad():
        mdn.head.weight.zero_()
        # logits (0, 1): component 1 most likely; means (-0.5, 0.3); stds softplus(0) + 1e-3
        mdn.head.bias.copy_(torch.tensor([0.0, 1.0, -0.5, 0.3, 0.0, 0.0]))
    assert float(mdn.act(torch.zeros(1, 3), mode="paper")) == pytest.approx(0.3)


def test_policies_take_any_encoder_and_validate_input():
    enc = MLPEncoder(5, embed_dim=7)
    policy = MDNPolicy(enc, 2, n_components=2)
    assert policy.act(torch.zeros(3, 5)).shape == (3, 2)
    with pytest.raises(ValueError, match="encoder"):
        BetaPolicy(torch.nn.Linear(3, 3), 1)
    with pytest.raises(ValueError, match="actions"):
        policy.loss(torch.zeros(3, 5), torch.zeros(3, 1))
    with pytest.raises(ValueError, match="obs"):
        policy.act(torch.zeros(3, 4))
    with pytest.raises(ValueError, match="n_bins"):
        ClassifierPolicy.for_vectors(3, 1, n_bins=1)
    with pytest.raises(ValueError, match="n_components"):
        MDNPolicy.for_vectors(3, 1, n_components=0)


def _bimodal_data(n=2000, seed=0):
    """obs x in [-1, 1]; action = +0.6 or -0.6 (50/50) plus small noise when x < 0, else 0.3 x."""
    gen = torch.Generator().manual_seed(seed)
    x = torch.rand(n, 1, generator=gen) * 2 - 1
    sign = torch.where(torch.rand(n, 1, generator=gen) < 0.5, -1.0, 1.0)
    y = torch.where(x < 0, 0.6 * sign, 0.3 * x) + 0.03 * torch.randn(n, 1, generator=gen)
    return {"obs": x, "actions": y.clamp(-1, 1)}


def test_multimodal_policies_find_both_modes_and_regression_averages():
    data = _bimodal_data()
    cfg = TrainConfig(steps=600, batch_size=128, lr=3e-3, seed=0, progress=False)
    obs = torch.full((400, 1), -0.5)
    torch.manual_seed(0)
    reg = RegressionPolicy.for_vectors(1, 1, hidden=32, loss_kind="mse")
    train(reg, lambda b, g: reg.loss(b["obs"], b["actions"]), data, cfg)
    assert abs(float(reg.act(obs[:1]))) < 0.25  # between the modes
    mdn = MDNPolicy.for_vectors(1, 1, hidden=32, n_components=3)
    train(mdn, lambda b, g: mdn.loss(b["obs"], b["actions"]), data, cfg)
    clf = ClassifierPolicy.for_vectors(1, 1, hidden=32, n_bins=40)
    train(clf, lambda b, g: clf.loss(b["obs"], b["actions"]), data, cfg)
    for policy, sample_mode, best in [(mdn, "sample", "paper"), (clf, "sample", "argmax")]:
        a = policy.act(obs, mode=sample_mode, generator=torch.Generator().manual_seed(0))
        frac_near = ((a.abs() - 0.6).abs() < 0.15).float().mean()
        assert frac_near > 0.8, (type(policy).__name__, float(frac_near))
        assert 0.25 < float((a > 0).float().mean()) < 0.75  # both modes are sampled
        assert abs(abs(float(policy.act(obs[:1], mode=best))) - 0.6) < 0.15  # commits to one mode
    # the unimodal part: the mode for x > 0 is 0.3 x
    beta = BetaPolicy.for_vectors(1, 1, hidden=32)
    train(beta, lambda b, g: beta.loss(b["obs"], b["actions"]), data, cfg)
    xs = torch.tensor([[0.5]])
    assert abs(float(beta.act(xs, mode="mean")) - 0.15) < 0.1


def test_chapter_02_figures_build():
    import matplotlib.pyplot as plt

    from ibc_tutorial.plotting import multimodality
    from ibc_tutorial.toy import SideRoadWorld, TreeWorld

    fig = multimodality.plot_beta_shapes([(0.5, 0.5), (2, 5)])
    assert "Beta" in fig.axes[0].get_title() and len(fig.axes[0].lines) == 2
    plt.close(fig)
    torch.manual_seed(0)
    policies = {name: make(1) for name, make in POLICIES.items()}
    for p in policies.values():
        p.encoder = MLPEncoder(1, embed_dim=16)  # observations of size 1, like the toy worlds'
    fig = multimodality.plot_action_distributions(
        policies, torch.zeros(1, 1), torch.rand(50) * 2 - 1, where="here"
    )
    assert [ax.get_title() for ax in fig.axes] == list(policies)
    plt.close(fig)
    fig = multimodality.plot_density_fits(
        torch.rand(50) * 2 - 1, torch.linspace(-1, 1, 11), {"flat": torch.full((11,), 0.5)}, title="t"
    )
    assert fig.axes[0].get_xlabel().startswith("steering")
    plt.close(fig)
    for world in (TreeWorld(), SideRoadWorld()):
        r = world.rollout(lambda obs: torch.zeros(len(obs), 1), 3, seed=0)
        fig = multimodality.plot_rollout_grid(world, {"a": r, "b": r, "c": r}, title="grid")
        assert (
            fig.axes[0].get_title().startswith("a:") and not fig.axes[3].axison
        )  # the empty fourth panel is hidden
        plt.close(fig)
