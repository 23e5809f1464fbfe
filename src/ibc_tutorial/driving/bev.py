"""The bird's-eye view: the town rasterised once, then cropped and rotated around the car per step.

The five channels follow the DA-IBC paper (sec. 2.1 and Fig. 1): 0 drivable area and
1 lane boundaries (road edges and centre lines), both 0/1; 2-4 the traffic lights' stop lines at
history indices -16, -9 and -1 of a queue whose last entry is the current step (the paper's three
light channels at "time steps -16, -9 and -1"; the queue convention is Roach's, which the book
follows; the paper does not say where its BEV code comes from), i.e. 15, 8 and 0 steps ago, clamped
at the episode's start. The paper's channels are binary, "values restricted to 0 or 1", white where
a light is red: ``light_encoding="flag"`` draws a stop line at 1 for red and yellow ("must stop") and
not at all for green, as every preset does. The book's variant, ``"intensity"``, draws the line in
every state: **red 1.0, yellow 0.6, green 0.3** (``LIGHT_LEVELS``), 0 where there is no line.

Why the book also offers intensities, measured (``driving.analysis.light_label_conflicts``,
chapter 07): within 9.5 m of its stop line the expert stops for red, drives on at green, and at
yellow stops only if 4 m/s^2 of braking suffice. A 0/1 flag that draws yellow as red contradicts
the expert's label whenever it drives through a late yellow (4 of about 6,700 such samples of the
ten-route town01 data); a flag that leaves yellow out contradicts its 60 yellow stops. With a level
per state no label contradicts what the view shows: at yellow, the speed and the line's distance
in the same observation decide.

The 192 x 192 view covers 38.4 m at 5 px/m, heading up, with the car 40 px above the bottom
edge. It is rendered by one gather from the town raster: every raster pixel holds a byte with
bit 0 = drivable, bit 1 = lane boundary and bits 2-7 = 1 + the id of the stop line drawn
there (0 for none); a 256-entry lookup table, built per step from the light states, turns a
gathered byte into the *packed* view byte: bits 0-1 the two road channels and three 2-bit
fields (bits 2-3, 4-5, 6-7) the light code of channels 2-4 (0 no line, 1 green, 2 yellow,
3 red). Smaller views (96, 64, 48, 32) cover the same field by pooling blocks of the 192 view:
OR for the road bits and the maximum for the light codes, which keeps the thin lines (max-pooling)
and shows the most urgent state where two lines share a block. ``unpack`` turns packed bytes into
the float32 channels the networks see.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np

from ibc_tutorial.driving.lanes import ARM_LENGTH, DIRECTIONS, LANE_WIDTH, Lane
from ibc_tutorial.driving.lights import STOP_LINE_LENGTH, STOP_LINE_THICKNESS
from ibc_tutorial.driving.pooling import pool_packed
from ibc_tutorial.driving.towns import TOWNS, Town, get_town
from ibc_tutorial.utils import check_choice

PIXELS_PER_METRE = 5
"""Resolution of the town raster and of the 192 view."""
FULL_SIZE = 192
"""Side of the full-resolution view in pixels (38.4 m)."""
EGO_ROW = FULL_SIZE - 40
"""Row (from the top) of the car's centre in the 192 view: 40 px above the bottom edge."""
SUPPORTED_SIZES = (192, 96, 64, 48, 32)
"""BEV sizes offered: 192 and the same field OR-pooled by 2, 3, 4 and 6."""
CHANNELS = ("drivable area", "lane boundaries", "lights t-16", "lights t-9", "lights t-1")
"""Names of the five channels, in order."""
LIGHT_LEVELS = (0.3, 0.6, 1.0)
"""Value of a stop line in channels 2-4 by light state: green 0.3, yellow 0.6, red 1.0 (0 = no line)."""
LIGHT_ENCODINGS = ("intensity", "flag")
"""How the light channels draw a stop line: "flag" (one "must stop" bit: red and yellow 1.0, green not drawn;
the paper's binary channels, every preset's), or "intensity" (by state: red 1.0, yellow 0.6, green 0.3; the
book's variant, chapter 07, and chapter 08's ablation)."""
LIGHT_SHIFTS = (2, 4, 6)
"""Bit offsets of the 2-bit light codes of channels 2, 3, 4 in a packed view byte."""


