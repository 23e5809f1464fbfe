"""DFO, Algorithm 1 of the DA-IBC paper, on analytic energies with known modes (``optimizers.dfo``)."""

import dataclasses
import math

import matplotlib.pyplot as plt
import pytest
import torch

from ibc_tutorial.kde import inverse_density_weights, kde_density
from ibc_tutorial.optimizers import ActionOptimizer
from ibc_tutorial.optimizers.dfo import (
    DFOConfig,
    DFOOptimizer,
    dfo,
    dfo_policy,
    dfo_trace,
    initial_samples,
    initial_weights,
)
from ibc_tutorial.widgets import _dfo_iteration_figure, dfo_stepper

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


def cfg(**kw):
    return DFOConfig(**{**SMALL, **kw})


@pytest.mark.parametrize("init", ["uniform", "kde", "inverse-kde"])
def test_equal_valleys_both_reached_with_sample(init):
    g = torch.Generator().manual_seed(0)
    experts = symmetric_experts()
    actions = torch.stack(
        [dfo(two_valleys(), experts, cfg(init=init), generator=g) for _ in range(200)]
    )  # (200, 1)
    right = (actions[:, 0] > 0).float().mean()
    assert 0.35 < float(right) < 0.65
    # and every answer lies in a valley (closer to a floor than to the ridge at 0)
    assert ((actions.abs() - 0.5).abs() < 0.25).all()


@pytest.mark.parametrize("init", ["uniform", "kde", "inverse-kde"])
def test_unequal_valleys_argmax_lands_on_the_deeper_floor(init):
    g = torch.Generator().manual_seed(1)
    experts = symmetric_experts()
    for _ in range(30):
        a = dfo(two_valleys(offset=1.0), experts, cfg(init=init, select="argmax"), generator=g)
        assert abs(float(a[0]) + 0.5) < 0.03


def test_sample_follows_the_sharpened_distribution_on_unequal_valleys():
    """After k energy evaluations the population follows roughly p(y|x)^k: the shallow valley fades with
    n_iters."""
    g = torch.Generator().manual_seed(2)
    experts = symmetric_experts()
    share = {}
    for k in (1, 5):
        acts = torch.stack(
            [
                dfo(two_valleys(offset=0.3), experts, cfg(init="uniform", n_iters=k), generator=g)
                for _ in range(300)
            ]
        )
        share[k] = float((acts[:, 0] > 0).float().mean())
    # equal widths: p(shallow) = e^{-k·0.3} / (1 + e^{-k·0.3}); k = 1: 0.43, k = 5: 0.18
    assert abs(share[1] - 1 / (1 + math.exp(0.3))) < 0.08
    assert share[5] < share[1] - 0.1


def test_results_inside_bounds_even_when_the_minimum_is_outside():
    # energy falling towards y = +2, outside [−1, 1]: noise pushes samples out, they are clamped
    def energy(y):
        return 50 * ((y - 2.0) ** 2).sum(-1)

    experts = torch.tensor([[0.9], [0.5], [-0.9]])
    g = torch.Generator().manual_seed(3)
    tr = dfo_trace(energy, experts, cfg(low=-1.0, high=1.0, init="uniform", select="argmax"), generator=g)
    for s in tr.samples:
        assert s.min() >= -1.0 and s.max() <= 1.0
    assert (tr.samples[-1] == 1.0).float().mean() > 0.2  # clamped onto the bound, not redrawn
    assert float(tr.action[0]) == 1.0

    # per-dimension bounds in 2-D
    def e2(y):
        return ((y - torch.tensor([5.0, -5.0])) ** 2).sum(-1)

    a = dfo(e2, torch.zeros(4, 2), cfg(low=[-1.0, -0.5], high=[1.0, 0.5], select="argmax"), generator=g)
    assert torch.allclose(a, torch.tensor([1.0, -0.5]))


def test_reproducible_with_a_generator_and_trace_matches_dfo():
    experts = symmetric_experts()
    c = DFOConfig(n_samples=256, init="uniform")
    a1 = dfo(two_valleys(), experts, c, generator=torch.Generator().manual_seed(7))
    a2 = dfo(two_valleys(), experts, c, generator=torch.Generator().manual_seed(7))
    tr = dfo_trace(two_valleys(), experts, c, generator=torch.Generator().manual_seed(7))
    assert torch.equal(a1, a2) and torch.equal(a1, tr.action) and tr.config == c
    assert len(tr.samples) == 5 and tr.energy_evaluations == 256 * 5
    assert tr.sigmas[:4] == [0.5, 0.25, 0.125, 0.0625] and math.isnan(tr.sigmas[4])
    for p, e in zip(tr.probs, tr.energies, strict=True):
        torch.testing.assert_close(p, torch.softmax(-e, 0))
    # the population shrinks onto the floors: spread around the nearest floor falls
    spread = [float(((s.abs() - 0.5) ** 2).mean()) for s in tr.samples]
    assert spread[-1] < spread[0] / 5


