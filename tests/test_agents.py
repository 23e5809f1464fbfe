"""The Fig. 2 network of the DA-IBC paper and the agents built on it (ibc_tutorial.experiments.agents.agent,
.presets)."""

import dataclasses

import numpy as np
import pytest
import torch

from ibc_tutorial.experiments.agents.agent import (
    Agent,
    architecture,
    build_network,
    network_from_architecture,
    to_tensor_obs,
)
from ibc_tutorial.experiments.agents.presets import (
    LAPTOP,
    PAPER,
    PRESETS,
    TINY,
    Preset,
    differences,
    get_preset,
)
from ibc_tutorial.policies import BetaPolicy, BEVStateEncoder, EnergyModel, ObservationEncoder


def _obs(b, size, seed=0):
    g = torch.Generator().manual_seed(seed)
    return {
        "bev": torch.randint(0, 2, (b, 5, size, size), generator=g).float(),
        "state": torch.rand(b, 3, generator=g) * torch.tensor([15.0, 2.0, 2.0])
        - torch.tensor([0.0, 1.0, 1.0]),
    }


def test_encoder_is_an_observation_encoder_with_two_256d_branches():
    enc = BEVStateEncoder(bev_size=64, channels=(8, 16), embed_dim=256)
    assert isinstance(enc, ObservationEncoder)
    z = enc(_obs(3, 64))
    assert z.shape == (3, 512) and enc.embed_dim == 512 and enc.batch_size(_obs(3, 64)) == 3
    # the second half depends on the state only, the first on the BEV only
    o1, o2 = _obs(3, 64, 0), _obs(3, 64, 1)
    mixed = {"bev": o1["bev"], "state": o2["state"]}
    assert torch.allclose(enc(mixed)[:, :256], enc(o1)[:, :256])
    assert torch.allclose(enc(mixed)[:, 256:], enc(o2)[:, 256:])


def test_encoder_rejects_bad_observations():
    enc = BEVStateEncoder(bev_size=32, channels=(4,), embed_dim=8)
    with pytest.raises(ValueError, match="obs must be a dict"):
        enc(torch.zeros(2, 5, 32, 32))
    with pytest.raises(ValueError, match=r"obs\['bev'\]"):
        enc(_obs(2, 64))
    with pytest.raises(ValueError, match=r"obs\['state'\]"):
        enc({"bev": _obs(2, 32)["bev"], "state": torch.zeros(3, 3)})


def test_build_network_heads():
    assert isinstance(build_network("bc", TINY), BetaPolicy)
    for m in ("ibc", "da-ibc"):
        net = build_network(m, TINY)
        assert isinstance(net, EnergyModel) and net.hidden == TINY.head_hidden
        e = net.energy(_obs(2, TINY.bev_size), torch.rand(7, 2) * 2 - 1)
        assert e.shape == (2, 7)
    with pytest.raises(ValueError, match="method"):
        build_network("gail", TINY)


def test_agents_act_in_the_box_and_reproducibly():
    actions = torch.rand(50, 2) * 2 - 1
    obs = _obs(4, TINY.bev_size)
    for m in ("bc", "ibc", "da-ibc"):
        torch.manual_seed(0)
        agent = Agent(m, build_network(m, TINY), TINY, actions)
        a1 = agent.act(obs, torch.Generator().manual_seed(3))
        a2 = agent.act({k: v.numpy() for k, v in obs.items()}, torch.Generator().manual_seed(3))
        assert a1.shape == (4, 2) and (a1.abs() <= 1).all()
        assert torch.equal(a1, a2)


def test_ibc_and_da_ibc_run_algorithm_1_as_the_paper_defines_them():
    actions = torch.rand(50, 2) * 2 - 1
    ibc = Agent("ibc", build_network("ibc", TINY), TINY, actions)
    da = Agent("da-ibc", build_network("da-ibc", TINY), TINY, actions)
    assert ibc.dfo_config.init == "uniform" and ibc.dfo_config.select == "argmax"
    assert da.dfo_config.init == "inverse-kde" and da.dfo_config.select == "sample"
    assert (da.dfo_config.n_samples, da.dfo_config.n_iters) == (TINY.dfo_samples, TINY.dfo_iters)
    assert Agent("bc", build_network("bc", TINY), TINY, actions).dfo_config is None
    # DA-IBC's initial weights are w ∝ 1 / ĝ (eq. 4 with h = 0.2), computed independently here
    d = ((actions[:, None, :] - actions[None, :, :]) / TINY.kde_bandwidth).pow(2).sum(-1)
    g = torch.exp(-0.5 * d).mean(1)
    w = (1 / g) / (1 / g).sum()
    assert torch.allclose(da.init_weights, w, rtol=1e-4)