def _unpack_table() -> np.ndarray:
    """(5, 256) float32: the value of each channel for every packed byte."""
    byte = np.arange(256)
    levels = np.array(
        (0.0,) + LIGHT_LEVELS, dtype=np.float32
    )  # by light code 0 none, 1 green, 2 yellow, 3 red
    rows = [byte & 1, (byte >> 1) & 1] + [levels[(byte >> shift) & 3] for shift in LIGHT_SHIFTS]
    return np.stack(rows).astype(np.float32)


UNPACK_TABLE = _unpack_table()
"""(5, 256) float32 lookup from a packed view byte to the five channel values."""
HISTORY_LAGS = (15, 8, 0)
"""Steps back of channels 2, 3, 4: history indices -16, -9, -1 with -1 the current step."""
LINE_HALF_WIDTH = 0.2
"""Half-width of painted lane boundaries (metres): lines are 0.4 m, two raster pixels."""
PAD = 40.0
"""Margin around the roads in the raster (metres), larger than the view's reach from the car."""


def check_bev_size(size) -> int:
    """Return ``size`` if it is one of ``SUPPORTED_SIZES``, else raise ValueError naming it."""
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or int(size) not in SUPPORTED_SIZES:
        raise ValueError(f"bev_size must be one of {SUPPORTED_SIZES}, got {size!r}")
    return int(size)


def _centre_lines(town: Town) -> list[Lane]:
    """Road centre lines: straight between junctions, and 9 m arcs round the corners."""
    out = []
    for u, v in town.layout.roads:
        pu, pv = town.nodes[u], town.nodes[v]
        d = (pv - pu) / np.linalg.norm(pv - pu)
        a, b = pu + d * ARM_LENGTH, pv - d * ARM_LENGTH
        out.append(
            Lane(
                -1, "road", a, b, float(np.linalg.norm(b - a)), points=np.zeros((0, 2)), headings=np.zeros(0)
            )
        )
    for n, p in enumerate(town.nodes):
        arms = [i for i in range(4) for ap in town.approaches if ap.node == n and ap.arm == i]
        if len(arms) != 2:
            continue  # T-junctions have no centre line inside
        a, b = arms
        t_in, t_out = -DIRECTIONS[a], DIRECTIONS[b]
        cross = t_in[0] * t_out[1] - t_in[1] * t_out[0]
        out.append(
            Lane(
                -1,
                "connector",
                p + DIRECTIONS[a] * ARM_LENGTH,
                p + DIRECTIONS[b] * ARM_LENGTH,
                ARM_LENGTH * math.pi / 2,
                turn="left" if cross > 0 else "right",
                center=p + (DIRECTIONS[a] + DIRECTIONS[b]) * ARM_LENGTH,
                radius=ARM_LENGTH,
                points=np.zeros((0, 2)),
                headings=np.zeros(0),
            )
        )
    return out


