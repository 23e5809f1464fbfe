"""The flow agent and DA-IBC with ranking NCE in the town (experiments.agents: presets, agent, train,
checkpoints, flow_readings, added_methods): tiny sizes, seconds each."""

import dataclasses

import numpy as np
import pytest
import torch

from ibc_tutorial import cli
from ibc_tutorial.experiments.agents.added_methods import (
    check_methods,
    folder_preset,
    parse_methods,
    replication_finished,
)
from ibc_tutorial.experiments.agents.agent import Agent, architecture, build_network, nearest_previous_steer
from ibc_tutorial.experiments.agents.checkpoints import load_agent, save_checkpoint
from ibc_tutorial.experiments.agents.flow_readings import (
    READ_SAMPLES,
    left_share,
    read_flow_states,
    sample_profile,
)
from ibc_tutorial.experiments.agents.presets import ALL_METHODS, LAPTOP, TINY, TWO_ANSWERS, Preset
from ibc_tutorial.experiments.agents.train import counter_examples, objective_for
from ibc_tutorial.experiments.agents.two_answers import STEER_GRID, read_states
from ibc_tutorial.negatives import ExpertSampler
from ibc_tutorial.objectives import info_nce_objective
from ibc_tutorial.optimizers.grid import symmetric_axis
from ibc_tutorial.policies.energy import EnergyModel
from ibc_tutorial.policies.flow import FlowPolicy


def _obs(n, size=32, seed=0, steer=None):
    g = torch.Generator().manual_seed(seed)
    state = torch.rand(n, 3, generator=g) * 2 - 1
    if steer is not None:
        state[:, 1] = torch.as_tensor(steer, dtype=torch.float32)
    return {"bev": (torch.rand(n, 5, size, size, generator=g) < 0.2).float(), "state": state}


# ---------------------------------------------------------------- settings and cost
def test_the_families_cost_at_most_a_twentieth_of_dfo_in_the_two_answers_preset():
    dfo = TWO_ANSWERS.network_evaluations("da-ibc")
    flow = TWO_ANSWERS.network_evaluations("flow")
    assert dfo == {"encoder": 1, "head": 512 * 3}
    assert flow == {"encoder": 1, "head": TWO_ANSWERS.flow_samples * TWO_ANSWERS.flow_steps}
    assert flow["head"] * 20 <= dfo["head"]
    assert TWO_ANSWERS.network_evaluations("da-ibc-rnce") == dfo  # the same Algorithm 1 as da-ibc
    # the families train with the preset's budget: nothing of the training settings is theirs
    assert TWO_ANSWERS.dfo_config("da-ibc-rnce") == TWO_ANSWERS.dfo_config("da-ibc")
    assert TWO_ANSWERS.dfo_config("flow") is None
    assert TWO_ANSWERS.flow_config().n_steps == 4 and TWO_ANSWERS.flow_config().n_samples == 16


def test_preset_checks_the_flow_fields_and_accepts_every_method():
    with pytest.raises(ValueError, match="flow_steps"):
        dataclasses.replace(TINY, flow_steps=0)
    with pytest.raises(ValueError, match="flow_samples"):
        dataclasses.replace(TINY, flow_samples=0)
    p = dataclasses.replace(TINY, methods=ALL_METHODS)
    assert Preset.from_dict(p.to_dict()) == p
    old = {k: v for k, v in LAPTOP.to_dict().items() if not k.startswith("flow_")}  # a folder made before
    assert Preset.from_dict(old) == LAPTOP
    with pytest.raises(ValueError, match="methods"):
        dataclasses.replace(TINY, methods=("bc", "diffusion"))
    with pytest.raises(ValueError, match="method"):
        TINY.network_evaluations("diffusion")


# ---------------------------------------------------------------- networks, objectives, checkpoints
def test_the_networks_of_the_families():
    flow, rnce = build_network("flow", TINY), build_network("da-ibc-rnce", TINY)
    assert isinstance(flow, FlowPolicy) and isinstance(rnce, EnergyModel)
    arch = architecture("flow", TINY)
    assert arch["network"] == "FlowPolicy" and arch["head_hidden"] == TINY.head_hidden
    assert architecture("da-ibc-rnce", TINY) == architecture("da-ibc", TINY)
    with pytest.raises(ValueError, match="network must be a FlowPolicy"):
        Agent("flow", rnce, TINY, torch.zeros(3, 2))
    assert counter_examples("flow", TINY) is None
    assert isinstance(counter_examples("da-ibc-rnce", TINY), ExpertSampler)