def test_single_is_batched_with_b_equal_1_and_rows_are_independent():
    experts = symmetric_experts()
    c = DFOConfig(n_samples=128)
    a = dfo(two_valleys(), experts, c, generator=torch.Generator().manual_seed(9))
    b = dfo(
        lambda y: two_valleys()(y[0])[None], experts, c, n_obs=1, generator=torch.Generator().manual_seed(9)
    )
    assert a.shape == (1,) and b.shape == (1, 1) and torch.equal(a, b[0])
    # B = 3 observations, each with its own single valley at c_b
    centres = torch.tensor([-0.6, 0.1, 0.7])

    def energy(y):
        return (y[..., 0] - centres[:, None]) ** 2 / TAU  # (B, N, 1) -> (B, N)

    acts = dfo(energy, experts, cfg(select="argmax"), n_obs=3, generator=torch.Generator().manual_seed(0))
    assert acts.shape == (3, 1)
    torch.testing.assert_close(acts[:, 0], centres, atol=0.02, rtol=0)


def test_initialisations_follow_their_weights():
    g = torch.Generator().manual_seed(4)
    experts = torch.cat(
        [torch.randn(900, 1, generator=g) * 0.05, 0.7 + torch.randn(100, 1, generator=g) * 0.05]
    )
    gk = kde_density(experts, experts).double()
    for init, w in (("kde", gk / gk.sum()), ("inverse-kde", (1 / gk) / (1 / gk).sum())):
        torch.testing.assert_close(
            initial_weights(experts, DFOConfig(init=init)).double(), w, rtol=1e-5, atol=0
        )
        y = initial_samples(experts, 2, DFOConfig(n_samples=20000, init=init), generator=g)  # (2, N, 1)
        assert y.shape == (2, 20000, 1)
        rare = float((y > 0.35).float().mean())
        assert abs(rare - float(w[900:].sum())) < 0.02
    assert initial_weights(experts, DFOConfig(init="uniform")) is None
    # the text's weights are the KDE module's inverse-density weights, the one place 1/ĝ is computed
    assert torch.equal(
        initial_weights(experts, DFOConfig(init="inverse-kde")), inverse_density_weights(experts)
    )
    u = initial_samples(
        experts, 1, DFOConfig(n_samples=20000, init="uniform", low=-1.0, high=1.0), generator=g
    )
    assert abs(float(u.mean())) < 0.03 and u.min() >= -1 and u.max() <= 1
    # the text's weights spread the samples over the clusters; the algorithm's concentrate them
    y_inv = initial_samples(experts, 1, DFOConfig(n_samples=20000, init="inverse-kde"), generator=g)
    y_kde = initial_samples(experts, 1, DFOConfig(n_samples=20000, init="kde"), generator=g)
    assert (y_inv > 0.35).float().mean() > 0.3 > 0.1 > (y_kde > 0.35).float().mean()
    # plain expert draws: every expert action equally likely, so the rare cluster keeps its 10 %
    w_exp = initial_weights(experts, DFOConfig(init="expert"))
    assert w_exp.shape == (1000,) and torch.allclose(w_exp, torch.full((1000,), 1e-3))
    y_exp = initial_samples(experts, 1, DFOConfig(n_samples=20000, init="expert"), generator=g)
    assert abs(float((y_exp > 0.35).float().mean()) - 0.1) < 0.01


def test_populations_follow_the_default_dtype():
    experts = symmetric_experts()
    old = torch.get_default_dtype()
    try:
        for dtype in (torch.float32, torch.float64):
            torch.set_default_dtype(dtype)
            for init in ("uniform", "expert", "inverse-kde"):
                w = initial_weights(experts, DFOConfig(init=init))
                assert w is None or w.dtype == dtype
                a = dfo(
                    two_valleys(),
                    experts.double(),
                    cfg(init=init),
                    generator=torch.Generator().manual_seed(0),
                )  # (1,)
                assert a.dtype == dtype
    finally:
        torch.set_default_dtype(old)