class TownRaster:
    """The town at ``PIXELS_PER_METRE``: one byte per pixel (see the module docstring)."""

    def __init__(self, town: Town):
        self.town = town
        self.res = PIXELS_PER_METRE
        x0, y0, x1, y1 = town.extent
        self.x_min, self.y_max = x0 - PAD, y1 + PAD
        self.width = int(math.ceil((x1 - x0 + 2 * PAD) * self.res))
        self.height = int(math.ceil((y1 - y0 + 2 * PAD) * self.res))
        if town.n_lights > 63:
            raise ValueError(f"a town may have at most 63 lights, {town.name} has {town.n_lights}")
        drivable = np.zeros((self.height, self.width), dtype=bool)
        for lane in town.lanes:
            self._paint(drivable, lane, LANE_WIDTH / 2)
        lines = np.zeros_like(drivable)
        for lane in _centre_lines(town):
            self._paint(lines, lane, LINE_HALF_WIDTH)
        # road edges: drivable pixels within two pixels of a non-drivable one
        interior = drivable.copy()
        for _ in range(int(round(2 * LINE_HALF_WIDTH * self.res))):
            interior[1:-1, 1:-1] &= (
                interior[:-2, 1:-1]
                & interior[2:, 1:-1]
                & interior[1:-1, :-2]
                & interior[1:-1, 2:]
                & interior[:-2, :-2]
                & interior[:-2, 2:]
                & interior[2:, :-2]
                & interior[2:, 2:]
            )
        lines |= drivable & ~interior
        stop_id = np.zeros((self.height, self.width), dtype=np.uint8)
        for s in town.stop_lines:
            self._paint_stop_line(stop_id, s)
        self.code = drivable.astype(np.uint8) | (lines.astype(np.uint8) << 1) | (stop_id << 2)  # (H, W) uint8
        """(H, W) one byte per pixel: bit 0 drivable, bit 1 lane boundary, bits 2-7 1 + stop-line id."""
        buildings = np.zeros_like(drivable)
        for poly in town.buildings:
            self._paint_polygon(buildings, poly)
        self.buildings = buildings
        """(H, W) building footprints (for pictures; the BEV has no building channel)."""

    # ------------------------------------------------------------------ coordinates
    def to_pixel(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """Continuous (row, col) raster coordinates of world points (metres)."""
        return (self.y_max - np.asarray(y)) * self.res, (np.asarray(x) - self.x_min) * self.res

    def _window(self, xmin, ymin, xmax, ymax):
        r0 = max(int((self.y_max - ymax) * self.res) - 1, 0)
        r1 = min(int((self.y_max - ymin) * self.res) + 2, self.height)
        c0 = max(int((xmin - self.x_min) * self.res) - 1, 0)
        c1 = min(int((xmax - self.x_min) * self.res) + 2, self.width)
        rows, cols = np.arange(r0, r1), np.arange(c0, c1)
        ys = self.y_max - (rows + 0.5) / self.res
        xs = self.x_min + (cols + 0.5) / self.res
        X, Y = np.meshgrid(xs, ys)
        return (slice(r0, r1), slice(c0, c1)), np.stack([X.ravel(), Y.ravel()], axis=1), X.shape

    def _paint(self, mask: np.ndarray, lane: Lane, half_width: float) -> None:
        if lane.center is None:
            pts = np.stack([lane.start, lane.end])
            lo, hi = pts.min(0) - half_width, pts.max(0) + half_width
        else:
            lo, hi = lane.center - lane.radius - half_width, lane.center + lane.radius + half_width
        win, xy, shape = self._window(lo[0], lo[1], hi[0], hi[1])
        mask[win] |= (lane.distance_to(xy) <= half_width).reshape(shape)

    def _paint_stop_line(self, stop_id: np.ndarray, s) -> None:
        e, d = np.array(s.entry), np.array(s.direction)
        r = np.array([d[1], -d[0]])
        c = s.corners()
        win, xy, shape = self._window(c[:, 0].min(), c[:, 1].min(), c[:, 0].max(), c[:, 1].max())
        along, across = (xy - e) @ d, (xy - e) @ r
        inside = (along >= -STOP_LINE_THICKNESS) & (along <= 0) & (np.abs(across) <= STOP_LINE_LENGTH / 2)
        view = stop_id[win]
        view[inside.reshape(shape)] = s.id + 1

    def _paint_polygon(self, mask: np.ndarray, poly: np.ndarray) -> None:
        win, xy, shape = self._window(*poly.min(0), *poly.max(0))
        inside = np.ones(len(xy), dtype=bool)
        for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):  # convex, counter-clockwise
            inside &= (b[0] - a[0]) * (xy[:, 1] - a[1]) - (b[1] - a[1]) * (xy[:, 0] - a[0]) >= 0
        mask[win] |= inside.reshape(shape)

    # ------------------------------------------------------------------ queries
    def lookup(self, x: float, y: float) -> int:
        """The raster byte under the world point (x, y); 0 outside the raster."""
        r, c = self.to_pixel(x, y)
        r, c = int(math.floor(r)), int(math.floor(c))
        if 0 <= r < self.height and 0 <= c < self.width:
            return int(self.code[r, c])
        return 0

    def is_drivable(self, x: float, y: float) -> bool:
        """True if the world point (x, y) lies on the road."""
        return bool(self.lookup(x, y) & 1)


