"""The sub-commands' work, each a function of the arguments ``ibc_tutorial.cli`` parsed and checked.

The CLI owns the command line: it parses it, checks the paths it names (before any work), and sets
``args.command_line`` for the provenance. Each function here turns the arguments into the
library's settings (a preset with its ``--set`` overrides: ``ValueError`` before any work), prints
what a user reads, and returns the exit code. Nothing here reads ``sys.argv``. Each imports its
modules when called, so that ``ibc-tutorial evaluate`` does not load the training code.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time

import torch

from ibc_tutorial.utils import atomic_write_bytes, check_choice, check_device, check_int, plural


def _threads(args: argparse.Namespace) -> int:
    return check_int("--threads", args.threads, minimum=0)


def collect(args: argparse.Namespace) -> int:
    """``ibc-tutorial collect``: drive the expert, store the demonstrations in ``--out``."""
    from ibc_tutorial.driving.collect import CollectConfig
    from ibc_tutorial.driving.collect import collect as collect_demonstrations
    from ibc_tutorial.experiments.settings import config_from

    config = config_from(CollectConfig, args)  # --town, --routes, --seed, ...: options named after its fields
    t0 = time.perf_counter()
    log = collect_demonstrations(config)
    seconds = time.perf_counter() - t0
    path = log.save(args.out)
    eps = log.meta["episodes"]
    dist = sum(e["distance_m"] for e in eps)
    inf = sum(e["red_light_infractions"] for e in eps)
    ends = sum(e["end"] != "completed" for e in eps)
    print(
        f"{plural(len(log), 'sample')} in {plural(len(eps), 'episode')} of {config.town}: "
        f"{dist / 1000:.1f} km, {plural(inf, 'red-light infraction')}, "
        f"{plural(ends, 'episode')} ended early; {seconds:.1f} s; written to {path}"
    )
    return 0


def train(args: argparse.Namespace) -> int:
    """``ibc-tutorial train``: the preset and its overrides, the data and the folder checked, then train."""
    from ibc_tutorial.driving.dataset import DemoLog
    from ibc_tutorial.experiments.agents import train as training
    from ibc_tutorial.experiments.agents.presets import get_preset, with_overrides
    from ibc_tutorial.experiments.agents.training_run import clear_run, inspect_run

    preset = get_preset(args.preset)
    if args.epochs is not None:
        preset = dataclasses.replace(preset, epochs=check_int("--epochs", args.epochs, minimum=1))
    preset = with_overrides(preset, getattr(args, "overrides", ()))
    seed = check_int("--seed", args.seed, minimum=0)
    threads = _threads(args)
    device = check_device("--device", getattr(args, "device", "cpu"))
    force = bool(getattr(args, "force", False))
    demo = DemoLog.load(args.data)
    if not force:
        state = inspect_run(args.out, args.method, preset, seed, demo.checksum(), args.data)
        if state.status == "done":
            print(
                f"{args.out} holds this run trained to epoch {state.epoch} already: nothing to do "
                "(--epochs N to train on, --force to start over)"
            )
            return 0
    else:
        clear_run(args.out)
    if threads:
        torch.set_num_threads(threads)
    result = training.train_agent(args.method, args.data, preset, seed, args.out, device=device)
    if not result.metrics or result.metrics[-1]["epoch"] != preset.epochs:
        raise ValueError(
            f"{args.out}: the run ended at epoch {result.metrics[-1]['epoch'] if result.metrics else 0}, "
            f"not {preset.epochs}"
        )
    again = f" (resumed after epoch {result.resumed_from})" if result.resumed_from else ""
    print(
        f"trained {args.method} (seed {seed}) to epoch {preset.epochs}{again} in {result.seconds:.0f} s; "
        f"checkpoints in {result.out}"
    )
    return 0


def evaluate(args: argparse.Namespace) -> int:
    """``ibc-tutorial evaluate``: drive a checkpoint's agent, print each episode, write ``--out``."""
    from ibc_tutorial import __version__
    from ibc_tutorial.driving.rollout import RolloutRecording
    from ibc_tutorial.experiments.agents.checkpoints import load_agent, training_seed
    from ibc_tutorial.experiments.agents.crossings import crossing_rows, ended_crossing_energies
    from ibc_tutorial.experiments.agents.evaluate import episode_rows, evaluate_agent, summarize_episodes
    from ibc_tutorial.experiments.runs import git_commit, machine

    seed = check_int("--seed", args.seed, minimum=0)
    threads = _threads(args)
    device = check_device("--device", getattr(args, "device", "cpu"))
    for name in ("episodes", "steps"):
        if getattr(args, name) is not None:
            check_int(f"--{name}", getattr(args, name), minimum=1)
    if args.policy_seed is not None:
        check_int("--policy-seed", args.policy_seed, minimum=0)
    crossings = getattr(args, "crossings", False)
    agent, ckpt = load_agent(args.checkpoint)
    agent.to(device)  # loaded onto the CPU (map_location="cpu"), then moved
    episodes = args.episodes or agent.preset.final_episodes
    steps = args.steps or agent.preset.final_steps
    policy_seed = args.policy_seed if args.policy_seed is not None else training_seed(ckpt)
    if policy_seed is None:
        raise ValueError(f"{args.checkpoint} does not record its training seed: pass --policy-seed")
    routeless = not getattr(args, "routed", False)
    if threads:
        torch.set_num_threads(threads)
    protocol = {"seed": seed, "policy_seed": policy_seed, "routeless": routeless}
    recording = RolloutRecording(xy=False, steps=crossings)
    results = evaluate_agent(agent, args.town, episodes, steps, **protocol, record=recording)
    rows = episode_rows(results)
    energy_steer = None
    if crossings:
        for row, r in zip(rows, results, strict=True):
            row["junction_crossings"] = crossing_rows(args.town, r)
        if agent.method != "bc":
            energy_steer = ended_crossing_energies(agent, args.town, rows, steps=steps, **protocol)
    print(
        f"{ckpt['method']} agent (epoch {ckpt['epoch']}) in {args.town}, {episodes} "
        f"{'routeless' if routeless else 'routed'} {'episode' if episodes == 1 else 'episodes'} of {steps} "
        f"steps from seed {seed}, "
        f"policy seed {policy_seed}:"
    )
    print(f"{'episode':>8} {'seed':>6} {'steps':>6} {'distance m':>11} {'infractions':>12} {'score':>8}  end")
    for k, r in enumerate(rows):
        print(
            f"{k:>8} {r['seed']:>6} {r['steps']:>6} {r['distance_m']:>11.1f} "
            f"{r['red_light_infractions']:>12} "
            f"{r['score']:>8.1f}  {r['termination'] or '-'}"
        )
    s = summarize_episodes(rows)
    print(
        f"mean score {s['score_mean']:.1f} ± {s['score_std']:.1f}, distance {s['distance_m_mean']:.1f} m, "
        f"infractions {s['red_light_infractions_mean']:.2f}"
    )
    if args.out:
        payload = {
            "checkpoint": str(args.checkpoint),
            "method": ckpt["method"],
            "town": args.town,
            "steps": steps,
            "seed": seed,
            "policy_seed": policy_seed,
            "routeless": routeless,
            "package_version": __version__,
            "commit": git_commit(),
            "machine": machine(),
            "summary": s,
            "episodes": rows,
        }
        if energy_steer is not None:  # the steering values of the ended crossings' energy_by_steer
            payload["energy_steer_grid"] = [round(float(v), 4) for v in energy_steer]
        atomic_write_bytes(args.out, json.dumps(payload, indent=1).encode())
    return 0 if all(math.isfinite(r["score"]) for r in rows) else 1


