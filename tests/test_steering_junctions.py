"""The sweep's junction measures on hand-made energies and traces (``experiments.steering.junctions``)."""

import math

import numpy as np
import pytest

from ibc_tutorial.experiments.steering.junctions import pooled_whiteness, section_whiteness, side_road_mass

GRID = np.array([-1.0, -0.5, 0.0, 0.5, 1.0])  # steering: +1 right, -1 left


def test_uniform_energy_puts_the_share_of_values_beyond_the_threshold():
    e = np.zeros((1, 5))
    # side road on the left (side=+1): values below 0 - 0.3, i.e. -1 and -0.5: 2 of 5
    assert side_road_mass(e, GRID, 0.0, side=+1, threshold=0.3)[0] == pytest.approx(0.4)
    # on the right: 0.5 and 1
    assert side_road_mass(e, GRID, 0.0, side=-1, threshold=0.3)[0] == pytest.approx(0.4)
    # beyond 0.5 strictly: only -1
    assert side_road_mass(e, GRID, 0.0, side=+1, threshold=0.5)[0] == pytest.approx(0.2)


def test_two_valleys_share_the_mass_and_the_side_decides_which_counts():
    big = 50.0
    e = np.array([[0.0, big, 0.0, big, big]])  # valleys at -1 (left) and 0 (straight)
    assert side_road_mass(e, GRID, 0.0, side=+1)[0] == pytest.approx(0.5, abs=1e-9)
    assert side_road_mass(e, GRID, 0.0, side=-1)[0] == pytest.approx(0.0, abs=1e-9)
    # a shallower side valley, 1 nat above: its share is 1 / (1 + e)
    e2 = np.array([[1.0, big, 0.0, big, big]])
    assert side_road_mass(e2, GRID, 0.0, side=+1)[0] == pytest.approx(1 / (1 + math.e), abs=1e-9)


def test_the_threshold_is_measured_from_the_experts_steer_per_state():
    e = np.zeros((2, 5))
    # state 0: expert at 0 -> -1, -0.5 count; state 1: expert at -0.5 -> only -1 counts
    m = side_road_mass(e, GRID, np.array([0.0, -0.5]), side=+1, threshold=0.3)
    assert m == pytest.approx([0.4, 0.2])


def test_mass_is_unchanged_by_a_constant_and_stable_for_large_energies():
    rng = np.random.default_rng(0)
    e = rng.normal(size=(4, 5))
    a = side_road_mass(e, GRID, 0.1, side=-1)
    assert side_road_mass(e + 1000.0, GRID, 0.1, side=-1) == pytest.approx(a)
    assert ((a >= 0) & (a <= 1)).all()


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"side": 0}, "side"),
        ({"scores": np.zeros((1, 4))}, "scores"),
        ({"scores": np.array([[0.0, np.inf, 0, 0, 0]])}, "finite"),
        ({"threshold": -0.1}, "threshold"),
    ],
)
def test_bad_input_is_refused(kwargs, match):
    args = {"scores": np.zeros((1, 5)), "grid": GRID, "expert_steer": 0.0, "side": 1} | kwargs
    with pytest.raises(ValueError, match=match):
        side_road_mass(**args)


def test_section_whiteness_counts_changes_inside_the_sections_only():
    dt = 0.1
    steer = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 5.0])
    inside = np.array([False, True, True, True, False, False])
    # changes 1->2 (+1) and 2->3 (-1) are inside; 0->1, 3->4 and 4->5 cross or lie outside
    assert section_whiteness(steer, inside, dt) == pytest.approx(1 / dt)
    # argmin jumping between two modes inside a section is whiter than holding one
    jitter = np.array([0.0, -0.8, 0.0, -0.8, 0.0])
    hold = np.zeros(5)
    all_in = np.ones(5, bool)
    assert section_whiteness(jitter, all_in, dt) == pytest.approx(8.0)
    assert section_whiteness(hold, all_in, dt) == 0.0
    # no two consecutive steps inside: no change to count
    assert math.isnan(section_whiteness(steer, np.array([True, False, True, False, True, False]), dt))
    with pytest.raises(ValueError, match="same length"):
        section_whiteness(steer, inside[:3], dt)


def test_pooled_whiteness_weights_by_changes():
    assert pooled_whiteness([(1.0, 1), (3.0, 1)]) == pytest.approx(math.sqrt(5.0))
    assert pooled_whiteness([(2.0, 3), (float("nan"), 0)]) == pytest.approx(2.0)
    assert math.isnan(pooled_whiteness([]))
