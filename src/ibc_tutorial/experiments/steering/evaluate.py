"""Closed-loop evaluation of a steering model on fixed town02 routes, as the paper's VISTA protocol.

**Routes** (``ROUTES``): four fixed town02 routes that keep straight past every side road: a lap
of the outer loop each way, on to 12 m before its first junction again (``loop-ccw``: side roads
on the left; ``loop-cw``: on the right; four side roads each) and the east-west road at y = 82 m each way (two
side roads each, ending before
the T at its end). 12 side-road passes and about 2.3 km per model and seed. Each route has its
own light phases (seeded by ``preset.eval_seed``).

**Reference** (``expert_reference``): the expert drives each route first, with the steering-only
task's longitudinal control (``task.longitudinal_config``); its positions, resampled every
``PATH_SPACING_M``, are the reference path.

**Crashes** (the steering-EBM paper's sec. 4, VISTA): the model steers, the expert's PID holds the
speed and stops at lights. A crash is the car's centre more than ``CRASH_DISTANCE_M`` = 2 m from the
reference path (or the car leaving the road, which the town's 8 m roads make coincide with
it). After a crash the car is restarted where the expert was 2 s (``RESTART_S``) later than at
the path point nearest the crash, on the first road lane from there (not inside a junction), at
rest, with the lights going on as they were: the environment is reset there (``DrivingEnv.reset``
with that start, the rest of the route and the light phases shifted by the time elapsed).
``crashes_per_km`` divides the crashes by the distance the model drove.

**W_cmd** (eq. 2 of the steering-EBM paper, ``metrics.whiteness``) of the steering commands, pooled
over the stretches between restarts, in the book's unit: steer per second (1/s), δt = 0.1 s. The
paper's commands are steering-wheel angles spanning about ±250° (its Fig. 4) where ours span ±1,
so **W in the paper's °/s ≈ 250 x W in 1/s** (``PAPER_DEG_PER_STEER``); in front-wheel angle, this
car's ±0.6 rad, it is 34.4 x W (``FRONT_WHEEL_DEG_PER_STEER``). The paper's stack decides at about
12 Hz (its appendix; 33 ms is its camera's frame spacing), we every 100 ms: jitter of the same size per
decision gives a W about 1.2 times smaller here.

**Sessions** (``SESSION_SHIFT_M``): a route can be driven in several sessions, each starting a little
further on with its own light phases; session 0 is the chapter's.

**At the junctions** (``junctions``, the sweep's measures): the W of the commands decided inside the
side-road sections (``section_w_cmd``: does argmin jitter between two modes there?), and, given the
model's scores, the share of its probability on steering towards the side road (``side_mass``).

**Swerve rate** (the paper's Table 2, ``metrics.swerve_rate``): a side-road section runs from
``SECTION_BEFORE_M`` = 15 m before the junction's entry to the end of the junction (the expert's
straight crossing). Its trace is the car's lateral offset from the reference path, positive
towards the side road, relative to the offset where the section began. A swerve: the peak
reaches ``CLEAR_M`` = 1.0 m, the room a car 2.0 m wide has on each side in a 4.0 m lane, so its
wheels touch the lane's line; a slight swerve (half): it reaches ``SLIGHT_M`` = 0.5 m, half that
room, and above the drift of ordinary lane keeping: in a first trial (a regression and a grid EBM
trained 1500 steps, 12 side-road passes each) the peaks were 0.00 to 0.31 m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ibc_tutorial.driving import route_following
from ibc_tutorial.driving.env import DrivingEnv, EnvConfig
from ibc_tutorial.driving.expert import Expert
from ibc_tutorial.driving.routes import Route
from ibc_tutorial.driving.towns import get_town
from ibc_tutorial.experiments.runs import read_npz
from ibc_tutorial.experiments.steering.junctions import (
    MASS_THRESHOLD,
    pooled_whiteness,
    section_whiteness,
    side_road_mass,
)
from ibc_tutorial.experiments.steering.presets import EVAL_TOWN, ROUTES
from ibc_tutorial.experiments.steering.task import longitudinal_config, steering_observation
from ibc_tutorial.metrics import crashes_per_km, swerve_rate, whiteness
from ibc_tutorial.utils import check_choice, check_int

REFERENCES = "references.npz"
"""The file of a study's (or a sweep's) folder that holds the expert's drives of the evaluation routes
(``Reference``, every session's), with the study's Fig. 5 window."""
PATH_SPACING_M = 0.5
"""Spacing of the resampled reference path."""
CRASH_DISTANCE_M = 2.0
"""VISTA's crash: farther than this from the expert's path."""
RESTART_S = 2.0
"""After a crash the car restarts where the expert was this much later."""
SECTION_BEFORE_M = 15.0
"""A side-road section starts this far before the junction's entry."""
SLIGHT_M = 0.5
"""Peak offset towards the side road of a slight swerve (counts half)."""
CLEAR_M = 1.0
"""Peak offset towards the side road of a swerve."""
DT = 0.1
"""Seconds between decisions."""
PAPER_DEG_PER_STEER = 250.0
"""The paper's steering-wheel degrees per unit of our steer (its ±250° range onto our ±1)."""
FRONT_WHEEL_DEG_PER_STEER = math.degrees(0.6)
"""This car's front-wheel degrees per unit of steer (δ_max = 0.6 rad)."""
FIG5_STEPS = 50
"""Length of the off-policy window of the Fig. 5 analogue: 5 s."""
FIG5_BEFORE = 30
"""Steps of that window before the expert enters the junction."""
SESSION_SHIFT_M = 2.0
"""Driving session k of a route starts ``k`` times this further along its first lane, with its own light
phases (``light_offsets``): session 0 is the route as the chapter drives it. The car meets each side road
at other moments of its control loop and of the lights, so a model's sessions differ as the paper's
driving sessions of one network did (its Table 1's rows)."""


def build_route(name: str, session: int = 0) -> Route:
    """The ``Route`` of ``ROUTES[name]`` in town02; session k starts ``k * SESSION_SHIFT_M`` further on."""
    check_choice("name", name, tuple(ROUTES))
    session = check_int("session", session, minimum=0)
    town = get_town(EVAL_TOWN)
    a, b, s, turns = ROUTES[name]
    for lane in town.lanes:
        if (
            lane.kind == "road"
            and tuple(town.nodes[lane.from_node]) == a
            and tuple(town.nodes[lane.to_node]) == b
        ):
            return Route(lane.id, s + session * SESSION_SHIFT_M, turns)
    raise ValueError(f"route {name!r}: no road lane from {a} to {b} in {EVAL_TOWN}")


def route_length(route: Route, cap_m: float = 0.0) -> float:
    """Metres the reference drives: ``driving.route_following.route_length`` in the evaluation town (the
    route's lanes up to ``END_MARGIN_M`` before the last one's end), or ``cap_m`` if shorter (0: no cap)."""
    total = route_following.route_length(route, EVAL_TOWN)
    return min(total, cap_m) if cap_m > 0 else total


def route_env(preset) -> DrivingEnv:
    """The town02 environment (``driving.env.DrivingEnv``) at the preset's BEV size, for driving the fixed
    routes (each episode is started with one)."""
    return DrivingEnv(config=EnvConfig(EVAL_TOWN, preset.bev_size, routeless=True, max_steps=10**6))


def light_offsets(env: DrivingEnv, preset, name: str, session: int = 0) -> np.ndarray:
    """(J,) the light phases of route ``name`` (seeded by ``preset.eval_seed``, the route's index and, from
    session 1 on, the session)."""
    key = [preset.eval_seed, list(ROUTES).index(name)] + ([int(session)] if session else [])
    rng = np.random.default_rng(key)
    return env.sim.schedule.random_offsets(rng)


@dataclass
class Reference:
    """The expert's drive of one route: the reference path and its side-road sections."""

    name: str
    """The route's name."""
    poses: np.ndarray
    """(K, 3) the expert's pose at each step."""
    lanes: np.ndarray
    """(K,) the lane it followed at each step."""
    speeds: np.ndarray
    """(K,) its speed (m/s)."""
    steer: np.ndarray
    """(K,) its steering commands."""
    turns_done: np.ndarray
    """(K,) junction choices made before each step."""
    offsets: np.ndarray
    """(J,) the light phases."""
    path: np.ndarray = field(default=None)
    """(M, 2) the path resampled every ``PATH_SPACING_M``."""
    path_step: np.ndarray = field(default=None)
    """(M,) the step at which the expert reached each path point."""
    sections: np.ndarray = field(default=None)
    """(P, 4) side-road sections: first and last path point, +1 (side road on the left) or -1
    (right), the step at which the expert entered the junction."""
    session: int = 0
    """The driving session (``SESSION_SHIFT_M``)."""

    def __post_init__(self):
        if self.path is None:
            self.path, self.path_step = resample_path(self.poses[:, :2], PATH_SPACING_M)
        if self.sections is None:
            self.sections = side_road_sections(self)

    def to_arrays(self) -> dict:
        keys = ("poses", "lanes", "speeds", "steer", "turns_done", "offsets", "path", "path_step", "sections")
        return {f"{reference_key(self.name, self.session)}/{k}": getattr(self, k) for k in keys}

    @classmethod
    def from_arrays(cls, name: str, arrays, session: int = 0) -> Reference:
        keys = ("poses", "lanes", "speeds", "steer", "turns_done", "offsets", "path", "path_step", "sections")
        key = reference_key(name, session)
        return cls(name, **{k: np.asarray(arrays[f"{key}/{k}"]) for k in keys}, session=session)


def read_references(path, routes, sessions: int = 1) -> tuple[list[list[Reference]], dict]:
    """The references of ``routes`` in sessions 0 to ``sessions`` - 1 from a ``REFERENCES`` file, as
    [session][route], and all the file's arrays; ValueError naming the file if it is damaged or lacks one."""
    arrays = read_npz(path, "delete it and re-run the same command")
    try:
        refs = [[Reference.from_arrays(n, arrays, session=k) for n in routes] for k in range(sessions)]
    except KeyError:
        raise ValueError(f"{path} lacks a route or session: delete it and re-run the same command") from None
    return refs, arrays


def reference_key(name: str, session: int = 0) -> str:
    """The prefix of a reference's arrays: the route's name (session 0), or ``name#s<k>``."""
    return name if not session else f"{name}#s{session}"


def resample_path(xy: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Points every ``spacing`` metres along the polyline ``xy`` (K, 2), and for each the first step reaching
    it."""
    seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)  # (K-1,)
    s = np.concatenate([[0.0], np.cumsum(seg)])  # (K,) arc length at each step
    grid = np.arange(0.0, s[-1], spacing)  # (M,)
    path = np.stack([np.interp(grid, s, xy[:, 0]), np.interp(grid, s, xy[:, 1])], axis=1)  # (M, 2)
    step = np.searchsorted(s, grid, side="left").clip(0, len(xy) - 1)  # (M,)
    return path, step


def side_road_sections(ref: Reference) -> np.ndarray:
    """(P, 4) the side-road passes of a reference (see ``Reference.sections``)."""
    town = get_town(EVAL_TOWN)
    s_of_step = np.zeros(len(ref.poses))
    s_of_step[1:] = np.cumsum(np.linalg.norm(np.diff(ref.poses[:, :2], axis=0), axis=1))
    out = []
    lanes = ref.lanes
    for k in range(1, len(lanes)):
        prev, cur = int(lanes[k - 1]), int(lanes[k])
        ap = town.approach_of_lane.get(prev)
        if prev == cur or ap is None or not town.approaches[ap].is_junction:
            continue
        exits = town.approaches[ap].exits
        if exits.get("straight") != cur:
            continue
        side = +1 if "left" in exits else -1
        k_end = k
        while k_end + 1 < len(lanes) and lanes[k_end + 1] == cur:
            k_end += 1
        a = int(np.searchsorted(ref.path_step, k, side="left")) - int(SECTION_BEFORE_M / PATH_SPACING_M)
        b = int(np.searchsorted(ref.path_step, k_end, side="right")) - 1
        if a >= 0 and b < len(ref.path) - 1 and k_end + 1 < len(lanes):  # the whole section lies on the route
            out.append((a, b, side, k))
    return np.array(out, dtype=np.int64).reshape(-1, 4)


def expert_reference(
    name: str, preset, keep_obs: tuple[int, int] | None = None, session: int = 0
) -> tuple[Reference, np.ndarray | None]:
    """The expert drives route ``name`` in driving session ``session``; returns its ``Reference`` (and the
    observations of steps ``keep_obs`` = (first, end), as the models would see them, or None)."""
    env = route_env(preset)
    route = build_route(name, session)
    length = route_length(route, preset.route_cap_m)
    offsets = light_offsets(env, preset, name, session)
    obs, info = env.reset(seed=preset.eval_seed, options={"route": route, "light_offsets": offsets})
    expert = Expert(env, longitudinal_config(preset.speed))
    town = env.town
    rows = {k: [] for k in ("poses", "lanes", "speeds", "steer", "turns_done")}
    kept, done = [], 0
    while info["distance_m"] < length:
        k = len(rows["poses"])
        if keep_obs is not None and keep_obs[0] <= k < keep_obs[1]:
            kept.append(steering_observation({"bev": obs["bev"][None], "state": obs["state"][None]}))
        a = expert.act()
        lane = expert.current_lane
        if rows["lanes"] and lane != rows["lanes"][-1] and town.lanes[lane].kind == "connector":
            ap = town.approach_of_lane.get(rows["lanes"][-1])
            done += int(ap is not None and town.approaches[ap].is_junction)
        rows["poses"].append(env.sim.car.pose)
        rows["lanes"].append(lane)
        rows["speeds"].append(env.sim.car.speed)
        rows["steer"].append(float(a[0]))
        rows["turns_done"].append(done)
        obs, _, terminated, _, info = env.step(a)
        if terminated or len(rows["poses"]) > 20000:
            raise RuntimeError(
                f"the expert did not complete route {name!r} ({info['termination'] or 'too long'})"
            )
    ref = Reference(name, offsets=offsets, session=session, **{k: np.array(v) for k, v in rows.items()})
    if keep_obs is None:
        return ref, None
    return ref, {
        "bev": np.concatenate([o["bev"] for o in kept]),
        "state": np.concatenate([o["state"] for o in kept]),
    }


def fig5_window(ref: Reference) -> tuple[int, int] | None:
    """(first, end) steps of 5 s around the first side-road pass the expert drives without slowing
    (speed > 3 m/s throughout), starting ``FIG5_BEFORE`` steps before it enters the junction; None if none."""
    for _a, _b, _side, k in ref.sections:
        first = int(k) - FIG5_BEFORE
        if (
            first >= 0
            and first + FIG5_STEPS <= len(ref.speeds)
            and (ref.speeds[first : first + FIG5_STEPS] > 3.0).all()
        ):
            return first, first + FIG5_STEPS
    return None


def _nearest(path: np.ndarray, xy, j: int, back: int = 20, ahead: int = 40) -> tuple[int, float]:
    """Index of the path point nearest ``xy`` within [j - back, j + ahead], and the signed lateral
    offset (m, left of the path positive) from the path's segment there."""
    lo, hi = max(0, j - back), min(len(path), j + ahead + 1)
    d2 = ((path[lo:hi] - np.asarray(xy)[None]) ** 2).sum(1)
    i = lo + int(np.argmin(d2))
    a, b = (i, i + 1) if i + 1 < len(path) else (i - 1, i)
    t = path[b] - path[a]
    t = t / max(float(np.linalg.norm(t)), 1e-9)
    r = np.asarray(xy) - path[i]
    return i, float(t[0] * r[1] - t[1] * r[0])  # z of t x r: > 0 left of the direction of travel


def drive_route(
    policy,
    ref: Reference,
    preset,
    *,
    max_steps: int | None = None,
    scorer=None,
    grid=None,
    mass_threshold: float = MASS_THRESHOLD,
) -> dict:
    """Drive route ``ref.name`` (session ``ref.session``) with ``policy`` (steering observations (1, ...)
    -> steer) under the crash-and-restart protocol (module docstring); returns the route's metrics and
    traces.

    The result: ``crashes``, ``distance_m`` (driven by the model), ``crashes_per_km``, ``w_cmd``
    (1/s), ``steps``, ``timeout`` (the step budget ran out), ``crash_steps``, ``swerve_peak_m`` (P,)
    and ``swerve_score`` (P,) per side-road section, ``section_w_cmd`` (1/s; ``junctions.section_whiteness``
    of the commands decided inside the sections, pooled over the stretches between restarts) and
    ``section_changes`` (how many changes it pools), ``pass_offsets`` (per pass, the offsets towards the
    side road, relative to the first, of which ``swerve_peak_m`` is the maximum), and ``steer`` (T,) the
    commands. With ``scorer``
    (observations (1, ...) -> (1, G) scores over ``grid`` (G,), lower = preferred), also ``side_mass``
    (P,): per pass, the mean over its states from the section's start to the junction's entry of
    ``junctions.side_road_mass`` (beyond ``mass_threshold`` from the expert's steer there; None: no
    such state driven) and ``pass_mass`` (per pass, the per-state shares it averages)."""
    env = route_env(preset)
    route = build_route(ref.name, ref.session)
    town = env.town
    budget = max_steps if max_steps is not None else 3 * len(ref.poses) + 600
    obs, info = env.reset(seed=preset.eval_seed, options={"route": route, "light_offsets": ref.offsets})
    expert = Expert(env, longitudinal_config(preset.speed))
    j, t_total, crashes, crash_steps, driven = 0, 0, 0, [], 0.0
    segments, current = [], []
    traces = [[] for _ in ref.sections]
    masses = [[] for _ in ref.sections]
    in_section, flags = [], []  # per stretch between restarts: whether each command was decided in a section
    entry = int(round(SECTION_BEFORE_M / PATH_SPACING_M))  # path points from a section's start to the entry
    end = len(ref.path) - 2
    while j < end and t_total < budget:
        seen = steering_observation({"bev": obs["bev"][None], "state": obs["state"][None]})  # (1, ...)
        steer = float(np.clip(policy(seen), -1.0, 1.0))
        here = [p for p, (a, b, _s, _k) in enumerate(ref.sections) if a <= j <= b]
        if scorer is not None:
            for p in here:
                a, _b, side, _k = ref.sections[p]
                if j <= a + entry:
                    expert_steer = float(ref.steer[min(int(ref.path_step[j]), len(ref.steer) - 1)])
                    scores = np.asarray(scorer(seen), dtype=np.float64).reshape(1, -1)  # (1, G)
                    masses[p].append(
                        float(side_road_mass(scores, grid, expert_steer, int(side), mass_threshold)[0])
                    )
        flags.append(bool(here))
        acc = float(expert.act()[1])
        current.append(steer)
        obs, _, terminated, _, info = env.step(np.array([steer, acc], dtype=np.float32))
        t_total += 1
        j, lat = _nearest(ref.path, (info["x"], info["y"]), j)
        for p, (a, b, side, _k) in enumerate(ref.sections):
            if a <= j <= b:
                traces[p].append(side * lat)
        if abs(lat) <= CRASH_DISTANCE_M and not terminated:
            continue
        # a crash: restart where the expert was RESTART_S later, on a road lane, at rest
        crashes += 1
        crash_steps.append(t_total)
        driven += info["distance_m"]
        segments.append(current)
        in_section.append(flags)
        current, flags = [], []
        k = int(ref.path_step[j]) + int(round(RESTART_S / DT))
        while k < len(ref.lanes) and town.lanes[int(ref.lanes[k])].kind != "road":
            k += 1
        if k >= len(ref.lanes) - 1 or k >= ref.path_step[end]:
            j = end
            break
        lane = int(ref.lanes[k])
        x, y, yaw = ref.poses[k]
        ln = town.lanes[lane]
        s = float(
            np.clip(((np.array([x, y]) - ln.start) @ ((ln.end - ln.start) / ln.length)), 0.0, ln.length)
        )
        restart = Route(lane, s, tuple(route.turns[int(ref.turns_done[k]) :]))
        offsets = (ref.offsets + t_total) % env.sim.schedule.cycle
        obs, info = env.reset(options={"route": restart, "light_offsets": offsets.astype(np.int64)})
        j = int(np.searchsorted(ref.path_step, k, side="left"))
    driven += info["distance_m"]
    segments.append(current)
    in_section.append(flags)
    section_w = [
        (section_whiteness(c, f, DT), int((np.asarray(f[1:]) & np.asarray(f[:-1])).sum()))
        for c, f in zip(segments, in_section, strict=True)
        if len(c) >= 2
    ]
    segs = [np.array(c) for c in segments if len(c) >= 2]
    n = sum(len(c) - 1 for c in segs)
    w = math.sqrt(sum((len(c) - 1) * whiteness(c, DT) ** 2 for c in segs) / n) if n else float("nan")
    # each section's offsets relative to the first (NaN: a restart skipped the whole section)
    peaks = np.array([max(tr) - tr[0] if tr else np.nan for tr in traces])  # (P,)
    scores = np.full(len(traces), np.nan)  # (P,)
    driven_passes = [p for p, tr in enumerate(traces) if tr]
    if driven_passes:
        rel = _pad([[v - traces[p][0] for v in traces[p]] for p in driven_passes])  # (P', T) NaN-padded
        scores[driven_passes] = swerve_rate(rel, slight=SLIGHT_M, clear=CLEAR_M, per_pass=True)
    return {
        "route": ref.name,
        "crashes": crashes,
        "distance_m": round(driven, 2),
        "crashes_per_km": crashes_per_km(crashes, driven) if driven > 0 else float("nan"),
        "w_cmd": round(w, 5),
        "steps": t_total,
        "timeout": bool(j < end),
        "crash_steps": crash_steps,
        "swerve_peak_m": [None if np.isnan(p) else round(float(p), 4) for p in peaks],
        "swerve_score": [None if np.isnan(v) else float(v) for v in scores],
        "section_w_cmd": _round_or_none(pooled_whiteness(section_w), 5),
        "section_changes": int(sum(k for _w, k in section_w)),
        "pass_offsets": [[round(v - tr[0], 4) for v in tr] for tr in traces],
        **(
            {
                "side_mass": [round(float(np.mean(m)), 5) if m else None for m in masses],
                "pass_mass": [[round(v, 5) for v in m] for m in masses],
            }
            if scorer is not None
            else {}
        ),
        "steer": np.concatenate([np.array(c) for c in segments if c]) if any(segments) else np.zeros(0),
    }


def _round_or_none(x: float, digits: int):
    return None if x is None or math.isnan(x) else round(float(x), digits)


def _pad(rows: list[list[float]]) -> np.ndarray:
    """Rows of unequal length as a (P, T) array padded with NaN."""
    out = np.full((len(rows), max(len(r) for r in rows)), np.nan)
    for i, r in enumerate(rows):
        out[i, : len(r)] = r
    return out


def expert_whiteness(ref: Reference) -> float:
    """W (1/s) of the expert's own steering commands along a reference."""
    return whiteness(ref.steer, DT)


def summarize_run_routes(routes: list[dict]) -> dict:
    """One run's routes pooled: crashes, distance, crashes per km, W_cmd (pooled over the commands'
    changes), the swerve rate over every side-road section driven, and the number of passes; where the
    routes have them, the sweep's measures: ``section_w_cmd`` (pooled over the sections' changes),
    ``peak_m`` and ``side_mass`` (means over the passes)."""
    crashes = sum(r["crashes"] for r in routes)
    dist = sum(r["distance_m"] for r in routes)
    w = pooled_whiteness([(r["w_cmd"], r["steps"] - 1) for r in routes])  # over the commands' changes
    scores = [s for r in routes for s in r["swerve_score"] if s is not None]
    extra = {}
    if all("section_w_cmd" in r for r in routes):  # the sweep's measures (evaluations made since they exist)
        sw = pooled_whiteness([(r["section_w_cmd"] or float("nan"), r["section_changes"]) for r in routes])
        peaks = [p for r in routes for p in r["swerve_peak_m"] if p is not None]
        extra.update(
            section_w_cmd=_round_or_none(sw, 5),
            peak_m=round(float(np.mean(peaks)), 4) if peaks else None,
        )
    if all("side_mass" in r for r in routes):
        mass = [m for r in routes for m in r["side_mass"] if m is not None]
        extra["side_mass"] = round(float(np.mean(mass)), 5) if mass else None
    return {
        "crashes": crashes,
        "distance_m": round(dist, 2),
        "crashes_per_km": round(crashes_per_km(crashes, dist), 4) if dist > 0 else None,
        "w_cmd": round(w, 5),
        "swerve_rate": round(float(np.mean(scores)), 4) if scores else None,
        "passes": len(scores),
        "timeouts": sum(bool(r["timeout"]) for r in routes),
        **extra,
    }
