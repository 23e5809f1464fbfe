"""Lanes: the directed centre lines a car drives along, with dense 1 m waypoints.

A town is a graph of axis-aligned roads between nodes (junctions and corners). Every road
carries one 4 m lane per direction, right-hand traffic, so a lane runs 2 m to the right of the
road's centre line. Around each node the last ``ARM_LENGTH`` metres of every road belong to
the junction: there, *connector* lanes join each incoming lane to each outgoing lane other
than the way back (no U-turns): a straight line, a right turn of radius 7 m or a left turn of
radius 11 m, both tangent to the lanes they join, so that the road centre line turns on a
9 m radius as in CARLA's towns.

An *approach* is one incoming lane at one node with the legal exits from it. At a T-junction
each approach has two exits; at a corner (a node of degree 2) there is one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

LANE_WIDTH = 4.0
"""Width of one lane in metres (a road is two lanes, 8 m)."""
ARM_LENGTH = 9.0
"""Distance from a node's centre to where its junction begins on every road (metres)."""
RIGHT_TURN_RADIUS = ARM_LENGTH - LANE_WIDTH / 2
"""Radius of a right-turn connector (7 m): the road centre line turns on ``ARM_LENGTH``."""
LEFT_TURN_RADIUS = ARM_LENGTH + LANE_WIDTH / 2
"""Radius of a left-turn connector (11 m)."""
WAYPOINT_SPACING = 1.0
"""Largest distance between consecutive waypoints of a lane (metres)."""

DIRECTIONS = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])
"""Unit vectors of the four compass directions, indexed 0 = east, 1 = north, 2 = west, 3 = south."""
DIRECTION_NAMES = ("east", "north", "west", "south")
TURNS = ("left", "straight", "right")
"""The exits an approach can have, named from the driver's seat."""


def right_of(d: np.ndarray) -> np.ndarray:
    """The unit vector 90 degrees clockwise of ``d`` (the driver's right, x east and y north)."""
    return np.array([d[1], -d[0]])


def left_of(d: np.ndarray) -> np.ndarray:
    """The unit vector 90 degrees counter-clockwise of ``d`` (the driver's left)."""
    return np.array([-d[1], d[0]])


def direction_index(vec) -> int:
    """Index into ``DIRECTIONS`` of an axis-aligned vector; ValueError for a diagonal one."""
    x, y = float(vec[0]), float(vec[1])
    if abs(x) > 1e-9 and abs(y) > 1e-9 or (abs(x) < 1e-9 and abs(y) < 1e-9):
        raise ValueError(f"roads must be axis-aligned and of non-zero length, got direction ({x}, {y})")
    if abs(y) < 1e-9:
        return 0 if x > 0 else 2
    return 1 if y > 0 else 3


