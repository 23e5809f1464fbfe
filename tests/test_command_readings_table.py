"""Chapter 11's readings under each command: which readings are taken, and the table printed from them."""

from ibc_tutorial.experiments.agents import command_readings
from ibc_tutorial.experiments.agents.command_readings import format_readings_table, readings_by_command


def test_readings_by_command_reads_each_command_for_told_agents_and_none_for_routeless(monkeypatch):
    calls = []
    monkeypatch.setattr(
        command_readings, "reading", lambda a, o, c: calls.append((a, c)) or {"agent": a, "c": c}
    )
    states = [({"bev": 0, "state": 1, "extra": 2}, {}), ({"bev": 3, "state": 4}, {})]
    got = readings_by_command({("ibc", 0): "told", ("ibc", 0, "routeless"): "free"}, states)
    assert len(got) == 2 * 3 + 2 * 1
    assert got["ibc", 0, 1, "right"] == {"agent": "told", "c": "right"}
    assert got["ibc", 0, 0, "none"] == {"agent": "free", "c": None}
    assert ("free", "left") not in calls


def test_format_readings_table_counts_two_valleys_and_averages_left_mass():
    readings = {
        ("ibc", s, 0, c): {"valleys": 2 if (s, c) == (1, "left") else 1, "left_mass": 0.2 * (s + 1)}
        for s in (0, 1)
        for c in ("left", "right", "follow", "none")
    }
    lines = format_readings_table(readings, ("ibc",), (0, 1), (7.5,), {"ibc": "IBC"}).splitlines()
    assert len(lines) == 2 and lines[0].split()[:2] == ["method", "state"]
    assert lines[1].split()[:4] == [
        "IBC",
        "7.5m",
        "1/2",
        "two;",
    ]  # the distance asked for, as given
    assert lines[1].count("left 0.30") == 4 and lines[1].count("0/2 two") == 3


def test_format_beta_table_averages_the_means_and_lists_the_shapes():
    from ibc_tutorial.experiments.agents.command_readings import format_beta_table

    readings = {
        ("bc", s, 0, c): {"mean": 0.1 * s, "shape": "U-shaped" if (s, c) == (1, "left") else "single-peaked"}
        for s in (0, 1)
        for c in ("left", "right", "follow", "none")
    }
    lines = format_beta_table(readings, (0, 1), (5.0,)).splitlines()
    assert len(lines) == 2 and "none (routeless)" in lines[0]
    assert lines[1].count("mean +0.05") == 4
    assert "U-shaped/single-peaked" in lines[1] and lines[1].count("single-peaked") == 4


def test_load_command_agents_pairs_each_command_agent_with_its_routeless_twin(tmp_path):
    import dataclasses

    import torch

    from ibc_tutorial.experiments.agents.agent import Agent, build_network
    from ibc_tutorial.experiments.agents.checkpoints import save_checkpoint
    from ibc_tutorial.experiments.agents.command_readings import load_command_agents
    from ibc_tutorial.experiments.agents.presets import TINY

    for folder, preset in (("cmd", dataclasses.replace(TINY, commands=True)), ("free", TINY)):
        agent = Agent("bc", build_network("bc", preset), preset, torch.rand(10, 2) * 2 - 1)
        save_checkpoint(
            tmp_path / folder / "runs/bc/seed3/final.pt", agent, data_sha256="0" * 64, epoch=1, seed=3
        )
    agents = load_command_agents(tmp_path / "cmd", tmp_path / "free", ("bc",), (3,))
    assert set(agents) == {("bc", 3), ("bc", 3, "routeless")}
    assert agents["bc", 3].takes_command and not agents["bc", 3, "routeless"].takes_command
