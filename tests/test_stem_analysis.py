"""The pooling of experiments.agents.stem_analysis on hand-made per-agent records (no driving)."""

import numpy as np
import pytest

from ibc_tutorial.experiments.agents.stem_analysis import (
    fig6_states,
    method_summary,
    pooled_readings,
    read_profile,
)


def episode(left: int, right: int, *, twice=0, both=0, circling=0, ended=False) -> dict:
    return {
        "left": left,
        "right": right,
        "stem_crossings": left + right,
        "ended_at_stem": ended,
        "row": {"termination": "building" if ended else ""},
        "distinct_approaches": 4,
        "lanes_covered": 0.2,
        "circling": circling,
        "stems_twice": twice,
        "stems_both": both,
        "stem_exits": {"8": {"left": left, "right": right}},
        "onsets": [{"turn": "left", "onset_m": 2.0}] * left + [{"turn": "right", "onset_m": -1.0}] * right,
    }


def state(
    rel: int, turn: str, left_mass: float, extent: float, valleys: int = 1, kind="stem", crossing: int = 0
) -> dict:
    return {
        "kind": kind,
        "crossing": crossing,
        "episode": 0,
        "t": 100 + rel,
        "rel": rel,
        "turn": turn,
        "window": True,
        "valleys": valleys,
        "left_mass": left_mass,
        "left_mass_low": left_mass,
        "range_extent": extent,
        "range_measure": extent,
    }


def test_method_summary_counts_and_intervals():
    files = [
        {"episodes": [episode(1, 3, twice=1, both=1), episode(0, 4, twice=1, circling=4)], "states": []},
        {"episodes": [episode(0, 2, ended=True), episode(2, 2, twice=1, both=1)], "states": []},
    ]
    s = method_summary(files)
    assert (s["agents"], s["episodes"], s["stem_crossings"], s["left"]) == (2, 4, 14, 3)
    assert s["left_share"].startswith("0.21") and s["minority_share"].startswith("0.21")
    assert (s["ended_at_stem"], s["terminated"], s["stems_twice"], s["stems_both"]) == (1, 1, 3, 2)
    assert s["circling"].startswith("0.25") and s["mode_coverage"].startswith("0.67")
    assert s["per_stem"] == {"8": {"left": 3, "right": 11}}
    assert s["onset_m"] == {"left": {"n": 3, "median": 2.0}, "right": {"n": 11, "median": -1.0}}


def test_pooled_readings_energy_and_beta():
    states = [
        state(0, "right", 0.02, 0.1),
        state(0, "left", 0.5, 1.2, valleys=2),
        state(1, "left", 0.95, 0.2),
    ]
    r = pooled_readings(states)
    assert r["n"] == 3 and r["valleys"] == {"1": 2, "2": 1} and r["both_sides_10pct"] == 1
    assert r["range_extent"]["median"] == pytest.approx(0.2)
    betas = [
        {"shape": "U-shaped", "mean": 0.05, "left_mass": 0.5},
        {"shape": "single-peaked", "mean": 0.6, "left_mass": 0.1},
    ]
    b = pooled_readings(betas)
    assert b["shapes"] == {"U-shaped": 1, "single-peaked": 1} and b["mean"]["abs_below_0.1"] == 1
    assert pooled_readings([]) == {"n": 0}


def test_fig6_rule_takes_each_crossings_most_undecided_state_then_the_median_extent():
    files = {
        "da-ibc-seed0": {
            "states": [  # crossing 0: most undecided at -3 (0.45); crossing 1: at -1 (0.6)
                state(-5, "right", 0.9, 0.1), state(-3, "right", 0.45, 0.3), state(0, "right", 0.0, 0.1),
                state(-1, "left", 0.6, 0.5, crossing=1), state(0, "left", 1.0, 0.9, crossing=1),
                state(2, "left", 0.5, 0.9, crossing=1),  # after the entry: not a candidate
            ]
        },
        "da-ibc-seed1": {"states": [state(-2, "right", 0.5, 0.2), state(-1, "ended", 0.5, 0.2, crossing=1)]},
        "ibc-seed0": {"states": [state(0, "right", 0.5, 0.1)]},  # another method
        "da-ibc-seed2": {"states": [state(5, "", 0.5, e, kind="red") for e in (0.4, 0.1, 0.2)]},
    }  # fmt: skip
    f = fig6_states(files)
    # candidates: extents 0.3 (seed0, -3), 0.5 (seed0, -1), 0.2 (seed1, -2): the median is 0.3
    assert (f["junction"]["agent"], f["junction"]["rel"], f["junction"]["range_extent"]) == (
        "da-ibc-seed0",
        -3,
        0.3,
    )
    assert f["red_light"]["range_extent"] == 0.2
    assert fig6_states({"bc-seed0": {"states": []}}) == {"junction": None, "red_light": None}


def test_read_profile():
    s = np.linspace(-1, 1, 41)
    r = read_profile(s, 10 * (s - 0.5) ** 2, 10 * (s - 0.5) ** 2)
    assert r["valleys"] == 1 and r["argmin_steer"] == pytest.approx(0.5) and r["left_mass"] < 0.02


def test_by_position_averages_per_state_and_turn():
    from ibc_tutorial.experiments.agents.stem_analysis import by_position

    files = [
        {"states": [state(-1, "left", 0.6, 0.2), state(0, "left", 0.9, 0.2), state(0, "right", 0.1, 0.2)]},
        {"states": [state(0, "left", 0.7, 0.2), state(0, "x", 0.5, 0.2, kind="red")]},
    ]
    pos, mean, n = by_position(files, "left")
    assert pos.tolist() == [-1, 0] and mean == pytest.approx([0.6, 0.8]) and n.tolist() == [1, 2]
    pos, mean, n = by_position(files, "right", positions=[0, 5])
    assert pos.tolist() == [0] and mean == pytest.approx([0.1])
