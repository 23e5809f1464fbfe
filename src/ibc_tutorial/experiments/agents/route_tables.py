"""Reading route drives (chapter 11): each driver's rows, tables per method, junction success, stem ends.

Two folders hold route drives: a command replication (``replicate --commands``), whose agents' and
expert's ``final_eval.json`` list one row per route drive, and a ``routes`` folder
(``route_study.run_route_drives``: chapter 09's routeless agents on the same routes). Both become
``{driver name: rows}`` (``<method>-seed<k>`` or "expert"; rows are ``RouteResult.row()`` dicts), and the
functions here turn those into what the chapter's table and intervals need:

* ``route_table``: one method's (A agents, R route drives) values of a row key (completion, driving
  score, ...), routes in one order for every agent, for ``stats.mean_interval`` and
  ``stats.difference_interval`` (the agents x routes bootstrap);
* ``success_counts``: per agent and route drive, the crossings with a command and those whose commanded
  exit was taken, for ``stats.ratio_of_sums_interval`` (success pooled over crossings);
* ``stem_ends``: the route drives that ended in a building or off the road inside a junction entered
  from a stem (chapter 08's "ends at a stem").
"""

from __future__ import annotations

import json
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ibc_tutorial import stats
from ibc_tutorial.driving.commands import COMMANDS
from ibc_tutorial.driving.route_following import ROUTE_TOWN
from ibc_tutorial.driving.stems import stem_approaches
from ibc_tutorial.experiments.agents.presets import METHODS
from ibc_tutorial.experiments.agents.replication_folder import FINAL_EVAL, expert_dir
from ibc_tutorial.experiments.agents.route_study import load_route_drives
from ibc_tutorial.stats import Interval
from ibc_tutorial.utils import check_choice

ROUTE_TOWN_STEMS = frozenset(stem_approaches(ROUTE_TOWN))
"""The town02 junction approaches that are stems of a T (left and right only)."""


def method_of(name: str) -> str:
    """The method of a driver name: ``"da-ibc-seed3"`` -> ``"da-ibc"``, ``"expert"`` -> ``"expert"``."""
    if name == "expert":
        return name
    method, sep, seed = name.rpartition("-seed")
    if not sep or method not in METHODS or not seed.isdigit():
        raise ValueError(
            f"name must be <method>-seed<k> with a method of {METHODS}, or 'expert', got {name!r}"
        )
    return method


def command_drivers(folder) -> dict[str, list[dict]]:
    """``{name: rows}`` of a command replication folder: each run's ``final_eval.json``, the expert's."""
    folder = Path(folder)
    out = {}
    for method in METHODS:
        runs = sorted(
            (folder / "runs" / method).glob(f"seed*/{FINAL_EVAL}"), key=lambda p: int(p.parent.name[4:])
        )
        for path in runs:
            out[f"{method}-{path.parent.name}"] = _route_rows(path)
    expert = expert_dir(folder) / FINAL_EVAL
    if expert.exists():
        out["expert"] = _route_rows(expert)
    if not out:
        raise ValueError(f"folder must hold runs/<method>/seed<k>/{FINAL_EVAL} files, found none in {folder}")
    return out


def _route_rows(path: Path) -> list[dict]:
    rows = json.loads(path.read_text())["episodes"]
    if not rows or "route" not in rows[0]:
        raise ValueError(f"{path} holds no route drives (is it a command replication's?)")
    return rows


def routeless_drivers(folder) -> dict[str, list[dict]]:
    """``{name: rows}`` of a ``routes`` folder (``route_study.load_route_drives``)."""
    return {name: d["episodes"] for name, d in load_route_drives(folder).items()}


def by_method(drivers: dict[str, list[dict]]) -> dict[str, dict[str, list[dict]]]:
    """``{method: {name: rows}}``, methods in the book's order, then the expert."""
    out: dict[str, dict[str, list[dict]]] = {}
    for name, rows in drivers.items():
        out.setdefault(method_of(name), {})[name] = rows
    return {m: out[m] for m in (*METHODS, "expert") if m in out}


def _ordered(rows: list[dict]) -> list[dict]:
    return sorted(rows, key=lambda r: (r["route"], r["seed"]))