def replicate(args: argparse.Namespace) -> int:
    """``ibc-tutorial replicate``: the preset (with its ``--set`` overrides) and the folder checked, then
    replicate. A one-off variant of a preset (chapter 08's ablations) is a replication with overrides."""
    from ibc_tutorial.experiments.agents import replicate as replication
    from ibc_tutorial.experiments.agents.presets import get_preset, with_overrides

    preset = get_preset(args.preset)
    overrides = list(getattr(args, "overrides", ()))
    if getattr(args, "commands", False):
        preset = dataclasses.replace(preset, commands=True)  # before the overrides: --set may still change it
    preset = with_overrides(preset, overrides)
    device = check_device("--device", getattr(args, "device", "cpu"))
    return _run_study(args, replication, preset, overrides, device=str(device))


def replicate_steering(args: argparse.Namespace) -> int:
    """``ibc-tutorial replicate-steering``: the preset (overrides) and the folder checked, then the study."""
    from ibc_tutorial.experiments.steering import replicate as study
    from ibc_tutorial.experiments.steering.presets import get_preset, with_overrides

    overrides = list(getattr(args, "overrides", ()))
    preset = with_overrides(get_preset(args.preset), overrides)
    check_choice("--device", args.device, ("cpu",))
    return _run_study(args, study, preset, overrides)


