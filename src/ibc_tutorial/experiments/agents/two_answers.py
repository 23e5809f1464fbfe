"""Chapter 12's study: where the demonstrations hold two answers at one state, do the agents keep both?

The question is the DA-IBC paper's claim 4 (an energy-based policy keeps several modes where an explicit one
averages them; its Fig. 6) asked where the data allow it. The ``two-answers`` preset's demonstrations
record every town01 stem crossing left and right from the identical state (``driving.collect``'s stem twins),
so that at each fork (``driving.forks``) one observation has two labels about 0.4 apart in steering. After
``replicate --preset two-answers`` has trained and evaluated the agents, ``analyse`` reads them in three
places, each with the same functions:

- **at held-out forks**: the forks of stem twins collected with another seed (``HELDOUT_PAIRS`` per town01
  stem), never trained on;
- **at town02 stem approaches**: every stem crossing of chapter 11's six town02 routes, from 8 to 2 m
  before the junction entry (``READ_DISTANCES_M``), driven by the preset's expert, which shows no turn
  before 2 m;
- **in closed loop**: the agents' own routeless town02 drives of the table (``stem_drive.npz`` of each run):
  the exits each agent took at the stems, and whether an episode ended at a stem.

A **reading** of one state (``read_states``): for an energy agent, the energy on a fine (steering,
acceleration) grid, the profile over steering (the lowest energy over acceleration,
``energy_profiles.steering_profile``), its valleys by the book's criterion (within ``DEPTH`` = 3 nats of
the minimum, separated by a barrier of at least ``BARRIER`` = 1 nat; on ``STEER_GRID`` = 161 values,
0.0125 apart, fine enough to resolve valleys 0.1 apart), whether there are two valleys, one left and one
right of straight, and the Boltzmann mass p(y | x) ∝ exp(-E(x, y)) of the marginal over acceleration left
and right of straight; at a fork also the energies of the two labels. For BC, its Beta over steering: the
mean (what it acts with), the mass left of straight and the shape. A flow agent has no energy: its reading is
the distribution of its own samples' steering (``flow_readings``): the share left of straight in place of
the Boltzmann mass, and the valleys of -log of their density read by the same criterion.

Every method present in the folder's ``runs/`` is read (the paper's three, and the families added by
``added_methods``: flow, DA-IBC with ranking NCE); each method's summary also gives what one decision costs
(network evaluations per observation, ``Preset.network_evaluations``) and its agents' training times.

    ibc-tutorial two-answers --out book/results/two-answers --workers 2 --threads 1
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from ibc_tutorial.driving.collect import CollectConfig, collect
from ibc_tutorial.driving.dataset import DemoDataset, DemoLog
from ibc_tutorial.driving.energy_profiles import BARRIER, DEPTH, beta_shape, read_profile
from ibc_tutorial.driving.expert import ExpertConfig
from ibc_tutorial.driving.forks import forks_per_stem, stem_forks
from ibc_tutorial.driving.route_following import (
    ROUTES,
    build_route,
    observations_before_crossings,
    route_crossings,
)
from ibc_tutorial.driving.stems import EXITS, episode_measures, stem_approaches, stem_crossings
from ibc_tutorial.experiments.agents.checkpoints import load_agent
from ibc_tutorial.experiments.agents.evaluate import EVAL_TOWN
from ibc_tutorial.experiments.agents.flow_readings import read_flow_states
from ibc_tutorial.experiments.agents.presets import ALL_METHODS, Preset
from ibc_tutorial.experiments.agents.replication_folder import DATA, FINAL_EVAL, STEM_DRIVE, expert_dir
from ibc_tutorial.experiments.agents.stem_drives import load_drive
from ibc_tutorial.experiments.agents.training_run import read_metrics
from ibc_tutorial.experiments.runs import (
    RESULTS,
    git_commit,
    machine,
    now,
    read_json_dict,
    write_json,
    write_npz,
)
from ibc_tutorial.optimizers.grid import steer_accel_grid
from ibc_tutorial.policies.encoders import to_tensor_obs
from ibc_tutorial.stats import minority, ratio_of_sums_difference, ratio_of_sums_interval, verdict

STEER_GRID = 161
"""Steering values of the reading grid over [-1, 1] (0.0125 apart; straight exactly 0)."""
ACCEL_GRID = 21
"""Acceleration values of the reading grid over [-1, 1]."""
READ_DISTANCES_M = tuple(float(d) for d in np.arange(8.0, 1.75, -0.5))
"""Where a town02 stem approach is read: every 0.5 m from 8 to 2 m before the junction entry."""
MASS_DISTANCES_M = (6.0, 4.5)
"""Of those, where the Boltzmann mass on each side is reported."""
MASS_FLOOR = 0.2
"""Mass on each side of straight from which a reading counts as keeping both sides."""
HELDOUT_PAIRS = 2
"""Twin pairs per town01 stem in the held-out fork set."""
HELDOUT_SEED = 1
"""Added to the preset's collection seed for the held-out fork set."""
CHUNK = 16
"""States per batch of grid energies."""