def test_energy_grid_matches_the_energy():
    agent = Agent("da-ibc", build_network("da-ibc", TINY), TINY, torch.rand(20, 2) * 2 - 1)
    obs = _obs(1, TINY.bev_size)
    steer, accel, e = agent.energy_grid(obs, 5)
    assert e.shape == (5, 5)
    assert steer[2] == 0 and np.array_equal(steer, -steer[::-1])  # straight is straight on every CPU
    ref = agent.network.energy(
        obs, torch.tensor([[steer[1], accel[3]]])
    )  # row = acceleration, column = steer
    assert abs(float(ref[0, 0].detach()) - e[3, 1]) < 1e-5
    with pytest.raises(ValueError, match="energy agent"):
        Agent("bc", build_network("bc", TINY), TINY, torch.zeros(3, 2)).energy_grid(obs)


def test_presets():
    assert set(PRESETS) == {"paper", "laptop", "ten-routes", "two-answers", "tiny"}
    assert (PAPER.lr, PAPER.epochs, PAPER.batch_size, PAPER.n_neg) == (1e-5, 400, 128, 1024)
    assert (PAPER.dfo_samples, PAPER.dfo_iters, PAPER.dfo_sigma_init, PAPER.dfo_shrink) == (
        16384,
        5,
        0.5,
        0.5,
    )
    assert (PAPER.kde_bandwidth, PAPER.bev_size, PAPER.embed_dim) == (0.2, 192, 256)
    assert LAPTOP.bev_size == 64 and "bev_size" in differences(PAPER, LAPTOP)
    assert Preset.from_dict(LAPTOP.to_dict()) == LAPTOP
    assert get_preset("tiny") is TINY
    # the base of chapter 08's ablations: the paper's 10 routes, 8 epochs, five agents
    previous = get_preset("ten-routes")
    assert differences(LAPTOP, previous) == {
        "routes": (20, 10),
        "epochs": (4, 8),
        "seeds": ([0, 1, 2, 3, 4, 5, 6], [0, 1, 2, 3, 4]),
    }
    assert LAPTOP.routes * LAPTOP.epochs == previous.routes * previous.epochs  # the same gradient steps
    # chapter 12's designed data: the laptop preset with stem twins, a turn begun 2 m before the entry
    two = get_preset("two-answers")
    assert differences(LAPTOP, two) == {
        "routes": (20, 6),
        "turn_hold_m": (0.0, 2.0),
        "stem_twins": (0, 20),
        "epochs": (4, 3),
        "eval_every": (2, 3),
        "seeds": ([0, 1, 2, 3, 4, 5, 6], [0, 1, 2, 3, 4]),
    }
    assert two.collect_config().stem_twins == 20 and two.collect_config().turn_hold_m == 2.0
    with pytest.raises(ValueError, match="preset"):
        get_preset("huge")
    with pytest.raises(ValueError, match="epochs"):
        dataclasses.replace(TINY, epochs=0)


def test_to_tensor_obs_from_numpy():
    o = to_tensor_obs({"bev": np.zeros((2, 5, 8, 8), np.float32), "state": np.zeros((2, 3), np.float64)})
    assert o["bev"].dtype == torch.float32 and o["state"].dtype == torch.float32


def test_the_network_is_built_from_its_architecture():
    for m in ("bc", "ibc", "da-ibc"):
        arch = architecture(m, LAPTOP)
        torch.manual_seed(0)
        a = build_network(m, LAPTOP)
        torch.manual_seed(0)
        b = network_from_architecture(arch)
        assert type(a) is type(b) and all(
            torch.equal(x, y) for x, y in zip(a.state_dict().values(), b.state_dict().values(), strict=True)
        )
        assert arch["network"] == type(a).__name__ and arch["encoder"] == type(a.encoder).__name__
        assert list(a.encoder.channels) == arch["cnn_channels"] and a.encoder.bev_size == arch["bev_size"]
    with pytest.raises(ValueError, match="arch"):
        network_from_architecture({"network": "MDNPolicy", "encoder": "BEVStateEncoder"})


