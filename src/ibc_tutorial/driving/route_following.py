"""Route following in town02: fixed routes, their commands, and how far a policy drives each (chapter 11).

**The routes** (``ROUTES``, listed here once): six town02 routes, each at least 1 km long with 7 to 15
junction crossings; together they take every exit of every junction approach of the town (48), so
left, straight and right, and both exits of all eight stems. They were picked from routes drawn by
``routes.random_route`` (greedy: first the fewest routes that take every stem exit, then those adding
the most approach exits not yet taken); ``tests/test_route_following.py`` checks the properties.
A route is a start on a road lane 3 m after its beginning and the turns at the T-junctions met; it
ends ``END_MARGIN_M`` before the entry of the junction after its last turn (``route_length``).

**Driving a route** (``drive_routes``): every route in its own environment (light phases seeded by the
route's index and ``seed``), side by side; at each step the policy sees the observation and, if it takes
one, the route's command (``driving.commands``). A ``RouteTracker`` follows the car along the route's
lanes. A route ends

* **completed**: the car has driven the route's length along it;
* **wrong turn**: the car reaches a road lane that is not the route's next one (it left a junction by
  another exit than the route's);
* **collision or leaving the road**: the simulator's termination (a building, off the road);
* **timeout**: after ``max_steps`` (the route's length at ``MIN_MEAN_SPEED`` m/s, lights included).

Per route: **route completion** (the share of the route's length driven along it before it ended), red
lights run (the simulator's rule), the **driving score** = completion x 0.7 ** (red lights) (CARLA's
leaderboard score with only its red-light penalty, the factor the DA-IBC paper uses), the paper's score
(distance x 0.7 ** red lights) and, per junction crossing of the route, the commanded exit and the exit
taken ("" if the route ended inside the junction): the **success rate per command** is the share of
crossings with that command whose commanded exit was taken (``junction_success``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ibc_tutorial.driving.commands import COMMANDS, FOLLOW, command_at, distance_to_entry
from ibc_tutorial.driving.env import EnvConfig, make_env
from ibc_tutorial.driving.expert import Expert, ExpertConfig
from ibc_tutorial.driving.rollout import DrivingPolicy
from ibc_tutorial.driving.routes import Route, random_route, random_start
from ibc_tutorial.driving.sim import SCORE_PENALTY, score
from ibc_tutorial.driving.towns import Town, get_town
from ibc_tutorial.utils import check_choice, check_int, check_positive, progress

ROUTE_TOWN = "town02"
"""The town the routes are in (the evaluation town, unseen in training)."""
START_S = 3.0
"""Every route starts this far (metres) along its first lane."""
END_MARGIN_M = 12.0
"""A route ends this far before the end of its last lane (before the next junction's stop line)."""
MIN_MEAN_SPEED = 1.5
"""A route's step budget: its length at this mean speed (m/s), waits at red lights included."""
ROUTES: dict[str, tuple[int, tuple[str, ...]]] = {
    "r1": (29, ("left", "left", "left", "right", "right", "right", "right", "left", "right", "left", "left",
                "left", "right", "right", "left")),
    "r2": (23, ("right", "right", "right", "left", "right", "left", "left", "left", "left", "right", "right",
                "straight", "right", "straight")),
    "r3": (17, ("left", "left", "right", "right", "left", "left", "straight", "left", "straight", "right")),
    "r4": (28, ("straight", "right", "straight", "straight", "straight", "right", "straight")),
    "r5": (20, ("left", "straight", "straight", "straight", "left", "straight", "straight")),
    "r6": (14, ("straight", "left", "left", "left", "right", "right", "straight")),
}  # fmt: skip
"""name -> (town02 road lane the route starts on, its turns at the T-junctions met)."""


def build_route(name: str) -> Route:
    """The ``Route`` of ``ROUTES[name]``."""
    lane, turns = ROUTES[check_choice("name", name, tuple(ROUTES))]
    return Route(lane, START_S, turns)


HELDOUT_TURNS = 6
"""Turns at T-junctions of every held-out route (``heldout_routes``)."""


def heldout_routes(seed: int, n: int = 8, turns: int = HELDOUT_TURNS) -> list[tuple[str, Route]]:
    """``n`` town02 routes drawn afresh from ``seed``: a random start (``routes.random_start``) and each
    junction's exit uniformly among its legal ones (``routes.uniform_exit``), ``turns`` T-junctions each,
    as ``(name, Route)`` pairs named ``h<seed>-<k>`` for ``drive_routes``. The six ``ROUTES`` were chosen to
    take every exit of the town; these are drawn only after the agents they test were trained, so nothing
    was chosen or tuned on them (chapter 11's check on routes it never drove)."""
    seed = check_int("seed", seed, minimum=0)
    check_int("n", n, minimum=1)
    check_int("turns", turns, minimum=1)
    town = get_town(ROUTE_TOWN)
    out = []
    for k in range(n):
        rng = np.random.default_rng([seed, k])
        lane, s = random_start(town, rng)
        out.append((f"h{seed}-{k}", random_route(town, rng, n_turns=turns, start=(lane, START_S))))
    return out


def route_lanes(route: Route, town: Town) -> list[int]:
    """The lanes of ``route``, up to the approach lane of the junction after its last turn."""
    return route.lanes(town, max_lanes=10_000)


def route_length(route: Route, town=ROUTE_TOWN) -> float:
    """Metres from the route's start to its end (``END_MARGIN_M`` before its last lane's end)."""
    tw = get_town(town) if isinstance(town, str) else town
    return float(sum(tw.lanes[k].length for k in route_lanes(route, tw)) - route.start_s - END_MARGIN_M)


def route_crossings(route: Route, town=ROUTE_TOWN) -> list[tuple[int, str]]:
    """(junction approach id, turn) of every junction crossing of the route, in order."""
    tw = get_town(town) if isinstance(town, str) else town
    lanes = route_lanes(route, tw)
    out = []
    for a, b in zip(lanes[:-1], lanes[1:], strict=True):
        ap = tw.approach_of_lane.get(a)
        if ap is not None and tw.approaches[ap].is_junction:
            out.append((ap, tw.lanes[b].turn))
    return out


def route_path(name: str, town=ROUTE_TOWN) -> tuple[np.ndarray, np.ndarray]:
    """(xy (N, 2), commands (N,)): the centre line of route ``name`` (its lanes' waypoints, from its start to
    its end) and the command a car there is given (``RouteTracker``); for maps, without driving."""
    tw = get_town(town) if isinstance(town, str) else town
    route = build_route(name)
    tracker = RouteTracker(route, tw)
    xy, commands = [], []
    for k, lane in enumerate(tracker.lanes):
        ln = tw.lanes[lane]
        s = np.arange(len(ln.points)) * ln.length / len(ln.points)  # (P,) metres along the lane
        keep = (tracker.lane_start[k] + s >= 0) & (tracker.lane_start[k] + s <= tracker.length)
        for p, h in zip(ln.points[keep], ln.headings[keep], strict=True):
            commands.append(tracker.update(float(p[0]), float(p[1]), float(h)))
            xy.append(p)
    return np.array(xy, dtype=float), np.array(commands, dtype=np.int64)


def route_exits(route: Route, town=ROUTE_TOWN) -> list[int]:
    """The number of exits of every junction the route crosses, in order (2 at a stem, 3 elsewhere)."""
    tw = get_town(town) if isinstance(town, str) else town
    return [len(tw.approaches[ap].exits) for ap, _ in route_crossings(route, tw)]


def chance_crossings(exits) -> float:
    """Expected junction crossings passed by the route's exit, before the first wrong one, by a car that
    takes each junction's exits with equal chance: sum over k of prod_{j <= k} 1 / exits_j (what luck gives
    a routeless car; chapter 11). ``exits``: the number of exits of each crossing, in order, each >= 1."""
    e = np.asarray(exits, dtype=float).reshape(-1)
    if (e < 1).any() or not np.all(e == np.round(e)):
        raise ValueError(f"exits must be whole numbers >= 1, got {exits!r}")
    return float(np.cumprod(1.0 / e).sum())


class RouteTracker:
    """Follows a car along a route's lanes: progress (metres along the route), the command, wrong turns.

    Call ``update(x, y, yaw)`` after every step (and once at the start); it returns the command for the
    state the car is in. ``wrong_turn`` becomes True once the car is on a road lane that is neither the
    route's current nor its next road lane; ``crossings`` lists, per junction of the route the car has
    entered, ``{"approach", "command", "taken"}`` (taken "" until the car is on a road lane again)."""

    def __init__(self, route: Route, town=ROUTE_TOWN):
        self.town = get_town(town) if isinstance(town, str) else town
        self.route = route
        self.lanes = route_lanes(route, self.town)
        starts = np.cumsum([0.0] + [self.town.lanes[k].length for k in self.lanes[:-1]])
        self.lane_start = starts - route.start_s  # route metre at which each lane begins
        self.length = route_length(route, self.town)
        self.turns = {}  # position in self.lanes of a junction approach -> its turn
        for p, (a, b) in enumerate(zip(self.lanes[:-1], self.lanes[1:], strict=True)):
            ap = self.town.approach_of_lane.get(a)
            if ap is not None and self.town.approaches[ap].is_junction:
                self.turns[p] = self.town.lanes[b].turn
        self.p = 0  # position in self.lanes of the lane the car is on
        self.progress_m = 0.0
        self.wrong_turn = False
        self.crossings: list[dict] = []

    @property
    def completion(self) -> float:
        """Share of the route driven along it, in [0, 1]."""
        return float(min(max(self.progress_m / self.length, 0.0), 1.0))

    @property
    def completed(self) -> bool:
        return self.progress_m >= self.length

    def _next_road(self, p: int) -> int | None:
        for q in range(p + 1, len(self.lanes)):
            if self.town.lanes[self.lanes[q]].kind == "road":
                return q
        return None

    def update(self, x: float, y: float, yaw: float) -> int:
        """Advance along the route to the car's pose; return the command (index into ``COMMANDS``)."""
        tw = self.town
        lane, idx, _ = tw.localize(x, y, yaw)
        kind = tw.lanes[lane].kind
        if lane != self.lanes[self.p]:
            window = self.lanes[self.p + 1 : self.p + 4]
            if lane in window:
                self.p += 1 + window.index(lane)
            elif kind == "road" and not self.wrong_turn:
                self.wrong_turn = True
                if self.p in self.turns:  # left the route's junction by another exit, from its approach
                    ap = tw.approach_of_lane[self.lanes[self.p]]
                    turn = self.turns[self.p]
                    self.crossings.append({"pos": self.p, "approach": int(ap), "command": turn, "taken": ""})
        on_route = lane == self.lanes[self.p]
        if on_route:
            ln = tw.lanes[lane]
            s = idx * ln.length / len(ln.points)
            self.progress_m = max(self.progress_m, self.lane_start[self.p] + s)
        # junction crossings: entered once the car is past an approach lane of the route
        for p, turn in self.turns.items():
            if p < self.p and not any(c["pos"] == p for c in self.crossings):
                ap = tw.approach_of_lane[self.lanes[p]]
                self.crossings.append({"pos": p, "approach": int(ap), "command": turn, "taken": ""})
        if kind == "road":
            for c in self.crossings:
                if not c["taken"] and (
                    self.wrong_turn or lane == self.lanes[self._next_road(c["pos"]) or -1]
                ):
                    exits = tw.approaches[c["approach"]].exits
                    c["taken"] = next((t for t, k in exits.items() if lane in tw.lanes[k].successors), "?")
        next_turn = next((t for q, t in self.turns.items() if q >= self.p), None)
        if next_turn is None and tw.lanes[self.lanes[self.p]].kind == "road":
            return FOLLOW  # past the last turn: the route ends before the next junction
        return command_at(tw, self.lanes[self.p], (x, y), next_turn)


@dataclass
class RouteResult:
    """How one drive of one route went."""

    route: str
    """The route's name."""
    seed: int
    """Seeds the route's light phases."""
    length_m: float
    """The route's length."""
    steps: int
    """Steps driven."""
    distance_m: float
    """Distance driven (metres, along or off the route)."""
    completion: float
    """Share of the route driven along it before it ended, in [0, 1]."""
    red_light_infractions: int
    """Red lights run."""
    end: str
    """"completed", "wrong_turn", "building", "off_road" or "timeout"."""
    crossings: list = field(default_factory=list)
    """Per junction crossing: ``{"approach", "command", "taken"}``."""
    xy: np.ndarray | None = field(default=None, repr=False)
    """(steps + 1, 2) positions, if recorded."""
    commands: np.ndarray | None = field(default=None, repr=False)
    """(steps + 1,) the command (index into ``COMMANDS``) at each recorded position, if recorded."""

    @property
    def driving_score(self) -> float:
        """completion x 0.7 ** (red lights run)."""
        return float(self.completion) * SCORE_PENALTY ** int(self.red_light_infractions)

    @property
    def score(self) -> float:
        """The DA-IBC paper's score: distance x 0.7 ** (red lights run)."""
        return score(self.distance_m, self.red_light_infractions)

    def row(self) -> dict:
        """A JSON row (numbers rounded)."""
        return {
            "route": self.route,
            "seed": int(self.seed),
            "length_m": round(self.length_m, 1),
            "steps": int(self.steps),
            "distance_m": round(float(self.distance_m), 2),
            "completion": round(float(self.completion), 4),
            "red_light_infractions": int(self.red_light_infractions),
            "driving_score": round(self.driving_score, 4),
            "score": round(self.score, 2),
            "end": self.end,
            "termination": "" if self.end in ("completed", "timeout") else self.end,
            "crossings": [{k: c[k] for k in ("approach", "command", "taken")} for c in self.crossings],
        }


def drive_routes(
    policy: DrivingPolicy | str,
    routes,
    *,
    bev: tuple[int, str] = (64, "intensity"),
    seed: int = 0,
    commands: bool = True,
    max_steps: int | None = None,
    record_xy: bool = False,
    show_progress: bool | None = None,
) -> list[RouteResult]:
    """Drive every route of ``routes`` (names of ``ROUTES``, or ``(name, Route)`` pairs) side by side.

    Args:
        policy: a ``DrivingPolicy`` (its batches hold a ``"command"`` when ``commands`` is on) or
            "expert" (the PID expert follows the route itself).
        routes: the routes.
        bev: the observation's BEV, ``(bev_size, light_encoding)`` (the agent's preset's).
        seed: the light phases of route ``k`` are drawn from ``[seed, k]``.
        commands: give the policy the route's command (``batch["command"]``, (B,) int64 indices into
            ``driving.commands.COMMANDS``); False: a routeless policy, which sees no command.
        max_steps: cap on every route's steps (None: its length at ``MIN_MEAN_SPEED``).
        record_xy: keep the car's positions and the command at each (``RouteResult.xy``, ``.commands``).
    """
    seed = check_int("seed", seed, minimum=0)
    if not isinstance(bev, tuple) or len(bev) != 2:
        raise ValueError(f"bev must be a pair (bev_size, light_encoding), got {bev!r}")
    bev_size, light_encoding = bev
    if isinstance(policy, str):
        check_choice("policy", policy, ("expert",))
    elif not callable(policy):
        raise ValueError(f"policy must be a callable or 'expert', got {type(policy).__name__}")
    if max_steps is not None:
        check_int("max_steps", max_steps, minimum=1)
    named = [(r, build_route(r)) if isinstance(r, str) else (str(r[0]), r[1]) for r in routes]
    if not named:
        raise ValueError("routes must name at least one route")
    town = get_town(ROUTE_TOWN)
    trackers = [RouteTracker(route, town) for _, route in named]
    budgets = [
        max_steps or math.ceil(check_positive("route length", t.length) / MIN_MEAN_SPEED * 10)
        for t in trackers
    ]
    config = EnvConfig(ROUTE_TOWN, bev_size, True, max(budgets), light_encoding=light_encoding)
    envs = [make_env(config=config) for _ in named]
    obs, cmds, tracks = [], [], []
    for k, (env, (_, route)) in enumerate(zip(envs, named, strict=True)):
        offsets = env.sim.schedule.random_offsets(np.random.default_rng([seed, k]))
        o, info = env.reset(seed=seed + k, options={"route": route, "light_offsets": offsets})
        obs.append(o)
        cmds.append(trackers[k].update(info["x"], info["y"], info["yaw"]))
        tracks.append([(info["x"], info["y"], cmds[-1])])
    experts = [Expert(env) for env in envs] if policy == "expert" else None
    ends = [""] * len(named)
    infos: list[dict] = [env.sim.info() for env in envs]
    active = list(range(len(named)))
    bar = progress(total=max(budgets), desc=f"{len(named)} routes in {ROUTE_TOWN}", enabled=show_progress)
    t = 0
    while active:
        if experts is not None:
            actions = np.stack([experts[i].act() for i in active])  # (B, 2)
        else:
            batch = {
                "bev": np.stack([obs[i]["bev"] for i in active]),  # (B, 5, S, S)
                "state": np.stack([obs[i]["state"] for i in active]),  # (B, 3)
            }
            if commands:
                batch["command"] = np.array([cmds[i] for i in active], dtype=np.int64)  # (B,)
            actions = np.asarray(policy(batch), dtype=np.float64).reshape(len(active), 2)
            with np.errstate(invalid="ignore"):
                actions = np.where(np.isnan(actions), actions, np.clip(actions, -1.0, 1.0))
        t += 1
        still = []
        for k, i in enumerate(active):
            obs[i], _, terminated, _, infos[i] = envs[i].step(actions[k])
            tr = trackers[i]
            cmds[i] = tr.update(infos[i]["x"], infos[i]["y"], infos[i]["yaw"])
            if record_xy:
                tracks[i].append((infos[i]["x"], infos[i]["y"], cmds[i]))
            if terminated:
                ends[i] = infos[i]["termination"]
            elif tr.wrong_turn:
                ends[i] = "wrong_turn"
            elif tr.completed:
                ends[i] = "completed"
            elif t >= budgets[i]:
                ends[i] = "timeout"
            if not ends[i]:
                still.append(i)
        active = still
        bar.update(1)
    bar.close()
    out = []
    for i, (name, _) in enumerate(named):
        tr, info = trackers[i], infos[i]
        out.append(
            RouteResult(
                name,
                seed,
                tr.length,
                int(info["step"]),
                float(info["distance_m"]),
                1.0 if ends[i] == "completed" else tr.completion,
                int(info["red_light_infractions"]),
                ends[i],
                list(tr.crossings),
                np.array(tracks[i])[:, :2] if record_xy else None,
                np.array(tracks[i])[:, 2].astype(np.int64) if record_xy else None,
            )
        )
    return out


def observation_before_crossing(
    name: str,
    crossing: int,
    before_m: float,
    *,
    bev_size: int = 64,
    light_encoding: str = "intensity",
    seed: int = 0,
) -> tuple[dict[str, np.ndarray], dict]:
    """The observation of the expert's car on route ``name`` at the first step it is ``before_m`` metres or
    less before the entry of the route's ``crossing``-th junction crossing (0-based; ``route_crossings``).

    Returns ``({"bev": (5, S, S), "state": (3,), "command": ()}, {"approach", "turn", "distance_m",
    "step"})``: the command is the route's (``RouteTracker``), the distance measured along the approach lane
    (``commands.distance_to_entry``). A stated rule for choosing a state, so that a figure drawn there is
    not chosen by hand (chapter 11). Light phases as ``drive_routes``'s first route with ``seed``."""
    ((obs, where),) = observations_before_crossing(
        name, crossing, [before_m], bev_size=bev_size, light_encoding=light_encoding, seed=seed
    )
    return obs, where


def observations_before_crossing(
    name: str,
    crossing: int,
    distances_m,
    *,
    bev_size: int = 64,
    light_encoding: str = "intensity",
    seed: int = 0,
) -> list[tuple[dict[str, np.ndarray], dict]]:
    """``observation_before_crossing`` at each distance of ``distances_m`` (metres before the entry, each
    >= 0), from one drive of the expert; in the order given."""
    return observations_before_crossings(
        name, [crossing], distances_m, bev_size=bev_size, light_encoding=light_encoding, seed=seed
    )[check_int("crossing", crossing, minimum=0)]


def observations_before_crossings(
    name: str,
    crossings,
    distances_m,
    *,
    bev_size: int = 64,
    light_encoding: str = "intensity",
    seed: int = 0,
    expert: ExpertConfig | None = None,
) -> dict[int, list[tuple[dict[str, np.ndarray], dict]]]:
    """For each of the route's ``crossings`` (0-based indices of ``route_crossings``), the observations at
    each distance of ``distances_m`` (``observation_before_crossing``), from one drive of the expert
    (``expert``: its settings, default ``ExpertConfig()``; chapter 12 reads the stems with the expert that
    begins its turns 2 m before the entry). Returns ``{crossing: [(obs, where), ...]}`` in the order of
    ``distances_m``."""
    route = build_route(name)
    town = get_town(ROUTE_TOWN)
    n_cross = len(route_crossings(route, town))
    crossings = [check_int("crossing", c, minimum=0) for c in np.atleast_1d(crossings).tolist()]
    for c in crossings:
        if c >= n_cross:
            raise ValueError(f"crossing must be below {n_cross} (route {name}'s crossings), got {c}")
    wanted = [check_positive("distances_m", float(d), allow_zero=True) for d in np.atleast_1d(distances_m)]
    if not wanted:
        raise ValueError("distances_m must hold at least one distance")
    expert = ExpertConfig() if expert is None else expert
    if not isinstance(expert, ExpertConfig):
        raise ValueError(f"expert must be an ExpertConfig, got {type(expert).__name__}")
    tracker = RouteTracker(route, town)
    order = sorted(tracker.turns)  # positions in the route's lanes of its junctions' approach lanes
    at = {order[c]: c for c in crossings}
    budget = math.ceil(tracker.length / MIN_MEAN_SPEED * 10)
    env = make_env(config=EnvConfig(ROUTE_TOWN, bev_size, True, budget, light_encoding=light_encoding))
    offsets = env.sim.schedule.random_offsets(np.random.default_rng([seed, 0]))
    obs, info = env.reset(seed=seed, options={"route": route, "light_offsets": offsets})
    driver = Expert(env, expert)
    found: dict[int, dict[int, tuple[dict, dict]]] = {c: {} for c in crossings}
    last = max(at)
    for step in range(budget):
        command = tracker.update(info["x"], info["y"], info["yaw"])
        if tracker.p > last:
            break
        c = at.get(tracker.p)
        if c is not None:
            d = distance_to_entry(town, tracker.lanes[tracker.p], (info["x"], info["y"]))
            ap = town.approach_of_lane[tracker.lanes[tracker.p]]
            for k, want in enumerate(wanted):
                if k not in found[c] and d <= want:
                    where = {
                        "approach": int(ap),
                        "turn": tracker.turns[tracker.p],
                        "distance_m": round(d, 3),
                        "step": step,
                    }
                    found[c][k] = ({**obs, "command": np.int64(command)}, where)
        obs, _, terminated, _, info = env.step(driver.act())
        if terminated:
            break
    for c in crossings:
        missing = [wanted[k] for k in range(len(wanted)) if k not in found[c]]
        if missing:
            raise ValueError(f"the expert never came within {missing} m of crossing {c} of route {name}")
    return {c: [found[c][k] for k in range(len(wanted))] for c in crossings}


def junction_success(rows) -> dict[str, dict]:
    """Per command (left, straight, right, and "all"): crossings, those whose commanded exit was taken, and
    their share. ``rows``: ``RouteResult.row()`` dicts (or their ``crossings`` lists' owners)."""
    out = {c: {"crossings": 0, "taken": 0} for c in (*COMMANDS[1:], "all")}
    for r in rows:
        for c in r["crossings"]:
            for key in (c["command"], "all"):
                out[key]["crossings"] += 1
                out[key]["taken"] += int(c["taken"] == c["command"])
    for v in out.values():
        v["rate"] = round(v["taken"] / v["crossings"], 4) if v["crossings"] else None
    return out


def summarize_routes(rows) -> dict:
    """Mean route completion, driving score, red lights, and how the routes ended, over ``rows``
    (``RouteResult.row()`` dicts)."""
    if not rows:
        raise ValueError("rows must hold at least one route")
    out = {"routes": len(rows)}
    for key in ("completion", "driving_score", "red_light_infractions", "score", "distance_m"):
        v = np.array([r[key] for r in rows], dtype=float)
        out[f"{key}_mean"] = round(float(v.mean()), 4)
        out[f"{key}_std"] = round(float(v.std()), 4)
    ends = ("completed", "wrong_turn", "building", "off_road", "timeout")
    out["ends"] = {e: sum(r["end"] == e for r in rows) for e in ends}
    out["junction_success"] = junction_success(rows)
    return out
