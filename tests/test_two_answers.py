"""Chapter 12's readings (experiments.agents.two_answers): one reading per state, per-agent exits, counts."""

import numpy as np
import pytest
import torch

from ibc_tutorial.driving.energy_profiles import valleys
from ibc_tutorial.experiments.agents.agent import Agent, build_network
from ibc_tutorial.experiments.agents.presets import TINY, TWO_ANSWERS
from ibc_tutorial.experiments.agents.two_answers import (
    STEER_GRID,
    both_sides,
    fig6_fork,
    heldout_forks,
    minority_interval,
    pair_counts,
    read_states,
    stem_exits,
)


def _states(n, size=32, seed=0):
    g = torch.Generator().manual_seed(seed)
    bev = (torch.rand(n, 5, size, size, generator=g) < 0.2).to(torch.uint8).numpy()
    state = torch.rand(n, 3, generator=g).numpy().astype(np.float32)
    return bev, state


class _TwoValleys(torch.nn.Module):
    """A stand-in energy network: E(y) = 4 min((s - 0.3)², (s + 0.3)²) / 0.01, lowest at steering ±0.3."""

    def __init__(self):
        super().__init__()
        self.unused = torch.nn.Parameter(torch.zeros(1))  # where the agent finds its device

    def embed(self, obs):
        return torch.zeros(len(obs["state"]), 1)

    def energy_from_embedding(self, z, actions):
        s = actions[..., 0]
        e = 4 * torch.minimum((s - 0.3) ** 2, (s + 0.3) ** 2) / 0.01  # (M,) or (B, M)
        return e.expand(len(z), *s.shape) if s.dim() == 1 else e


def test_a_two_valley_energy_reads_as_two_valleys_with_half_its_mass_each_side():
    agent = Agent("ibc", build_network("ibc", TINY), TINY, torch.rand(10, 2) * 2 - 1)
    agent.network = _TwoValleys()
    bev, state = _states(3)
    labels = np.array([[[-0.3, 0.0], [0.3, 0.0]]] * 3, dtype=np.float32)
    r = read_states(agent, bev, state, labels)
    assert r["two_sided"].all() and (r["valleys"] == 2).all()
    assert np.allclose(r["left_mass"], 0.5, atol=1e-6)
    assert np.allclose(r["label_energy"], 0.0, atol=1e-4)  # both labels at the bottom of their valleys
    assert r["profile"].shape == (3, STEER_GRID)
    assert both_sides(r["left_mass"]).all()


def test_readings_of_a_trained_shaped_network_and_of_bc():
    actions = torch.rand(30, 2) * 2 - 1
    bev, state = _states(5)
    for method in ("ibc", "da-ibc"):
        agent = Agent(method, build_network(method, TINY), TINY, actions)
        r = read_states(agent, bev, state)
        for k, p in enumerate(r["profile"]):  # the same criterion as the book's valleys
            steer = np.linspace(-1, 1, STEER_GRID)
            assert r["valleys"][k] == len(valleys(steer, p))
        assert ((r["left_mass"] >= 0) & (r["left_mass"] <= 1)).all()
    bc = Agent("bc", build_network("bc", TINY), TINY, actions)
    r = read_states(bc, bev, state)
    assert r["alpha"].shape == (5,) and ((r["mean"] >= -1) & (r["mean"] <= 1)).all()
    with pytest.raises(ValueError, match="bev and state"):
        read_states(bc, bev, state[:2])


def _drive(episodes):
    """A fake recorded drive of town02: each episode a list of (stem approach lane, exit lane) crossings."""
    from ibc_tutorial.driving.towns import get_town

    town = get_town("town02")
    rows, eps = [], []
    for crossings, terminated in episodes:
        lanes = []
        for ap_id, turn in crossings:
            ap = town.approaches[ap_id]
            conn = ap.exits[turn]
            lanes += [ap.lane] * 3 + [conn] * 3 + [town.lanes[conn].successors[0]] * 2
        if terminated:
            ap = town.approaches[crossings[-1][0]]
            lanes += [ap.lane, ap.exits["left"]]
        lanes = np.array(lanes)
        eps.append(
            {"lane": lanes, "pose": np.zeros((len(lanes), 3)), "actions": np.zeros((len(lanes) - 1, 2))}
        )
        rows.append({"termination": "collision" if terminated else ""})
    return {"rows": rows, "episodes": eps, "obs": None}


def test_stem_exits_per_agent_and_the_pooled_minority():
    from ibc_tutorial.driving.stems import stem_approaches

    stem = stem_approaches("town02")[0]
    always_left = stem_exits(_drive([([(stem, "left")] * 3, False), ([(stem, "left")] * 2, True)]))
    assert (always_left["left"], always_left["right"], always_left["both_exits"]) == (5, 0, False)
    assert always_left["stem_ends"] == 1
    mixed = stem_exits(_drive([([(stem, "left"), (stem, "right")], False), ([(stem, "right")] * 2, False)]))
    assert (mixed["left"], mixed["right"], mixed["both_exits"], mixed["stem_ends"]) == (1, 3, True, 0)
    iv = minority_interval([mixed, mixed])
    assert iv.estimate == pytest.approx(0.25) and iv.low <= 0.25 <= iv.high
    assert minority_interval([always_left, always_left]).estimate == 0.0


def test_pair_counts_and_the_fig6_rule():
    r = {"two_sided": np.array([False, True, False, False, False, True])}
    assert pair_counts(r, np.array([0, 0, 1, 1, 2, 2])) == {"pairs": 3, "two_valleys": 2}
    assert fig6_fork({"gap": np.array([0.5, 0.1, 0.3, 0.4])}) == 2  # the lower middle of 0.1 0.3 0.4 0.5


def test_heldout_forks_are_two_answer_states():
    f = heldout_forks(TWO_ANSWERS)
    assert len(f["gap"]) >= 20 and (f["gap"] >= 0.3).all()
    assert (f["labels"][:, 0, 0] < f["labels"][:, 1, 0]).all()  # left label steers left of the right one
    assert f["bev"].shape[1:] == (5, TWO_ANSWERS.bev_size, TWO_ANSWERS.bev_size)


def test_read_profile_is_the_one_reading_of_a_profile():
    from ibc_tutorial.driving.energy_profiles import read_profile
    from ibc_tutorial.optimizers.grid import symmetric_axis

    s = symmetric_axis(161, torch.float64).numpy()
    double = 40 * np.minimum((s - 0.4) ** 2, (s + 0.4) ** 2)  # valleys at ±0.4, 6.4 nats between
    single = 5 * s**2
    r2, r1 = read_profile(s, double, double), read_profile(s, single, single)
    assert r2["two_sided"] and r2["valleys"] == 2 and r2["left_mass"] == pytest.approx(0.5)
    assert not r1["two_sided"] and r1["valleys"] == 1 and r1["argmin_steer"] == 0.0
    shallow = np.minimum(40 * (s - 0.4) ** 2, 40 * (s + 0.4) ** 2 + 3.5)  # the left valley 3.5 nats up
    assert not read_profile(s, shallow, shallow)["two_sided"]
