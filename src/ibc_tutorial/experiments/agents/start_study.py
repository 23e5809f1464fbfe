"""Every agent of a replication folder, and the expert, driven from more town02 starts (chapter 09).

The table's ten starts and the five held-out ones are all the starts a replication drives; chapter 09 shows
that the start moves each method's share of the expert by more than the agents do. ``run_start_drives``
drives every driver of a folder (``stem_drives.drivers``: every ``runs/<method>/seed<k>/final.pt``, then the
expert) for ``episodes`` more routeless town02 episodes of ``steps`` steps from the starts ``seed``,
``seed + 1``, ... (the table's protocol with other starts: the DFO draws of each agent's training seed):

    ibc-tutorial starts --folder book/results/laptop --seed 40000 --out book/results/laptop/more-starts

One JSON file per driver in ``out`` (``<method>-seed<k>.json``, ``expert.json``: ``final_eval.json``'s
fields), a driver whose file exists is skipped, so an interrupted run resumes, and ``provenance.json``
records every invocation, its command, commit, machine and CPU seconds per driver.
"""

from __future__ import annotations

from pathlib import Path

from ibc_tutorial.experiments.agents.checkpoints import load_agent, training_seed
from ibc_tutorial.experiments.agents.evaluate import episode_rows, evaluate_agent, summarize_episodes
from ibc_tutorial.experiments.agents.stem_drives import drivers
from ibc_tutorial.experiments.runs import read_driver_files, run_missing_recorded, write_json
from ibc_tutorial.utils import check_int


def run_start_drives(
    folder, out, seed: int, episodes: int = 10, steps: int = 3000, only=None, log=print, command: str = ""
) -> list[str]:
    """Drive each driver of ``folder`` without a file in ``out`` from the starts ``seed`` ... ``seed +
    episodes - 1``; returns the names driven. ``only``: names to drive (None: all); ``command``: the command
    line, recorded in ``out/provenance.json``. ValueError if ``out`` holds drives of another protocol."""
    seed = check_int("seed", seed, minimum=0)
    episodes = check_int("episodes", episodes, minimum=1)
    steps = check_int("steps", steps, minimum=1)
    named = drivers(folder)
    if only:
        unknown = sorted(set(only) - {n for n, _ in named})
        if unknown:
            raise ValueError(f"only must name drivers of {folder} ({[n for n, _ in named]}), got {unknown}")
    protocol = {"seed": seed, "episodes": episodes, "steps": steps, "folder": Path(folder).name}

    def drive(name, ck, path):
        if ck is None:
            agent, policy_seed = "expert", 0
        else:
            agent, ckpt = load_agent(ck)
            policy_seed = training_seed(ckpt) or 0
        results = evaluate_agent(agent, "town02", episodes, steps, seed=seed, policy_seed=policy_seed)
        rows = episode_rows(results)
        checkpoint = None if ck is None else str(Path(ck).relative_to(Path(folder)))
        meta = {"driver": name, "checkpoint": checkpoint, "policy_seed": policy_seed}
        write_json(path, {**meta, "summary": summarize_episodes(rows), "episodes": rows})

    path_of = lambda name: Path(out) / f"{name}.json"  # noqa: E731
    return run_missing_recorded(named, out, protocol, path_of, drive, only=only, log=log, command=command)


def load_start_drives(out) -> dict[str, dict]:
    """name -> the JSON of every driver's file in ``out`` (``run_start_drives``'s), by file name."""
    return read_driver_files(out, "start drives")
