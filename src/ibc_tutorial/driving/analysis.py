"""Where a car went: junction passes, exits taken per approach (``exit_counts``, the one count of
them), share of the road network covered.

The measures of the DA-IBC paper's Fig. 5 analogue (free driving in town02, chapter 09): a
multimodal agent leaves one junction approach by different exits on different visits and so
covers more of the town; a unimodal one always turns the same way. The inputs are the
per-step records of ``driving.rollout`` with ``RolloutRecording(steps=True)`` (its ``EpisodeResult.trace``).

And two measures of the expert's labels (chapter 07): ``light_label_conflicts`` (how often the
BEV's light channels contradict the expert near a stop line, per encoding) and
``speed_control_report`` (derivative kicks and throttle/brake chatter in its acceleration).
"""

from __future__ import annotations

import numpy as np

from ibc_tutorial.driving.lanes import TURNS
from ibc_tutorial.driving.towns import Town, get_town
from ibc_tutorial.utils import check_choice, check_positive

COVERAGE_HEADING = np.pi / 3
"""A waypoint counts as passed only by a pose heading within this angle (60 degrees) of its lane."""


def _town(town) -> Town:
    return get_town(town) if isinstance(town, str) else town


def junction_visits(town, lanes: np.ndarray, *, ended_inside: bool = False) -> list[dict]:
    """Every pass through a junction in a sequence of lanes: ``{"approach", "node", "turn", "step"}``.

    The exit is read from the first road lane after the approach lane: the turn whose connector
    leads onto it (robust to the overlapping connectors at a junction's entry). ``step`` is the
    last step on the approach lane. With ``ended_inside``, a record that ends inside a junction
    (a demonstration's route ends once its last turn is begun) adds that pass too, its exit read
    from the first of the approach's connectors it entered.
    """
    tw = _town(town)
    road = set(tw.road_lanes)
    lanes = np.asarray(lanes).reshape(-1)
    visits = []
    prev, prev_step = None, None
    for k, lane in enumerate(lanes.tolist()):
        if lane not in road:
            continue
        if prev is not None and lane != prev:
            visits += _junction_pass(
                tw, prev, prev_step, lambda conn, lane=lane: lane in tw.lanes[conn].successors
            )
        prev, prev_step = lane, k
    if ended_inside and prev is not None and len(lanes) and int(lanes[-1]) not in road:
        entered = lanes[prev_step + 1 :].tolist()  # the lanes after the last road lane
        first = {conn: entered.index(conn) for conn in set(entered)}
        visits += _junction_pass(tw, prev, prev_step, first.__contains__, order=first.get)
    return visits


def _junction_pass(tw: Town, lane: int, step: int, took, order=None) -> list[dict]:
    """The pass from approach lane ``lane`` (last on it at ``step``) by the first exit whose connector
    ``took(connector)`` accepts (in the order of ``order(connector)`` if given); [] if none or no junction."""
    ap_id = tw.approach_of_lane.get(lane)
    if ap_id is None or not tw.approaches[ap_id].is_junction:
        return []
    ap = tw.approaches[ap_id]
    exits = [(turn, conn) for turn, conn in ap.exits.items() if took(conn)]
    if order is not None:
        exits.sort(key=lambda e: order(e[1]))
    if not exits:
        return []
    return [{"approach": int(ap_id), "node": int(ap.node), "turn": exits[0][0], "step": int(step)}]


def log_junction_visits(log) -> list[dict]:
    """``junction_visits`` of every episode of a demonstration log (``driving.dataset.DemoLog``),
    the pass each route ends inside included (``ended_inside``): the exits its expert took."""
    return [v for sl in log.episodes() for v in junction_visits(log.town, log.lane[sl], ended_inside=True)]


def exit_counts(visits) -> dict[int, dict[str, int]]:
    """Visits of each junction approach by exit: ``{approach: {"left": n, "straight": n, "right": n}}``.

    The one count of exits per junction approach (chapters 07, 09, 10). ``visits``: the dicts of
    ``junction_visits`` or ``log_junction_visits`` (keys "approach" and "turn").
    """
    out: dict[int, dict[str, int]] = {}
    for v in visits:
        try:
            ap, turn = int(v["approach"]), v["turn"]
        except (TypeError, KeyError, ValueError):
            raise ValueError(
                f"visits must be dicts with an integer 'approach' and a 'turn', got {v!r}"
            ) from None
        check_choice("turn", turn, TURNS)
        out.setdefault(ap, dict.fromkeys(TURNS, 0))[turn] += 1
    return out


