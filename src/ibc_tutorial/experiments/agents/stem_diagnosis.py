"""What the agents of a replication do at the stems of the T-junctions, read from its stored files
(chapter 12's first section).

- ``stem_crossings``: from ``evaluate --crossings`` files (``FOLDER/crossings/<method>-seed<k>.json``), every
  crossing from a stem of town02 by how it ended (a completed left or right turn, or the episode's end), with
  the most leftward and most rightward steering applied in it, and where each ended episode ended;
- ``episode_agreement``: how many of the episodes driven again are the table's, row for row (a CPU other
  than the one that trained the agents may drive some of them a few metres otherwise);
- ``ended_energies``: in the crossings that ended an episode, the energy over steering the crossings file
  kept at every state, with where its lowest point lies and what steering as far as a turn costs;
- ``change_counts``: a method's exits at the stems (``claims.stem_counts``) in several stem analyses, one per
  change tried (an ablation folder's, or the same agents driven with DFO changed).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ibc_tutorial.driving import get_town
from ibc_tutorial.experiments.agents.claims import StemCounts, stem_counts
from ibc_tutorial.experiments.agents.replication_folder import read_final_eval, run_dir

KINDS = ("left turn", "right turn", "ended")
"""How a crossing from a stem ended: a completed turn either way, or the episode (building, off road)."""
WHERE = ("at a stem", "at another approach", "outside a junction")
"""Where an episode that ended in a building or off the road ended."""


def stem_approaches(town: str) -> set:
    """Ids of the stems of ``town``: the junction approaches whose only exits are left and right."""
    return {a.id for a in get_town(town).approaches if a.is_junction and set(a.exits) == {"left", "right"}}


@dataclass(frozen=True)
class StemCrossings:
    """One method's crossings from the stems of town02 in a replication's table episodes."""

    steering: dict[str, np.ndarray]
    """``{kind: (N, 2)}`` for each of ``KINDS``: (most leftward, most rightward) steering of each crossing."""
    ends: dict[str, int]
    """``{where: episodes}`` for each of ``WHERE``: the episodes that ended in a building or off the road."""


def _episode_rows(path: Path, folder: Path, method: str, seed: int) -> tuple[dict, list, list]:
    """The crossings file, its episodes without their crossings, and the table's episodes."""
    ev = json.loads(path.read_text())
    table = read_final_eval(run_dir(folder, method, seed) / "final_eval.json")["episodes"]
    drove = [{k: v for k, v in e.items() if k != "junction_crossings"} for e in ev["episodes"]]
    return ev, drove, table


def _crossings_file(folder: Path, method: str, seed: int, same_episodes: bool = True) -> dict:
    path = folder / "crossings" / f"{method}-seed{seed}.json"
    ev, drove, table = _episode_rows(path, folder, method, seed)
    if same_episodes and drove != table:
        raise ValueError(f"{path} did not drive the episodes of the table's final_eval.json again")
    if [e["seed"] for e in drove] != [e["seed"] for e in table]:
        raise ValueError(f"{path} did not drive from the starts of the table's final_eval.json")
    return ev


def episode_agreement(folder, method: str, seeds) -> tuple[int, int]:
    """(identical, all): how many episodes of ``method``'s crossings files in ``folder`` are the table's
    row for row (score, distance, lights, ending), of all those driven again; ValueError if a file drove
    from other starts than its table."""
    folder, same, total = Path(folder), 0, 0
    for s in seeds:
        _crossings_file(folder, method, s, same_episodes=False)  # the starts must be the table's
        _, drove, table = _episode_rows(folder / "crossings" / f"{method}-seed{s}.json", folder, method, s)
        same += sum(a == b for a, b in zip(drove, table, strict=True))
        total += len(table)
    return same, total