def _run_study(args: argparse.Namespace, study, preset, overrides: list, **settings) -> int:
    """What both studies' commands do once their preset is made: ``--threads`` and ``--workers``
    checked, the folder cleared (``--force``) and checked before any work, then ``study.replicate``."""
    threads = _threads(args)
    workers = check_int("--workers", args.workers, minimum=1)
    if getattr(args, "force", False):
        study.clear_folder(args.out)
    study.check_folder(args.out, preset)  # before any work
    if threads:
        torch.set_num_threads(threads)
    command = getattr(args, "command_line", "")
    study.replicate(preset, args.out, command=command, overrides=overrides, workers=workers, **settings)
    return 0


def stems(args: argparse.Namespace) -> int:
    """``ibc-tutorial stems drive|analyse``: the stem analysis of a replication folder (resumable)."""
    from pathlib import Path

    from ibc_tutorial.experiments.agents import stem_analysis, stem_drives

    command = getattr(args, "command_line", "")
    torch.set_num_threads(1)
    if args.step == "drive":
        dfo = {k: getattr(args, f"dfo_{k}") for k in ("select", "samples", "iters")}
        dfo = {k: v for k, v in dfo.items() if v is not None}
        protocol = stem_drives.DriveProtocol(
            args.episodes, args.steps, dfo=dfo or None, table_seeds=args.table_seeds
        )
        stem_drives.run_drives(args.folder, args.out, protocol, only=args.only, command=command)
        return 0
    if not args.summary_only:
        stem_analysis.run_analysis(args.folder, args.out, command=command)
    stem_analysis.summarise(args.out, Path(args.folder) / "data" / "town01.npz")
    return 0


def two_answers(args: argparse.Namespace) -> int:
    """``ibc-tutorial two-answers``: the two-answers replication (resumed, or nothing left to do; left
    untouched when ``--methods`` adds methods to it finished), the added methods' runs
    (``agents.added_methods``), then the readings of every agent present
    (``experiments.agents.two_answers.analyse``) into ``<out>/analysis``."""
    from pathlib import Path

    from ibc_tutorial.experiments.agents import added_methods, two_answers
    from ibc_tutorial.experiments.agents import replicate as replication
    from ibc_tutorial.experiments.agents.presets import get_preset

    preset = get_preset("two-answers")
    added = getattr(args, "methods", None)
    added = None if added is None else added_methods.check_methods(added, preset)  # before any work
    if added and not getattr(args, "force", False) and added_methods.replication_finished(args.out, preset):
        replication.check_folder(args.out, preset)  # the finished replication is left untouched
        if _threads(args):
            torch.set_num_threads(_threads(args))
    else:
        _run_study(args, replication, preset, [])
    if added:
        workers = check_int("--workers", args.workers, minimum=1)
        added_methods.add_methods(args.out, added, command=getattr(args, "command_line", ""), workers=workers)
    torch.set_num_threads(1)
    two_answers.analyse(
        args.out,
        Path(args.out) / "analysis",
        baseline=args.baseline,
        command=getattr(args, "command_line", ""),
    )
    return 0


