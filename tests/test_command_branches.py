"""CIL's branched network (``Preset.command_branches``) and the held-out town02 routes (chapter 11)."""

import dataclasses
import json

import numpy as np
import pytest
import torch

from ibc_tutorial.driving.route_following import (
    ROUTE_TOWN,
    heldout_routes,
    route_crossings,
    route_length,
)
from ibc_tutorial.driving.towns import get_town
from ibc_tutorial.experiments.agents.agent import Agent, architecture, build_network
from ibc_tutorial.experiments.agents.checkpoints import load_agent, save_checkpoint
from ibc_tutorial.experiments.agents.presets import TINY, Preset, with_overrides
from ibc_tutorial.policies.encoders import BEVStateEncoder

BRANCHED = dataclasses.replace(TINY, commands=True, command_branches=True)


def _obs(commands):
    torch.manual_seed(1)
    b = len(commands)
    return {
        "bev": (torch.rand(b, 5, 32, 32) > 0.5).float(),
        "state": torch.rand(b, 3),
        "command": torch.tensor(commands),
    }


def test_each_command_goes_through_its_own_branch_layer_computed_by_hand():
    torch.manual_seed(0)
    enc = BEVStateEncoder(32, (4, 8), 16, n_commands=4, command_branches=True)
    obs = _obs([0, 1, 2, 3, 2])
    z = enc(obs)  # (5, 32)
    assert z.shape == (5, 32) and enc.embed_dim == 32
    st = obs["state"] * torch.tensor([0.1, 1.0, 1.0])
    st = torch.cat([st, torch.nn.functional.one_hot(obs["command"], 4).float()], dim=1)
    joint = torch.cat([enc.cnn(obs["bev"]), enc.state_mlp(st)], dim=1)  # (5, 32)
    for i, c in enumerate(obs["command"].tolist()):
        w, b = enc.branches[c].weight, enc.branches[c].bias
        assert torch.allclose(z[i], torch.relu(w @ joint[i] + b), atol=1e-6)


def test_gradients_reach_only_the_branches_used():
    torch.manual_seed(0)
    enc = BEVStateEncoder(32, (4, 8), 16, n_commands=4, command_branches=True)
    enc(_obs([1, 3, 1])).sum().backward()
    used = [
        enc.branches[k].weight.grad is not None and enc.branches[k].weight.grad.abs().sum() > 0
        for k in range(4)
    ]
    assert used == [False, True, False, True]


def test_branches_are_recorded_saved_and_loaded(tmp_path):
    for method in ("bc", "ibc", "da-ibc"):
        arch = architecture(method, BRANCHED)
        assert arch["command_branches"] is True and arch["commands"] == 4
        assert "command_branches" not in architecture(method, dataclasses.replace(TINY, commands=True))
        torch.manual_seed(0)
        agent = Agent(method, build_network(method, BRANCHED), BRANCHED, torch.rand(20, 2) * 2 - 1)
        path = tmp_path / f"{method}.pt"
        save_checkpoint(path, agent, data_sha256="0" * 64, epoch=1, seed=0)
        loaded, ckpt = load_agent(path)
        assert loaded.network.encoder.command_branches and len(loaded.network.encoder.branches) == 4
        obs = _obs([0, 2, 3])
        assert torch.equal(agent.network.encoder(obs), loaded.network.encoder(obs))


def test_branch_layers_add_four_joint_layers_of_parameters():
    plain = build_network("da-ibc", dataclasses.replace(TINY, commands=True))
    branched = build_network("da-ibc", BRANCHED)
    n = sum(p.numel() for p in branched.parameters()) - sum(p.numel() for p in plain.parameters())
    e = plain.encoder.embed_dim
    assert n == 4 * (e * e + e)


def test_refusals_name_the_argument():
    with pytest.raises(ValueError, match="command_branches needs n_commands"):
        BEVStateEncoder(32, (4, 8), 16, n_commands=0, command_branches=True)
    with pytest.raises(ValueError, match="command_branches must be True or False"):
        BEVStateEncoder(32, (4, 8), 16, n_commands=4, command_branches="yes")
    with pytest.raises(ValueError, match="command_branches=True needs commands=True"):
        dataclasses.replace(TINY, command_branches=True)
    with pytest.raises(ValueError, match="command_branches must be True or False"):
        dataclasses.replace(TINY, commands=True, command_branches=1)
    assert with_overrides(
        dataclasses.replace(TINY, commands=True), ["command_branches=true"]
    ).command_branches
    assert Preset.from_dict({"name": "old"}).command_branches is False  # stored before the field existed