@cache
def get_raster(town_name: str) -> TownRaster:
    """The raster of a town, built once (about a second) and cached."""
    return TownRaster(get_town(town_name))


class BEVRenderer:
    """Renders the five-channel BEV of a pose from a town raster, at one of ``SUPPORTED_SIZES``."""

    def __init__(self, raster: TownRaster, size: int = FULL_SIZE, light_encoding: str = "intensity"):
        self.raster = raster
        self.size = check_bev_size(size)
        self.light_encoding = check_choice("light_encoding", light_encoding, LIGHT_ENCODINGS)
        self.pool = FULL_SIZE // self.size
        res = raster.res
        forward = (EGO_ROW - (np.arange(FULL_SIZE) + 0.5)) / res  # (192,) metres ahead of each row
        right = (np.arange(FULL_SIZE) + 0.5 - FULL_SIZE / 2) / res  # (192,) metres right of each column
        self._f = forward * res  # (192,) in raster pixels
        self._r = right * res  # (192,)
        self._reach = float(np.hypot(np.abs(self._f).max(), np.abs(self._r).max())) + 2  # pixels from the car
        self._low = np.arange(256, dtype=np.uint8) & 3  # bits 0-1 of every byte
        self._n_lights = raster.town.n_lights

    def check_lights(self, lights, batch: int | None = None) -> np.ndarray:
        """``lights`` as uint8 (3, L), or (batch, 3, L): light states 0 green, 1 yellow, 2 red."""
        want = (3, self._n_lights) if batch is None else (batch, 3, self._n_lights)
        arr = np.asarray(lights)
        if arr.shape != want or arr.dtype.kind not in "iu" or (arr.size and (arr.min() < 0 or arr.max() > 2)):
            raise ValueError(
                f"lights must be light states (0 green, 1 yellow, 2 red) of shape {want}, got "
                f"{arr.dtype} of shape {arr.shape}"
            )
        return arr.astype(np.uint8, copy=False)

    def _lut(self, lights: np.ndarray) -> np.ndarray:
        """256-entry table from raster byte to packed view byte, for light states (3, L) at the three lags."""
        if self.light_encoding == "flag":
            code = np.where(lights == 0, 0, 3).astype(
                np.uint8
            )  # (3, L): green not drawn, yellow and red as red
        else:
            code = lights.astype(np.uint8) + 1  # (3, L): 1 green, 2 yellow, 3 red
        ids = np.zeros(64, dtype=np.uint8)
        ids[1 : self._n_lights + 1] = (
            (code[0] << LIGHT_SHIFTS[0]) | (code[1] << LIGHT_SHIFTS[1]) | (code[2] << LIGHT_SHIFTS[2])
        )
        return self._low | ids[np.arange(256) >> 2]

    def _indices(self, x: float, y: float, yaw: float) -> np.ndarray:
        """Flat raster indices (192, 192) int32 of the view's pixels for one pose.

        Pixel (r, q) sees the world point car + forward f_r + right l_q, right = (sin, -cos):
        its raster column is col0 + cos f_r + sin l_q and its row row0 - sin f_r + cos l_q
        (in pixels), each an outer sum of a row term and a column term. Computed in float32
        (a ten-thousandth of a pixel off at worst) and truncated, which is the floor here
        because the raster's margin keeps every index positive.
        """
        ras = self.raster
        c, s = math.cos(yaw), math.sin(yaw)
        col0 = (x - ras.x_min) * ras.res
        row0 = (ras.y_max - y) * ras.res
        col = np.add.outer((col0 + c * self._f).astype(np.float32), (s * self._r).astype(np.float32))
        row = np.add.outer((row0 - s * self._f).astype(np.float32), (c * self._r).astype(np.float32))
        reach = self._reach
        if not (reach <= col0 < ras.width - reach and reach <= row0 < ras.height - reach):
            np.clip(col, 0, ras.width - 1, out=col)  # a pose near the raster's edge: clamp
            np.clip(row, 0, ras.height - 1, out=row)
        idx = row.astype(np.int32)
        idx *= ras.width
        idx += col.astype(np.int32)
        return idx

    def packed(self, x: float, y: float, yaw: float, lights: np.ndarray) -> np.ndarray:
        """(S, S) uint8 packed view, one byte per pixel (cheap to store; see the module docstring and
        ``unpack``)."""
        lights = self.check_lights(lights)
        return self._pool(self._lut(lights).take(self.raster.code.ravel().take(self._indices(x, y, yaw))))

    def _pool(self, codes: np.ndarray) -> np.ndarray:
        """(..., 192, 192) packed bytes -> (..., S, S): OR of the road bits, maximum of each light code
        (``driving.pooling.pool_packed``, as strided slices)."""
        return pool_packed(codes, self.pool)

    def unpack(self, packed: np.ndarray) -> np.ndarray:
        """(..., S, S) packed bytes -> (..., 5, S, S) float32 channels: road 0/1, lights 0/0.3/0.6/1."""
        packed = np.asarray(packed, dtype=np.uint8)
        out = np.empty(packed.shape[:-2] + (5,) + packed.shape[-2:], dtype=np.float32)
        for c in range(5):
            out[..., c, :, :] = UNPACK_TABLE[c].take(packed)
        return out

    def render(self, x: float, y: float, yaw: float, lights: np.ndarray) -> np.ndarray:
        """(5, S, S) float32 BEV of a car at (x, y) heading ``yaw``.

        Args:
            lights: (3, L) light states (0 green, 1 yellow, 2 red) of every stop line at the lags of
                channels 2, 3 and 4 (``HISTORY_LAGS`` steps ago), e.g. ``DrivingSim.light_history()``.
        """
        return self.unpack(self.packed(x, y, yaw, lights))

    def packed_batch(self, poses: np.ndarray, lights: np.ndarray) -> np.ndarray:
        """(B, S, S) packed views of poses (B, 3) = (x, y, yaw) with light states (B, 3, L)."""
        poses = np.asarray(poses, dtype=float).reshape(-1, 3)
        lights = self.check_lights(lights, batch=len(poses))
        out = np.empty((len(poses), self.size, self.size), dtype=np.uint8)
        for b in range(len(poses)):
            out[b] = self.packed(poses[b, 0], poses[b, 1], poses[b, 2], lights[b])
        return out

    def render_batch(self, poses: np.ndarray, lights: np.ndarray) -> np.ndarray:
        """(B, 5, S, S) float32 BEVs of poses (B, 3) = (x, y, yaw) with light states (B, 3, L)."""
        return self.unpack(self.packed_batch(poses, lights))


def get_renderer(town_name: str, size: int = FULL_SIZE, light_encoding: str = "intensity") -> BEVRenderer:
    """A renderer for ``town_name`` at ``size`` (checked against ``SUPPORTED_SIZES``)."""
    check_choice("town", town_name, TOWNS)
    return BEVRenderer(get_raster(town_name), check_bev_size(size), light_encoding)
