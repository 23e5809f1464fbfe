"""The road-following study's closed-loop protocol: reference path, crashes and restarts, side-road
sections."""

import numpy as np
import pytest

from ibc_tutorial.experiments.steering import evaluate as ev
from ibc_tutorial.experiments.steering.presets import TINY


def test_resample_path_and_lateral_offset_by_hand():
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [2.0, 0.0]])  # the car stood still at step 2
    path, step = ev.resample_path(xy, 0.5)
    assert path.tolist() == [[0.0, 0.0], [0.5, 0.0], [1.0, 0.0], [1.5, 0.0]]
    assert step.tolist() == [0, 1, 1, 3]  # the first step that reached each point
    i, lat = ev._nearest(path, (1.1, 0.5), 0)
    assert i == 2 and lat == pytest.approx(0.5)  # left of the direction of travel: positive
    assert ev._nearest(path, (0.4, -1.5), 0) == (1, pytest.approx(-1.5))


def test_routes():
    town_routes = {name: ev.build_route(name) for name in ev.ROUTES}
    assert town_routes["loop-ccw"].turns == ("straight",) * 4
    assert 700 < ev.route_length(town_routes["loop-cw"]) < 1100
    assert ev.route_length(town_routes["y82-west"], cap_m=70.0) == 70.0
    with pytest.raises(ValueError, match="name"):
        ev.build_route("nowhere")


@pytest.fixture(scope="module")
def reference():
    ref, _ = ev.expert_reference("y82-west", TINY)
    return ref


def test_reference_and_its_side_road_section(reference):
    ref = reference
    dist = np.linalg.norm(np.diff(ref.poses[:, :2], axis=0), axis=1).sum()
    assert 69.0 <= dist <= 71.0  # the capped route
    # westbound on y = 82 m the first side road (x = 139 m, to the north) is on the right
    assert ref.sections.shape == (1, 4) and ref.sections[0, 2] == -1
    a, b, _, k = ref.sections[0]
    assert ref.path_step[a] < k <= ref.path_step[b]  # the section starts before the junction's entry
    assert (b - a) * ev.PATH_SPACING_M == pytest.approx(
        ev.SECTION_BEFORE_M + 18.0, abs=1.5
    )  # 15 m + the crossing
    arrays = ref.to_arrays()
    again = ev.Reference.from_arrays("y82-west", arrays)
    assert np.array_equal(again.path, ref.path) and np.array_equal(again.sections, ref.sections)


def test_straight_ahead_never_crashes_on_a_straight_road(reference):
    r = ev.drive_route(lambda obs: 0.0, reference, TINY)
    assert r["crashes"] == 0 and not r["timeout"] and r["w_cmd"] == 0.0
    assert 68.0 <= r["distance_m"] <= 71.0
    assert r["swerve_score"] == [0.0] and abs(r["swerve_peak_m"][0]) < 0.05


def test_one_swerve_is_one_crash_and_a_restart_two_seconds_on(reference):
    calls = []

    def policy(obs):  # a scripted driver: hard right for 1.5 s, then straight on
        calls.append(obs["state"][0, 0])
        return 0.5 if len(calls) <= 15 else 0.0

    r = ev.drive_route(policy, reference, TINY)
    assert (
        r["crashes"] == 1 and 15 < r["crash_steps"][0] <= 40 and not r["timeout"]
    )  # it drifts on after 1.5 s
    k = r["crash_steps"][0]
    assert calls[k] == 0.0  # restarted at rest (the speed seen right after the crash)
    # the car skipped 2 s of the expert's drive (about 12 m at 6 m/s, less while it sped up)
    assert 40.0 < r["distance_m"] < 70.0 - 5.0
    assert r["crashes_per_km"] == pytest.approx(
        1000.0 / r["distance_m"], rel=1e-3
    )  # distance rounded to 1 cm


def test_always_right_crashes_again_and_again(reference):
    r = ev.drive_route(lambda obs: 0.4, reference, TINY)
    assert r["crashes"] >= 3 and r["crashes_per_km"] > 20
    assert np.diff(r["crash_steps"]).min() >= 1
