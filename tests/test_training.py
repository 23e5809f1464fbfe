"""The one training loop (resumable, any data with ``batch``) and the energy-model objectives (InfoNCE with
any sampler, grid variants)."""

import pytest
import torch

from ibc_tutorial.losses import grid_cross_entropy, info_nce, soft_targets, temporal_smoothing
from ibc_tutorial.negatives import ExpertSampler, UniformSampler
from ibc_tutorial.objectives import consecutive_pairs, grid_objective, info_nce_objective
from ibc_tutorial.optimizers.grid import action_grid, grid_argmin
from ibc_tutorial.policies import EnergyModel, MLPEncoder
from ibc_tutorial.training import TrainConfig, Trainer, draw_minibatch, train


def bimodal_data(m=512, seed=0):
    """x in [-1, 1]; y = +0.5 or -0.5 with equal probability when x > 0, else y = 0."""
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(m, 1, generator=g) * 2 - 1
    sign = torch.where(torch.rand(m, generator=g) < 0.5, -1.0, 1.0)
    y = torch.where(x[:, 0] > 0, 0.5 * sign, torch.zeros(m))[:, None]
    return {"obs": x, "actions": y}


def small_model(seed=0, action_dim=1):
    torch.manual_seed(seed)
    return EnergyModel(MLPEncoder(1, embed_dim=32, hidden=32), action_dim, hidden=32)


@pytest.mark.parametrize("sampler", [UniformSampler(-1.0, 1.0), ExpertSampler(0.2)])
def test_info_nce_objective_learns_two_modes(sampler):
    data = bimodal_data()
    model = small_model()
    result = train(
        model,
        info_nce_objective(model, sampler, 32),
        data,
        TrainConfig(steps=300, batch_size=64, lr=5e-3, log_every=100),
    )
    assert result.losses[-1] < result.losses[0]
    grid = action_grid(101)
    _, e = grid_argmin(model, torch.tensor([[0.6], [-0.6]]), grid, return_energies=True)
    ys = grid[:, 0]
    # bimodal where the expert is: both ±0.5 are local minima far below the energy at 0
    e_pos = e[0]
    left, right, mid = (
        e_pos[(ys + 0.5).abs().argmin()],
        e_pos[(ys - 0.5).abs().argmin()],
        e_pos[ys.abs().argmin()],
    )
    assert left < mid - 1 and right < mid - 1
    # unimodal at 0 elsewhere
    assert abs(float(grid[e[1].argmin(), 0])) < 0.15


def test_info_nce_objective_is_the_loss_of_its_parts():
    data = bimodal_data(16)
    model = small_model()
    calls = []

    def sampler(actions, n, gen):
        calls.append(actions.clone())
        return torch.linspace(-1, 1, n).reshape(1, n, 1).expand(len(actions), n, 1)

    w = torch.rand(16)
    batch = {**data, "w": w}
    got = info_nce_objective(model, sampler, 7, weight_key="w")(batch, torch.Generator())
    torch.testing.assert_close(calls[0], data["actions"])  # the sampler sees the minibatch's expert actions
    e_pos = model.energy(data["obs"], data["actions"][:, None, :])[:, 0]
    e_neg = model.energy(data["obs"], torch.linspace(-1, 1, 7)[:, None])
    torch.testing.assert_close(got, info_nce(e_pos, e_neg, w))


def test_grid_objective_variants_are_the_losses_of_the_paper():
    model = small_model()
    grid = action_grid(9)
    obs, y = torch.randn(5, 1), torch.rand(5, 1) - 0.5
    obs2, y2 = torch.randn(5, 1), torch.rand(5, 1) - 0.5
    e = torch.cat([model.energy(obs, y[:, None, :]), model.energy(obs, grid)], 1)  # (B, 1 + G)
    e2 = torch.cat([model.energy(obs2, y2[:, None, :]), model.energy(obs2, grid)], 1)
    batch = {"obs": obs, "actions": y, "next_obs": obs2, "next_actions": y2}
    gen = torch.Generator()
    # one-hot: eq. 3 = InfoNCE with the grid as counter-examples
    torch.testing.assert_close(grid_objective(model, grid)(batch, gen), info_nce(e[:, 0], e[:, 1:]))
    # soft targets (eq. 5) over [ground truth; grid]
    cand = torch.cat([y[:, None, :], grid.expand(5, -1, -1)], 1)
    want = grid_cross_entropy(e, soft_targets(cand, y, 0.05))
    torch.testing.assert_close(grid_objective(model, grid, temperature=0.05)(batch, gen), want)
    # temporal smoothing (eq. 4): both frames' CE plus α‖e_t − e_{t+1}‖ over the grid columns only
    ce = 0.5 * (info_nce(e[:, 0], e[:, 1:]) + info_nce(e2[:, 0], e2[:, 1:]))
    want = ce + temporal_smoothing(e[:, 1:], e2[:, 1:], 0.7)
    torch.testing.assert_close(grid_objective(model, grid, smoothing=0.7)(batch, gen), want)