def route_table(drivers: dict[str, list[dict]], key: str) -> np.ndarray:
    """(A, R) ``key`` of every row, one line per driver of ``drivers`` (one method's), its route drives
    ordered by route then seed. ValueError if the drivers drove different routes."""
    if not drivers:
        raise ValueError("drivers must hold at least one driver")
    lines, order = [], None
    for name, rows in drivers.items():
        rows = _ordered(rows)
        routes = [(r["route"], r["seed"]) for r in rows]
        if order is None:
            order = routes
        elif routes != order:
            raise ValueError(f"drivers must have driven the same routes: {name} drove {routes}, not {order}")
        lines.append([float(r[key]) for r in rows])
    return np.array(lines)  # (A, R)


def success_counts(drivers: dict[str, list[dict]], command: str = "all") -> tuple[np.ndarray, np.ndarray]:
    """(taken (A, R), crossings (A, R)): per driver and route drive, the junction crossings with
    ``command`` ("left", "straight", "right" or "all") and those whose commanded exit was taken. A route
    that ended inside a junction (``taken`` "") counts that crossing as not taken."""
    check_choice("command", command, (*COMMANDS[1:], "all"))
    taken, crossings = [], []
    for rows in drivers.values():
        t, c = [], []
        for r in _ordered(rows):
            cs = [x for x in r["crossings"] if command in ("all", x["command"])]
            t.append(sum(x["taken"] == x["command"] for x in cs))
            c.append(len(cs))
        taken.append(t)
        crossings.append(c)
    return np.array(taken, dtype=float), np.array(crossings, dtype=float)


def stem_ends(rows: list[dict]) -> list[dict]:
    """The rows (route drives) that ended in a building or off the road inside a junction entered from a
    stem: the route's last crossing is from a stem approach and has no exit (``taken`` "")."""
    return [
        r
        for r in rows
        if r["end"] in ("building", "off_road")
        and r["crossings"]
        and r["crossings"][-1]["taken"] == ""
        and r["crossings"][-1]["approach"] in ROUTE_TOWN_STEMS
    ]


def count_stem_crossings(rows: list[dict]) -> int:
    """How many junction crossings of ``rows`` were entered from a stem."""
    return sum(c["approach"] in ROUTE_TOWN_STEMS for r in rows for c in r["crossings"])


def missed_crossings(drivers: dict[str, list[dict]]) -> Counter:
    """``Counter`` of (commanded exit, exit taken) over the missed crossings of ``drivers``' rows; a route
    that ended inside the junction took "none"."""
    return Counter(
        (x["command"], x["taken"] or "none")
        for rows in drivers.values()
        for r in rows
        for x in r["crossings"]
        if x["taken"] != x["command"]
    )


ENDS = ("completed", "wrong_turn", "building", "off_road", "timeout")
"""How a route drive ends (``driving.route_following``), in the table's order."""


@dataclass(frozen=True)
class GroupSummary:
    """One group of drivers (one method's agents, say) on the routes: chapter 11's table row."""

    agents: int
    """Drivers in the group."""
    completion: Interval
    """Mean route completion over agents x route drives, with its two-level bootstrap interval."""
    score: Interval
    """Mean driving score (completion x 0.7 ** red lights run), likewise."""
    red: float
    """Red lights run per route drive."""
    ends: dict
    """``{end: route drives}`` for every end of ``ENDS``."""
    stem_ends: int
    """Route drives that ended in a building or off the road inside a junction entered from a stem."""


def group_summary(drivers: dict[str, list[dict]], seed=0) -> GroupSummary:
    """The table row of ``drivers`` (``{name: rows}``, all on the same routes)."""
    rows = [r for rs in drivers.values() for r in rs]
    return GroupSummary(
        agents=len(drivers),
        completion=stats.mean_interval(route_table(drivers, "completion"), seed=seed),
        score=stats.mean_interval(route_table(drivers, "driving_score"), seed=seed),
        red=float(route_table(drivers, "red_light_infractions").mean()),
        ends={e: sum(r["end"] == e for r in rows) for e in ENDS},
        stem_ends=len(stem_ends(rows)),
    )


def format_group_table(groups: dict[str, GroupSummary]) -> str:
    """The rows of ``groups`` as chapter 11's fixed-width table (completion, score, red lights, ends)."""
    lines = [f"{'drivers':>18} {'agents':>6} {'completion':>19} {'driving score':>19} {'red/route':>9}  ends"]
    for name, g in groups.items():
        ends = " ".join(f"{e} {n}" for e, n in g.ends.items() if n)
        lines.append(
            f"{name:>18} {g.agents:6d} {str(g.completion):>19} {str(g.score):>19} {g.red:9.2f}  {ends}"
        )
    return "\n".join(lines)
