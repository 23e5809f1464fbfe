"""Traffic lights: timing of the cycle and the red-light rule."""

import numpy as np
import pytest

from ibc_tutorial.driving.lights import GREEN, RED, YELLOW, LightSchedule, LightTiming, RedLightMonitor
from ibc_tutorial.driving.towns import get_town


@pytest.fixture
def schedule():
    town = get_town("town02")
    return LightSchedule(town.stop_lines, town.n_junctions)


def test_cycle_timing(schedule):
    offsets = np.random.default_rng(0).integers(0, 450, schedule.n_junctions)
    states = schedule.states(np.arange(450), offsets)  # (450, L): one full 45 s cycle
    assert schedule.period == 450
    for light in range(schedule.n_lights):
        s = states[:, light]
        assert (s == GREEN).sum() == 100 and (s == YELLOW).sum() == 30 and (s == RED).sum() == 320
        # green is one block of 10 s followed by 3 s of yellow (cyclically)
        start = np.flatnonzero((s == GREEN) & (np.roll(s, 1) != GREEN))
        assert len(start) == 1
        rolled = np.roll(s, -start[0])
        assert (
            (rolled[:100] == GREEN).all()
            and (rolled[100:130] == YELLOW).all()
            and (rolled[130:] == RED).all()
        )
    for j in range(schedule.n_junctions):  # at most one head of a junction is not red at any time
        heads = states[:, schedule.junction == j]
        assert ((heads != RED).sum(axis=1) <= 1).all()
        assert ((heads != RED).sum(axis=1) == 0).sum() == 3 * 20  # 2 s all red per head's turn
    assert np.isclose((states == RED).mean(), 32 / 45)  # red about two thirds of the time
    assert np.array_equal(schedule.table(offsets)[7], schedule.states(7 + 450 * 3, offsets))


def test_offsets_shift_the_cycle(schedule):
    a = schedule.states(np.arange(450), np.zeros(schedule.n_junctions, int))
    b = schedule.states(np.arange(450), np.full(schedule.n_junctions, 37))
    assert np.array_equal(np.roll(a, -37, axis=0), b)


def test_timing_is_validated():
    with pytest.raises(ValueError, match="green_s"):
        LightTiming(green_s=0)


def test_monitor_counts_red_crossings_once():
    town = get_town("town02")
    mon = RedLightMonitor(town.stop_lines)
    line = town.stop_lines[4]
    e, d = np.array(line.entry), np.array(line.direction)
    states = np.full(town.n_lights, RED, dtype=np.uint8)
    assert mon.update(e - 0.5 * d, e + 0.5 * d, states) == [4]
    assert mon.update(e + 0.5 * d, e + 1.5 * d, states) == []  # already past: no second count
    assert mon.count == 1
    mon.reset()
    green = np.full(town.n_lights, GREEN, dtype=np.uint8)
    assert mon.update(e - 0.5 * d, e + 0.5 * d, green) == [] and mon.count == 0
    right = np.array([d[1], -d[0]])  # crossing the line's extension in the other lane does not count
    assert mon.update(e - 0.5 * d + 4.5 * right, e + 0.5 * d + 4.5 * right, states) == []
