"""``driving.pooling.pool_packed``: the BEV's block pooling as strided slices, bit for bit the renderer's."""

import numpy as np
import pytest

from ibc_tutorial.driving.bev import LIGHT_SHIFTS, SUPPORTED_SIZES, BEVRenderer, get_raster
from ibc_tutorial.driving.pooling import pool_packed


def reference_pool(codes: np.ndarray, k: int) -> np.ndarray:
    """The renderer's pooling as it was written before ``pool_packed``: numpy reductions over the
    axes of each k x k block (slow, plainly right)."""
    s = codes.shape[-1] // k
    b = codes.reshape(*codes.shape[:-2], s, k, s, k)  # (..., S, k, S, k)
    out = np.bitwise_or.reduce(np.bitwise_or.reduce(b & 3, axis=-1), axis=-2)  # (..., S, S) road bits
    for shift in LIGHT_SHIFTS:
        out |= ((b >> shift) & 3).max(axis=(-3, -1)) << shift
    return out


@pytest.mark.parametrize("size", SUPPORTED_SIZES)
def test_pool_packed_equals_the_renderers_pooling_on_every_byte(size):
    renderer = BEVRenderer(get_raster("town02"), size)
    rng = np.random.default_rng(size)
    codes = rng.integers(0, 256, size=(3, 192, 192), dtype=np.uint8)  # every byte value, batched
    want = reference_pool(codes, renderer.pool)
    assert np.array_equal(renderer._pool(codes), want)
    assert np.array_equal(pool_packed(codes, renderer.pool), want)
    assert np.array_equal(pool_packed(codes[0], renderer.pool), want[0])  # one view


def test_pool_packed_on_a_rendered_view_with_lights():
    renderer = BEVRenderer(get_raster("town02"), 64)
    town = renderer.raster.town
    sl = town.stop_lines[0]
    x, y = np.asarray(sl.entry) - 5.0 * np.array([np.cos(0.0), np.sin(0.0)])
    lights = np.full((3, town.n_lights), 2, dtype=np.uint8)  # all red: every stop line drawn
    view = renderer._lut(lights).take(renderer.raster.code.ravel().take(renderer._indices(x, y, 0.0)))
    pooled = pool_packed(view, 3)
    assert np.array_equal(pooled, reference_pool(view, 3))
    assert pooled.shape == (64, 64) and ((pooled >> 2) > 0).any()  # stop lines in view


def test_pool_packed_refuses_what_it_cannot_pool():
    with pytest.raises(ValueError, match="uint8"):
        pool_packed(np.zeros((192, 192), dtype=np.int32), 3)
    with pytest.raises(ValueError, match="multiples"):
        pool_packed(np.zeros((100, 100), dtype=np.uint8), 3)
    ones = np.ones((6, 6), dtype=np.uint8)
    assert pool_packed(ones, 1) is ones
