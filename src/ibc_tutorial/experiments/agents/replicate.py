"""One command from data to every table and figure of chapters 08-09: the closed-loop replication.

    ibc-tutorial replicate --preset laptop --out book/results/laptop

Steps (the DA-IBC paper's secs. 4.1-4.3, at the preset's scale):

1. collect the expert's demonstrations in town01 (``data/town01.npz``);
2. for each seed, for each method (bc, ibc, da-ibc): train an agent (``train.train_agent``), with
   its periodic town02 evaluations (the Fig. 4 curve), then its final evaluation: the preset's
   ``final_episodes`` batched episodes of ``final_steps`` steps in town02 (the table);
3. once the first seed's BC and DA-IBC agents are done: free driving in town02 (the Fig. 5
   analogue) and DA-IBC's energy landscapes (the Fig. 6 analogue), see ``figures``;
4. after every run: ``results.json``, ``PROVENANCE.md`` and ``provenance.json`` (see ``results``).

Interrupted, the same command resumes: finished runs are skipped and an unfinished one resumes
from its ``last.pt``. Checkpoints kept: ``final.pt`` of the first seed's BC and DA-IBC agents
(the rest are deleted once evaluated, to keep the shipped results small; ``--keep-checkpoints``
keeps them all).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import torch

from ibc_tutorial.driving.collect import CollectConfig, collect
from ibc_tutorial.driving.dataset import DemoDataset, DemoLog
from ibc_tutorial.experiments.agents.checkpoints import load_agent
from ibc_tutorial.experiments.agents.evaluate import EVAL_SEED, episode_rows, evaluate_agent, summarize
from ibc_tutorial.experiments.agents.figures import free_driving, landscapes
from ibc_tutorial.experiments.agents.presets import METHODS, Preset, get_preset
from ibc_tutorial.experiments.agents.results import (
    DATA, PROVENANCE, RESULTS, collect_results, finished_runs, now, preset_results, run_dir, run_name, write_json,
    write_provenance)
from ibc_tutorial.experiments.agents.train import train_agent
from ibc_tutorial.kde import inverse_density_weights
from ibc_tutorial.utils import check_int

FIGURE_METHODS = ("bc", "da-ibc")
"""The agents of the first seed kept for the Fig. 5/6 analogues (their ``final.pt`` is kept too)."""


def _init_worker(threads: int) -> None:
    torch.set_num_threads(max(1, int(threads)))


_WORKER_DATA: dict = {}
"""Per worker process: the rendered dataset and its KDE probabilities, made once."""


def _dataset(data: Path, preset: Preset) -> tuple[DemoDataset, torch.Tensor]:
    """The rendered demonstrations and their minibatch probabilities w ∝ 1 / ĝ, made once per process."""
    key = (str(data), data.stat().st_mtime_ns, preset.bev_size, preset.kde_bandwidth)
    if key not in _WORKER_DATA:
        ds = DemoDataset(data, bev_size=preset.bev_size, cache=True)
        _WORKER_DATA[key] = (ds, inverse_density_weights(ds.actions, preset.kde_bandwidth))  # (M,) eqs. 4-5
    return _WORKER_DATA[key]


def run_one(method: str, seed: int, out, preset, *, keep_checkpoints: bool = False, show_progress: bool | None = False,
            log=print) -> dict:
    """Train one agent, evaluate it finally in town02 and write its ``final_eval.json``; returns that dict."""
    preset = preset if isinstance(preset, Preset) else Preset.from_dict(preset)
    out = Path(out)
    data = out / DATA
    dataset, probs = _dataset(data, preset)
    d = run_dir(out, method, seed)
    res = train_agent(method, data, preset, seed, d, dataset=dataset, sample_probs=probs, show_progress=show_progress,
                      log=log)
    te = time.perf_counter()
    rows = episode_rows(evaluate_agent(res.agent, "town02", preset.final_episodes, preset.final_steps,
                                       seed=EVAL_SEED, policy_seed=seed, show_progress=show_progress))
    ev = {"method": method, "seed": seed, "town": "town02", "steps": preset.final_steps, "summary": summarize(rows),
          "episodes": rows, "train_seconds": round(res.seconds, 1), "eval_seconds": round(time.perf_counter() - te, 1)}
    (d / "last.pt").unlink(missing_ok=True)
    if not keep_checkpoints and not (seed == preset.seeds[0] and method in FIGURE_METHODS):
        (d / "final.pt").unlink(missing_ok=True)
    write_json(d / "final_eval.json", ev)
    return ev


def replicate(preset: Preset, out, *, command: str = "", keep_checkpoints: bool = False, workers: int = 1, log=print,
              show_progress: bool | None = None) -> dict:
    """Run the whole replication (see the module docstring); returns the contents of ``results.json``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    prov_file = out / PROVENANCE
    previous = json.loads(prov_file.read_text()) if prov_file.exists() else {}
    started = previous.get("started") or now()
    wall_before = float(previous.get("wall_seconds", 0.0)) if previous.get("preset") == preset.to_dict() else 0.0
    command = command or f"ibc-tutorial replicate --preset {preset.name} --out {out}"
    planned = [run_name(m, s) for s in preset.seeds for m in METHODS]
    res_file = out / RESULTS
    results = json.loads(res_file.read_text()) if res_file.exists() else {}

    def save(complete: bool) -> None:
        results.update(collect_results(out, preset))
        results.update(preset_results(preset, complete))
        write_json(res_file, results)
        write_provenance(out, preset, started, wall_before + time.perf_counter() - t0, finished_runs(out, preset), planned,
                         command, complete)

    # 1. the demonstrations
    data = out / DATA
    if not data.exists():
        demo = collect(CollectConfig("town01", preset.routes, preset.collect_seed, preset.min_minutes, preset.max_minutes),
                       show_progress=show_progress)
        demo.save(data)
        if log:
            log(f"collected {len(demo)} samples in town01")
    results["data"] = {"file": DATA, "samples": len(DemoLog.load(data)), "routes": preset.routes}

    # 2-3. the runs, seed by seed (in ``workers`` processes: the first seed's runs are submitted first)
    todo = [(m, s) for s in preset.seeds for m in METHODS if not (run_dir(out, m, s) / "final_eval.json").exists()]

    def after_run(ev: dict) -> None:
        if log:
            log(f"{ev['method']} seed {ev['seed']}: final town02 score {ev['summary']['score_mean']:.1f} ± "
                f"{ev['summary']['score_std']:.1f} ({ev['train_seconds']:.0f} s training, {ev['eval_seconds']:.0f} s evaluation)")
        save(False)

    def figures_if_ready() -> None:
        s0 = preset.seeds[0]
        if "free_driving" in results or not all((run_dir(out, m, s0) / "final_eval.json").exists() for m in FIGURE_METHODS):
            return
        agents = {m: load_agent(run_dir(out, m, s0) / "final.pt")[0] for m in FIGURE_METHODS}
        summary, recordings = free_driving(out, preset, agents, log=log)
        results["free_driving"] = summary
        results["landscapes"] = landscapes(out, agents["da-ibc"], recordings, log=log)
        save(False)

    figures_if_ready()
    if workers <= 1:
        for method, seed in todo:
            after_run(run_one(method, seed, out, preset, keep_checkpoints=keep_checkpoints, show_progress=show_progress,
                              log=log))
            figures_if_ready()
    else:
        ctx = multiprocessing.get_context("spawn")  # no fork after torch has started its threads
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker,
                                 initargs=(torch.get_num_threads(),)) as pool:
            futures = [pool.submit(run_one, m, s, str(out), preset.to_dict(), keep_checkpoints=keep_checkpoints)
                       for m, s in todo]
            for fut in as_completed(futures):
                after_run(fut.result())
                figures_if_ready()
    save(True)
    if log:
        log(f"replication finished in {(wall_before + time.perf_counter() - t0) / 60:.1f} min; results in {out}")
    return results


def run(args: argparse.Namespace) -> int:
    """``ibc-tutorial replicate`` (arguments in ``ibc_tutorial.cli``): check the inputs, then replicate."""
    try:
        preset = get_preset(args.preset)
        threads = check_int("--threads", args.threads, minimum=0)
        workers = check_int("--workers", args.workers, minimum=1)
    except ValueError as exc:
        raise SystemExit(f"ibc-tutorial replicate: {exc}") from None
    if threads:
        torch.set_num_threads(threads)
    command = "ibc-tutorial " + " ".join(sys.argv[1:]) if sys.argv and "replicate" in sys.argv else ""
    replicate(preset, args.out, command=command, keep_checkpoints=args.keep_checkpoints, workers=workers)
    return 0