# ------------------------------------------------------------------ the states
def heldout_forks(preset: Preset) -> dict:
    """The forks of a held-out set of stem twins (``HELDOUT_PAIRS`` per town01 stem, another seed; no routes),
    one per pair: ``{"bev" (F, 5, S, S) uint8, "state" (F, 3), "labels" (F, 2, 2) (left label, right
    label), "approach" (F,), "entry_m" (F,), "gap" (F,)}``, and the per-stem counts."""
    c = preset.collect_config()
    config = CollectConfig(
        **{**c.__dict__, "routes": 0, "stem_twins": HELDOUT_PAIRS, "seed": c.seed + HELDOUT_SEED}
    )
    log = collect(config, show_progress=False)
    forks = [f for f in stem_forks(log) if f["turn"] == "left"]  # one per pair: its left twin
    data = DemoDataset(log, preset.bev_size, light_encoding=preset.light_encoding)
    rows = np.array([f["fork_row"] for f in forks])
    obs, _ = data.batch(rows)
    return {
        "bev": obs["bev"].numpy().astype(np.uint8),
        "state": obs["state"].numpy(),
        "labels": np.stack([f["labels"] for f in forks]).astype(np.float32),  # (F, 2, 2): left, right
        "approach": np.array([f["approach"] for f in forks]),
        "entry_m": np.array([f["entry_m"] for f in forks]),
        "gap": np.array([f["gap"] for f in forks]),
    }


def stem_approach_states(preset: Preset) -> dict:
    """Every stem crossing of the six town02 routes (``route_following.ROUTES``), read at
    ``READ_DISTANCES_M`` along the approach of the preset's expert (no steering noise):
    ``{"bev" (N, 5, S, S) uint8, "state" (N, 3), "pair" (N,) (which route stem crossing), "distance_m" (N,)
    (measured), "read_at" (N,) (the distance asked for), "route" [...], "approach" [...]}`` (one entry of the
    last two per crossing)."""
    stems = set(stem_approaches(EVAL_TOWN))
    expert = ExpertConfig(turn_hold_m=preset.turn_hold_m)
    bevs, states, pair, dist, read_at, routes, approaches = [], [], [], [], [], [], []
    for name in ROUTES:
        crossings = route_crossings(build_route(name))
        at = [k for k, (ap, _) in enumerate(crossings) if ap in stems]
        if not at:
            continue
        got = observations_before_crossings(
            name,
            at,
            READ_DISTANCES_M,
            bev_size=preset.bev_size,
            light_encoding=preset.light_encoding,
            expert=expert,
        )
        for k in at:
            for want, (obs, where) in zip(READ_DISTANCES_M, got[k], strict=True):
                bevs.append(obs["bev"].astype(np.uint8))
                states.append(obs["state"])
                pair.append(len(routes))
                dist.append(where["distance_m"])
                read_at.append(want)
            routes.append(name)
            approaches.append(int(crossings[k][0]))
    return {
        "bev": np.stack(bevs),
        "state": np.stack(states).astype(np.float32),
        "pair": np.array(pair),
        "distance_m": np.array(dist),
        "read_at": np.array(read_at),
        "route": routes,
        "approach": approaches,
    }


