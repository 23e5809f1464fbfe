"""Does the code of each replication folder's commit compute what the checked code computes? (chapter 08)

Chapter 08 compares the canonical replication (``book/results/laptop``) with ablation folders, each one
``replicate --set`` change of it or of the 10-route replication (``book/results/ten-routes``), and the
folders were made at the commits their ``PROVENANCE.md`` names, on the machines it names. A difference
between two folders should come from the setting that differs, not from code that changed in between.
This script checks that, run by run: for each folder, and for BC and DA-IBC at seed 0, it trains the run
on this machine until its first periodic evaluation (epoch ``eval_every``, with the folder's stored
preset and demonstrations), twice:

- with the code of the folder's own commit (a temporary ``git worktree``);
- with the checked code (this checkout's ``src``: the ``today`` keys of the output);

and compares the two bit for bit: the training loss at that epoch and every episode of the evaluation
(distance, red lights, how it ended). It also compares both with what the folder stored, which was made
on the machine its provenance names. A folder made with the checked code needs no second run
(``--skip-old`` for those).

    ATEN_CPU_CAPABILITY=avx2 python tools/check_ablation_code.py \
        --out book/results/ablations/code_check.json \
        --skip-old ablations/no-held-brakes ablations/intensity-lights ablations/constant-schedule

About 2 minutes of one core per run (two at a time); the worktrees are removed afterwards.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "book" / "results"
FOLDERS = {  # folder -> where its demonstrations are
    "laptop": "laptop",
    "ten-routes": "ten-routes",
    "ablations/half-epochs": "ablations/half-epochs",
    "ablations/turn-hold": "ablations/turn-hold",
    "ablations/no-held-brakes": "ablations/no-held-brakes",
    "ablations/intensity-lights": "ablations/intensity-lights",
    "ablations/constant-schedule": "ablations/constant-schedule",
}
METHODS = ("bc", "da-ibc")

# Run in a subprocess with one version of the code on PYTHONPATH: train until the first periodic
# evaluation (the log line comes right after metrics.jsonl is written), print that metrics entry.
# Only calls that every commit since the first ablation has: Preset.from_dict and train_agent.
TRAIN_TO_FIRST_EVALUATION = """
import json, sys, tempfile
from pathlib import Path
import torch
from ibc_tutorial.experiments.agents.presets import Preset
from ibc_tutorial.experiments.agents.train import train_agent

torch.set_num_threads(1)
run_json, data, method = sys.argv[1:4]
preset = Preset.from_dict(json.loads(Path(run_json).read_text())["preset"])


class FirstEvaluation(Exception):
    pass


def stop(line):
    raise FirstEvaluation


with tempfile.TemporaryDirectory() as d:
    try:
        train_agent(method, data, preset, 0, Path(d) / "run", show_progress=False, log=stop)
    except FirstEvaluation:
        pass
    first = json.loads((Path(d) / "run" / "metrics.jsonl").read_text().splitlines()[0])
print(json.dumps({"epoch": first["epoch"], "loss": first["loss"], "episodes": first["episodes"]}))
"""


def first_evaluation(src: Path, run_json: Path, data: Path, method: str) -> dict:
    """Train with the code in ``src`` until the first periodic evaluation; its metrics entry."""
    env = dict(os.environ, PYTHONPATH=str(src), OMP_NUM_THREADS="1", TQDM_DISABLE="1")
    done = subprocess.run(
        [sys.executable, "-c", TRAIN_TO_FIRST_EVALUATION, str(run_json), str(data), method],
        env=env,
        cwd=src.parent,
        capture_output=True,
        text=True,
    )
    if done.returncode:
        raise RuntimeError(f"training with {src} failed:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def stored_first_evaluation(run: Path) -> dict:
    first = json.loads((run / "metrics.jsonl").read_text().splitlines()[0])
    return {"epoch": first["epoch"], "loss": first["loss"], "episodes": first["episodes"]}


def commit_of(folder: Path) -> str:
    prov = json.loads((folder / "provenance.json").read_text())
    return prov["commit"] if "commit" in prov else prov["invocations"][0]["commit"]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, help="where the JSON of the comparisons goes")
    parser.add_argument("--workers", type=int, default=2, help="trainings at a time")
    parser.add_argument("--skip-old", nargs="*", default=(), help="folders whose own commit is not run")
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT / "src"))
    from ibc_tutorial.driving.dataset import DemoLog
    from ibc_tutorial.utils import atomic_write_bytes

    # the demonstrations: each run's recorded checksum must be that of the file it is trained on
    jobs, rows = [], []
    for name, data_folder in FOLDERS.items():
        data = RESULTS / data_folder / "data" / "town01.npz"
        checksum = DemoLog.load(data).checksum()
        for method in METHODS:
            run = RESULTS / name / "runs" / method / "seed0"
            recorded = json.loads((run / "run.json").read_text())["data_sha256"]
            if recorded != checksum:
                raise SystemExit(f"{run}: trained on data {recorded[:12]}, not {data} ({checksum[:12]})")
            row = {"folder": name, "method": method, "commit": commit_of(RESULTS / name), "data": data_folder}
            rows.append(row)
            jobs.append((row, "today", ROOT / "src", run, data))

    with tempfile.TemporaryDirectory() as tmp:
        trees = {}
        for row in rows:
            c = row["commit"]
            if row["folder"] in args.skip_old or c in trees:
                continue
            trees[c] = Path(tmp) / c[:7]
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(trees[c]), c], check=True
            )
        try:
            for row in rows:
                if row["folder"] not in args.skip_old:
                    run = RESULTS / row["folder"] / "runs" / row["method"] / "seed0"
                    jobs.append(
                        (
                            row,
                            "own_commit",
                            trees[row["commit"]] / "src",
                            run,
                            RESULTS / row["data"] / "data" / "town01.npz",
                        )
                    )

            def work(job):
                row, key, src, run, data = job
                row[key] = first_evaluation(src, run / "run.json", data, row["method"])
                print(f"{row['folder']} {row['method']} {key}: loss {row[key]['loss']}", flush=True)

            with ThreadPoolExecutor(args.workers) as pool:
                list(pool.map(work, jobs))
        finally:
            for tree in trees.values():
                subprocess.run(
                    ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=False
                )

    for row in rows:
        stored = stored_first_evaluation(RESULTS / row["folder"] / "runs" / row["method"] / "seed0")
        row["stored"] = {"loss": stored["loss"], "score_mean": _mean(stored["episodes"])}
        row["today_equals_stored"] = _same(row["today"], stored)
        if "own_commit" in row:
            row["today_equals_own_commit"] = _same(row["today"], row["own_commit"])
        for key in ("today", "own_commit"):
            if key in row:
                row[key] = {"loss": row[key]["loss"], "score_mean": _mean(row[key]["episodes"])}
    import platform

    import torch

    out = {
        "command": "python tools/check_ablation_code.py " + " ".join(sys.argv[1:]),
        "machine": {
            "node": platform.platform(),
            "torch": torch.__version__,
            "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        },
        "today_commit": subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip(),
        "rows": rows,
    }
    atomic_write_bytes(Path(args.out), (json.dumps(out, indent=1) + "\n").encode())
    return 0


def _same(a: dict, b: dict) -> bool:
    return a["epoch"] == b["epoch"] and a["loss"] == b["loss"] and a["episodes"] == b["episodes"]


def _mean(episodes: list[dict]) -> float:
    return round(sum(e["score"] for e in episodes) / len(episodes), 3)


if __name__ == "__main__":
    raise SystemExit(main())
