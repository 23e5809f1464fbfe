"""Chapter 04's experiment (``experiments.counter_examples``): its measures against the expert's
own density, its histograms, a short reproducible run, and the checks of its config."""

import math

import pytest
import torch

from ibc_tutorial.experiments.counter_examples import (
    CounterExampleConfig,
    CounterExampleRun,
    evaluate,
    expert_nll,
    make_datasets,
    mode_masses,
    negatives_histogram,
    run,
    train_config,
    valid_mass,
)
from ibc_tutorial.negatives import ExpertSampler, UniformSampler
from ibc_tutorial.toy import JunctionWorld
from ibc_tutorial.training import TrainConfig


def test_evaluate_of_the_expert_density_reaches_the_floor():
    problem = JunctionWorld()
    config = CounterExampleConfig(n_heldout=60)
    _, heldout = make_datasets(problem, config)

    class Oracle(torch.nn.Module):
        """E(x, y) = -log p(y|x) of the expert itself."""

        def embed(self, obs):
            return obs

        def energy_from_embedding(self, z, actions):
            a = actions.expand(len(z), -1, -1) if actions.ndim == 2 else actions
            n = a.shape[1]
            return -problem.log_density(z.repeat_interleave(n, 0), a.reshape(-1, 2)).reshape(len(z), n)

    out = evaluate(Oracle(), heldout, problem, config)
    assert abs(out["nll"] - expert_nll(problem, heldout)) < 0.05 and out["hit"] == 1.0
    # the expert's own density puts (nearly) all its mass within 0.15 of a valid action
    assert (valid_mass(Oracle(), heldout["obs"], problem) > 0.99).all()


def test_negatives_histogram_and_mode_masses():
    actions = torch.tensor([[0.0, 0.0]]).repeat(10, 1)
    h = negatives_histogram(ExpertSampler(0.0), actions, 4, batches=2, batch_size=4, bins=10)
    assert (
        h.shape == (10, 10) and float(h.sum()) == pytest.approx(1.0) and float(h[5, 5]) == pytest.approx(1.0)
    )
    u = negatives_histogram(UniformSampler(-1.0, 1.0), actions, 100, batches=20, bins=4)
    assert (u > 0.05).all()  # uniform counter-examples visit every cell

    problem = JunctionWorld()

    class Flat(torch.nn.Module):
        hidden = 1

        def embed(self, obs):
            return obs

        def energy_from_embedding(self, z, actions):
            return torch.zeros(len(z), actions.shape[-2])

    m = mode_masses(Flat(), torch.tensor([[0.0, 1.0, 0.0, 0.5]]), problem, grid_n=41, radius=0.15)
    # a flat landscape puts on each disc of radius 0.15 about its share of the box: π 0.15² / 4
    torch.testing.assert_close(m, torch.full((1, 3), math.pi * 0.15**2 / 4), atol=0.004, rtol=0)
    # valid_mass counts only the valid actions: three discs at a junction, one when cruising
    both = torch.tensor([[0.0, 1.0, 0.0, 0.5], [0.0, 0.0, 0.0, 0.5]])
    v = valid_mass(Flat(), both, problem, grid_n=41, radius=0.15)
    torch.testing.assert_close(v, torch.tensor([3.0, 1.0]) * math.pi * 0.15**2 / 4, atol=0.012, rtol=0)
    with pytest.raises(ValueError, match="radius"):
        valid_mass(Flat(), both, problem, radius=0.0)
    with pytest.raises(ValueError, match="obs"):
        valid_mass(Flat(), torch.zeros(2, 3), problem)


def test_a_short_run_records_its_measures():
    world = JunctionWorld()
    config = CounterExampleConfig(
        n_train=128, n_heldout=16, train=train_config(steps=4, batch_size=8, log_every=2), grid_n=11
    )
    data = make_datasets(world, config)
    out = run(world, UniformSampler(), config, seed=0, data=data)
    assert isinstance(out, CounterExampleRun) and out.steps == [2, 4]
    assert len(out.nll) == len(out.hit) == len(out.losses) == 2 and all(math.isfinite(v) for v in out.nll)
    again = run(world, UniformSampler(), config, seed=0, data=data)
    assert again.nll == out.nll  # reproducible from the seed


def test_counter_example_config_is_checked():
    with pytest.raises(ValueError, match="n_neg"):
        CounterExampleConfig(n_neg=0)
    with pytest.raises(ValueError, match="hit_radius"):
        CounterExampleConfig(hit_radius=0.0)


def test_train_config_holds_the_chapters_settings():
    config = CounterExampleConfig()
    assert (config.train.steps, config.train.batch_size, config.train.lr, config.train.log_every) == (
        600,
        64,
        3e-3,
        50,
    )
    assert train_config(steps=300).steps == 300 and train_config(steps=300).batch_size == 64
    with pytest.raises(TypeError):
        train_config(step=300)  # a misspelt field is not silently ignored
    with pytest.raises(ValueError, match="config.train.steps"):
        CounterExampleConfig(train=train_config(steps=0))
    with pytest.raises(ValueError, match="config.train.lr"):
        CounterExampleConfig(train=train_config(lr=0.0))
    with pytest.raises(ValueError, match="config.train must be a TrainConfig"):
        CounterExampleConfig(train={"steps": 600})


def test_run_uses_its_seed_not_the_train_seed():
    world = JunctionWorld()
    small = dict(n_train=64, n_heldout=8, grid_n=5)
    a = CounterExampleConfig(**small, train=train_config(steps=2, batch_size=4, log_every=2, seed=0))
    b = CounterExampleConfig(**small, train=TrainConfig(steps=2, batch_size=4, lr=3e-3, log_every=2, seed=7))
    data = make_datasets(world, a)
    assert (
        run(world, UniformSampler(), a, seed=3, data=data).losses
        == run(world, UniformSampler(), b, seed=3, data=data).losses
    )
