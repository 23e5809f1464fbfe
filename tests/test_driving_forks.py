"""Stem twins (driving.collect) and forks (driving.forks): replays, forks, label gaps, per-stem counts."""

import numpy as np
import pytest

from ibc_tutorial.driving.collect import CollectConfig, collect, n_episodes
from ibc_tutorial.driving.forks import forks_per_stem, replay, stem_forks
from ibc_tutorial.driving.lights import GREEN
from ibc_tutorial.driving.sim import DrivingSim
from ibc_tutorial.driving.stems import stem_approaches

ROUTES = CollectConfig(routes=2, min_minutes=1.0, max_minutes=1.5, brake_noise=1.0)
TWINS = CollectConfig(
    routes=1, min_minutes=0.1, max_minutes=0.1, brake_noise=1.0, stem_twins=1, turn_hold_m=2.0
)


@pytest.fixture(scope="module")
def route_log():
    return collect(ROUTES, show_progress=False)


@pytest.fixture(scope="module")
def twin_log():
    return collect(TWINS, show_progress=False)


def test_unflipped_replay_is_the_recorded_episode(route_log, twin_log):
    for log, episodes in ((route_log, (0, 1)), (twin_log, (0, 1, 2))):
        for ep in episodes:
            rows = log.episode == ep
            r = replay(log, ep)
            assert np.array_equal(r["action"], log.action[rows])
            assert np.array_equal(r["lane"], log.lane[rows])


def test_twins_cross_every_stem_both_ways_from_one_state(twin_log):
    stems = stem_approaches("town01")
    assert twin_log.n_episodes == n_episodes(TWINS) == 1 + 2 * len(stems)
    forks = stem_forks(twin_log, show_progress=False)
    twins = [f for f in forks if f["twin"]]
    counts = forks_per_stem(twins, "town01")
    assert set(counts) == set(stems)
    assert all(c["left"] >= 1 and c["right"] >= 1 for c in counts.values())
    for f in twins:
        other = f["episode"] + (1 if f["turn"] == "left" else -1)  # its twin is the episode beside it
        a = f["fork_row"]
        b = np.flatnonzero(twin_log.episode == other)[f["fork"]]
        for k in ("pose", "speed", "prev_action", "lights"):  # the same observation at the fork
            assert np.array_equal(getattr(twin_log, k)[a], getattr(twin_log, k)[b]), k
        assert np.array_equal(twin_log.action[a], f["labels"][0])
        assert np.array_equal(twin_log.action[b], f["labels"][1])  # the replayed twin is the recorded one
        assert f["gap"] >= 0.3  # a driver who decides at one point
        assert 0.5 < f["entry_m"] < 6.0
        # left labels steer left of right labels
        left, right = (f["labels"][0, 0], f["labels"][1, 0])[:: 1 if f["turn"] == "left" else -1]
        assert left < right


def test_route_forks_are_the_lookahead_s(route_log):
    forks = stem_forks(route_log, show_progress=False)
    assert len(forks) == 2  # these two routes cross two stems
    for f in forks:  # the default expert eases into a turn: a small gap, about 4-4.5 m before the entry
        assert not f["twin"]
        assert f["gap"] < 0.2 and 3.0 < f["entry_m"] < 5.5


def test_green_offsets_keep_the_light_green():
    sim = DrivingSim("town01")
    rng = np.random.default_rng(0)
    for light in (0, 5, 11):
        offsets = sim.schedule.offsets_green_from_start(light, 80, rng)
        assert (sim.schedule.states(np.arange(80), offsets)[:, light] == GREEN).all()
    with pytest.raises(ValueError, match="steps"):
        sim.schedule.offsets_green_from_start(0, 500, rng)


def test_bad_input(route_log):
    with pytest.raises(ValueError, match="episode"):
        replay(route_log, 99)
    with pytest.raises(ValueError, match="flip index"):
        replay(route_log, 0, flip=(999,))
    with pytest.raises(ValueError, match="stem_twins"):
        CollectConfig(stem_twins=-1)
    with pytest.raises(ValueError, match="twin_start_m"):
        CollectConfig(twin_start_m=(20.0, 10.0))
    with pytest.raises(ValueError, match="routeless"):
        CollectConfig(routeless=True, stem_twins=1)
    routeless = collect(CollectConfig(routes=1, min_minutes=0.05, max_minutes=0.05, routeless=True))
    with pytest.raises(ValueError, match="routeless"):
        stem_forks(routeless)


def test_fork_traces_agree_before_the_fork_and_differ_at_it(twin_log):
    fork = next(f for f in stem_forks(twin_log, show_progress=False) if f["twin"])
    from ibc_tutorial.driving.forks import fork_traces

    t = fork_traces(twin_log, fork, before=5, after=3)
    k = t["fork"]
    assert k == 5 and len(t["recorded"]) == len(t["twin"]) == len(t["entry_m"]) == 9
    assert np.array_equal(t["recorded"][:k], t["twin"][:k])
    assert abs(t["recorded"][k] - t["twin"][k]) == pytest.approx(fork["gap"])
    assert (np.diff(t["entry_m"]) <= 0).all()  # the car approaches the entry


def test_stem_forks_of_chosen_episodes(twin_log):
    forks = stem_forks(twin_log, show_progress=False, episodes=[1, 2])
    assert {f["episode"] for f in forks} == {1, 2} and len(forks) == 2
    with pytest.raises(ValueError, match="episodes"):
        stem_forks(twin_log, episodes=[999])