def test_consecutive_pairs_stay_inside_episodes():
    data = {"obs": torch.arange(7.0)[:, None], "episode": torch.tensor([0, 0, 0, 1, 1, 2, 2])}
    pairs = consecutive_pairs(data)
    assert pairs["obs"][:, 0].tolist() == [0, 1, 3, 5]
    assert pairs["next_obs"][:, 0].tolist() == [1, 2, 4, 6]
    assert (pairs["episode"] == pairs["next_episode"]).all()
    with pytest.raises(ValueError, match="episode"):
        consecutive_pairs({"obs": torch.zeros(3, 1)})


def test_training_is_seeded_and_records_evaluations():
    data = bimodal_data(128)
    runs = []
    for _ in range(2):
        model = small_model(seed=3)

        def evals(model=model):  # this run's model
            return float(model.energy(torch.zeros(1, 1), torch.zeros(1, 1, 1)))

        res = train(
            model,
            info_nce_objective(model, ExpertSampler(0.1), 8),
            data,
            TrainConfig(steps=40, batch_size=16, log_every=10),
            evaluate=evals,
        )
        runs.append(res)
    assert runs[0].losses == runs[1].losses and runs[0].evals == runs[1].evals
    assert len(runs[0].evals) == 4 and runs[0].steps == [10, 20, 30, 40]


def test_grid_objective_with_smoothing_trains():
    data = bimodal_data(200)
    data["episode"] = torch.arange(200) // 20
    pairs = consecutive_pairs(data)
    model = small_model()
    res = train(
        model,
        grid_objective(model, action_grid(32), temperature=0.01, smoothing=1.0),
        pairs,
        TrainConfig(steps=60, batch_size=32, log_every=20),
    )
    assert all(torch.isfinite(torch.tensor(res.losses)))


def test_objective_bad_input():
    model = small_model()
    with pytest.raises(ValueError, match="n_neg"):
        info_nce_objective(model, UniformSampler(), 0)
    with pytest.raises(ValueError, match="temperature"):
        grid_objective(model, action_grid(5), temperature=0)
    with pytest.raises(ValueError, match="smoothing"):
        grid_objective(model, action_grid(5), smoothing=-1)


def _params(model):
    return [p.detach().clone() for p in model.parameters()]


def test_a_resumed_run_is_bit_identical(tmp_path):
    data = bimodal_data(200)
    config = TrainConfig(steps=60, batch_size=16, log_every=20, seed=4)
    whole = small_model(seed=5)
    res_whole = train(whole, info_nce_objective(whole, ExpertSampler(0.1), 8), data, config)
    # stop after 33 steps (mid log interval), save the state to disk, continue in a fresh model and trainer
    first = small_model(seed=5)
    trainer = Trainer(
        first,
        info_nce_objective(first, ExpertSampler(0.1), 8),
        data,
        TrainConfig(**{**config.__dict__, "steps": 33}),
    )
    res_a = trainer.run()
    torch.save(trainer.state_dict(), tmp_path / "state.pt")
    state = torch.load(tmp_path / "state.pt", weights_only=True)
    second = small_model(seed=99)  # other initial weights: all overwritten by the state
    res_b = train(second, info_nce_objective(second, ExpertSampler(0.1), 8), data, config, state=state)
    assert all(torch.equal(a, b) for a, b in zip(_params(whole), _params(second), strict=True))
    assert res_whole.steps == [20, 40, 60] and res_a.steps == [20, 33] and res_b.steps == [40, 60]
    assert res_b.losses[1] == res_whole.losses[2]  # steps 41-60: the same minibatches and counter-examples