def test_bad_arguments_get_clear_errors():
    experts = symmetric_experts()
    e = two_valleys()
    c = DFOConfig(n_samples=8)
    # the settings are validated once, when the config is built
    with pytest.raises(ValueError, match="n_samples"):
        DFOConfig(n_samples=0)
    with pytest.raises(ValueError, match="low must be < high"):
        DFOConfig(low=1.0, high=1.0)
    with pytest.raises(ValueError, match="low must be < high"):
        DFOConfig(low=0.5, high=-0.5)
    with pytest.raises(ValueError, match="low must be < high"):
        DFOConfig(low=[-1.0, 0.5], high=[1.0, 0.0])
    with pytest.raises(ValueError, match="low"):
        DFOConfig(low=float("nan"))
    with pytest.raises(ValueError, match="n_iters"):
        DFOConfig(n_iters=0)
    with pytest.raises(ValueError, match="init"):
        DFOConfig(init="kde-inverse")
    with pytest.raises(ValueError, match="select"):
        DFOConfig(select="max")
    with pytest.raises(ValueError, match="sigma_init"):
        DFOConfig(sigma_init=-0.1)
    with pytest.raises(ValueError, match="bandwidth"):
        DFOConfig(bandwidth=0.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.n_samples = 4
    assert DFOConfig(low=[-1, -0.5], high=(1, 0.5)).low == (
        -1.0,
        -0.5,
    )  # sequences stored as tuples of floats
    # what depends on the actions is checked when DFO runs
    with pytest.raises(ValueError, match="action dimension"):
        dfo(e, experts, DFOConfig(low=[-1.0, -1.0], high=[1.0, 1.0]))  # D = 1 actions, D = 2 bounds
    with pytest.raises(ValueError, match="config must be a DFOConfig"):
        dfo(e, experts, dict(n_samples=8))
    with pytest.raises(ValueError, match="energy_fn must map actions"):
        dfo(lambda y: y.sum(-1)[:, None], experts, c)  # (N, 1) instead of (N,)
    with pytest.raises(ValueError, match="energy_fn must map actions"):
        dfo(lambda y: torch.zeros(3), experts, c)
    with pytest.raises(ValueError, match="NaN"):
        dfo(lambda y: torch.full((len(y),), float("nan")), experts, c)
    with pytest.raises(ValueError, match="expert_actions must have 2 dimensions"):
        dfo(e, torch.zeros(5))
    with pytest.raises(ValueError, match="expert_actions must hold at least one"):
        dfo(e, torch.zeros(0, 1), c)
    with pytest.raises(ValueError, match="inside"):
        dfo(e, torch.tensor([[1.5]]))
    with pytest.raises(ValueError, match="init_weights"):
        dfo(e, experts, init_weights=torch.ones(3))
    with pytest.raises(ValueError, match="n_obs"):
        dfo(e, experts, c, n_obs=0)
    with pytest.raises(ValueError, match="one energy per candidate"):
        dfo(lambda y: torch.zeros(2, 5), experts, c, n_obs=3)


def test_single_and_batched_forms_agree_row_by_row():
    """Row 0 of B observations at once is what the single form gives for observation 0 with the same draws.

    With the uniform start and one argmax iteration, the only draw is the (B, N, D) uniform
    population, whose first N rows are the single form's (1, N, D) population.
    """
    experts = symmetric_experts()
    c = DFOConfig(n_samples=256, n_iters=1, init="uniform", select="argmax")
    centres = torch.tensor([-0.6, 0.1, 0.7])

    def batched(y):
        return (y[..., 0] - centres[:, None]) ** 2 / TAU  # (B, N, 1) -> (B, N)

    def single(y):
        return (y[:, 0] - centres[0]) ** 2 / TAU  # (N, 1) -> (N,), observation 0

    acts = dfo(batched, experts, c, n_obs=3, generator=torch.Generator().manual_seed(4))  # (3, 1)
    one = dfo(single, experts, c, generator=torch.Generator().manual_seed(4))  # (1,)
    assert acts.shape == (3, 1) and one.shape == (1,)
    assert torch.equal(one, acts[0])
    torch.testing.assert_close(
        acts[:, 0], centres, atol=0.05, rtol=0
    )  # every row in its own valley (256 uniform samples)


@pytest.mark.parametrize("init", ["uniform", "kde", "inverse-kde", "expert"])
@pytest.mark.parametrize("select", ["sample", "argmax"])
def test_trace_action_equals_dfo_with_equal_seeds(init, select):
    experts = symmetric_experts()
    c = DFOConfig(n_samples=200, n_iters=4, init=init, select=select)
    a = dfo(two_valleys(0.2), experts, c, generator=torch.Generator().manual_seed(11))
    tr = dfo_trace(two_valleys(0.2), experts, c, generator=torch.Generator().manual_seed(11))
    assert torch.equal(a, tr.action) and len(tr.samples) == 4


class _QuadraticModel(torch.nn.Module):
    """A stand-in with the EnergyModel interface: E(x, y) = (y − x)² / TAU."""

    def embed(self, obs):
        return obs  # (B, 1)

    def energy_from_embedding(self, z, actions):
        return ((actions - z[:, None, :]) ** 2).sum(-1) / TAU  # (B, N)


def test_dfo_policy_acts_on_a_batch_of_observations():
    experts = torch.linspace(-0.9, 0.9, 50)[:, None]
    policy = dfo_policy(
        _QuadraticModel(), experts, cfg(select="argmax"), generator=torch.Generator().manual_seed(0)
    )
    obs = torch.tensor([[-0.3], [0.0], [0.8]])
    acts = policy(obs)
    assert acts.shape == (3, 1)
    torch.testing.assert_close(acts, obs, atol=0.02, rtol=0)


class _DictObsModel(_QuadraticModel):
    """Observations as a dict of tensors (as the driving environment gives): B is the embedding's length."""

    def embed(self, obs):
        return obs["target"] + 0.0 * obs["speed"]  # (B, 1)


def test_dfo_policy_and_optimizer_take_dict_observations():
    experts = torch.linspace(-0.9, 0.9, 50)[:, None]
    obs = {
        "target": torch.tensor([[-0.3], [0.0], [0.8]]),
        "speed": torch.zeros(3, 1),
    }  # len(obs) == 2 keys, B = 3
    model = _DictObsModel().train()
    policy = dfo_policy(model, experts, cfg(select="argmax"), generator=torch.Generator().manual_seed(0))
    acts = policy(obs)
    assert acts.shape == (3, 1) and model.training  # eval mode only during the decision
    torch.testing.assert_close(acts, obs["target"], atol=0.02, rtol=0)
    opt = DFOOptimizer(experts, cfg(select="argmax"))
    assert isinstance(opt, ActionOptimizer)
    torch.testing.assert_close(opt.infer(model, obs, generator=torch.Generator().manual_seed(0)), acts)


@pytest.mark.parametrize("select", ["sample", "argmax"])
def test_dfo_stepper_titles_the_last_iteration_by_the_choice_made(select):
    grid = torch.linspace(-1, 1, 101)[:, None]
    experts = symmetric_experts()
    c = DFOConfig(n_samples=200, n_iters=3, select=select)
    widget = dfo_stepper(two_valleys(), grid, experts, c)
    assert "expert" in widget.children[0].children[1].options  # every initialisation offered
    assert widget.children[-1].value[:4] == b"\x89PNG"
    trace = dfo_trace(two_valleys(), experts, c, generator=torch.Generator().manual_seed(0))
    fig = _dfo_iteration_figure(trace, 3, grid[:, 0].numpy(), two_valleys()(grid).numpy(), 30)
    ax, energy_ax = fig.axes
    assert ("drawn from p̃" in ax.get_title()) == (select == "sample")
    assert ("argmax" in ax.get_title()) == (select == "argmax")
    assert energy_ax.get_ylabel() == "energy E(x, y) (nats, red)" and ax.get_xlabel() and ax.get_ylabel()
    plt.close(fig)


def test_energy_policy_acts_in_eval_mode_and_restores_training():
    from ibc_tutorial.optimizers import EnergyPolicy
    from ibc_tutorial.optimizers.grid import GridOptimizer, action_grid

    class Model(torch.nn.Module):  # E(x, y) = (y − x)², and it records its mode when scored
        def __init__(self):
            super().__init__()
            self.modes = []

        def embed(self, obs):
            return obs

        def energy_from_embedding(self, z, actions):
            self.modes.append(self.training)
            return ((actions[None] - z[:, None, :]) ** 2).sum(-1)  # (B, G)

    model = Model().train()
    policy = EnergyPolicy(model, GridOptimizer(action_grid(21)))
    a = policy(torch.tensor([[0.3], [-0.7]]))
    torch.testing.assert_close(a, torch.tensor([[0.3], [-0.7]]))
    assert model.modes == [False] and model.training  # scored in eval mode, then restored
    with pytest.raises(ValueError, match="ActionOptimizer"):
        EnergyPolicy(model, "dfo")
