"""k networks as one stacked model (``benchmarks/stacked.py``, a prototype that
``benchmarks/bench_replicate.py --prototypes`` measures; not part of the library): the same
losses, gradients, draws and Adam state as k separate ``training.Trainer`` runs, up to the
rounding of the batched kernels."""

import dataclasses
import sys
from pathlib import Path

import pytest
import torch

from ibc_tutorial.experiments.agents.agent import build_network
from ibc_tutorial.experiments.agents.presets import TINY
from ibc_tutorial.experiments.agents.train import objective_for
from ibc_tutorial.negatives import ExpertSampler, UniformSampler
from ibc_tutorial.training import TrainConfig, Trainer, draw_minibatch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from stacked import StackedNetworks, StackedTrainer  # noqa: E402

SEEDS = (0, 1, 2)


class Demos:
    """Random BEVs (0/1), states and actions in [-1, 1], as ``DemoBatches`` returns them."""

    def __init__(self, m=64, size=TINY.bev_size):
        g = torch.Generator().manual_seed(5)
        self.bev = (torch.rand(m, 5, size, size, generator=g) > 0.7).float()
        self.state = torch.rand(m, 3, generator=g)
        self.actions = torch.rand(m, 2, generator=g) * 2 - 1

    def __len__(self):
        return len(self.bev)

    def batch(self, idx):
        return {"obs": {"bev": self.bev[idx], "state": self.state[idx]}, "actions": self.actions[idx]}


def networks(method):
    out = []
    for s in SEEDS:
        torch.manual_seed(s)
        out.append(build_network(method, TINY))
    return out


def sampler_of(method):
    return None if method == "bc" else UniformSampler(-1.0, 1.0) if method == "ibc" else ExpertSampler(0.1)


def rel(a, b):
    return float((a - b).norm() / b.norm().clamp_min(1e-30))


@pytest.mark.parametrize("method", ["bc", "ibc", "da-ibc"])
def test_losses_gradients_and_draws_are_those_of_separate_runs(method):
    data, nets = Demos(), networks(method)
    config = TrainConfig(steps=5, batch_size=16, lr=1e-3)
    st = StackedTrainer(nets, data, config, SEEDS, sampler=sampler_of(method), n_neg=TINY.n_neg)
    mb = st.draw()
    losses = st.stack.losses(mb["bev"], mb["state"], mb["actions"], mb["negatives"])  # (k,)
    losses.sum().backward()
    for i, s in enumerate(SEEDS):
        g = torch.Generator().manual_seed(s)
        idx = draw_minibatch(None, len(data), 16, g)  # what agent i's own Trainer draws first
        loss = objective_for(method, nets[i], TINY)(data.batch(idx), g)  # then its counter-examples
        loss.backward()
        assert torch.equal(g.get_state(), st.generators[i].get_state())  # the same draws, in the same order
        assert torch.allclose(losses[i].detach(), loss.detach(), rtol=1e-5, atol=1e-6)
        for name, prm in nets[i].named_parameters():
            if name == "head.2.bias" and method != "bc":
                # InfoNCE does not depend on a constant shift of the energy: this gradient is 0 up to rounding
                assert prm.grad.abs().max() < 1e-5
                continue
            assert rel(st.stack.params[name].grad[i], prm.grad) < 1e-4, name


def test_training_steps_follow_separate_trainers_and_give_their_state():
    data, nets = Demos(), networks("da-ibc")
    config = TrainConfig(steps=3, batch_size=16, lr=1e-3, lr_schedule="cosine")
    st = StackedTrainer(nets, data, config, SEEDS, sampler=ExpertSampler(0.1), n_neg=TINY.n_neg)
    losses = st.run()
    assert len(losses) == 3 and losses[0].shape == (3,) and st.step == 3
    assert st.run() == []  # already at config.steps
    for i, s in enumerate(SEEDS):
        tr = Trainer(
            nets[i], objective_for("da-ibc", nets[i], TINY), data, dataclasses.replace(config, seed=s)
        )
        tr.run()
        mine = st.agent_state_dict(i)
        assert torch.equal(mine["generator"], tr.generator.get_state()) and mine["step"] == tr.step
        diffs = torch.cat([(mine["model"][n] - v).abs().flatten() for n, v in nets[i].state_dict().items()])
        # Adam's first steps move each weight by about lr whatever the gradient's size, so a weight whose
        # gradient is rounding noise (the head's output bias) may differ by a few lr; the rest agree closely
        assert diffs.max() <= 3 * 3 * config.lr and (diffs < 1e-5).float().mean() > 0.99
        # agent i's state loads into a one-model Trainer as its own would
        fresh = Trainer(build_network("da-ibc", TINY), objective_for("da-ibc", nets[i], TINY), data, config)
        fresh.load_state_dict(mine)
        assert torch.equal(
            fresh.optimizer.state_dict()["state"][0]["exp_avg"], mine["optimizer"]["state"][0]["exp_avg"]
        )


def test_inference_matches_each_network():
    nets = networks("ibc")
    stack = StackedNetworks(nets)
    data = Demos()
    bev = torch.stack([data.bev[:4], data.bev[4:8], data.bev[8:12]])  # (k, B, 5, S, S)
    state = torch.stack([data.state[:4], data.state[4:8], data.state[8:12]])
    actions = torch.rand(3, 4, 7, 2) * 2 - 1  # (k, B, N, D)
    with torch.no_grad():
        z = stack.embed(bev, state)  # (k, B, E)
        e = stack.energy_from_embedding(z, actions)  # (k, B, N)
        for i, net in enumerate(nets):
            zi = net.embed({"bev": bev[i], "state": state[i]})
            assert torch.allclose(z[i], zi, atol=1e-6)
            assert torch.allclose(e[i], net.energy_from_embedding(zi, actions[i]), atol=1e-5)
    for net, back in zip(nets, stack.unstack(), strict=True):
        for (n, a), (_, b) in zip(net.state_dict().items(), back.state_dict().items(), strict=True):
            assert torch.equal(a, b), n


def test_refusals():
    with pytest.raises(ValueError, match="at least one"):
        StackedNetworks([])
    with pytest.raises(ValueError, match="same parameter shapes"):
        StackedNetworks([build_network("ibc", TINY), build_network("bc", TINY)])
    with pytest.raises(ValueError, match="EnergyModel or BetaPolicy"):
        StackedNetworks([torch.nn.Linear(2, 2)])
    with pytest.raises(ValueError, match="one seed per network"):
        StackedTrainer(networks("bc"), Demos(), TrainConfig(steps=1), (0, 1))
    with pytest.raises(ValueError, match="sampler"):
        StackedTrainer(networks("ibc"), Demos(), TrainConfig(steps=1), SEEDS)
    with pytest.raises(ValueError, match="energy models"):
        StackedNetworks(networks("bc")).energy_from_embedding(torch.zeros(3, 1, 32), torch.zeros(3, 1, 2, 2))