def test_da_ibc_rnce_trains_with_ranking_nce_on_da_ibc_counter_examples():
    torch.manual_seed(0)
    net = build_network("da-ibc-rnce", TINY)
    batch = {"obs": _obs(4), "actions": torch.rand(4, 2) * 2 - 1}
    loss = objective_for("da-ibc-rnce", net, TINY)(batch, torch.Generator().manual_seed(3))
    ranking = info_nce_objective(net, ExpertSampler(TINY.neg_sigma), TINY.n_neg, ranking=True)
    assert loss.item() == pytest.approx(ranking(batch, torch.Generator().manual_seed(3)).item(), rel=1e-6)
    plain = objective_for("da-ibc", net, TINY)(batch, torch.Generator().manual_seed(3))
    assert loss.item() != pytest.approx(plain.item(), rel=1e-4)  # log q subtracted: another objective


def test_flow_trains_by_flow_matching():
    torch.manual_seed(0)
    net = build_network("flow", TINY)
    batch = {"obs": _obs(4), "actions": torch.rand(4, 2) * 2 - 1}
    loss = objective_for("flow", net, TINY)(batch, torch.Generator().manual_seed(0))
    want = net.loss(batch["obs"], batch["actions"], torch.Generator().manual_seed(0))
    assert torch.isfinite(loss) and loss.item() == pytest.approx(want.item())


@pytest.mark.parametrize("method", ["flow", "da-ibc-rnce"])
def test_checkpoint_round_trip_with_weights_only(method, tmp_path):
    torch.manual_seed(0)
    actions = torch.rand(20, 2) * 2 - 1
    agent = Agent(method, build_network(method, TINY), TINY, actions)
    path = save_checkpoint(tmp_path / "a.pt", agent, data_sha256="ab" * 32, epoch=1, seed=0, half=True)
    raw = torch.load(path, weights_only=True)  # plain data only
    assert raw["method"] == method and raw["architecture"] == architecture(method, TINY)
    back, _ = load_agent(path, method=method, preset=TINY)
    assert back.method == method and back.network_evaluations() == agent.network_evaluations()
    assert (back.init_weights is not None) == (method == "da-ibc-rnce")  # DA-IBC's DFO start
    obs = _obs(3)
    a = back.act(obs, torch.Generator().manual_seed(1))
    b = back.act(obs, torch.Generator().manual_seed(1))
    assert a.shape == (3, 2) and torch.equal(a, b) and a.abs().max() <= 1.0


# ---------------------------------------------------------------- the flow agent's choice
def test_nearest_previous_steer_keeps_the_side_the_car_has_taken():
    samples = torch.tensor([[[-0.4, 1.0], [0.35, -1.0], [0.5, 0.2]], [[-0.4, 1.0], [0.35, -1.0], [0.5, 0.2]]])
    got = nearest_previous_steer(samples, torch.tensor([-0.1, 0.45]))
    assert torch.equal(got, torch.tensor([[-0.4, 1.0], [0.5, 0.2]]))  # the whole sample: its acceleration too
    with pytest.raises(ValueError, match="previous_steer"):
        nearest_previous_steer(samples, torch.zeros(3))
    with pytest.raises(ValueError, match="samples"):
        nearest_previous_steer(samples[0], torch.zeros(2))


def test_the_flow_agent_acts_with_the_sample_nearest_its_previous_steering():
    torch.manual_seed(0)
    agent = Agent("flow", build_network("flow", TINY), TINY, torch.zeros(5, 2))
    obs = _obs(6, steer=[-0.9, -0.3, 0.0, 0.2, 0.6, 1.0])
    act = agent.act(obs, torch.Generator().manual_seed(4))
    samples = agent.network.sample(obs, generator=torch.Generator().manual_seed(4))  # (B, N, 2)
    assert samples.shape == (6, TINY.flow_samples, 2)
    assert torch.equal(act, nearest_previous_steer(samples, obs["state"][:, 1]))
    policy = agent.policy(seed=2)
    np.testing.assert_array_equal(
        policy({k: v.numpy() for k, v in obs.items()}),
        agent.policy(seed=2)({k: v.numpy() for k, v in obs.items()}),
    )
    with pytest.raises(ValueError, match="energy agent"):
        agent.energy_grid({k: v[:1] for k, v in obs.items()})