def test_heldout_routes_are_drawn_from_their_seed_and_are_legal():
    a, b = heldout_routes(71000, 5), heldout_routes(71000, 5)
    assert a == b and heldout_routes(71001, 5) != a
    assert [n for n, _ in a] == [f"h71000-{k}" for k in range(5)]
    town = get_town(ROUTE_TOWN)
    for _, route in a:
        assert town.lanes[route.start_lane].kind == "road"
        crossings = route_crossings(route)
        assert len(crossings) == len(route.turns) == 6
        assert [t for _, t in crossings] == list(route.turns)
        for ap, turn in crossings:
            assert turn in town.approaches[ap].exits
        assert route_length(route) > 100.0
    # the first of 5 and of 8 are the same routes: each is drawn from (seed, k)
    assert heldout_routes(71000, 8)[:5] == a
    for bad in (-1, 1.5, "7"):
        with pytest.raises(ValueError, match="seed"):
            heldout_routes(bad)
    with pytest.raises(ValueError, match="n must"):
        heldout_routes(0, 0)


def _folder_with_one_bc_agent(folder, preset, seed):
    """A replication-like folder holding one untrained BC agent, ``runs/bc/seed0/final.pt``."""
    (folder / "runs" / "bc" / "seed0").mkdir(parents=True)
    torch.manual_seed(0)
    agent = Agent("bc", build_network("bc", preset), preset, torch.rand(20, 2) * 2 - 1)
    save_checkpoint(
        folder / "runs" / "bc" / "seed0" / "final.pt", agent, data_sha256="0" * 64, epoch=1, seed=seed
    )
    return folder


def test_route_drives_on_heldout_routes_record_their_protocol(tmp_path):
    from ibc_tutorial.experiments.agents.route_study import load_route_drives, run_route_drives

    folder = _folder_with_one_bc_agent(tmp_path / "cmd", BRANCHED, seed=0)
    out = tmp_path / "out"
    run_route_drives(folder, out, log=None, max_steps=3, heldout_seed=5, heldout_count=2, only=["bc-seed0"])
    rows = load_route_drives(out)["bc-seed0"]["episodes"]
    assert [r["route"] for r in rows] == ["h5-0", "h5-1"]
    prov = json.loads((out / "provenance.json").read_text())
    assert prov["protocol"]["heldout_seed"] == 5 and prov["protocol"]["heldout_count"] == 2
    with pytest.raises(ValueError, match="another protocol"):
        run_route_drives(folder, out, log=None, max_steps=3, heldout_seed=6, heldout_count=2)
    assert np.isfinite([r["completion"] for r in rows]).all()


def test_start_drives_resume_and_record_their_protocol(tmp_path):
    from ibc_tutorial.experiments.agents.evaluate import episode_rows, evaluate_agent
    from ibc_tutorial.experiments.agents.start_study import load_start_drives, run_start_drives

    folder = _folder_with_one_bc_agent(tmp_path / "rep", TINY, seed=3)
    out = tmp_path / "starts"
    done = run_start_drives(folder, out, seed=500, episodes=2, steps=5, log=None)
    assert done == ["bc-seed0", "expert"]
    files = load_start_drives(out)
    rows = files["bc-seed0"]["episodes"]
    assert [r["seed"] for r in rows] == [500, 501] and files["bc-seed0"]["policy_seed"] == 3
    # the same rows as evaluate_agent gives from those starts with the agent's training seed
    loaded, _ = load_agent(folder / "runs" / "bc" / "seed0" / "final.pt")
    assert rows == episode_rows(evaluate_agent(loaded, "town02", 2, 5, seed=500, policy_seed=3))
    assert [r["seed"] for r in files["expert"]["episodes"]] == [500, 501]
    assert run_start_drives(folder, out, seed=500, episodes=2, steps=5, log=None) == []  # resumed: nothing
    prov = json.loads((out / "provenance.json").read_text())
    assert prov["protocol"] == {"seed": 500, "episodes": 2, "steps": 5, "folder": "rep"}
    assert len(prov["invocations"]) == 2
    with pytest.raises(ValueError, match="another protocol"):
        run_start_drives(folder, out, seed=600, episodes=2, steps=5, log=None)
    with pytest.raises(ValueError, match="only must name drivers"):
        run_start_drives(folder, tmp_path / "x", seed=1, only=["ibc-seed9"], log=None)
    with pytest.raises(ValueError, match="seed"):
        run_start_drives(folder, tmp_path / "y", seed=-1, log=None)
