"""Every agent of a replication folder, and the expert, driven on the town02 routes (chapter 11).

A command replication (``replicate --commands``) drives its own agents on the routes in its final
evaluation. Chapter 11 also needs the routeless agents of chapter 09 on the same routes, without a command:
their completion shows what luck at the junctions gives. ``run_route_drives`` does that for any folder
(``ibc-tutorial routes --folder book/results/laptop --out book/results/laptop/on-routes``): each driver
(``stem_drives.drivers``: every ``runs/<method>/seed<k>/final.pt``, then the expert) drives every route
``drives`` times, given a command exactly when its checkpoint takes one, with the light phases of
``route_driving.ROUTE_SEED`` and the DFO draws of its training seed, as the command replication's evaluation.
One JSON file per driver in ``out`` (``<method>-seed<k>.json``, ``expert.json``); a driver whose file
exists is skipped, so an interrupted run resumes, and ``provenance.json`` records every invocation.
"""

from __future__ import annotations

from pathlib import Path

from ibc_tutorial.driving.route_following import ROUTES, heldout_routes
from ibc_tutorial.experiments.agents.checkpoints import load_agent, training_seed
from ibc_tutorial.experiments.agents.route_driving import ROUTE_SEED, evaluate_on_routes, summarize_route_rows
from ibc_tutorial.experiments.agents.stem_drives import drivers
from ibc_tutorial.experiments.runs import read_driver_files, run_missing_recorded, write_json
from ibc_tutorial.utils import check_int


def run_route_drives(
    folder,
    out,
    drives: int = 1,
    only=None,
    log=print,
    command: str = "",
    max_steps: int | None = None,
    heldout_seed: int | None = None,
    heldout_count: int = 8,
) -> list[str]:
    """Drive each driver of ``folder`` without a file in ``out`` on every route; returns the names driven.

    ``drives``: drives of every route per driver (drive ``k``: light phases seeded ``ROUTE_SEED + k``);
    ``only``: names to drive (e.g. ``["bc-seed0", "expert"]``), None for all; ``command``: the command line,
    recorded in ``out/provenance.json``; ``max_steps``: cap on every route drive's steps (None: each route's
    own budget); ``heldout_seed``: drive ``heldout_count`` routes drawn afresh from this seed
    (``route_following.heldout_routes``) instead of the six fixed ``ROUTES``. ValueError if ``out`` holds
    drives of another protocol."""
    drives = check_int("drives", drives, minimum=1)
    if max_steps is not None:
        check_int("max_steps", max_steps, minimum=1)
    if heldout_seed is None:
        routes = tuple(ROUTES)
    else:
        routes = heldout_routes(check_int("heldout_seed", heldout_seed, minimum=0), heldout_count)
    named = drivers(folder)
    if only:
        unknown = sorted(set(only) - {n for n, _ in named})
        if unknown:
            raise ValueError(f"only must name drivers of {folder} ({[n for n, _ in named]}), got {unknown}")
    protocol = {"drives": drives, "seed": ROUTE_SEED, "folder": Path(folder).name, "max_steps": max_steps}
    if heldout_seed is not None:  # recorded only when taken: fixed-route folders read as before
        protocol.update(heldout_seed=heldout_seed, heldout_count=heldout_count)

    def drive(name, ck, path):
        if ck is None:
            agent, policy_seed, takes = "expert", 0, False
        else:
            agent, ckpt = load_agent(ck)
            policy_seed, takes = training_seed(ckpt) or 0, agent.takes_command
        rows = evaluate_on_routes(
            agent, routes, drives=drives, seed=ROUTE_SEED, policy_seed=policy_seed, max_steps=max_steps
        )
        checkpoint = None if ck is None else str(Path(ck).relative_to(Path(folder)))
        summary = summarize_route_rows(rows)
        meta = {"driver": name, "checkpoint": checkpoint, "commands": takes, "policy_seed": policy_seed}
        write_json(path, {**meta, "summary": summary, "episodes": rows})

    path_of = lambda name: Path(out) / f"{name}.json"  # noqa: E731
    return run_missing_recorded(named, out, protocol, path_of, drive, only=only, log=log, command=command)


def load_route_drives(out) -> dict[str, dict]:
    """name -> the JSON of every driver's file in ``out`` (``run_route_drives``'s), by file name."""
    return read_driver_files(out, "route drives")