def test_ended_crossing_energies_replay_the_episode_and_refuse_what_they_cannot_reproduce():
    from ibc_tutorial.driving.rollout import RolloutRecording
    from ibc_tutorial.experiments.agents.crossings import ended_crossing_energies
    from ibc_tutorial.experiments.agents.evaluate import episode_rows, evaluate_agent

    torch.manual_seed(0)
    actions = torch.tensor([[0.6, 1.0]] * 100 + [[0.7, 0.9]] * 100)  # DFO starts at hard right turns: crashes
    agent = Agent("da-ibc", build_network("da-ibc", TINY), TINY, actions)
    results = evaluate_agent(
        agent,
        "town02",
        episodes=2,
        steps=60,
        seed=1000,
        policy_seed=0,
        record=RolloutRecording(xy=False, steps=True, obs=True),
    )
    assert all(r.terminated for r in results)
    rows = episode_rows(results)
    end = rows[0][
        "steps"
    ]  # pretend episode 0 ended inside a crossing of its last 3 states; episode 1 finished one
    rows[0]["junction_crossings"] = [{"finished": False, "start": end - 3, "stop": end + 1}]
    rows[1]["junction_crossings"] = [{"finished": True, "start": 0, "stop": 4}]
    steer = ended_crossing_energies(agent, "town02", rows, steps=60, seed=1000, policy_seed=0, n_grid=9)
    assert steer.shape == (9,) and steer[0] == -1.0 and steer[-1] == 1.0
    profiles = np.array(rows[0]["junction_crossings"][0]["energy_by_steer"])  # (3 states with an action, 9)
    assert profiles.shape == (3, 9) and (profiles.min(axis=1) == 0).all()
    tr = results[0].trace
    _, _, e = agent.energy_grid({"bev": tr["bev"][end - 1][None], "state": tr["state"][end - 1][None]}, 9)
    np.testing.assert_allclose(
        profiles[-1], e.min(axis=0) - e.min(), atol=2e-3
    )  # the last state's, as recorded
    ended = rows[0]["junction_crossings"][0]  # read as every reading of an energy at a state
    assert len(ended["valleys_by_state"]) == len(ended["argmin_steer_by_state"]) == 3
    for k, p in enumerate(profiles):
        assert ended["valleys_by_state"][k] >= 1
        j = int(np.argmin(np.abs(steer - ended["argmin_steer_by_state"][k])))
        assert p[j] == 0  # the preferred steering: where the profile is 0
    assert "energy_by_steer" not in rows[1]["junction_crossings"][0]
    rows[0]["distance_m"] += 1.0  # not what a replay gives
    with pytest.raises(ValueError, match="the replay of episode 0 ended"):
        ended_crossing_energies(agent, "town02", rows, steps=60, seed=1000, policy_seed=0, n_grid=9)
    bc = Agent("bc", build_network("bc", TINY), TINY, actions)
    with pytest.raises(ValueError, match="needs an energy agent"):
        ended_crossing_energies(bc, "town02", rows, steps=60, seed=1000, policy_seed=0)
    with pytest.raises(ValueError, match="n_grid must be"):
        ended_crossing_energies(agent, "town02", rows, steps=60, seed=1000, policy_seed=0, n_grid=1)
    rows[0]["termination"] = ""
    assert ended_crossing_energies(agent, "town02", rows, steps=60, seed=1000, policy_seed=0) is None


def test_evaluate_agent_refuses_a_recording_that_is_not_a_rollout_recording():
    from ibc_tutorial.experiments.agents.evaluate import evaluate_agent

    with pytest.raises(ValueError, match="record must be a RolloutRecording, got dict"):
        evaluate_agent("expert", episodes=1, steps=5, record={"xy": True})


def test_steering_profile_is_the_lowest_energy_over_acceleration_from_zero():
    from ibc_tutorial.driving.energy_profiles import steering_profile
    from ibc_tutorial.optimizers.grid import steer_accel_grid

    e = np.array([[3.0, 1.0, 4.0], [2.0, 5.0, 0.5]])  # (accel, steer)
    assert np.array_equal(steering_profile(e), np.array([1.5, 0.5, 0.0]))
    assert steering_profile(np.stack([e, e + 7.0])).shape == (2, 3)  # (B, accel, steer) -> (B, steer)
    with pytest.raises(ValueError, match="energy must have an acceleration and a steering axis"):
        steering_profile(np.zeros(3))
    v, grid = steer_accel_grid(3)
    assert v.tolist() == [-1.0, 0.0, 1.0] and grid.shape == (9, 2)
    assert grid[:3, 1].tolist() == [-1.0] * 3 and grid[:3, 0].tolist() == [-1.0, 0.0, 1.0]  # accel slowest