def families(args: argparse.Namespace) -> int:
    """``ibc-tutorial families``: chapter 13's study (``experiments.family_study``), resumable."""
    from ibc_tutorial.experiments import family_study

    def seeds(name: str, text: str) -> tuple[int, ...]:
        try:
            return tuple(int(s) for s in str(text).split(",") if s.strip())
        except ValueError:
            raise ValueError(f"{name} must be integers separated by commas, got {text!r}") from None

    settings = family_study.FamiliesSettings(
        tune_seeds=seeds("--tune-seeds", args.tune_seeds), report_seeds=seeds("--seeds", args.seeds)
    )
    family_study.run_study(
        args.out,
        settings,
        workers=check_int("--workers", args.workers, minimum=1),
        threads=_threads(args) or 1,
        command=getattr(args, "command_line", ""),
        force=bool(args.force),
        note=args.note,
    )
    return 0


def routes(args: argparse.Namespace) -> int:
    """``ibc-tutorial routes``: every agent of ``--folder`` and the expert on the routes (resumable)."""
    from ibc_tutorial.experiments.agents.route_study import run_route_drives

    drives = check_int("--drives", args.drives, minimum=1)
    torch.set_num_threads(1)
    heldout = getattr(args, "heldout_seed", None)
    if heldout is not None:
        check_int("--heldout-seed", heldout, minimum=0)
    count = check_int("--heldout-routes", getattr(args, "heldout_routes", 8), minimum=1)
    run_route_drives(
        args.folder,
        args.out,
        drives,
        args.only,
        command=getattr(args, "command_line", ""),
        heldout_seed=heldout,
        heldout_count=count,
    )
    return 0


def starts(args: argparse.Namespace) -> int:
    """``ibc-tutorial starts``: every agent of ``--folder`` and the expert from more starts (resumable)."""
    from ibc_tutorial.experiments.agents.start_study import run_start_drives

    seed = check_int("--seed", args.seed, minimum=0)
    episodes = check_int("--episodes", args.episodes, minimum=1)
    steps = check_int("--steps", args.steps, minimum=1)
    torch.set_num_threads(1)
    run_start_drives(
        args.folder, args.out, seed, episodes, steps, args.only, command=getattr(args, "command_line", "")
    )
    return 0


def sweep_steering(args: argparse.Namespace) -> int:
    """``ibc-tutorial sweep-steering``: shares, models, seeds, sessions and the preset checked, the folder
    checked, then the sweep."""
    from ibc_tutorial.experiments.steering import sweep as study
    from ibc_tutorial.experiments.steering.presets import get_preset, with_overrides

    overrides = list(getattr(args, "overrides", ()))
    if any(str(o).split("=", 1)[0].strip() == "side_road_share" for o in overrides):
        raise ValueError("--set side_road_share: the sweep sets the share from --shares")
    base = with_overrides(get_preset(args.preset), overrides)
    shares = study.check_shares(args.shares)
    models = tuple(m.strip() for m in str(args.models).split(",") if m.strip())
    try:
        seeds = tuple(int(s) for s in str(args.seeds).split(",") if s.strip())
    except ValueError:
        raise ValueError(f"--seeds must be integers separated by commas, got {args.seeds!r}") from None
    try:
        settings = study.SweepSettings(
            shares=shares,
            models=models,
            seeds=seeds,
            sessions=args.sessions,
            mass_threshold=study.SWEEP.mass_threshold,
        )
    except ValueError as exc:
        raise ValueError(f"--{str(exc).lstrip('-')}") from None
    threads = _threads(args)
    workers = check_int("--workers", args.workers, minimum=1)
    check_choice("--device", args.device, ("cpu",))
    if getattr(args, "force", False):
        study.clear_folder(args.out)
    study.check_folder(args.out, settings, base)  # before any work
    if threads:
        torch.set_num_threads(threads)
    command = getattr(args, "command_line", "")
    study.sweep(
        settings,
        base,
        args.out,
        command=command,
        overrides=overrides,
        workers=workers,
        threads=torch.get_num_threads(),
    )
    return 0
