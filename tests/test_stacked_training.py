"""Seeds trained as one stacked model (``stacked_training.train_stacked``) against one run per seed."""

import pytest
import torch

from ibc_tutorial.experiments.toy_runs import make_explicit
from ibc_tutorial.negatives import UniformSampler
from ibc_tutorial.objectives import grid_objective, info_nce_objective, likelihood_objective
from ibc_tutorial.optimizers.grid import action_grid
from ibc_tutorial.policies import EnergyModel, MLPEncoder
from ibc_tutorial.stacked_training import train_stacked
from ibc_tutorial.toy import TreeWorld
from ibc_tutorial.training import TrainConfig, train

SEEDS = (0, 3, 7)
CONFIG = TrainConfig(steps=12, batch_size=16, lr=3e-3, log_every=5, lr_schedule="cosine", progress=False)


@pytest.fixture(autouse=True)
def float64():
    dtype = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)  # as the toy chapters train
    yield
    torch.set_default_dtype(dtype)


@pytest.fixture
def demos():
    return TreeWorld().expert_demonstrations(8, seed=0)


def _ebm(obs_dim):
    return EnergyModel(MLPEncoder(obs_dim, embed_dim=16, hidden=16), action_dim=1, hidden=16, layers=2)


BUILDERS = {
    "regression": (lambda d: make_explicit("regression", d), likelihood_objective),
    "Beta": (lambda d: make_explicit("Beta", d), likelihood_objective),
    "classifier": (lambda d: make_explicit("classifier", d), likelihood_objective),
    "MDN": (lambda d: make_explicit("MDN", d), likelihood_objective),
    "InfoNCE": (_ebm, lambda m: info_nce_objective(m, UniformSampler(-1.0, 1.0), 8)),
    "grid, soft": (_ebm, lambda m: grid_objective(m, action_grid(9), temperature=0.01)),
}


@pytest.mark.parametrize("kind", sorted(BUILDERS))
def test_stacked_equals_separate_runs(demos, kind):
    build, objective = BUILDERS[kind]
    data, d = demos.training_data(), demos.obs.shape[1]
    separate, stacked = [], []
    for seed in SEEDS:
        torch.manual_seed(100 + seed)
        separate.append(build(d))
        torch.manual_seed(100 + seed)
        stacked.append(build(d))
    curves = [
        train(m, objective(m), data, TrainConfig(**{**CONFIG.__dict__, "seed": s}))
        for m, s in zip(separate, SEEDS, strict=True)
    ]
    stacked_curves = train_stacked(stacked, objective, data, CONFIG, SEEDS)
    for a, b, ca, cb in zip(separate, stacked, curves, stacked_curves, strict=True):
        assert not b.training
        gap = max(
            float((p - q).detach().abs().max()) for p, q in zip(a.parameters(), b.parameters(), strict=True)
        )
        assert gap < 1e-9, f"{kind}: weights {gap:.1e} apart"  # round-off, amplified by a few steps
        assert ca.steps == cb.steps == [5, 10, 12]
        assert max(abs(x - y) for x, y in zip(ca.losses, cb.losses, strict=True)) < 1e-9
    moved = max(
        float((p - q).detach().abs().max())
        for p, q in zip(stacked[0].parameters(), stacked[1].parameters(), strict=True)
    )
    assert moved > 1e-3  # the seeds are trained apart, not one copy


def test_stacked_refuses_bad_input(demos):
    data = demos.training_data()
    torch.manual_seed(0)
    a, b = make_explicit("regression", 1), make_explicit("Beta", 1)
    with pytest.raises(ValueError, match="models must share one architecture"):
        train_stacked([a, b], likelihood_objective, data, CONFIG, (0, 1))
    with pytest.raises(ValueError, match="seeds must give one seed per model"):
        train_stacked([a, make_explicit("regression", 1)], likelihood_objective, data, CONFIG, (0,))
    with pytest.raises(ValueError, match="models must be distinct"):
        train_stacked([a, a], likelihood_objective, data, CONFIG, (0, 1))
    with pytest.raises(ValueError, match="DrawnObjective"):
        train_stacked(
            [a], lambda m: lambda batch, g: m.loss(batch["obs"], batch["actions"]), data, CONFIG, (0,)
        )
    bad = dict(data, actions=data["actions"] * 3)  # outside [-1, 1]: the loss's value check, before training
    with pytest.raises(ValueError, match=r"must lie in \[-1, 1\]"):
        train_stacked([b], likelihood_objective, bad, CONFIG, (0,))