# ---------------------------------------------------------------- readings of a flow agent
class _Bimodal(torch.nn.Module):
    """A stand-in flow: half its samples at steering -0.3, half at +0.3 (a little spread), or all at 0.1."""

    def __init__(self, two: bool):
        super().__init__()
        self.two = two
        self.unused = torch.nn.Parameter(torch.zeros(1))

    def sample(self, obs, n_samples=None, n_steps=None, generator=None):
        b = len(obs["state"])
        noise = 0.02 * torch.randn(b, n_samples, 2, generator=generator)
        centre = (
            torch.where(torch.arange(n_samples) % 2 == 0, -0.3, 0.3)
            if self.two
            else torch.full((n_samples,), 0.1)
        )
        return noise + torch.stack([centre, torch.zeros(n_samples)], dim=-1)[None]


def test_a_flow_agent_is_read_by_its_samples():
    bev, state = (v.numpy() for v in _obs(3).values())
    agent = Agent("flow", build_network("flow", TINY), TINY, torch.zeros(5, 2))
    agent.network = _Bimodal(two=True)
    r = read_states(agent, bev.astype(np.uint8), state)
    assert r["two_sided"].all() and (r["valleys"] == 2).all()
    assert np.allclose(r["left_mass"], 0.5) and r["samples"].shape == (3, READ_SAMPLES)
    assert r["profile"].shape == (3, STEER_GRID) and "label_energy" not in r
    agent.network = _Bimodal(two=False)
    r = read_states(agent, bev.astype(np.uint8), state)
    assert not r["two_sided"].any() and (r["valleys"] == 1).all() and (r["left_mass"] == 0).all()
    with pytest.raises(ValueError, match="agent must be a flow agent"):
        read_flow_states(Agent("bc", build_network("bc", TINY), TINY, torch.zeros(5, 2)), bev, state, [0.0])


def test_sample_profile_and_left_share():
    s = symmetric_axis(161, torch.float64).numpy()
    p = sample_profile(s, np.array([-0.3] * 10 + [0.3] * 10))
    assert p.min() == 0 and np.isfinite(p).all() and p[80] > 3  # a barrier at straight
    assert left_share(np.array([-1.0, 0.0, 1.0, 2.0])) == pytest.approx(0.375)
    with pytest.raises(ValueError, match="bandwidth"):
        sample_profile(s, np.zeros(3), bandwidth=0)
    with pytest.raises(ValueError, match="samples"):
        sample_profile(s, np.zeros(0))


# ---------------------------------------------------------------- adding methods to a study
def test_methods_to_add_are_checked_before_any_work(tiny_replication, tmp_path, capsys):
    assert parse_methods(" flow, da-ibc-rnce ") == ("flow", "da-ibc-rnce")
    for bad in ("", "flow,flow", "diffusion"):
        with pytest.raises(ValueError, match="methods must name"):
            parse_methods(bad)
    with pytest.raises(ValueError, match="does not train"):
        check_methods(("flow", "ibc"), TWO_ANSWERS)
    assert folder_preset(tiny_replication) == TINY
    assert replication_finished(tiny_replication, TINY)
    assert not replication_finished(tmp_path, TINY)
    out = tmp_path / "study"
    assert cli.main(["two-answers", "--out", str(out), "--methods", "flow,bc"]) == 2
    assert "does not train" in capsys.readouterr().err and not out.exists()


