"""Where a car went: junction passes, exits taken per approach, share of the road network covered.

The measures of the DA-IBC paper's Fig. 5 analogue (free driving in town02, chapter 09): a
multimodal agent leaves one junction approach by different exits on different visits and so
covers more of the town; a unimodal one always turns the same way. The inputs are the
per-step records of ``driving.rollout(..., record_steps=True)`` (its ``EpisodeResult.trace``).
"""

from __future__ import annotations

import numpy as np

from ibc_tutorial.driving.towns import Town, get_town
from ibc_tutorial.utils import check_positive

COVERAGE_HEADING = np.pi / 3
"""A waypoint counts as passed only by a pose heading within this angle (60 degrees) of its lane."""


def _town(town) -> Town:
    return get_town(town) if isinstance(town, str) else town


def junction_visits(town, lanes: np.ndarray) -> list[dict]:
    """Every pass through a junction in a sequence of lanes: ``{"approach", "node", "turn", "step"}``.

    The exit is read from the first road lane after the approach lane: the turn whose connector
    leads onto it (robust to the overlapping connectors at a junction's entry). ``step`` is the
    last step on the approach lane.
    """
    tw = _town(town)
    road = set(tw.road_lanes)
    visits = []
    prev, prev_step = None, None
    for k, lane in enumerate(np.asarray(lanes).tolist()):
        if lane not in road:
            continue
        if prev is not None and lane != prev:
            ap_id = tw.approach_of_lane.get(prev)
            if ap_id is not None and tw.approaches[ap_id].is_junction:
                ap = tw.approaches[ap_id]
                for turn, conn in ap.exits.items():
                    if lane in tw.lanes[conn].successors:
                        visits.append({"approach": int(ap_id), "node": int(ap.node), "turn": turn, "step": int(prev_step)})
                        break
        prev, prev_step = lane, k
    return visits


def exits_per_approach(visits: list[dict]) -> dict[int, dict]:
    """Per junction approach: visits and the different exits taken, ``{approach: {"node", "visits", "turns"}}``."""
    out: dict[int, dict] = {}
    for v in visits:
        d = out.setdefault(v["approach"], {"node": v["node"], "visits": 0, "turns": []})
        d["visits"] += 1
        if v["turn"] not in d["turns"]:
            d["turns"].append(v["turn"])
    return out


def road_coverage(town, poses: np.ndarray, radius: float = 3.0, *, chunk: int = 256) -> float:
    """Share of the town's road-lane waypoints (1 m apart, both directions) that the car passed.

    A waypoint counts as passed if some recorded pose (x, y, yaw) lies within ``radius`` metres
    of it with a heading within 60 degrees of the lane's (so driving one direction covers one
    lane). Exact, by distances from every waypoint to every pose, ``chunk`` waypoints at a time.

    Args:
        town: a town name or ``Town``.
        poses: (T, 3) recorded poses (x, y, yaw).
    """
    radius = check_positive("radius", radius)
    tw = _town(town)
    road = np.isin(tw.wp_lane, tw.road_lanes)
    wp, wh = tw.wp_xy[road], tw.wp_heading[road]  # (W, 2), (W,)
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)  # (T, 3)
    covered = np.zeros(len(wp), dtype=bool)  # (W,)
    if len(poses) == 0:
        return 0.0
    lane_dir = np.stack([np.cos(wh), np.sin(wh)], axis=1)  # (W, 2) unit headings
    car_dir = np.stack([np.cos(poses[:, 2]), np.sin(poses[:, 2])], axis=1)  # (T, 2)
    for a in range(0, len(wp), chunk):
        d2 = ((wp[a:a + chunk, None, :] - poses[None, :, :2]) ** 2).sum(-1)  # (C, T) squared distances
        aligned = lane_dir[a:a + chunk] @ car_dir.T >= np.cos(COVERAGE_HEADING)  # (C, T): cos(heading gap) >= cos 60°
        covered[a:a + chunk] = ((d2 <= radius * radius) & aligned).any(1)
    return float(covered.mean())