# ------------------------------------------------------------------ one reading
@torch.no_grad()
def read_states(agent, bev: np.ndarray, state: np.ndarray, labels: np.ndarray | None = None) -> dict:
    """Readings of ``agent`` at N states (``bev`` (N, 5, S, S), ``state`` (N, 3); ``labels`` (N, 2, 2):
    two actions per state whose energies are read too, energy agents only). See the module's docstring.
    Returns arrays of N.
    """
    if len(bev) != len(state):
        raise ValueError(f"bev and state must hold the same states, got {len(bev)} and {len(state)}")
    if agent.method == "flow":  # no energy: its samples' steering (flow_readings)
        steer = steer_accel_grid(STEER_GRID, ACCEL_GRID)[0].double().numpy()  # (G,) straight exactly 0
        return read_flow_states(agent, bev, state, steer, CHUNK)
    if agent.method == "bc":
        alpha, beta = [], []
        for a in range(0, len(state), CHUNK):
            obs = to_tensor_obs({"bev": bev[a : a + CHUNK], "state": state[a : a + CHUNK]}, agent.device)
            al, be = agent.network(obs)  # (B, 2) each: steering, acceleration
            alpha.append(al[:, 0].cpu().numpy())
            beta.append(be[:, 0].cpu().numpy())
        alpha, beta = np.concatenate(alpha), np.concatenate(beta)
        shapes = [beta_shape(float(x), float(y)) for x, y in zip(alpha, beta, strict=True)]
        return {
            "alpha": alpha,
            "beta": beta,
            "mean": np.array([s["mean"] for s in shapes]),
            "left_mass": np.array([s["mass_left"] for s in shapes]),
            "shape": np.array([s["shape"] for s in shapes]),
        }
    steer, grid = steer_accel_grid(STEER_GRID, ACCEL_GRID)  # (G,), (A G, 2)
    steer_np = steer.double().numpy()
    out = {k: [] for k in ("valleys", "two_sided", "left_mass", "argmin_steer", "label_energy", "profile")}
    for a in range(0, len(state), CHUNK):
        obs = to_tensor_obs({"bev": bev[a : a + CHUNK], "state": state[a : a + CHUNK]}, agent.device)
        z = agent.network.embed(obs)  # (B, D)
        e = agent.network.energy_from_embedding(z, grid.to(agent.device)).double().cpu()  # (B, A G)
        e = e.reshape(len(z), ACCEL_GRID, STEER_GRID)  # (B, A, G)
        low = e.min(dim=1).values  # (B, G): the lowest over acceleration
        marg = -torch.logsumexp(-e, dim=1)  # (B, G): the marginal over acceleration
        floor = e.amin(dim=(1, 2))  # (B,)
        if labels is not None:
            lab = torch.from_numpy(np.asarray(labels[a : a + CHUNK], dtype=np.float32)).to(agent.device)
            el = agent.network.energy_from_embedding(z, lab).double().cpu()  # (B, 2)
            out["label_energy"].append((el - floor[:, None]).numpy())
        for p, m in zip((low - low.min(dim=1, keepdim=True).values).numpy(), marg.numpy(), strict=True):
            r = read_profile(steer_np, p, m)  # the one reading of a profile (driving.energy_profiles)
            for k in ("valleys", "two_sided", "left_mass", "argmin_steer"):
                out[k].append(r[k])
            out["profile"].append(p.astype(np.float32))
    res = {k: np.array(v) for k, v in out.items() if k not in ("label_energy",)}
    if labels is not None:
        res["label_energy"] = np.concatenate(out["label_energy"])  # (N, 2)
    return res


