"""One command from data to every table and figure of chapters 08-09: the closed-loop replication.

    ibc-tutorial replicate --preset laptop --out book/results/laptop

Steps (the DA-IBC paper's secs. 4.1-4.3, at the preset's scale):

1. collect the expert's demonstrations in town01 (``data/town01.npz``);
2. for each seed, for each method (bc, ibc, da-ibc): train an agent (``agent_training``), with
   its periodic town02 evaluations (the Fig. 4 curve), then its final evaluation: the preset's
   ``final_episodes`` batched episodes of ``final_steps`` steps in town02 (the table);
3. after the first seed: free driving in town02 for BC and DA-IBC (the Fig. 5 analogue:
   trajectories, road coverage, exits per junction approach) and DA-IBC's energy landscapes
   at a junction and at a red light with ten DFO inferences each (the Fig. 6 analogue);
4. after every run: ``results.json`` (everything the chapters read), ``PROVENANCE.md`` and
   ``provenance.json`` (command, commit, date, machine, wall time, what is finished).

Interrupted, the same command resumes: finished runs are skipped and an unfinished one resumes
from its ``last.pt``. Checkpoints kept: ``final.pt`` of the first seed's BC and DA-IBC agents
(the rest are deleted once evaluated, to keep the shipped results small; ``--keep-checkpoints``
keeps them all).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import torch

from ibc_tutorial import __version__, kde
from ibc_tutorial.presets import METHODS, PAPER, Preset, differences, get_preset
from ibc_tutorial.utils import atomic_write_bytes, check_int

RESULTS = "results.json"
"""The file the chapters read."""
FREE_DRIVING = "free_driving.npz"
"""Trajectories of the free-driving episodes (Fig. 5 analogue)."""
LANDSCAPES = "landscapes.npz"
"""Energy grids, observations and DFO inferences (Fig. 6 analogue)."""
JUNCTION_DISTANCE = 8.0
"""The junction observation is taken where the car is closest to this distance (m) before the entry."""
JUNCTION_RANGE = (4.0, 15.0)
"""Distances (m) before the entry at which a junction observation is taken (a green light preferred)."""
RED_DISTANCE = (2.0, 15.0)
"""A red-light observation: on an approach whose light is red, this far (m) from the entry."""


def _now() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def machine() -> dict:
    """CPU count and model, OS, Python and torch versions, torch's threads."""
    model = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"nproc": os.cpu_count(), "cpu": model, "os": platform.platform(), "python": platform.python_version(),
            "torch": torch.__version__, "torch_threads": torch.get_num_threads()}


