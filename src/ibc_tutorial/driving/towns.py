"""The two towns, laid out after CARLA's town01 (training) and town02 (evaluation).

Only T-junctions and corners, one 4 m lane per direction, right-hand traffic, rounded
corners, as in CARLA's first two towns (the layouts are listed in ``docs/design.md``). A layout is a list of
node centres, the axis-aligned roads between them, and the rectangular blocks the roads enclose;
``Town`` turns it into lanes with dense waypoints, approaches with their legal exits, stop
lines (one traffic-light head per junction approach) and building footprints.

Coordinates are metres, x east and y north.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import numpy as np

from ibc_tutorial.driving.lanes import ARM_LENGTH, LANE_WIDTH, RIGHT_TURN_RADIUS, Approach, Lane, build_lanes
from ibc_tutorial.driving.lights import StopLine, make_stop_lines
from ibc_tutorial.utils import check_choice

SIDEWALK = 1.5
"""Gap between the kerb and a building (metres)."""


@dataclass(frozen=True)
class TownLayout:
    """The road graph of a town: nodes, roads and the blocks between them."""

    name: str
    """"town01" or "town02"."""
    nodes: tuple[tuple[float, float], ...]
    """Node centres (junctions and corners) in metres."""
    roads: tuple[tuple[int, int], ...]
    """Axis-aligned roads between pairs of nodes."""
    blocks: tuple[tuple[float, float, float, float], ...]
    """Blocks enclosed by road centre lines, as (x0, y0, x1, y1); each holds one building."""


def _layout(name, nodes: dict[str, tuple[float, float]], chains: list[list[str]], blocks) -> TownLayout:
    keys = list(nodes)
    roads = []
    for chain in chains:
        for a, b in zip(chain[:-1], chain[1:], strict=True):
            roads.append((keys.index(a), keys.index(b)))
    return TownLayout(name, tuple(nodes.values()), tuple(roads), tuple(blocks))


# town01, about 400 x 335 m, 12 T-junctions: an outer loop, north-south roads at x = 88 and 335,
# east-west connectors between them at y = 55, 130 and 196, and a stub at x = 152 (y 0 to 55).
TOWN01 = _layout(
    "town01",
    {
        "sw": (0, 0),
        "se": (394, 0),
        "ne": (394, 328),
        "nw": (0, 328),
        "s88": (88, 0),
        "s152": (152, 0),
        "s335": (335, 0),
        "n88": (88, 328),
        "n335": (335, 328),
        "a88": (88, 55),
        "a152": (152, 55),
        "a335": (335, 55),
        "b88": (88, 130),
        "b335": (335, 130),
        "c88": (88, 196),
        "c335": (335, 196),
    },
    [
        ["sw", "s88", "s152", "s335", "se", "ne", "n335", "n88", "nw", "sw"],
        ["s88", "a88", "b88", "c88", "n88"],
        ["s335", "a335", "b335", "c335", "n335"],
        ["a88", "a152", "a335"],
        ["b88", "b335"],
        ["c88", "c335"],
        ["s152", "a152"],
    ],
    [
        (0, 0, 88, 328),
        (335, 0, 394, 328),
        (88, 0, 152, 55),
        (152, 0, 335, 55),
        (88, 55, 335, 130),
        (88, 130, 335, 196),
        (88, 196, 335, 328),
    ],
)

# town02, about 200 x 200 m, 8 T-junctions: an outer loop, an east-west road at y = 82, north-south
# roads at x = 50 (y 82 to 197) and x = 139 (y 82 to 131), and an east-west road at y = 131 (x 50 to 196).
TOWN02 = _layout(
    "town02",
    {
        "sw": (0, 0),
        "se": (196, 0),
        "ne": (196, 197),
        "nw": (0, 197),
        "w82": (0, 82),
        "m82": (50, 82),
        "c82": (139, 82),
        "e82": (196, 82),
        "m131": (50, 131),
        "c131": (139, 131),
        "e131": (196, 131),
        "n50": (50, 197),
    },
    [
        ["sw", "se", "e82", "e131", "ne", "n50", "nw", "w82", "sw"],
        ["w82", "m82", "c82", "e82"],
        ["m82", "m131", "n50"],
        ["c82", "c131"],
        ["m131", "c131", "e131"],
    ],
    [(0, 0, 196, 82), (0, 82, 50, 197), (50, 82, 139, 131), (139, 82, 196, 131), (50, 131, 196, 197)],
)

LAYOUTS = {"town01": TOWN01, "town02": TOWN02}
TOWNS = tuple(LAYOUTS)
"""Names of the towns: ``("town01", "town02")``."""


def building_polygon(block: tuple[float, float, float, float]) -> np.ndarray:
    """(8, 2) footprint of the building on a block: inset ``SIDEWALK`` from the kerbs, corners cut.

    The kerb at each corner of a block is an arc of radius ``RIGHT_TURN_RADIUS - LANE_WIDTH/2``
    (the inside of a right turn); each corner is cut by the tangent to that arc shrunk by the
    sidewalk, so the building keeps about ``SIDEWALK`` metres (at least 1.2 m) from the road.
    """
    x0, y0, x1, y1 = block
    inset = LANE_WIDTH + SIDEWALK  # from the road centre line
    kerb_r = RIGHT_TURN_RADIUS - LANE_WIDTH / 2
    # corner arc centre is ARM_LENGTH from the node along both roads; cut tangent at radius kerb_r - SIDEWALK
    cut = 2 * ARM_LENGTH - (kerb_r - SIDEWALK) * math.sqrt(2) - 2 * inset  # x+y of the cut, minus the corner
    cut = max(cut, 0.0)
    ax0, ay0, ax1, ay1 = x0 + inset, y0 + inset, x1 - inset, y1 - inset
    return np.array(
        [
            (ax0 + cut, ay0),
            (ax1 - cut, ay0),
            (ax1, ay0 + cut),
            (ax1, ay1 - cut),
            (ax1 - cut, ay1),
            (ax0 + cut, ay1),
            (ax0, ay1 - cut),
            (ax0, ay0 + cut),
        ]
    )


class Town:
    """A town built from its layout: lanes, approaches, stop lines, buildings, extent."""

    def __init__(self, layout: TownLayout):
        self.layout = layout
        self.name = layout.name
        self.nodes = np.array(layout.nodes, dtype=float)  # (N, 2)
        self.lanes: list[Lane]
        self.approaches: list[Approach]
        self.lanes, self.approaches = build_lanes(self.nodes, list(layout.roads))
        self.junction_nodes = sorted({ap.node for ap in self.approaches if ap.is_junction})
        self.stop_lines: list[StopLine] = make_stop_lines(self.approaches, self.junction_nodes)
        self.approach_of_lane = {ap.lane: ap.id for ap in self.approaches}  # incoming road lane -> approach
        self.light_of_approach = {s.approach: s.id for s in self.stop_lines}
        self.buildings = [building_polygon(b) for b in layout.blocks]
        half = LANE_WIDTH
        self.extent = (
            float(self.nodes[:, 0].min() - half),
            float(self.nodes[:, 1].min() - half),
            float(self.nodes[:, 0].max() + half),
            float(self.nodes[:, 1].max() + half),
        )
        """(xmin, ymin, xmax, ymax) of the roads in metres."""
        # every waypoint of every lane, for localisation
        self.wp_xy = np.concatenate([ln.points for ln in self.lanes])  # (W, 2)
        self.wp_heading = np.concatenate([ln.headings for ln in self.lanes])  # (W,)
        self.wp_lane = np.concatenate([np.full(len(ln.points), ln.id) for ln in self.lanes])  # (W,)
        self.wp_index = np.concatenate([np.arange(len(ln.points)) for ln in self.lanes])  # (W,)
        self.road_lanes = [ln.id for ln in self.lanes if ln.kind == "road"]

    @property
    def n_junctions(self) -> int:
        return len(self.junction_nodes)

    @property
    def n_lights(self) -> int:
        return len(self.stop_lines)

    @property
    def size(self) -> tuple[float, float]:
        """(width, height) of the road network in metres."""
        x0, y0, x1, y1 = self.extent
        return x1 - x0, y1 - y0

    def localize(
        self, x: float, y: float, yaw: float, max_heading_error: float = math.pi / 3
    ) -> tuple[int, int, float]:
        """The lane waypoint nearest to (x, y) among those heading within ``max_heading_error`` of ``yaw``.

        Returns ``(lane id, waypoint index, distance in metres)``.
        """
        dh = np.abs(np.angle(np.exp(1j * (self.wp_heading - yaw))))
        d2 = (self.wp_xy[:, 0] - x) ** 2 + (self.wp_xy[:, 1] - y) ** 2
        d2 = np.where(dh <= max_heading_error, d2, np.inf)
        k = int(np.argmin(d2))
        return int(self.wp_lane[k]), int(self.wp_index[k]), float(math.sqrt(d2[k]))

    def next_lane(self, lane_id: int, turn: str | None = None) -> int:
        """The lane after ``lane_id``; at a junction approach, the exit named by ``turn``."""
        lane = self.lanes[lane_id]
        if lane.kind == "connector":
            return lane.successors[0]
        ap = self.approaches[self.approach_of_lane[lane_id]]
        if len(ap.exits) == 1:
            return next(iter(ap.exits.values()))
        if turn not in ap.exits:
            raise ValueError(f"turn must be one of {sorted(ap.exits)} at approach {ap.id}, got {turn!r}")
        return ap.exits[turn]

    def __repr__(self) -> str:
        w, h = self.size
        return (
            f"Town({self.name!r}: {w:.0f} x {h:.0f} m, {self.n_junctions} junctions, "
            f"{self.n_lights} lights, {len(self.lanes)} lanes)"
        )


@cache
def get_town(name: str = "town01") -> Town:
    """The town called ``name`` ("town01" or "town02"), built once and cached."""
    check_choice("town", name, TOWNS)
    return Town(LAYOUTS[name])