def stem_crossings(folder, method: str, seeds, same_episodes: bool = True) -> StemCrossings:
    """``StemCrossings`` of ``method``'s agents ``seeds`` in ``folder`` (a replication with ``crossings/``).
    With ``same_episodes`` (the default), ValueError if a crossings file's episodes are not the table's, row
    for row; with ``same_episodes=False``, only the starts must be the table's (``episode_agreement`` counts
    the rows that agree)."""
    folder, stems = Path(folder), stem_approaches("town02")
    steering: dict[str, list] = {k: [] for k in KINDS}
    ends = dict.fromkeys(WHERE, 0)
    for s in seeds:
        for e in _crossings_file(folder, method, s, same_episodes)["episodes"]:
            crossed = e["junction_crossings"]
            for c in crossed:
                if c["finished"] and c["approach"] in stems:
                    steering[f"{c['turn']} turn"].append((c["steer_min"], c["steer_max"]))
            if not e["termination"]:
                continue
            last = crossed[-1] if crossed and not crossed[-1]["finished"] else None  # ended inside it
            if last is None:
                ends["outside a junction"] += 1
            elif last["approach"] in stems:
                ends["at a stem"] += 1
                steering["ended"].append((last["steer_min"], last["steer_max"]))
            else:
                ends["at another approach"] += 1
    return StemCrossings({k: np.array(v, dtype=float).reshape(-1, 2) for k, v in steering.items()}, ends)


@dataclass(frozen=True)
class EndedCrossing:
    """The energy over steering at the states of a crossing from a stem that ended an episode."""

    name: str
    """``"IBC seed 0, start 1007"``: the agent and the episode's start."""
    energies: np.ndarray
    """(T, G) energy at each state (the lowest over acceleration), in nats above the state's minimum."""
    steer_grid: np.ndarray
    """(G,) the steering values of the grid."""
    lowest: tuple[float, float]
    """The least and the most of the lowest-energy steering over the states."""
    turn_cost: tuple[float, float]
    """The least energy, over the states, of steering as far as a left turn and as far as a right turn."""


def ended_energies(
    folder, method: str, seeds, left_turn: float, right_turn: float, same_episodes: bool = True
) -> list[EndedCrossing]:
    """Every crossing of ``method``'s agents whose energies the crossings files kept (those that ended an
    episode); "a turn" is steering at or left of ``left_turn``, at or right of ``right_turn``;
    ``same_episodes`` as in ``stem_crossings``."""
    if not left_turn < 0 < right_turn:
        raise ValueError(f"left_turn must be < 0 < right_turn, got {left_turn}, {right_turn}")
    out = []
    for s in seeds:
        ev = _crossings_file(Path(folder), method, s, same_episodes)
        steer = np.array(ev.get("energy_steer_grid", []), dtype=float)  # (G,)
        for e in ev["episodes"]:
            for c in e["junction_crossings"]:
                if "energy_by_steer" not in c:
                    continue
                E = np.array(c["energy_by_steer"], dtype=float)  # (T, G)
                lowest = steer[E.argmin(axis=1)]  # (T,)
                left = E[:, steer <= left_turn].min()
                right = E[:, steer >= right_turn].min()
                name = f"{method.upper()} seed {s}, start {e['seed']}"
                out.append(
                    EndedCrossing(name, E, steer, (lowest.min(), lowest.max()), (float(left), float(right)))
                )
    return out


def change_counts(changes: dict[str, tuple], seed: int = 0) -> dict[tuple[str, str], StemCounts]:
    """``{(change, method): StemCounts}`` for ``changes`` = ``{change: (analysis folder, methods)}``, each
    folder a stem analysis's ``analysis/`` with one ``<method>-seed<k>.json`` per agent (``expert.json``
    for the expert)."""
    out = {}
    for name, (folder, methods) in changes.items():
        paths = [p for p in sorted(Path(folder).glob("*.json")) if p.name != "provenance.json"]
        files = {p.stem: json.loads(p.read_text()) for p in paths}
        if not files:
            raise ValueError(f"changes[{name!r}]: {folder} holds no agent's stem analysis")
        for m in methods:
            out[name, m] = stem_counts(files, m, seed=seed)
    return out