def git_commit() -> str:
    """``git rev-parse HEAD`` of the working tree (or "unknown"), with "+changes" if it is not clean."""
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True,
                               timeout=10).stdout.strip()
        return (head or "unknown") + (" +uncommitted changes" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def run_dir(out, method: str, seed: int) -> Path:
    """Folder of one training run."""
    return Path(out) / "runs" / method / f"seed{seed}"


# ---------------------------------------------------------------------- aggregation
def _pooled(rows: list[dict]) -> dict:
    from ibc_tutorial.evaluation import summarize

    return summarize(rows)


def collect_results(out, preset: Preset) -> dict:
    """Read every finished run under ``out`` into the dict written to ``results.json``."""
    from ibc_tutorial.agent_training import read_metrics

    out = Path(out)
    table, curves, finals = {}, {}, {}
    for method in METHODS:
        rows, per_seed = [], {}
        curves[method] = {}
        for seed in preset.seeds:
            d = run_dir(out, method, seed)
            if (d / "metrics.jsonl").exists():
                m = read_metrics(d)
                curves[method][str(seed)] = {"epoch": [e["epoch"] for e in m], "score": [e["eval"]["score_mean"] for e in m],
                                             "distance_m": [e["eval"]["distance_m_mean"] for e in m],
                                             "infractions": [e["eval"]["red_light_infractions_mean"] for e in m],
                                             "loss": [e["loss"] for e in m]}
            f = d / "final_eval.json"
            if f.exists():
                ev = json.loads(f.read_text())
                rows += ev["episodes"]
                per_seed[str(seed)] = ev["summary"]
        finals[method] = per_seed
        if rows:
            table[method] = dict(_pooled(rows), agents=len(per_seed))
    return {"table": table, "final_per_seed": finals, "curves": curves}


def write_provenance(out, preset: Preset, started: str, wall_s: float, done: list[str], planned: list[str],
                     command: str, complete: bool) -> None:
    """``provenance.json`` and ``PROVENANCE.md``: how, where and when the results were made."""
    out = Path(out)
    old = json.loads((out / "provenance.json").read_text()) if (out / "provenance.json").exists() else {}
    notes = list(old.get("notes", []))  # kept across resumed invocations
    prov = {"command": command, "commit": git_commit(), "package_version": __version__, "started": started,
            "finished": _now() if complete else None, "updated": _now(), "wall_seconds": round(wall_s, 1),
            "complete": complete, "runs_done": done, "runs_planned": planned, "machine": machine(),
            "preset": preset.to_dict(), "notes": notes}
    atomic_write_bytes(out / "provenance.json", json.dumps(prov, indent=1).encode())
    m = prov["machine"]
    lines = [
        f"# Provenance of the `{preset.name}` replication", "",
        f"- command: `{command}`",
        f"- commit: `{prov['commit']}` (ibc_tutorial {__version__})",
        f"- started: {started}; {'finished: ' + prov['finished'] if complete else 'NOT FINISHED (last update ' + prov['updated'] + ')'}",
        f"- wall time: {wall_s / 60:.1f} min",
        f"- machine: {m['nproc']} CPUs ({m['cpu']}), {m['os']}, Python {m['python']}, torch {m['torch']} "
        f"with {m['torch_threads']} thread(s)",
        f"- runs finished: {len(done)} of {len(planned)}" + ("" if complete else f" (missing: {sorted(set(planned) - set(done))})"),
        "", "Differences of this preset from the paper's settings (field: paper -> this preset):", "",
    ]
    lines += [f"- `{k}`: {a} -> {b}" for k, (a, b) in differences(PAPER, preset).items()]
    if notes:
        lines += ["", "Notes:", ""] + [f"- {n}" for n in notes]
    atomic_write_bytes(out / "PROVENANCE.md", ("\n".join(lines) + "\n").encode())


# ---------------------------------------------------------------------- Fig. 5 and Fig. 6 analogues
def free_driving(out, preset: Preset, agents: dict, log=print) -> dict:
    """Free driving in town02 for each agent in ``agents`` ({method: Agent}); writes ``free_driving.npz``.

    Returns ``{method: {"episodes": [...]}}`` and the recordings (with observations) for ``landscapes``.
    """
    from ibc_tutorial.evaluation import EVAL_SEED, drive_recording, exits_per_approach, junction_visits, road_coverage

    summary, arrays, recordings = {}, {}, {}
    for method, agent in agents.items():
        eps = []
        for i in range(preset.routeless_episodes):
            rec = drive_recording(agent, "town02", preset.routeless_steps, seed=EVAL_SEED + i, policy_seed=0, keep_obs=True)
            visits = junction_visits("town02", rec["lane"])
            eps.append({"result": rec["result"], "coverage": round(road_coverage("town02", rec["pose"]), 4),
                        "visits": visits, "exits": {str(k): v for k, v in exits_per_approach(visits).items()}})
            arrays[f"{method}_{i}_xy"] = rec["pose"][:, :2].astype(np.float32)
            recordings[(method, i)] = rec
        allpose = np.concatenate([recordings[(method, i)]["pose"] for i in range(preset.routeless_episodes)])
        from ibc_tutorial.evaluation import road_coverage as cov

        all_visits = [v for e in eps for v in e["visits"]]
        summary[method] = {"episodes": eps, "coverage_all": round(cov("town02", allpose), 4),
                           "exits_all": {str(k): v for k, v in exits_per_approach(all_visits).items()}}
        if log:
            log(f"free driving {method}: coverage {summary[method]['coverage_all']:.3f}, "
                f"{len(all_visits)} junction passes")
    buf = __import__("io").BytesIO()
    np.savez_compressed(buf, **arrays)
    atomic_write_bytes(Path(out) / FREE_DRIVING, buf.getvalue())
    return summary, recordings


def _pick_junction(rec_list) -> tuple | None:
    """(recording, step, approach, turns) of the junction observation: among the approaches where the
    car met a green light 4-15 m before the entry (all approaches if none), one taken with different
    exits if there is one (left and right preferred), else the most visited one; the moment is the
    one 4-15 m before the entry closest to 8 m, with a green light if there is one."""
    from ibc_tutorial.evaluation import exits_per_approach, junction_visits

    all_visits = [(rec, v) for rec in rec_list for v in junction_visits("town02", rec["lane"])]
    if not all_visits:
        return None
    summary = exits_per_approach([v for _, v in all_visits])

    def green_in_range(a) -> bool:  # a moment 4-15 m before the entry with a green light, on some visit
        for rec, v in all_visits:
            if v["approach"] != a:
                continue
            j, lane = v["step"], rec["lane"][v["step"]]
            while j >= 0 and rec["lane"][j] == lane:
                if JUNCTION_RANGE[0] <= rec["entry_dist"][j] <= JUNCTION_RANGE[1] and not rec["red_ahead"][j]:
                    return True
                j -= 1
        return False

    # a moving decision first (green light), then different exits (left and right best), then visits
    ap = max(summary, key=lambda a: (green_in_range(a), ("left" in summary[a]["turns"]) and ("right" in summary[a]["turns"]),
                                     len(summary[a]["turns"]), summary[a]["visits"], -a))
    candidates = []  # (out of range, red, |distance - 8 m|, order, step, rec)
    for order, (rec, v) in enumerate(x for x in all_visits if x[1]["approach"] == ap):
        k = v["step"]
        lane = rec["lane"][k]
        j = k
        while j >= 0 and rec["lane"][j] == lane:  # back along the stretch on the approach lane
            d = float(rec["entry_dist"][j])
            out = not JUNCTION_RANGE[0] <= d <= JUNCTION_RANGE[1]
            candidates.append((out, bool(rec["red_ahead"][j]), abs(d - JUNCTION_DISTANCE), order, j, rec))
            j -= 1
    *_, step, rec = min(candidates, key=lambda c: c[:5])
    return rec, step, ap, summary[ap]


def _pick_red(rec_list) -> tuple | None:
    for rec in rec_list:
        ok = np.flatnonzero(rec["red_ahead"] & (rec["entry_dist"] >= RED_DISTANCE[0]) & (rec["entry_dist"] <= RED_DISTANCE[1]))
        if len(ok):
            return rec, int(ok[np.argmin(np.abs(rec["entry_dist"][ok] - 6.0))])
    return None


def landscapes(out, agent, recordings: dict, n_grid: int = 41, n_inferences: int = 10, log=print) -> dict:
    """Energy over (steer, acceleration) and ten DFO inferences at a junction and at a red light; writes ``landscapes.npz``."""
    da = [r for (m, _), r in sorted(recordings.items()) if m == agent.method]
    others = [r for (m, _), r in sorted(recordings.items()) if m != agent.method]
    found = {"junction": _pick_junction(da) or _pick_junction(others), "red_light": _pick_red(da) or _pick_red(others)}
    arrays, meta = {}, {}
    gen = torch.Generator().manual_seed(0)
    for name, pick in found.items():
        if pick is None:
            meta[name] = None
            continue
        rec, step = pick[0], pick[1]
        obs = {"bev": rec["bev"][step][None], "state": rec["state"][step][None]}
        steer, accel, e = agent.energy_grid(obs, n_grid)
        points = np.stack([agent.act(obs, gen).numpy()[0] for _ in range(n_inferences)])  # (10, 2)
        arrays.update({f"{name}_energy": e.astype(np.float32), f"{name}_points": points.astype(np.float32),
                       f"{name}_bev": rec["bev"][step], f"{name}_state": rec["state"][step]})
        arrays["steer"], arrays["accel"] = steer.astype(np.float32), accel.astype(np.float32)
        meta[name] = {"pose": [round(float(x), 3) for x in rec["pose"][step]], "speed": round(float(rec["speed"][step]), 3),
                      "entry_dist_m": round(float(rec["entry_dist"][step]), 2), "red_ahead": bool(rec["red_ahead"][step]),
                      "episode_seed": rec["result"]["seed"]}
        if name == "junction":
            meta[name].update(approach=pick[2], node=pick[3]["node"], visits=pick[3]["visits"], turns=pick[3]["turns"])
    buf = __import__("io").BytesIO()
    np.savez_compressed(buf, **arrays)
    atomic_write_bytes(Path(out) / LANDSCAPES, buf.getvalue())
    if log:
        log(f"energy landscapes: {', '.join(k for k, v in meta.items() if v is not None) or 'none found'}")
    return meta


# ---------------------------------------------------------------------- the command
def _init_worker(threads: int) -> None:
    torch.set_num_threads(max(1, int(threads)))


_WORKER_DATA: dict = {}
"""Per worker process: the rendered dataset and its KDE probabilities, made once."""


def run_one(method: str, seed: int, out, preset, *, keep_checkpoints: bool = False, dataset=None, sample_probs=None,
            show_progress: bool | None = False, log=print) -> dict:
    """Train one agent, evaluate it finally in town02 and write its ``final_eval.json``; returns that dict."""
    from ibc_tutorial.agent_training import train_agent
    from ibc_tutorial.driving.dataset import DemoDataset
    from ibc_tutorial.evaluation import EVAL_SEED, episode_rows, evaluate_agent, summarize

    preset = preset if isinstance(preset, Preset) else Preset.from_dict(preset)
    out = Path(out)
    data = out / "data" / "town01.npz"
    if dataset is None:
        key = (str(data), preset.bev_size, preset.kde_bandwidth)
        if key not in _WORKER_DATA:
            ds = DemoDataset(data, bev_size=preset.bev_size, cache=True)
            _WORKER_DATA[key] = (ds, kde.sampling_probs(ds.actions, preset.kde_bandwidth, "inverse-kde"))
        dataset, sample_probs = _WORKER_DATA[key]
    d = run_dir(out, method, seed)
    res = train_agent(method, data, preset, seed, d, dataset=dataset, sample_probs=sample_probs,
                      show_progress=show_progress, log=log)
    te = time.perf_counter()
    rows = episode_rows(evaluate_agent(res.agent, "town02", preset.final_episodes, preset.final_steps,
                                       seed=EVAL_SEED, policy_seed=seed, show_progress=show_progress))
    ev = {"method": method, "seed": seed, "town": "town02", "steps": preset.final_steps, "summary": summarize(rows),
          "episodes": rows, "train_seconds": round(res.seconds, 1), "eval_seconds": round(time.perf_counter() - te, 1)}
    (d / "last.pt").unlink(missing_ok=True)
    if not keep_checkpoints and not (seed == preset.seeds[0] and method in ("bc", "da-ibc")):
        (d / "final.pt").unlink(missing_ok=True)
    atomic_write_bytes(d / "final_eval.json", json.dumps(ev, indent=1).encode())
    return ev


def replicate(preset: Preset, out, *, command: str = "", keep_checkpoints: bool = False, workers: int = 1, log=print,
              show_progress: bool | None = None) -> dict:
    """Run the whole replication (see the module docstring); returns the contents of ``results.json``."""
    from ibc_tutorial.checkpoints import load_agent
    from ibc_tutorial.driving.collect import CollectConfig, collect
    from ibc_tutorial.driving.dataset import DemoDataset

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    prov_file = out / "provenance.json"
    previous = json.loads(prov_file.read_text()) if prov_file.exists() else {}
    started = previous.get("started") or _now()
    wall_before = float(previous.get("wall_seconds", 0.0)) if previous.get("preset") == preset.to_dict() else 0.0
    command = command or f"ibc-tutorial replicate --preset {preset.name} --out {out}"
    planned = [f"{m}/seed{s}" for s in preset.seeds for m in METHODS]
    res_file = out / RESULTS
    results = json.loads(res_file.read_text()) if res_file.exists() else {}

    def save(complete: bool):
        done = [f"{m}/seed{s}" for s in preset.seeds for m in METHODS if (run_dir(out, m, s) / "final_eval.json").exists()]
        results.update(collect_results(out, preset))
        results.update(preset=preset.to_dict(), paper=PAPER.to_dict(),
                       differences={k: list(v) for k, v in differences(PAPER, preset).items()}, complete=complete)
        atomic_write_bytes(res_file, json.dumps(results, indent=1).encode())
        write_provenance(out, preset, started, wall_before + time.perf_counter() - t0, done, planned, command, complete)

    # 1. the demonstrations
    data = out / "data" / "town01.npz"
    if not data.exists():
        demo = collect(CollectConfig("town01", preset.routes, preset.collect_seed, preset.min_minutes, preset.max_minutes),
                       show_progress=show_progress)
        demo.save(data)
        if log:
            log(f"collected {len(demo)} samples in town01")
    from ibc_tutorial.driving.dataset import DemoLog

    results["data"] = {"file": "data/town01.npz", "samples": len(DemoLog.load(data)), "routes": preset.routes}
    # 2-3. the runs, seed by seed (in ``workers`` processes: the first seed's runs are submitted first)
    todo = [(m, s) for s in preset.seeds for m in METHODS if not (run_dir(out, m, s) / "final_eval.json").exists()]

    def after_run(ev: dict) -> None:
        if log:
            log(f"{ev['method']} seed {ev['seed']}: final town02 score {ev['summary']['score_mean']:.1f} ± "
                f"{ev['summary']['score_std']:.1f} ({ev['train_seconds']:.0f} s training, {ev['eval_seconds']:.0f} s evaluation)")
        save(False)

    def figures_if_ready() -> None:
        s0 = preset.seeds[0]
        if "free_driving" in results or not all((run_dir(out, m, s0) / "final_eval.json").exists() for m in ("bc", "da-ibc")):
            return
        agents = {m: load_agent(run_dir(out, m, s0) / "final.pt")[0] for m in ("bc", "da-ibc")}
        summary, recordings = free_driving(out, preset, agents, log=log)
        results["free_driving"] = summary
        results["landscapes"] = landscapes(out, agents["da-ibc"], recordings, log=log)
        save(False)

    figures_if_ready()
    if workers <= 1:
        dataset = DemoDataset(data, bev_size=preset.bev_size, cache=True)
        probs = kde.sampling_probs(dataset.actions, preset.kde_bandwidth, "inverse-kde")  # (M,) shared by every run
        for method, seed in todo:
            after_run(run_one(method, seed, out, preset, keep_checkpoints=keep_checkpoints, dataset=dataset,
                              sample_probs=probs, show_progress=show_progress, log=log))
            figures_if_ready()
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

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


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--preset", default="laptop", help="paper, laptop or tiny (default: %(default)s)")
    parser.add_argument("--out", required=True, help="folder for the data, runs, results and provenance")
    parser.add_argument("--keep-checkpoints", action="store_true", help="keep every agent's final.pt")
    parser.add_argument("--threads", type=int, default=0,
                        help="torch CPU threads per process (default 0: torch's choice; 1 is fastest on a busy machine)")
    parser.add_argument("--workers", type=int, default=1, help="training runs in parallel processes (default: %(default)s)")


def run(args: argparse.Namespace) -> int:
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


def load_results(out) -> dict:
    """What the chapters read from a replication folder: ``results.json`` and ``provenance.json`` as
    dicts, ``free_driving.npz`` and ``landscapes.npz`` as dicts of arrays (empty if absent)."""
    out = Path(out)
    if not (out / RESULTS).exists():
        raise ValueError(f"no {RESULTS} in {out}: run 'ibc-tutorial replicate --out {out}' first")
    res = {"results": json.loads((out / RESULTS).read_text()),
           "provenance": json.loads((out / "provenance.json").read_text()) if (out / "provenance.json").exists() else {}}
    for key, name in (("free_driving", FREE_DRIVING), ("landscapes", LANDSCAPES)):
        if (out / name).exists():
            with np.load(out / name) as z:
                res[key] = {k: z[k] for k in z.files}
        else:
            res[key] = {}
    return res