def test_trainer_takes_any_data_with_batch():
    class Squares:
        """A map-style dataset whose minibatches are made on demand."""

        def __len__(self):
            return 50

        def batch(self, indices):
            x = indices.float()[:, None] / 50
            return {"obs": x, "actions": x**2}

    seen = []
    model = torch.nn.Linear(1, 1)

    def objective(batch, gen):
        seen.append(batch["obs"])
        return ((model(batch["obs"]) - batch["actions"]) ** 2).mean()

    res = train(model, objective, Squares(), TrainConfig(steps=30, batch_size=8, log_every=10, lr=1e-2))
    assert len(seen) == 30 and res.losses[-1] < res.losses[0]
    with pytest.raises(ValueError, match="batch"):
        train(model, objective, [1, 2, 3], TrainConfig(steps=1))


def test_draw_minibatch_is_the_draw_training_makes():
    probs = torch.tensor([0.0, 0.2, 0.0, 0.8])
    a = draw_minibatch(probs, 4, 500, torch.Generator().manual_seed(1))
    assert set(a.tolist()) == {1, 3} and 0.7 < (a == 3).float().mean() < 0.9
    u = draw_minibatch(None, 7, 300, torch.Generator().manual_seed(1))
    assert u.min() >= 0 and u.max() == 6
    seen = []
    model = torch.nn.Linear(1, 1)

    def objective(batch, gen):
        seen.append(batch["i"])
        return model.weight.sum() * 0.0

    train(
        model,
        objective,
        {"i": torch.arange(4)},
        TrainConfig(steps=1, batch_size=32, seed=3),
        sample_probs=probs,
    )
    assert torch.equal(seen[0], draw_minibatch(probs, 4, 32, torch.Generator().manual_seed(3)))


def test_trainer_refuses_a_foreign_state():
    model = small_model()
    trainer = Trainer(
        model, info_nce_objective(model, UniformSampler(), 4), bimodal_data(32), TrainConfig(steps=5)
    )
    with pytest.raises(ValueError, match="state must hold"):
        trainer.load_state_dict({"model": model.state_dict()})
    with pytest.raises(ValueError, match=r"state\['step'\] must be <="):
        trainer.load_state_dict(dict(trainer.state_dict(), step=6))


def test_cosine_schedule_decays_and_resumes_bit_identically():
    data = bimodal_data(200)
    config = TrainConfig(steps=60, batch_size=16, log_every=20, seed=4, lr=1e-2, lr_schedule="cosine")
    whole = small_model(seed=5)
    train(whole, info_nce_objective(whole, ExpertSampler(0.1), 8), data, config)
    constant = small_model(seed=5)
    train(
        constant,
        info_nce_objective(constant, ExpertSampler(0.1), 8),
        data,
        TrainConfig(**{**config.__dict__, "lr_schedule": "constant"}),
    )
    assert not all(
        torch.equal(a, b) for a, b in zip(_params(whole), _params(constant), strict=True)
    )  # the schedule acts

    class Killed(Exception):
        pass

    first = small_model(seed=5)
    trainer = Trainer(first, info_nce_objective(first, ExpertSampler(0.1), 8), data, config)
    saved = {}

    def kill_after_first_log(step, loss):
        saved.update(trainer.state_dict())
        raise Killed

    with pytest.raises(Killed):
        trainer.run(callback=kill_after_first_log)
    assert saved["step"] == 20
    second = small_model(seed=99)
    train(second, info_nce_objective(second, ExpertSampler(0.1), 8), data, config, state=saved)
    assert all(torch.equal(a, b) for a, b in zip(_params(whole), _params(second), strict=True))
    assert trainer.learning_rate(0) == 1e-2 and trainer.learning_rate(30) == pytest.approx(5e-3)
    assert 0 < trainer.learning_rate(59) < 1e-4
    with pytest.raises(ValueError, match="lr_schedule"):
        Trainer(
            first, info_nce_objective(first, ExpertSampler(0.1), 8), data, TrainConfig(lr_schedule="step")
        )