# ------------------------------------------------------------------ closed loop
def stem_exits(drive: dict) -> dict:
    """The stems in an agent's recorded drive (``experiments.agents.stem_drives.load_drive``): per episode its
    finished stem crossings left and right and whether it ended at a stem; and in all."""
    per_episode = []
    for row, tr in zip(drive["rows"], drive["episodes"], strict=True):
        steer = tr["actions"][:, 0]
        m = episode_measures(EVAL_TOWN, tr["lane"], tr["pose"], steer, terminated=bool(row["termination"]))
        per_episode.append({"left": m["left"], "right": m["right"], "ended_at_stem": m["ended_at_stem"]})
    left = sum(e["left"] for e in per_episode)
    right = sum(e["right"] for e in per_episode)
    return {
        "episodes": per_episode,
        "left": left,
        "right": right,
        "crossings": left + right,
        "both_exits": left > 0 and right > 0,
        "stem_ends": sum(e["ended_at_stem"] for e in per_episode),
    }


def _exit_tables(exits_by_agent: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """(A, E) left exits and (A, E) stem crossings of each agent's episodes."""
    left = np.array([[e["left"] for e in a["episodes"]] for a in exits_by_agent], dtype=float)
    total = np.array([[e["left"] + e["right"] for e in a["episodes"]] for a in exits_by_agent], dtype=float)
    return left, total


def minority_interval(exits_by_agent: list[dict]):
    """The pooled minority exit share (min(left, right) / crossings) of a method's agents, with its
    two-level interval (agents, then episodes: ``stats.ratio_of_sums_interval``)."""
    return ratio_of_sums_interval(*_exit_tables(exits_by_agent), transform=minority)


def minority_difference(exits_a: list[dict], exits_b: list[dict]) -> dict:
    """The DA-IBC paper's claim 4 as chapter 09 judges it: method A's pooled minority exit share minus
    method B's, with its two-level interval (``stats.ratio_of_sums_difference``) and the verdict of "A takes
    the minority exit more often than B" (``stats.verdict`` against 0)."""
    iv = ratio_of_sums_difference(*_exit_tables(exits_a), *_exit_tables(exits_b), transform=minority)
    return {
        "difference": [round(iv.estimate, 4), round(iv.low, 4), round(iv.high, 4)],
        "verdict": verdict(iv),
    }


def per_agent_minority(exits: dict) -> float | None:
    """One agent's minority exit share at the stems (None without a stem crossing)."""
    n = exits["crossings"]
    return min(exits["left"], exits["right"]) / n if n else None


def both_sides(left_mass: np.ndarray, floor: float = MASS_FLOOR) -> np.ndarray:
    """Whether each reading keeps at least ``floor`` of its Boltzmann mass on each side of straight."""
    m = np.asarray(left_mass, dtype=float)
    return (m >= floor) & (1 - m >= floor)


def pair_counts(reading: dict, pair: np.ndarray) -> dict:
    """Of the (agent's) stem approaches (``pair``: which approach each state is of), how many show two
    valleys, one each side of straight, at some state."""
    pair = np.asarray(pair)
    ids = np.unique(pair)
    two = [bool(np.asarray(reading["two_sided"])[pair == p].any()) for p in ids]
    return {"pairs": len(ids), "two_valleys": int(sum(two))}


def fork_summary(forks_data: dict) -> dict:
    """What the held-out forks are: how many, per stem, their distance before the entry and label gaps."""
    gap, entry = forks_data["gap"], forks_data["entry_m"]
    return {
        "forks": len(gap),
        "gap_min": round(float(gap.min()), 3),
        "gap_median": round(float(np.median(gap)), 3),
        "gap_max": round(float(gap.max()), 3),
        "entry_m_min": round(float(entry.min()), 2),
        "entry_m_max": round(float(entry.max()), 2),
    }


def data_forks(log, town="town01") -> dict:
    """The forks of a demonstration log (``driving.forks.stem_forks``) summarised: crossings, left, the
    label gaps (min, median, max), the fork's distance before the entry, and crossings per stem and way."""
    forks = stem_forks(log)
    gaps = np.array([f["gap"] for f in forks])
    entry = np.array([f["entry_m"] for f in forks])
    per_stem = forks_per_stem(forks, town)
    spread = lambda v, *qs: [round(float(np.percentile(v, q)), 3) for q in qs] if len(v) else None  # noqa: E731
    return {
        "crossings": len(forks),
        "left": sum(f["turn"] == "left" for f in forks),
        "stems_crossed": sum(1 for c in per_stem.values() if sum(c.values())),
        "stems": len(per_stem),
        "least_each_way": min(min(c[e] for e in EXITS) for c in per_stem.values()),
        "most_each_way": max(max(c[e] for e in EXITS) for c in per_stem.values()),
        "gap": spread(gaps, 0, 50, 100),  # None for demonstrations without a fork
        "entry_m": None if not len(entry) else [round(float(x), 2) for x in (entry.min(), entry.max())],
        "samples": len(log),
        "fork_share": round(len(forks) / len(log), 5),
    }


def crossings_of(drive: dict) -> list[dict]:
    """Every stem crossing of an agent's recorded drive, with its episode (for the figures)."""
    out = []
    for i, tr in enumerate(drive["episodes"]):
        for c in stem_crossings(EVAL_TOWN, tr["lane"], tr["actions"][:, 0]):
            out.append({**c, "episode": i})
    return out


def train_times(run: Path) -> dict:
    """One run's training time from its files: ``train_seconds`` (the ``train_agent`` call, as its
    ``final_eval.json`` records it; a resumed run's last call only) and ``learn_seconds`` (that minus the
    periodic town02 evaluations of ``metrics.jsonl``); None where not recorded."""
    ev = read_json_dict(run / FINAL_EVAL, "re-run the replication")
    total = ev.get("train_seconds")
    if not isinstance(total, (int, float)):
        return {"train_seconds": None, "learn_seconds": None}
    evals = sum(float(m.get("eval_seconds", 0.0)) for m in read_metrics(run))
    return {"train_seconds": round(float(total), 1), "learn_seconds": round(float(total) - evals, 1)}


def runs_of(folder) -> list[tuple[str, int, Path]]:
    """(method, seed, run folder) of every finished run of a replication folder, every method present."""
    out = []
    for m_dir in sorted((Path(folder) / "runs").iterdir()):
        if m_dir.name == "expert":
            continue
        for s_dir in sorted(m_dir.glob("seed*"), key=lambda p: int(p.name[4:])):
            if (s_dir / "final.pt").exists():
                out.append((m_dir.name, int(s_dir.name[4:]), s_dir))
    return out


# ------------------------------------------------------------------ the study's analysis
def agent_summary(method: str, fork_r: dict, appr_r: dict, approach: dict, exits: dict) -> dict:
    """One agent's numbers: at the forks, at the town02 stem approaches, in closed loop (a flow agent's
    valleys and masses are those of its samples: ``flow_readings``)."""
    at_mass = np.isin(approach["read_at"], MASS_DISTANCES_M)  # the states read at 6 and 4.5 m
    row = {
        "crossings": exits["crossings"],
        "left": exits["left"],
        "right": exits["right"],
        "minority": None if exits["crossings"] == 0 else round(per_agent_minority(exits), 4),
        "both_exits": exits["both_exits"],
        "stem_ends": exits["stem_ends"],
        "fork_both_sides": int(both_sides(fork_r["left_mass"]).sum()),
        "approach_both_sides": int(both_sides(np.asarray(appr_r["left_mass"])[at_mass]).sum()),
        "approach_mass_readings": int(at_mass.sum()),
    }
    if method == "bc":
        row["fork_mean_steer"] = [round(float(x), 3) for x in np.percentile(fork_r["mean"], [0, 50, 100])]
        row["fork_shapes"] = {s: int((fork_r["shape"] == s).sum()) for s in np.unique(fork_r["shape"])}
        return row
    row.update(
        fork_two_valleys=int(fork_r["two_sided"].sum()),
        forks=len(fork_r["two_sided"]),
        **{f"approach_{k}": v for k, v in pair_counts(appr_r, approach["pair"]).items()},
    )
    if "label_energy" in fork_r:  # an energy agent: its two labels' energies at the forks
        le = fork_r["label_energy"]  # (F, 2): left label, right label, above the grid's minimum
        row.update(
            fork_label_energy_median=[round(float(x), 2) for x in np.median(le, axis=0)],
            fork_label_within_depth=int(((le <= DEPTH).all(axis=1)).sum()),
        )
    return row


def method_summary(rows: list[dict], exits: list[dict], evaluations: dict | None = None) -> dict:
    """A method's agents pooled: crossings, the minority share with its interval, agents taking both exits,
    stem ends, and (energy and flow agents) the approach pairs and forks with two valleys; with
    ``evaluations`` (``Preset.network_evaluations``) the cost of a decision, and the agents' training times
    (median and each, in seed order) where their rows hold them."""
    iv = minority_interval(exits) if sum(e["crossings"] for e in exits) else None
    out = {
        "agents": len(rows),
        "crossings": sum(r["crossings"] for r in rows),
        "minority": None if iv is None else [round(iv.estimate, 4), round(iv.low, 4), round(iv.high, 4)],
        "agents_both_exits": sum(r["both_exits"] for r in rows),
        "stem_ends": sum(r["stem_ends"] for r in rows),
        "fork_both_sides": sum(r["fork_both_sides"] for r in rows),
        "approach_both_sides": sum(r["approach_both_sides"] for r in rows),
        "approach_mass_readings": sum(r["approach_mass_readings"] for r in rows),
    }
    if "approach_pairs" in rows[0]:
        out.update(
            approach_pairs=sum(r["approach_pairs"] for r in rows),
            approach_two_valleys=sum(r["approach_two_valleys"] for r in rows),
            forks=sum(r["forks"] for r in rows),
            fork_two_valleys=sum(r["fork_two_valleys"] for r in rows),
        )
    if evaluations is not None:
        out["network_evaluations_per_decision"] = dict(evaluations)
    for key in ("train_seconds", "learn_seconds"):
        times = [r.get(key) for r in rows]
        if times and all(isinstance(t, (int, float)) for t in times):
            out[key] = {"median": round(float(np.median(times)), 1), "agents": times}
    return out


def read_folder(folder, forks: dict, approach: dict, log=print) -> tuple[dict, dict]:
    """Every agent of a replication folder read at ``forks`` and ``approach`` (``read_states``) and its own
    recorded drives (``stem_exits``): ``({"agents": {name: row}, "methods": {method: pooled}}, arrays)``;
    ``arrays`` holds each agent's readings (``<name>/<where>/<key>``)."""
    rows, exits, arrays, costs = {}, {}, {}, {}
    for method, seed, d in runs_of(folder):
        name = f"{method}-seed{seed}"
        agent = load_agent(d / "final.pt")[0]
        fr = read_states(agent, forks["bev"], forks["state"], forks["labels"] if agent.has_energy else None)
        ar = read_states(agent, approach["bev"], approach["state"])
        ex = stem_exits(load_drive(d / STEM_DRIVE))
        rows[name] = {**agent_summary(method, fr, ar, approach, ex), **train_times(d)}
        costs[method] = agent.network_evaluations()
        exits.setdefault(method, []).append(ex)
        for where, r in (("forks", fr), ("approach", ar)):
            for k, v in r.items():
                arrays[f"{name}/{where}/{k}"] = np.asarray(v)
        if log:
            log(f"read {name}: {rows[name]['crossings']} stem crossings in its table drives")
    methods = {
        m: method_summary([rows[n] for n in rows if n.startswith(f"{m}-seed")], exits[m], costs[m])
        for m in exits
    }
    crossed = {m for m, ex in exits.items() if sum(e["crossings"] for e in ex)}  # a share needs crossings
    claim4 = {
        f"{a} - bc": minority_difference(exits[a], exits["bc"])
        for a in sorted(exits, key=ALL_METHODS.index)
        if a != "bc" and {a, "bc"} <= crossed
    }
    return {"agents": rows, "methods": methods, "claim4": claim4}, arrays


def fig6_fork(forks: dict) -> int:
    """The held-out fork that chapter 12 draws (a stated rule, not a choice by hand): the one whose label gap
    is the median's (the lower middle one for an even count)."""
    order = np.argsort(forks["gap"], kind="stable")
    return int(order[(len(order) - 1) // 2])


@torch.no_grad()
def landscape(agent, bev: np.ndarray, state: np.ndarray) -> np.ndarray:
    """(ACCEL_GRID, STEER_GRID) energies of an energy agent at one state, minus their minimum."""
    _, grid = steer_accel_grid(STEER_GRID, ACCEL_GRID)
    obs = to_tensor_obs({"bev": bev[None], "state": state[None]}, agent.device)
    e = agent.network.energy_from_embedding(agent.network.embed(obs), grid.to(agent.device))[0]
    e = e.double().cpu().numpy().reshape(ACCEL_GRID, STEER_GRID)
    return e - e.min()


def analyse(folder, out, *, baseline=None, log=print, command: str = "") -> dict:
    """Chapter 12's readings of a ``two-answers`` replication ``folder`` (and of a ``baseline`` replication
    folder's agents at the same states), written to ``out``: ``summary.json``, ``readings.npz`` (the states,
    every agent's readings, the Fig. 6 landscapes) and ``provenance.json``. Returns the summary."""
    folder, out = Path(folder), Path(out)
    started = now()
    preset = Preset.from_dict(read_json_dict(folder / RESULTS, "run the replication first")["preset"])
    if baseline is not None:  # the baseline's agents read the same rendered states: the same view
        other = Preset.from_dict(
            read_json_dict(Path(baseline) / RESULTS, "give a finished replication")["preset"]
        )
        if (other.bev_size, other.light_encoding) != (preset.bev_size, preset.light_encoding):
            raise ValueError(
                f"baseline must see the study's view (bev_size {preset.bev_size}, light_encoding "
                f"{preset.light_encoding!r}), got {other.bev_size} and {other.light_encoding!r}"
            )
    forks = heldout_forks(preset)
    approach = stem_approach_states(preset)
    if log:
        log(f"{len(forks['gap'])} held-out forks, {len(approach['route'])} town02 stem approaches")
    summary = {
        "design": data_forks(DemoLog.load(folder / DATA)),
        "heldout_forks": fork_summary(forks),
        "approach": {"crossings": len(approach["route"]), "states": len(approach["pair"])},
        "settings": {
            "steer_grid": STEER_GRID,
            "accel_grid": ACCEL_GRID,
            "depth": DEPTH,
            "barrier": BARRIER,
            "read_distances_m": list(READ_DISTANCES_M),
            "mass_distances_m": list(MASS_DISTANCES_M),
            "mass_floor": MASS_FLOOR,
        },
    }
    summary["study"], arrays = read_folder(folder, forks, approach, log)
    expert = stem_exits(load_drive(expert_dir(folder) / STEM_DRIVE))
    summary["expert"] = {k: v for k, v in expert.items() if k != "episodes"}
    k = fig6_fork(forks)
    summary["fig6_fork"] = {"index": k, "gap": round(float(forks["gap"][k]), 3)}
    for method in ("ibc", "da-ibc"):
        agent = load_agent(folder / "runs" / method / f"seed{preset.seeds[0]}" / "final.pt")[0]
        arrays[f"fig6/{method}"] = landscape(agent, forks["bev"][k], forks["state"][k])
    if baseline is not None:
        base = Path(baseline)
        summary["baseline_design"] = data_forks(DemoLog.load(base / DATA))
        summary["baseline"], base_arrays = read_folder(base, forks, approach, log)
        arrays.update({f"baseline/{key}": v for key, v in base_arrays.items()})
    for key in ("bev", "state", "labels", "approach", "entry_m", "gap"):
        arrays[f"states/forks/{key}"] = np.asarray(forks[key])
    for key in ("bev", "state", "pair", "distance_m", "read_at"):
        arrays[f"states/approach/{key}"] = np.asarray(approach[key])
    summary["approach"].update(route=approach["route"], stem=approach["approach"])
    out.mkdir(parents=True, exist_ok=True)
    write_npz(out / "readings.npz", arrays)
    write_json(out / "summary.json", summary)
    write_json(
        out / "provenance.json",
        {
            "command": command,
            "commit": git_commit(),
            "machine": machine(),
            "started": started,
            "finished": now(),
        },
    )
    return summary