def junction_crossings(town, lanes: np.ndarray, steer: np.ndarray) -> list[dict]:
    """Every crossing of a junction in an episode's record, with the steering applied during it.

    A crossing starts at the first state off a junction approach lane and lasts until the first
    state on a road lane again (the exit), or to the end of the record: an episode that ended
    inside the junction (in a building, off the road) ends its last crossing unfinished.

    Args:
        town: a town name or ``Town``.
        lanes: (T + 1,) the lane of each state (``EpisodeResult.trace["lane"]``).
        steer: (T,) the steering applied after each state (``trace["actions"][:, 0]``; positive
            turns right, chapter 7).

    Returns:
        One dict per crossing: ``approach``, ``node``, ``start`` and ``stop`` (its states are
        ``start .. stop - 1``), ``turn`` (the exit taken; "" if the record ends inside, "?" if the
        road lane reached is none of the approach's exits),
        ``finished`` (False for that last one), ``steer_min`` and ``steer_max`` (the most leftward
        and most rightward steering applied during it).
    """
    tw = _town(town)
    road = set(tw.road_lanes)
    lanes = np.asarray(lanes).reshape(-1)
    steer = np.asarray(steer, dtype=float).reshape(-1)
    if len(steer) not in (len(lanes), len(lanes) - 1):
        raise ValueError(
            f"steer must hold one value per state or per step: {len(lanes)} states, got {len(steer)}"
        )
    out: list[dict] = []
    open_: dict | None = None
    prev_road = None  # the last road lane seen
    for k, lane in enumerate(lanes.tolist()):
        if lane in road:
            if open_ is not None:
                ap = tw.approaches[open_["approach"]]
                open_["turn"] = next((t for t, c in ap.exits.items() if lane in tw.lanes[c].successors), "?")
                open_["stop"], open_["finished"] = k, True
                out.append(open_)
                open_ = None
            prev_road = lane
        elif open_ is None and prev_road is not None:
            ap_id = tw.approach_of_lane.get(prev_road)
            if ap_id is not None and tw.approaches[ap_id].is_junction:
                open_ = {"approach": int(ap_id), "node": int(tw.approaches[ap_id].node), "start": k}
            prev_road = None
    if open_ is not None:
        open_.update(stop=len(lanes), turn="", finished=False)
        out.append(open_)
    for c in out:
        s = steer[c["start"] : min(c["stop"], len(steer))]
        c["steer_min"] = float(s.min()) if len(s) else 0.0
        c["steer_max"] = float(s.max()) if len(s) else 0.0
    return out


def exits_per_approach(visits: list[dict]) -> dict[int, dict]:
    """Per junction approach: visits and the different exits taken, ``{approach: {"node", "visits",
    "turns"}}``.

    The summary the replication's free-driving record stores; the counts are ``exit_counts``'s,
    ``turns`` lists the exits taken in the order first taken.
    """
    counts = exit_counts(visits)
    out: dict[int, dict] = {}
    for v in visits:
        d = out.setdefault(
            v["approach"],
            {"node": v["node"], "visits": sum(counts[int(v["approach"])].values()), "turns": []},
        )
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
        d2 = ((wp[a : a + chunk, None, :] - poses[None, :, :2]) ** 2).sum(-1)  # (C, T) squared distances
        aligned = lane_dir[a : a + chunk] @ car_dir.T >= np.cos(
            COVERAGE_HEADING
        )  # (C, T): cos(heading gap) >= cos 60°
        covered[a : a + chunk] = ((d2 <= radius * radius) & aligned).any(1)
    return float(covered.mean())


def stop_line_gaps(
    town, poses: np.ndarray, lanes: np.ndarray, car_half: float = 2.3
) -> tuple[np.ndarray, np.ndarray]:
    """Distance from the front bumper to the stop line of the lane being driven, and its light.

    Args:
        town: a town name or ``Town``.
        poses: (N, 3) poses (x, y, yaw); lanes: (N,) the lane of each pose.
        car_half: half the car's length (metres).

    Returns:
        gaps (N,) metres (NaN off a light-controlled approach lane; negative past the line) and
        light (N,) ids of those lines (-1 where none).
    """
    from ibc_tutorial.driving.lights import STOP_LINE_THICKNESS

    tw = _town(town)
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    lanes = np.asarray(lanes).reshape(-1)
    light = np.array(
        [tw.light_of_approach.get(tw.approach_of_lane.get(int(ln), -1), -1) for ln in lanes], dtype=int
    )
    gaps = np.full(len(poses), np.nan)
    on = light >= 0
    if on.any():
        entry = np.array([tw.stop_lines[k].entry for k in light[on]])  # (M, 2)
        d = np.array([tw.stop_lines[k].direction for k in light[on]])  # (M, 2) unit travel direction
        front = poses[on, :2] + car_half * np.stack([np.cos(poses[on, 2]), np.sin(poses[on, 2])], axis=1)
        gaps[on] = ((entry - STOP_LINE_THICKNESS * d - front) * d).sum(1)
    return gaps, light


