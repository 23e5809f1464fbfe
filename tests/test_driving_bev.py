"""The bird's-eye view: geometry, channels, pooled views, history, against independent references."""

import math

import numpy as np
import pytest
import torch

from ibc_tutorial.driving.bev import (
    EGO_ROW,
    FULL_SIZE,
    SUPPORTED_SIZES,
    BEVRenderer,
    get_raster,
    get_renderer,
)

ALL_GREEN = np.zeros((3, 24), dtype=np.uint8)  # light states: 0 green, 1 yellow, 2 red


def slow_bev_codes(raster, x, y, yaw):
    """An independent (float64, pixel by pixel in plain Python maths) gather of the raster bytes."""
    out = np.zeros((FULL_SIZE, FULL_SIZE), dtype=np.uint8)
    for r in range(0, FULL_SIZE):
        f = (EGO_ROW - (r + 0.5)) / 5.0
        for q in range(0, FULL_SIZE):
            lft = (q + 0.5 - FULL_SIZE / 2) / 5.0
            wx = x + f * math.cos(yaw) + lft * math.sin(yaw)
            wy = y + f * math.sin(yaw) - lft * math.cos(yaw)
            out[r, q] = raster.lookup(wx, wy)
    return out


def test_bev_matches_an_independent_gather():
    raster = get_raster("town02")
    r = BEVRenderer(raster, 192)
    x, y, yaw = 30.3, -2.1, 0.37
    bev = r.render(x, y, yaw, ALL_GREEN)
    ref = slow_bev_codes(raster, x, y, yaw)
    assert ((bev[0] != (ref & 1)).mean()) < 0.002  # float32 vs float64 may flip a pixel on an edge
    assert ((bev[1] != ((ref >> 1) & 1)).mean()) < 0.002


def test_straight_road_geometry():
    """Heading east in the right lane of town02's south road (centre line y = 0, lane at y = -2)."""
    r = get_renderer("town02", 192)
    bev = r.render(60.0, -2.0, 0.0, ALL_GREEN)
    row = EGO_ROW - 50  # 10 m ahead
    cols = np.flatnonzero(bev[0, row])
    # road from 2 m right of the car to 6 m left of it: columns 96 - 30 .. 96 + 10
    assert cols.min() == pytest.approx(66, abs=1) and cols.max() == pytest.approx(105, abs=1)
    lines = np.flatnonzero(bev[1, row])
    assert {66, 67}.issubset(lines) and {104, 105}.issubset(lines)  # the two road edges
    assert bev[1, row, 84:88].any() and not bev[1, row, 70:82].any()  # the centre line 2 m to the left
    assert bev[0, EGO_ROW, 96] == 1  # the car is on the road
    assert set(np.unique(bev[2:])) <= {0.0, np.float32(0.3)}  # all lights green: lines at 0.3 or nothing


def test_heading_up_rotation():
    """The same place seen heading north: the view rotates with the car."""
    r = get_renderer("town02", 192)
    east = r.render(60.0, -2.0, 0.0, ALL_GREEN)
    # a car heading north on the west road (x centre line 0, northbound lane at x = +2) sees the
    # same straight-road picture
    north = r.render(2.0, 40.0, math.pi / 2, ALL_GREEN)
    assert (east[:2, :100] != north[:2, :100]).mean() < 0.01


