"""The training runs of chapters 02-03 as jobs (experiments.toy_runs): what they build from a seed,
their checks, and that a worker process trains the same model as this process."""

from dataclasses import replace
from functools import partial

import pytest
import torch

from ibc_tutorial import parallel
from ibc_tutorial.experiments import toy_runs
from ibc_tutorial.negatives import UniformSampler
from ibc_tutorial.objectives import info_nce_objective, likelihood_objective
from ibc_tutorial.policies import ClassifierPolicy, EnergyModel, MDNPolicy, RegressionPolicy
from ibc_tutorial.toy import TreeWorld
from ibc_tutorial.training import TrainConfig, train

SHORT = TrainConfig(steps=4, batch_size=16, lr=3e-3, log_every=2, progress=False)


@pytest.fixture(scope="module")
def demos():
    return TreeWorld().expert_demonstrations(4, seed=0)


@pytest.fixture(scope="module", autouse=True)
def stop_workers():
    yield
    parallel.shutdown()


def same_weights(a, b):
    sa, sb = a.state_dict(), b.state_dict()
    return sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa)


def test_train_explicit_builds_the_named_policies_in_order_from_one_seed(demos):
    out = toy_runs.train_explicit(demos, 2, ("MDN", "classifier"), config=SHORT)
    assert list(out) == ["classifier", "MDN"]  # the order of EXPLICIT
    assert isinstance(out["classifier"][0], ClassifierPolicy) and isinstance(out["MDN"][0], MDNPolicy)
    torch.manual_seed(2)  # by hand: built one after another, then trained with the seed
    by_hand = [toy_runs.make_explicit(name, demos.obs.shape[1]) for name in ("classifier", "MDN")]
    for p in by_hand:
        curve = train(p, likelihood_objective(p), demos.training_data(), replace(SHORT, seed=2))
    assert same_weights(out["classifier"][0], by_hand[0]) and same_weights(out["MDN"][0], by_hand[1])
    assert out["MDN"][1].losses == curve.losses


def test_train_explicit_checks(demos):
    with pytest.raises(ValueError, match="names"):
        toy_runs.train_explicit(demos, 0, ("regression", "tree"), config=SHORT)
    with pytest.raises(ValueError, match="names"):
        toy_runs.train_explicit(demos, 0, ("Beta", "Beta"), config=SHORT)
    with pytest.raises(ValueError, match="names"):
        toy_runs.train_explicit(demos, 0, (), config=SHORT)
    with pytest.raises(ValueError, match="demos"):
        toy_runs.train_explicit(demos.training_data(), 0, config=SHORT)
    with pytest.raises(ValueError, match="seed"):
        toy_runs.train_explicit(demos, -1, config=SHORT)
    with pytest.raises(ValueError, match="config"):
        toy_runs.train_explicit(demos, 0, config={"steps": 3})
    with pytest.raises(ValueError, match="name"):
        toy_runs.make_explicit("tree", 1)


def test_fit_regression(demos):
    policy = toy_runs.fit_regression(demos, 1, steps=3)
    assert isinstance(policy, RegressionPolicy) and policy.act(demos.obs[:5]).shape == (5, 1)
    with pytest.raises(ValueError, match="demos"):
        toy_runs.fit_regression(demos.obs, 1, steps=3)


def test_fit_ebm_the_same_in_a_worker_process(demos):
    objective = partial(info_nce_objective, sampler=UniformSampler(-1.0, 1.0), n_neg=4)
    calls = [(demos.training_data(), 1, objective, seed) for seed in (0, 1)]
    here = parallel.parallel_map(toy_runs.fit_ebm, calls, steps=5, width=8, workers=1)
    there = parallel.parallel_map(toy_runs.fit_ebm, calls, steps=5, width=8, workers=2)
    for (m1, c1), (m2, c2) in zip(here, there, strict=True):
        assert isinstance(m1, EnergyModel) and m1.hidden == 8
        assert same_weights(m1, m2) and c1.losses == c2.losses
    assert not same_weights(here[0][0], here[1][0])
    with pytest.raises(ValueError, match="objective"):
        toy_runs.fit_ebm(demos.training_data(), 1, "info_nce")
    with pytest.raises(ValueError, match="width"):
        toy_runs.fit_ebm(demos.training_data(), 1, objective, width=0)


def weights_apart(a, b) -> float:
    with torch.no_grad():
        return max(float((p - q).abs().max()) for p, q in zip(a.parameters(), b.parameters(), strict=True))


def test_the_sweeps_train_what_the_single_runs_train():
    """train_explicit_stacked, fit_regressions and fit_ebms: each seed's network as its single run's, up to
    round-off (the weights agree to 1e-9 after a few steps; the same initial weights exactly)."""
    seeds = (0, 3)
    dtype = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)  # as the chapters train
    try:
        demos = TreeWorld().expert_demonstrations(4, seed=0)
        d = demos.obs.shape[1]
        alone = [toy_runs.train_explicit(demos, s, ("classifier", "MDN"), config=SHORT) for s in seeds]
        untrained = [toy_runs.explicit_policies(demos, s, ("classifier", "MDN")) for s in seeds]
        assert same_weights(
            untrained[1]["MDN"], toy_runs.explicit_policies(demos, 3, ("classifier", "MDN"))["MDN"]
        )
        for name in ("classifier", "MDN"):
            swept = toy_runs.train_explicit_stacked(demos, [u[name] for u in untrained], seeds, config=SHORT)
            for (p, curve), one in zip(swept, alone, strict=True):
                assert weights_apart(p, one[name][0]) < 1e-9 and curve.steps == one[name][1].steps
        for p, s in zip(toy_runs.fit_regressions(demos, seeds, steps=3), seeds, strict=True):
            assert weights_apart(p, toy_runs.fit_regression(demos, s, steps=3)) < 1e-9
        objective = partial(info_nce_objective, sampler=UniformSampler(-1.0, 1.0), n_neg=4)
        data = demos.training_data()
        for (m, _), s in zip(
            toy_runs.fit_ebms(data, d, objective, seeds, steps=5, width=8), seeds, strict=True
        ):
            assert (
                m.hidden == 8
                and weights_apart(m, toy_runs.fit_ebm(data, d, objective, s, steps=5, width=8)[0]) < 1e-9
            )
    finally:
        torch.set_default_dtype(dtype)
    with pytest.raises(ValueError, match="demos"):
        toy_runs.fit_regressions(demos.obs, seeds)
    with pytest.raises(ValueError, match="seed"):
        toy_runs.fit_regressions(demos, (0, -1))
    with pytest.raises(ValueError, match="objective"):
        toy_runs.fit_ebms(demos.training_data(), 1, "info_nce", seeds)