def light_label_conflicts(log, stop_distance: float = 9.5, stopped_speed: float = 0.1) -> dict:
    """How the expert's labels near a stop line agree with what the light channels show.

    Every sample whose front bumper is within ``stop_distance`` metres before the stop line of its
    own lane is classed by that light's state at the sample (green, yellow, red) and by what the
    expert does on this approach from then on: ``"stop"`` if the car comes to rest
    (speed < ``stopped_speed`` with a label that does not pull away) before leaving the lane;
    ``"go"`` if it drives on into the junction, not braking at this sample; ``"slowing"`` if it
    brakes now yet drives on; ``"changed"`` if the light changed between the sample and that
    outcome (the state at the sample did not decide it). Samples of an episode that ends on the
    approach are left out. A *conflict* of an encoding is a sample whose channel value cannot
    tell the label apart from the opposite one:

    * ``"binary"`` (red and yellow drawn alike, green not drawn): yellow or red with "go", or green
      with "stop";
    * ``"red only"`` (yellow not drawn): red with "go", yellow or green with "stop";
    * ``"intensity"`` (each state its own value): red with "go" or green with "stop"; at yellow the
      expert's choice follows from the distance and the speed (``ExpertConfig.yellow_brake``),
      which the BEV and the state show, so it is no conflict of the channel.

    Args:
        log: a ``DemoLog`` (pose, speed, lights, lane, episode).

    Returns:
        ``{"counts": {(state, label): n}, "conflicts": {encoding: n}, "near": n}``.
    """
    from ibc_tutorial.driving.lights import GREEN, RED, YELLOW

    stop_distance = check_positive("stop_distance", stop_distance)
    gaps, light = stop_line_gaps(log.town, log.pose, log.lane)
    near = np.flatnonzero((gaps > 0) & (gaps <= stop_distance))
    resting = (log.speed < stopped_speed) & (log.action[:, 1] <= 0)  # (N,) at rest, not pulling away
    label = {}
    for i in near:  # walk on along the approach lane to the rest or to the junction
        j = i
        while (
            not resting[j]
            and j + 1 < len(log)
            and log.episode[j + 1] == log.episode[i]
            and log.lane[j + 1] == log.lane[i]
        ):
            j += 1
        if not resting[j] and (j + 1 == len(log) or log.episode[j + 1] != log.episode[i]):
            continue  # the episode ends on the approach: unknown
        if (log.lights[i : j + 1, light[i]] != log.lights[i, light[i]]).any():
            label[i] = "changed"  # the light changed before the outcome: the sample did not decide it
        elif resting[j]:
            label[i] = "stop"
        else:
            label[i] = "go" if log.action[i, 1] >= 0 else "slowing"
    near = np.array([i for i in near if i in label], dtype=int)
    names = {GREEN: "green", YELLOW: "yellow", RED: "red"}
    counts = {(s, lab): 0 for s in names.values() for lab in ("stop", "go", "slowing", "changed")}
    for i in near:
        counts[(names[int(log.lights[i, light[i]])], label[i])] += 1
    c = counts
    conflicts = {
        "binary": c[("yellow", "go")] + c[("red", "go")] + c[("green", "stop")],
        "red only": c[("red", "go")] + c[("yellow", "stop")] + c[("green", "stop")],
        "intensity": c[("red", "go")] + c[("green", "stop")],
    }
    return {"counts": counts, "conflicts": conflicts, "near": int(len(near))}


def speed_control_report(town: str = "town02", seeds=range(5), steps: int = 3000, config=None) -> dict:
    """How smooth the expert's acceleration labels are, over routeless drives of ``steps`` steps.

    Returns ``{"switch_jump": (S,), "sign_changes": (K,)}``: per drive, the largest change of the
    acceleration label at a step where the target speed switches between cruise and turn speed
    (a derivative kick shows here), and per stop for a light (a run of steps with a stop line to
    stop at), how often the label's sign flips between throttle and brake (chatter).
    """
    from ibc_tutorial.driving.env import make_env
    from ibc_tutorial.driving.expert import Expert, ExpertConfig

    config = ExpertConfig() if config is None else config
    env = make_env(town, bev_size=32, routeless=True, max_steps=steps)
    speeds = {config.cruise_speed, config.turn_speed}
    jumps, flips = [], []
    for seed in seeds:
        env.reset(seed=int(seed))
        expert = Expert(env, config)
        acc, target, stopping = [], [], []
        for _ in range(steps):
            a = expert.act()
            acc.append(float(a[1]))
            target.append(expert.last["target_speed"])
            stopping.append(expert.last["stop_distance"] is not None)
            _, _, terminated, truncated, _ = env.step(a)
            if terminated or truncated:
                break
        acc, target = np.array(acc), np.array(target)  # (T,), (T,)
        switch = [k for k in range(1, len(target)) if {target[k - 1], target[k]} == speeds]
        jumps.append(max((abs(acc[k] - acc[k - 1]) for k in switch), default=0.0))
        edges = np.flatnonzero(np.diff(np.r_[0, np.array(stopping, dtype=int), 0]))
        for a0, a1 in zip(edges[::2], edges[1::2], strict=True):
            sign = np.sign(acc[a0:a1])
            sign = sign[sign != 0]
            flips.append(int((np.diff(sign) != 0).sum()))
    return {"switch_jump": np.array(jumps), "sign_changes": np.array(flips, dtype=int)}
