"""Agents taking a route command (chapter 11): the network, the checkpoints' refusals, replicate."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from ibc_tutorial.experiments.agents.agent import Agent, architecture, build_network
from ibc_tutorial.experiments.agents.checkpoints import load_agent, save_checkpoint
from ibc_tutorial.experiments.agents.presets import TINY, Preset
from ibc_tutorial.experiments.agents.route_driving import evaluate_on_routes

SHIPPED = Path(__file__).parents[1] / "book" / "results" / "laptop" / "runs" / "da-ibc" / "seed0" / "final.pt"
CMD = dataclasses.replace(TINY, commands=True)


def _obs(b=3, command=True, size=32):
    obs = {"bev": np.zeros((b, 5, size, size), np.float32), "state": np.zeros((b, 3), np.float32)}
    if command:
        obs["command"] = np.array([0, 1, 3][:b], dtype=np.int64)
    return obs


def _agent(method, preset):
    torch.manual_seed(0)
    return Agent(method, build_network(method, preset), preset, torch.rand(20, 2) * 2 - 1)


@pytest.mark.parametrize("method", ["bc", "ibc", "da-ibc"])
def test_the_command_changes_the_output_through_the_state_mlp(method):
    agent = _agent(method, CMD)
    assert architecture(method, CMD)["commands"] == 4 and "commands" not in architecture(method, TINY)
    assert agent.network.encoder.state_mlp[0].in_features == 3 + 4
    obs = {k: torch.from_numpy(v) for k, v in _obs().items()}
    z = agent.network.encoder(obs)
    obs2 = dict(obs, command=torch.tensor([2, 2, 2]))
    assert not torch.allclose(z, agent.network.encoder(obs2))
    assert torch.equal(
        z[:, : agent.network.encoder.branch_dim], agent.network.encoder(obs2)[:, :16]
    )  # BEV part
    assert agent.act(_obs(), torch.Generator().manual_seed(0)).shape == (3, 2)


@pytest.mark.parametrize("method", ["bc", "da-ibc"])
def test_checkpoints_refuse_the_wrong_input(tmp_path, method):
    for preset, name in ((CMD, "cmd.pt"), (TINY, "plain.pt")):
        save_checkpoint(tmp_path / name, _agent(method, preset), data_sha256="0" * 64, epoch=1, seed=0)
    cmd_agent, ckpt = load_agent(tmp_path / "cmd.pt")
    assert cmd_agent.takes_command and ckpt["architecture"]["commands"] == 4
    with pytest.raises(ValueError, match="takes a route command .*must hold 'command'"):
        cmd_agent.act(_obs(command=False))
    plain, _ = load_agent(tmp_path / "plain.pt")
    assert not plain.takes_command
    with pytest.raises(ValueError, match="is routeless .*must not hold 'command'"):
        plain.act(_obs(command=True))
    # driven on a route: a command agent without commands, a routeless one with them
    with pytest.raises(ValueError, match="takes a route command"):
        evaluate_on_routes(cmd_agent, ["r4"], commands=False, max_steps=2)
    with pytest.raises(ValueError, match="is routeless"):
        evaluate_on_routes(plain, ["r4"], commands=True, max_steps=2)
    rows = evaluate_on_routes(plain, ["r4"], max_steps=3)  # routeless: no command, as trained
    assert rows[0]["steps"] == 3 and rows[0]["end"] in ("timeout", "off_road", "building")


@pytest.mark.skipif(not SHIPPED.exists(), reason="the shipped laptop agents")
def test_shipped_checkpoints_load_as_routeless():
    agent, ckpt = load_agent(SHIPPED)
    assert not agent.takes_command and "commands" not in ckpt["architecture"]
    assert Preset.from_dict(ckpt["preset"]).commands is False


def test_replicate_with_commands_end_to_end(tmp_path, capsys):
    from ibc_tutorial.cli import main

    out = tmp_path / "cmd"
    argv = ["replicate", "--preset", "tiny", "--commands", "--out", str(out), "--set", "route_max_steps=8"]
    assert main(argv) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["preset"]["commands"] is True and res["complete"] is True
    assert set(res["table"]) == {"bc", "ibc", "da-ibc", "expert"}
    for method in ("bc", "ibc", "da-ibc", "expert"):
        d = out / "runs" / method / ("seed0" if method != "expert" else "")
        ev = json.loads((d / "final_eval.json").read_text())
        assert [r["route"] for r in ev["episodes"]] == ["r1", "r2", "r3", "r4", "r5", "r6"]
        assert all(r["steps"] <= 8 for r in ev["episodes"])
        assert {"completion_mean", "driving_score_mean", "junction_success", "ends"} <= set(ev["summary"])
    agent, _ = load_agent(out / "runs" / "da-ibc" / "seed0" / "final.pt")
    assert agent.takes_command
    assert json.loads((out / "provenance.json").read_text())["complete"] is True
    assert main(argv) == 0  # resumed: nothing left to do
    # the same folder without --commands: another preset, refused before any work
    assert main(["replicate", "--preset", "tiny", "--out", str(out), "--set", "route_max_steps=8"]) == 2
    assert "differs in commands" in capsys.readouterr().err


def test_route_drives_of_a_folder_resume_and_keep_each_agents_input(tmp_path, capsys):
    from ibc_tutorial.cli import main
    from ibc_tutorial.experiments.agents.route_study import load_route_drives, run_route_drives

    folder = tmp_path / "rep"
    for method, preset in (("bc", TINY), ("da-ibc", CMD)):  # a routeless agent and a command agent
        d = folder / "runs" / method / "seed0"
        d.mkdir(parents=True)
        save_checkpoint(d / "final.pt", _agent(method, preset), data_sha256="0" * 64, epoch=1, seed=0)
    out = tmp_path / "drives"
    done = run_route_drives(folder, out, only=["bc-seed0", "da-ibc-seed0"], log=None, max_steps=4)
    assert done == ["bc-seed0", "da-ibc-seed0"]
    drives = load_route_drives(out)
    assert set(drives) == {"bc-seed0", "da-ibc-seed0"}
    assert drives["bc-seed0"]["commands"] is False and drives["da-ibc-seed0"]["commands"] is True
    assert [r["route"] for r in drives["bc-seed0"]["episodes"]] == ["r1", "r2", "r3", "r4", "r5", "r6"]
    assert all(r["steps"] <= 4 for d in drives.values() for r in d["episodes"])
    assert run_route_drives(folder, out, log=None, max_steps=4, only=["bc-seed0"]) == []  # resumed
    prov = json.loads((out / "provenance.json").read_text())
    assert len(prov["invocations"]) == 2 and prov["protocol"]["max_steps"] == 4
    with pytest.raises(ValueError, match="another protocol"):
        run_route_drives(folder, out, drives=2, log=None, max_steps=4)
    with pytest.raises(ValueError, match="only must name drivers"):
        run_route_drives(folder, out, only=["ibc-seed9"], log=None)
    assert main(["routes", "--folder", str(tmp_path / "none"), "--out", str(out)]) == 2
    assert "--folder must be a replication folder" in capsys.readouterr().err


@pytest.mark.parametrize("method", ["bc", "da-ibc"])
def test_reading_under_each_command_and_the_refusals(method):
    from ibc_tutorial.experiments.agents.command_readings import reading

    agent = _agent(method, CMD)
    obs = {"bev": np.zeros((5, 32, 32), np.float32), "state": np.array([3.0, 0.0, 0.0], np.float32)}
    left, right = reading(agent, obs, "left", n_grid=21), reading(agent, obs, "right", n_grid=21)
    assert 0.0 <= left["left_mass"] <= 1.0
    if method == "bc":
        assert left["shape"] in ("single-peaked", "U-shaped", "J-shaped", "flat") and -1 <= left["mean"] <= 1
        assert (left["alpha"], left["beta"]) != (
            right["alpha"],
            right["beta"],
        )  # the command reaches the head
    else:
        assert left["profile"].shape == (21,) and left["profile"].min() == 0.0 and left["valleys"] >= 1
        assert not np.allclose(left["profile"], right["profile"])
    with pytest.raises(ValueError, match="takes a route command"):
        reading(agent, obs, None)
    with pytest.raises(ValueError, match="is routeless"):
        reading(_agent(method, TINY), obs, "left")
    with pytest.raises(ValueError, match="one bev"):
        reading(agent, {"bev": obs["bev"][None], "state": obs["state"]}, "left")


def test_reading_counts_straight_as_half_left_on_every_cpu(monkeypatch):
    """torch.linspace(-1, 1, 81)[40] is -1.5e-8 with AVX2 kernels and 0 without: the reading's grid is
    exact (``symmetric_axis``), so the straight value's mass is split, not counted left on one CPU and
    halved on another."""
    from ibc_tutorial.experiments.agents.command_readings import reading

    agent = _agent("da-ibc", CMD)
    grid = np.linspace(-1.0, 1.0, 5)
    e = np.full((5, 5), 10.0)
    e[:, 2] = 0.0  # all the mass at straight
    shifted = grid.copy()
    shifted[2] = -1.5e-8
    monkeypatch.setattr(type(agent), "energy_grid", lambda self, obs, n_per_dim=5: (shifted, grid, e))
    obs = {"bev": np.zeros((5, 32, 32), np.float32), "state": np.zeros(3, np.float32)}
    r = reading(agent, obs, "left", n_grid=5)
    assert r["steer"][2] == 0.0 and abs(r["left_mass"] - 0.5) < 1e-3
