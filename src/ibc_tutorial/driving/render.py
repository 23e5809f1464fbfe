"""RGB pictures: the BEV in colour (the paper's Fig. 1(b)), the car on it, and whole-town maps."""

from __future__ import annotations

import numpy as np

from ibc_tutorial.driving.bev import EGO_ROW, FULL_SIZE, LIGHT_LEVELS, PIXELS_PER_METRE, TownRaster
from ibc_tutorial.driving.car import CarConfig

ROAD_COLOURS = np.array(
    [
        [80, 80, 80],  # drivable area: grey
        [255, 255, 255],  # lane boundaries: white
    ],
    dtype=np.uint8,
)
"""Colour of the two road channels (0/1)."""
LIGHT_COLOURS = np.array(
    [
        [40, 200, 60],  # green (level 0.3)
        [255, 200, 0],  # yellow (level 0.6)
        [255, 40, 40],  # red (level 1.0)
    ],
    dtype=np.uint8,
)
"""Colour of a stop line by the light level of its channel (``bev.LIGHT_LEVELS``)."""
LAG_BRIGHTNESS = (0.45, 0.7, 1.0)
"""Light channels 2, 3, 4 (15, 8 and 0 steps ago) are drawn this bright: the newest on top, brightest."""
BACKGROUND = np.array([0, 0, 0], dtype=np.uint8)
EGO_COLOUR = np.array([0, 200, 255], dtype=np.uint8)
BUILDING_COLOUR = np.array([150, 110, 60], dtype=np.uint8)


def bev_to_rgb(bev: np.ndarray) -> np.ndarray:
    """(5, S, S) BEV -> (S, S, 3) uint8 picture: road channels in ``ROAD_COLOURS``, stop lines in the colour
    of their light (``LIGHT_COLOURS``), older channels dimmer and painted first."""
    bev = np.asarray(bev)
    if bev.ndim != 3 or bev.shape[0] != 5:
        raise ValueError(f"bev must have shape (5, S, S), got {bev.shape}")
    img = np.empty(bev.shape[1:] + (3,), dtype=np.uint8)
    img[:] = BACKGROUND
    for ch in range(2):
        img[bev[ch] > 0] = ROAD_COLOURS[ch]
    for ch, bright in zip(range(2, 5), LAG_BRIGHTNESS, strict=True):
        for colour, level in zip(LIGHT_COLOURS, LIGHT_LEVELS, strict=True):
            img[np.isclose(bev[ch], level, atol=0.05)] = (colour * bright).astype(np.uint8)
    return img


def draw_ego(img: np.ndarray, car: CarConfig | None = None) -> np.ndarray:
    """Draw the car (heading up) on a (S, S, 3) picture of a BEV of side S; returns a copy.

    ``car``: its dimensions (``CarConfig()`` if None)."""
    car = CarConfig() if car is None else car
    img = img.copy()
    scale = img.shape[0] / FULL_SIZE
    res = PIXELS_PER_METRE * scale
    r0, c0 = EGO_ROW * scale, FULL_SIZE / 2 * scale
    hl, hw = car.length / 2 * res, car.width / 2 * res
    img[int(round(r0 - hl)) : int(round(r0 + hl)), int(round(c0 - hw)) : int(round(c0 + hw))] = EGO_COLOUR
    return img


def town_rgb(
    raster: TownRaster, stop_flags: np.ndarray | None = None, step: int = 1
) -> tuple[np.ndarray, tuple]:
    """A picture of the whole town and its extent for ``imshow``.

    Args:
        raster: the town's raster.
        stop_flags: optional (L,) booleans: stop lines drawn red where True, green elsewhere
            (None draws them all in white).
        step: keep every ``step``-th pixel (2 halves the resolution).

    Returns:
        ``(image (H, W, 3) uint8, (left, right, bottom, top) in metres)``.
    """
    code = raster.code[::step, ::step]
    img = np.empty(code.shape + (3,), dtype=np.uint8)
    img[:] = (235, 235, 235)
    img[raster.buildings[::step, ::step]] = BUILDING_COLOUR
    img[(code & 1) > 0] = (90, 90, 90)
    img[(code & 2) > 0] = (250, 250, 250)
    ids = code >> 2
    if stop_flags is None:
        img[ids > 0] = (255, 255, 255)
    else:
        flags = np.concatenate([[False], np.asarray(stop_flags, dtype=bool)])
        on = ids > 0
        img[on & flags[ids]] = (230, 30, 30)
        img[on & ~flags[ids]] = (30, 200, 60)
    h, w = raster.code.shape
    extent = (raster.x_min, raster.x_min + w / raster.res, raster.y_max - h / raster.res, raster.y_max)
    return img, extent