def test_light_channels_draw_each_state_by_intensity():
    town_raster = get_raster("town02")
    r = BEVRenderer(town_raster, 192)
    town = town_raster.town
    line = town.stop_lines[0]
    e, d = np.array(line.entry), np.array(line.direction)
    x, y = e - 10 * d  # 10 m before the line, on its lane
    yaw = math.atan2(d[1], d[0])
    lights = np.zeros((3, town.n_lights), dtype=np.uint8)  # all green at every lag
    lights[1, 0] = 1  # light 0: yellow 8 steps ago
    lights[2, 0] = 2  # light 0: red now
    bev = r.render(x, y, yaw, lights)
    assert bev.dtype == np.float32
    own = bev[4] == np.float32(1.0)  # this lane's line, red now
    assert own.sum() > 20
    rows = np.flatnonzero(own.any(axis=1))
    assert (
        10 * 5 - 8 <= EGO_ROW - rows.max() <= 10 * 5 + 2
    )  # the line, 10 m ahead of the centre, is 1.2 m thick
    assert (bev[3][own] == np.float32(0.6)).all()  # yellow 8 steps ago
    assert (bev[2][own] == np.float32(0.3)).all()  # green 15 steps ago
    assert set(np.unique(bev[2:])) <= {0.0, np.float32(0.3), np.float32(0.6), 1.0}


def test_lights_must_be_states():
    r = get_renderer("town02", 64)
    with pytest.raises(ValueError, match="lights must be light states"):
        r.render(60.0, -2.0, 0.0, np.zeros((3, 24), dtype=bool))  # a flag, not a state
    with pytest.raises(ValueError, match="lights must be light states"):
        r.render(60.0, -2.0, 0.0, np.full((3, 24), 3, dtype=np.uint8))
    with pytest.raises(ValueError, match=r"shape \(3, 24\)"):
        r.render(60.0, -2.0, 0.0, np.zeros((3, 23), dtype=np.uint8))


@pytest.mark.parametrize("size", [s for s in SUPPORTED_SIZES if s != 192])
def test_small_views_are_max_pooled(size):
    full = get_renderer("town01", 192)
    small = get_renderer("town01", size)
    red = np.random.default_rng(size).integers(0, 3, (3, 36)).astype(np.uint8)  # mixed light states
    for x, y, yaw in [(88.0 + 2, 100.0, math.pi / 2), (200.0, 55.0 - 2, 0.3), (150.0, 2.0, 2.0)]:
        a = torch.from_numpy(full.render(x, y, yaw, red))
        ref = torch.nn.functional.max_pool2d(a[None], 192 // size)[0].numpy()
        assert np.array_equal(small.render(x, y, yaw, red), ref)
        assert small.render(x, y, yaw, red)[1].sum() > 0  # thin lines survive


def test_batch_equals_single():
    r = get_renderer("town01", 64)
    rng = np.random.default_rng(0)
    poses = np.c_[rng.uniform(0, 390, 5), rng.uniform(0, 320, 5), rng.uniform(-3, 3, 5)]
    red = rng.integers(0, 3, (5, 3, 36)).astype(np.uint8)
    batch = r.render_batch(poses, red)
    for b in range(5):
        assert np.array_equal(batch[b], r.render(*poses[b], red[b]))


def test_far_poses_are_clamped_not_crashing():
    r = get_renderer("town02", 64)
    bev = r.render(-500.0, 900.0, 1.0, ALL_GREEN)
    assert bev.shape == (5, 64, 64) and not bev.any()


def test_bad_sizes_are_refused():
    with pytest.raises(ValueError, match="bev_size must be one of"):
        get_renderer("town01", 100)
    with pytest.raises(ValueError, match="bev_size"):
        get_renderer("town01", 64.0)


def test_the_flag_encoding_draws_red_and_yellow_alike_and_green_not():
    lights = np.random.default_rng(1).integers(0, 3, (3, 36)).astype(np.uint8)
    pose = (88.0 + 2, 100.0, math.pi / 2)
    by_state = get_renderer("town01", 64).render(*pose, lights)
    flag = get_renderer("town01", 64, light_encoding="flag").render(*pose, lights)
    assert np.array_equal(flag[:2], by_state[:2])
    assert set(np.unique(flag[2:])) <= {0.0, 1.0}
    assert np.array_equal(flag[2:] == 1.0, by_state[2:] >= np.float32(0.6))  # red or yellow
    with pytest.raises(ValueError, match="light_encoding"):
        get_renderer("town01", 64, light_encoding="bits")