@dataclass(eq=False)
class Lane:
    """One directed lane: a straight segment or a circular arc, with its dense waypoints."""

    id: int
    """Index of the lane in ``Town.lanes``."""
    kind: str
    """"road" (between two junctions) or "connector" (inside a junction or corner)."""
    start: np.ndarray
    """(2,) first point (metres)."""
    end: np.ndarray
    """(2,) last point (metres); the next lane starts here."""
    length: float
    """Arc length in metres."""
    turn: str = "straight"
    """"straight", "left" or "right" (road lanes are straight)."""
    node: int = -1
    """For a connector: the node it crosses; -1 for a road lane."""
    from_node: int = -1
    """For a road lane: the node it leaves; for a connector: -1."""
    to_node: int = -1
    """For a road lane: the node it enters; for a connector: -1."""
    center: np.ndarray | None = None
    """(2,) centre of the arc of a turning connector; None for straight lanes."""
    radius: float = 0.0
    """Radius of a turning connector (metres); 0 for straight lanes."""
    successors: list[int] = field(default_factory=list)
    """Ids of the lanes that may follow this one."""
    points: np.ndarray = field(default=None, repr=False)
    """(K, 2) waypoints at equal spacing <= ``WAYPOINT_SPACING``, from ``start`` (``end`` excluded)."""
    headings: np.ndarray = field(default=None, repr=False)
    """(K,) direction of travel at each waypoint (radians, counter-clockwise from east)."""

    def __post_init__(self):
        self.start = np.asarray(self.start, dtype=float)
        self.end = np.asarray(self.end, dtype=float)
        if self.points is None:
            n = max(1, math.ceil(self.length / WAYPOINT_SPACING - 1e-9))
            s = np.arange(n) * (self.length / n)
            self.points, self.headings = self.sample(s)

    @property
    def heading_in(self) -> float:
        """Direction of travel where the lane starts (radians)."""
        return float(self.sample(np.array([0.0]))[1][0])

    @property
    def heading_out(self) -> float:
        """Direction of travel where the lane ends (radians)."""
        return float(self.sample(np.array([self.length]))[1][0])

    def sample(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points (N, 2) and headings (N,) at arc lengths ``s`` (N,) from the start."""
        s = np.asarray(s, dtype=float)
        if self.center is None:
            d = (self.end - self.start) / self.length
            pts = self.start[None, :] + s[:, None] * d[None, :]
            return pts, np.full(s.shape, math.atan2(d[1], d[0]))
        sign = 1.0 if self.turn == "left" else -1.0  # counter-clockwise for a left turn
        phi0 = math.atan2(self.start[1] - self.center[1], self.start[0] - self.center[0])
        phi = phi0 + sign * s / self.radius
        pts = self.center[None, :] + self.radius * np.stack([np.cos(phi), np.sin(phi)], axis=1)
        return pts, phi + sign * math.pi / 2

    def distance_to(self, xy: np.ndarray) -> np.ndarray:
        """Distance (N,) from points ``xy`` (N, 2) to the lane's centre line (a segment or an arc)."""
        xy = np.asarray(xy, dtype=float)
        if self.center is None:
            d = (self.end - self.start) / self.length
            t = np.clip((xy - self.start) @ d, 0.0, self.length)
            return np.linalg.norm(xy - (self.start + t[:, None] * d), axis=1)
        rel = xy - self.center
        r = np.linalg.norm(rel, axis=1)
        phi = np.arctan2(rel[:, 1], rel[:, 0])
        sign = 1.0 if self.turn == "left" else -1.0
        phi0 = math.atan2(self.start[1] - self.center[1], self.start[0] - self.center[0])
        # angle travelled from the start, wrapped to (-pi, pi]; inside the arc if in [0, sweep]
        along = np.angle(np.exp(1j * sign * (phi - phi0)))
        sweep = self.length / self.radius
        inside = (along >= 0) & (along <= sweep)
        d_arc = np.abs(r - self.radius)
        d_end = np.minimum(np.linalg.norm(xy - self.start, axis=1), np.linalg.norm(xy - self.end, axis=1))
        return np.where(inside, d_arc, d_end)


@dataclass(eq=False)
class Approach:
    """One incoming lane at one node, with the legal exits from it."""

    id: int
    """Index in ``Town.approaches``."""
    node: int
    """The node (junction or corner) the lane enters."""
    arm: int
    """Direction index (0 E, 1 N, 2 W, 3 S) from the node towards where the car comes from."""
    lane: int
    """Id of the incoming road lane."""
    exits: dict[str, int]
    """Turn ("left", "straight", "right") -> id of the connector lane that takes it."""
    is_junction: bool
    """True at a T-junction (a choice, and a traffic light), False at a corner."""
    entry: np.ndarray
    """(2,) where the junction begins on this lane: the end of the incoming lane."""

    @property
    def direction(self) -> np.ndarray:
        """(2,) unit vector of travel on the incoming lane."""
        return -DIRECTIONS[self.arm]


def build_lanes(nodes: np.ndarray, edges: list[tuple[int, int]]) -> tuple[list[Lane], list[Approach]]:
    """Build every lane and every approach of a road graph.

    Args:
        nodes: (N, 2) node centres in metres.
        edges: undirected roads as pairs of node indices, each axis-aligned and longer than
            two junction arms.

    Returns:
        ``(lanes, approaches)``: road lanes first (two per edge), then connectors (one per
        approach and exit), each with its successors filled in.
    """
    nodes = np.asarray(nodes, dtype=float)
    arms: list[dict[int, int]] = [dict() for _ in range(len(nodes))]  # node -> {direction: neighbour}
    for u, v in edges:
        d = direction_index(nodes[v] - nodes[u])
        if np.linalg.norm(nodes[v] - nodes[u]) <= 2 * ARM_LENGTH + 1.0:
            raise ValueError(f"road {u}-{v} is too short for two junctions")
        if d in arms[u] or (d + 2) % 4 in arms[v]:
            raise ValueError(f"two roads leave node {u} or {v} in the same direction")
        arms[u][d] = v
        arms[v][(d + 2) % 4] = u

    lanes: list[Lane] = []
    road_lane: dict[tuple[int, int], int] = {}  # (from node, to node) -> lane id
    for u, v in edges:
        for a, b in ((u, v), (v, u)):
            d = DIRECTIONS[direction_index(nodes[b] - nodes[a])]
            off = right_of(d) * (LANE_WIDTH / 2)
            start = nodes[a] + d * ARM_LENGTH + off
            end = nodes[b] - d * ARM_LENGTH + off
            lane = Lane(
                len(lanes), "road", start, end, float(np.linalg.norm(end - start)), from_node=a, to_node=b
            )
            road_lane[(a, b)] = lane.id
            lanes.append(lane)

    approaches: list[Approach] = []
    for n, node_arms in enumerate(arms):
        if len(node_arms) < 2:
            raise ValueError(f"node {n} is a dead end: every node needs at least two roads")
        for a, src in sorted(node_arms.items()):
            t_in = -DIRECTIONS[a]
            start = nodes[n] + DIRECTIONS[a] * ARM_LENGTH + right_of(t_in) * (LANE_WIDTH / 2)
            exits: dict[str, int] = {}
            for b in sorted(node_arms):
                if b == a:
                    continue  # no U-turns
                t_out = DIRECTIONS[b]
                end = nodes[n] + t_out * ARM_LENGTH + right_of(t_out) * (LANE_WIDTH / 2)
                cross = t_in[0] * t_out[1] - t_in[1] * t_out[0]
                if b == (a + 2) % 4:
                    lane = Lane(
                        len(lanes), "connector", start, end, float(np.linalg.norm(end - start)), node=n
                    )
                else:  # a quarter circle, to the left if cross > 0
                    turn, r, side = (
                        ("left", LEFT_TURN_RADIUS, left_of)
                        if cross > 0
                        else ("right", RIGHT_TURN_RADIUS, right_of)
                    )
                    lane = Lane(
                        len(lanes),
                        "connector",
                        start,
                        end,
                        r * math.pi / 2,
                        turn=turn,
                        node=n,
                        center=start + side(t_in) * r,
                        radius=r,
                    )
                lane.successors = [road_lane[(n, node_arms[b])]]
                lanes.append(lane)
                exits[lane.turn] = lane.id
            incoming = road_lane[(src, n)]
            lanes[incoming].successors = sorted(exits.values())
            approaches.append(
                Approach(
                    len(approaches), n, a, incoming, exits, len(node_arms) >= 3, lanes[incoming].end.copy()
                )
            )
    return lanes, approaches