def _digest(folder):
    """Every file under ``folder``: its SHA-256 (as the shared replication's check in tests/conftest.py)."""
    import hashlib

    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def _cheap_states(folder):
    """Stand-ins for the held-out forks and the town02 stem approaches: a few states of the tiny preset's
    demonstrations (the real ones drive the expert for minutes), with the keys ``analyse`` reads."""
    from ibc_tutorial.driving.dataset import DemoDataset, DemoLog

    data = DemoDataset(DemoLog.load(folder / "data" / "town01.npz"), TINY.bev_size, light_encoding="flag")
    obs, actions = data.batch(torch.arange(0, 12))
    bev, state = obs["bev"].numpy().astype(np.uint8), obs["state"].numpy()
    labels = np.stack([actions.numpy(), actions.numpy()], axis=1)  # (F, 2, 2)
    labels[:, 0, 0], labels[:, 1, 0] = -0.2, 0.2
    forks = {
        "bev": bev[:4],
        "state": state[:4],
        "labels": labels[:4].astype(np.float32),
        "approach": np.arange(4),
        "entry_m": np.full(4, 3.0),
        "gap": np.full(4, 0.4),
    }
    approach = {
        "bev": bev[4:],
        "state": state[4:],
        "pair": np.repeat(np.arange(2), 4),
        "distance_m": np.tile([6.0, 5.0, 4.5, 3.0], 2),
        "read_at": np.tile([6.0, 5.0, 4.5, 3.0], 2),
        "route": ["a", "b"],
        "approach": [1, 2],
    }
    return forks, approach


def test_methods_added_to_a_finished_study_and_analysed(tiny_replication, tmp_path, monkeypatch):
    """End to end at the tiny preset's size: both families trained into a copy of a finished replication
    (its runs, data and results untouched), resumed with nothing left to do, and every method analysed."""
    import json
    import shutil

    from ibc_tutorial.experiments.agents import two_answers
    from ibc_tutorial.experiments.agents.added_methods import add_methods

    folder = tmp_path / "rep"
    shutil.copytree(tiny_replication, folder)
    before = {
        k: v for k, v in _digest(folder).items() if not k.startswith("provenance") and "PROVENANCE" not in k
    }
    record = add_methods(
        folder, ("flow", "da-ibc-rnce"), command="ibc-tutorial two-answers --methods ...", log=None
    )
    after = _digest(folder)
    assert all(after[k] == v for k, v in before.items())  # nothing of the replication changed
    assert record["methods"] == ["flow", "da-ibc-rnce"] and set(record["results"]["table"]) >= {
        "flow",
        "da-ibc-rnce",
    }
    assert record["invocations"][0]["runs_done"] == ["flow/seed0", "da-ibc-rnce/seed0"]
    for m in ("flow", "da-ibc-rnce"):
        ev = json.loads((folder / "runs" / m / "seed0" / "final_eval.json").read_text())
        assert (
            ev["method"] == m
            and ev["train_seconds"] > 0
            and not (folder / "runs" / m / "seed0" / "last.pt").exists()
        )
    prov = json.loads((folder / "provenance.json").read_text())
    assert any("methods added (flow, da-ibc-rnce" in n for n in prov["notes"])
    assert "methods added" in (folder / "PROVENANCE.md").read_text()
    runs_before = _digest(folder / "runs")
    again = add_methods(folder, "flow,da-ibc-rnce", log=None)  # resumed: nothing left to train
    assert _digest(folder / "runs") == runs_before and len(again["invocations"]) == 2
    with pytest.raises(ValueError, match="does not train"):
        add_methods(folder, ("ibc",), log=None)

    forks, approach = _cheap_states(folder)
    monkeypatch.setattr(two_answers, "heldout_forks", lambda preset: forks)
    monkeypatch.setattr(two_answers, "stem_approach_states", lambda preset: approach)
    summary = two_answers.analyse(folder, tmp_path / "analysis", log=None)
    methods = summary["study"]["methods"]
    assert set(methods) == {"bc", "ibc", "da-ibc", "flow", "da-ibc-rnce"}
    cost = {m: methods[m]["network_evaluations_per_decision"]["head"] for m in methods}
    assert cost["flow"] == TINY.flow_samples * TINY.flow_steps and cost["da-ibc-rnce"] == TINY.dfo_samples * 2
    assert all(methods[m]["train_seconds"]["median"] > 0 for m in methods)
    flow = summary["study"]["agents"]["flow-seed0"]
    assert (
        flow["forks"] == 4 and 0 <= flow["fork_two_valleys"] <= 4 and "fork_label_energy_median" not in flow
    )
    assert "fork_label_energy_median" in summary["study"]["agents"]["da-ibc-rnce-seed0"]
    readings = np.load(tmp_path / "analysis" / "readings.npz")
    assert readings["flow-seed0/forks/samples"].shape == (4, READ_SAMPLES)
    assert summary["design"]["gap"] is None  # the tiny demonstrations hold no stem twins
