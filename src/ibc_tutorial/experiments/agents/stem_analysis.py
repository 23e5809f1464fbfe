"""The stem analysis of chapters 08-09 on the drives of ``agents.stem_drives``: measures, energies, DFO.

``analyse_agent`` reads one agent's drive file and its checkpoint and writes ``analysis/<name>.json``
(one per agent, atomically: an interrupted run resumes) with

- per episode, ``driving.stems.episode_measures`` and the steering onset of every finished stem crossing;
- per state of every stem crossing (from ``stem_drives.LEAD`` states before its entry to its exit) and per
  stop at a red light: for an energy agent, its energy over steering (the lowest over acceleration on a
  ``GRID`` x ``GRID`` grid of [-1, 1]², as ``crossings.ended_crossing_energies`` computes it) read by
  ``driving.energy_profiles``: valleys within 3 nats separated by >= 1 nat, the Boltzmann mass left of
  straight (of that profile, and of the marginal over acceleration, -log Σ_a exp(-E)), the steering
  within 3 nats (extent and measure); for BC, its Beta over steering (``energy_profiles.beta_shape``);
- the same left mass (BC: the Beta's mass left of straight) with the previous steering in the state set to
  0 (``left_mass_no_prev``): the counterfactual that asks whether the previous action locks a choice in;
- at the entry state of every stem crossing of an energy agent: ``DRAWS`` DFO decisions with the
  agent's own settings (its share of left steering against the Boltzmann mass) and one ``dfo_trace``
  (the population's probability mass left of straight at each iteration: the sharpening).

``summarise`` pools the files per method with the agents x episodes bootstrap (``stats``) into
``summary.json``; ``fig6_states`` names the Fig. 6 analogue's two states by a stated rule.

    ibc-tutorial stems analyse --out book/results/laptop/stems
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import torch

from ibc_tutorial import stats
from ibc_tutorial.driving.analysis import junction_crossings
from ibc_tutorial.driving.energy_profiles import (
    beta_shape,
    boltzmann_sides,
    steering_profile,
)
from ibc_tutorial.driving.energy_profiles import read_profile as profile_reading
from ibc_tutorial.driving.stems import (
    LEAD,
    decision_window,
    episode_measures,
    red_stops,
    steering_onset,
    stem_crossings,
    stem_exit_counts,
)
from ibc_tutorial.experiments.agents.checkpoints import load_agent
from ibc_tutorial.experiments.agents.evaluate import EVAL_TOWN
from ibc_tutorial.experiments.agents.stem_drives import METHODS, drive_file, drivers, load_drive, unpack_bev
from ibc_tutorial.experiments.runs import git_commit, machine, now, write_json
from ibc_tutorial.optimizers.dfo import dfo_trace
from ibc_tutorial.optimizers.grid import steer_accel_grid

GRID = 41
"""Values per action dimension of the energy grid (as ``crossings.ENERGY_GRID``)."""
DRAWS = 64
"""DFO decisions drawn at each entry state."""
DFO_SEED = 0
"""Seed of those draws."""
CHUNK = 32
"""Observations per batch of the energy grids."""


@torch.no_grad()
def energy_profiles(agent, bev: np.ndarray, state: np.ndarray, n_grid: int = GRID):
    """Per observation, the energy over steering: the lowest over accelerations (N, G) and the marginal
    -log Σ_a exp(-E) (N, G), both minus their minimum; and the steering grid (G,)."""
    steer, grid = steer_accel_grid(n_grid)  # (G,), (G², 2)
    lows, margs = [], []
    for a in range(0, len(state), CHUNK):
        obs = {"bev": torch.from_numpy(bev[a : a + CHUNK]), "state": torch.from_numpy(state[a : a + CHUNK])}
        z = agent.network.embed(obs)  # (B, E)
        e = agent.network.energy_from_embedding(z, grid).reshape(len(z), n_grid, n_grid)  # (B, accel, steer)
        marg = -torch.logsumexp(-e, dim=1)  # (B, G)
        lows.append(steering_profile(e.numpy()))  # (B, G)
        margs.append((marg - marg.min(dim=1, keepdim=True).values).numpy())
    return steer.numpy(), np.concatenate(lows), np.concatenate(margs)


def read_profile(steer: np.ndarray, low: np.ndarray, marg: np.ndarray) -> dict:
    """The readings of one state's profile (``driving.energy_profiles.read_profile``), rounded as stored."""
    r = profile_reading(steer, low, marg)
    return {
        "valleys": r["valleys"],
        "valley_steer": [round(v, 3) for v in r["valley_steer"]],
        "argmin_steer": round(r["argmin_steer"], 3),
        "left_mass_low": round(r["left_mass_low"], 4),
        "left_mass": round(r["left_mass"], 4),
        "range_extent": round(r["range_extent"], 3),
        "range_measure": round(r["range_measure"], 3),
    }


@torch.no_grad()
def dfo_at(agent, bev: np.ndarray, state: np.ndarray, draws: int = DRAWS, seed: int = DFO_SEED) -> dict:
    """``draws`` DFO decisions of the agent at one observation, and one ``dfo_trace`` of it."""
    gen = torch.Generator().manual_seed(seed)
    obs = {"bev": np.repeat(bev[None], draws, 0), "state": np.repeat(state[None], draws, 0)}
    acts = agent.act(obs, gen).numpy()  # (draws, 2)
    z = agent.network.embed({"bev": torch.from_numpy(bev[None]), "state": torch.from_numpy(state[None])})
    tr = dfo_trace(
        lambda a: agent.network.energy_from_embedding(z, a)[0],
        agent.expert_actions,
        agent.dfo_config,
        init_weights=agent.init_weights if agent.method == "da-ibc" else None,
        generator=torch.Generator().manual_seed(seed),
    )
    return {
        "draws_left": round(float((acts[:, 0] < 0).mean()), 4),
        "draws_steer_mean": round(float(acts[:, 0].mean()), 4),
        "iter_left_mass": [
            round(float(p[s[:, 0] < 0].sum()), 4) for s, p in zip(tr.samples, tr.probs, strict=True)
        ],
        "iter_left_share": [round(float((s[:, 0] < 0).float().mean()), 4) for s in tr.samples],
    }


def _steer_at(steer: np.ndarray, t: int) -> float | None:
    """The steering applied after state t (None at the last state, after which nothing was applied)."""
    return round(float(steer[t]), 4) if t < len(steer) else None


def analyse_agent(name: str, checkpoint: Path | None, drive_path: Path) -> dict:
    """Everything of one agent (see the module's docstring); the expert gets the episode measures only."""
    d = load_drive(drive_path)
    agent = None if checkpoint is None else load_agent(checkpoint)[0]
    obs = d["obs"]
    where = (
        {}
        if obs is None
        else {(int(e), int(t)): k for k, (e, t) in enumerate(zip(obs["episode"], obs["t"], strict=True))}
    )
    episodes, states = [], []
    for i, (row, tr) in enumerate(zip(d["rows"], d["episodes"], strict=True)):
        steer = tr["actions"][:, 0]
        m = episode_measures(EVAL_TOWN, tr["lane"], tr["pose"], steer, terminated=bool(row["termination"]))
        m["stem_exits"] = {str(k): v for k, v in m["stem_exits"].items()}
        crossings = stem_crossings(EVAL_TOWN, tr["lane"], steer)
        m["onsets"] = [
            {"turn": c["turn"], "onset_m": round(steering_onset(c, tr["pose"], steer), 2)}
            for c in crossings
            if c["finished"] and c["turn"] in ("left", "right")
        ]
        m.update(row=row)
        episodes.append(m)
        if agent is None:
            continue
        for ci, c in enumerate(crossings):
            window = set(decision_window(c, steer).tolist())
            for t in range(c["start"] - 10, c["stop"]):
                if (i, t) in where:
                    states.append(
                        {
                            "kind": "stem",
                            "episode": i,
                            "t": t,
                            "crossing": ci,
                            "approach": c["approach"],
                            "turn": c["turn"] if c["finished"] else "ended",
                            "rel": t - c["start"],
                            "window": t in window,
                            "steer": _steer_at(steer, t),
                            "obs": where[(i, t)],
                        }
                    )
        for t in red_stops(tr["red_ahead"], tr["speed"], tr["entry_dist"]).tolist():
            if (i, t) in where:
                states.append(
                    {
                        "kind": "red",
                        "episode": i,
                        "t": t,
                        "steer": _steer_at(steer, t),
                        "entry_dist": round(float(tr["entry_dist"][t]), 2),
                        "obs": where[(i, t)],
                    }
                )
    if agent is not None and states:
        idx = np.array([s["obs"] for s in states])
        bev, state = unpack_bev(obs["bev"][idx]), obs["state"][idx].astype(np.float32)
        no_prev = state.copy()
        no_prev[:, 1] = 0.0  # (N, 3): the previous steering set to straight (the counterfactual of item 3)
        if agent.method == "bc":
            with torch.no_grad():
                alpha, beta = agent.network({"bev": torch.from_numpy(bev), "state": torch.from_numpy(state)})
                a0, b0 = agent.network({"bev": torch.from_numpy(bev), "state": torch.from_numpy(no_prev)})
            for s, a, b, a_, b_ in zip(
                states,
                alpha[:, 0].tolist(),
                beta[:, 0].tolist(),
                a0[:, 0].tolist(),
                b0[:, 0].tolist(),
                strict=True,
            ):
                shape = beta_shape(a, b)
                s.update(alpha=round(a, 4), beta=round(b, 4), shape=shape["shape"])
                s.update(mean=round(shape["mean"], 4), left_mass=round(shape["mass_left"], 4))
                s.update(left_mass_no_prev=round(beta_shape(a_, b_)["mass_left"], 4))
        else:
            steer_grid, low, marg = energy_profiles(agent, bev, state)
            _, _, marg0 = energy_profiles(agent, bev, no_prev)
            for k, s in enumerate(states):
                s.update(read_profile(steer_grid, low[k], marg[k]))
                s.update(left_mass_no_prev=round(boltzmann_sides(steer_grid, marg0[k])["left"], 4))
                if s["kind"] == "stem" and s["rel"] == 0:
                    s.update(dfo_at(agent, bev[k], state[k]))
    for s in states:
        s.pop("obs")
    return {"name": name, "episodes": episodes, "states": states}


def run_analysis(folder, out, log=print, command: str = "") -> list[str]:
    """``analyse_agent`` for every drive file (``stem_drives.drive_file``: ``out/drives``, else the
    replication's own records in ``folder/runs``) without its ``out/analysis`` file.

    Each invocation that analyses something is recorded in ``out/analysis/provenance.json``
    (commit, command, machine, CPU seconds per agent)."""
    out = Path(out)
    prov_path = out / "analysis" / "provenance.json"
    inv = {
        "command": command,
        "commit": git_commit(),
        "machine": machine(),
        "started": now(),
    }
    done = []
    for name, ck in drivers(folder):
        src, dst = drive_file(folder, out, name), out / "analysis" / f"{name}.json"
        if src is None or dst.exists():
            continue
        t0 = time.process_time()
        write_json(dst, analyse_agent(name, ck, src))
        inv.setdefault("cpu_seconds", {})[name] = round(time.process_time() - t0, 1)
        inv["finished"] = now()
        prov = json.loads(prov_path.read_text()) if prov_path.exists() else {"invocations": []}
        prov["invocations"] = [i for i in prov["invocations"] if i["started"] != inv["started"]] + [inv]
        write_json(prov_path, prov)
        done.append(name)
        if log:
            log(f"{now()} analysed {name}", flush=True)
    return done


# --------------------------------------------------------------------------- pooling
def _table(files: list[dict], key) -> np.ndarray:
    return np.array([[float(key(e)) for e in f["episodes"]] for f in files])  # (A, E)


def method_summary(files: list[dict], seed: int = 0) -> dict:
    """Per-method measures with agents x episodes bootstrap intervals, and the state readings pooled.

    Shares are pooled over events (``stats.ratio_of_sums_interval``): ``left_share`` and
    ``minority_share`` (min(p, 1 - p)) over finished stem crossings, ``mode_coverage`` over stems
    crossed at least twice in an episode; per-episode means (``stats.mean_interval``):
    ``distinct_approaches``, ``lanes_covered``, ``circling`` (the share of episodes that circle).
    The state groups: ``stem_approach`` (the ``LEAD`` states before a stem's entry), ``stem_window``
    (``decision_window``), ``stem_entry`` (its first state; ``_left``, ``_right`` by the exit taken),
    ``stem_window_unfinished`` (crossings the record ended inside: turn "ended"), ``red_stop``.
    """
    left, cross = _table(files, lambda e: e["left"]), _table(files, lambda e: e["stem_crossings"])
    out: dict = {"agents": len(files), "episodes": int(left.size), "stem_crossings": int(cross.sum()),
                 "left": int(left.sum())}  # fmt: skip
    if cross.sum() > 0:
        out["left_share"] = str(stats.ratio_of_sums_interval(left, cross, seed=seed))
        out["minority_share"] = str(
            stats.ratio_of_sums_interval(left, cross, transform=stats.minority, seed=seed)
        )
    out["ended_at_stem"] = int(_table(files, lambda e: e["ended_at_stem"]).sum())
    out["terminated"] = int(_table(files, lambda e: bool(e["row"]["termination"])).sum())
    for key in ("distinct_approaches", "lanes_covered"):
        out[key] = str(stats.mean_interval(_table(files, lambda e, k=key: e[k]), seed=seed))
    out["circling"] = str(stats.mean_interval(_table(files, lambda e: e["circling"] > 0), seed=seed))
    twice, both = _table(files, lambda e: e["stems_twice"]), _table(files, lambda e: e["stems_both"])
    out["stems_twice"], out["stems_both"] = int(twice.sum()), int(both.sum())
    if twice.sum() > 0:
        out["mode_coverage"] = str(stats.ratio_of_sums_interval(both, twice, seed=seed))
    per_stem: dict[str, dict] = {}
    for f in files:
        for e in f["episodes"]:
            for a, c in e["stem_exits"].items():
                d = per_stem.setdefault(a, {"left": 0, "right": 0})
                d["left"] += c["left"]
                d["right"] += c["right"]
    out["per_stem"] = dict(sorted(per_stem.items(), key=lambda kv: int(kv[0])))
    onsets = {t: [o["onset_m"] for f in files for e in f["episodes"] for o in e["onsets"] if o["turn"] == t]
              for t in ("left", "right")}  # fmt: skip
    out["onset_m"] = {t: {"n": len(v), "median": round(float(np.nanmedian(v)), 2) if len(v) else None}
                      for t, v in onsets.items()}  # fmt: skip
    states = [s for f in files for s in f["states"]]
    out["states"] = {}
    for label, sel in (
        ("stem_approach", lambda s: s["kind"] == "stem" and s["rel"] < 0),
        ("stem_window", lambda s: s["kind"] == "stem" and s["window"]),
        ("stem_entry", lambda s: s["kind"] == "stem" and s["rel"] == 0),
        ("stem_entry_left", lambda s: s["kind"] == "stem" and s["rel"] == 0 and s["turn"] == "left"),
        ("stem_entry_right", lambda s: s["kind"] == "stem" and s["rel"] == 0 and s["turn"] == "right"),
        ("stem_window_unfinished", lambda s: s["kind"] == "stem" and s["window"] and s["turn"] == "ended"),
        ("red_stop", lambda s: s["kind"] == "red"),
    ):
        out["states"][label] = pooled_readings([s for s in states if sel(s)])
    return out


def pooled_readings(states: list[dict]) -> dict:
    """Counts and means of the per-state readings (energy agents: valleys, mass, range; BC: Beta shapes)."""
    out: dict = {"n": len(states)}
    if not states:
        return out
    if "valleys" in states[0]:
        v = np.array([s["valleys"] for s in states])
        out["valleys"] = {str(k): int((v == k).sum()) for k in sorted(set(v.tolist()))}
        for key in ("left_mass", "left_mass_low", "range_extent", "range_measure"):
            x = np.array([s[key] for s in states])
            out[key] = {"mean": round(float(x.mean()), 4), "median": round(float(np.median(x)), 4)}
        lm = np.array([s["left_mass"] for s in states])
        out["both_sides_10pct"] = int(((lm >= 0.1) & (lm <= 0.9)).sum())
        dfo = [s for s in states if "draws_left" in s]
        if dfo:
            out["dfo"] = {
                "n": len(dfo),
                "draws_left_mean": round(float(np.mean([s["draws_left"] for s in dfo])), 4),
                "left_mass_mean": round(float(np.mean([s["left_mass"] for s in dfo])), 4),
                "iter_left_mass_mean": np.round(
                    np.mean([s["iter_left_mass"] for s in dfo], axis=0), 4
                ).tolist(),
            }
    elif "shape" in states[0]:
        shapes = [s["shape"] for s in states]
        out["shapes"] = {k: shapes.count(k) for k in sorted(set(shapes))}
        m = np.array([s["mean"] for s in states])
        out["mean"] = {"mean": round(float(m.mean()), 4), "abs_below_0.1": int((np.abs(m) < 0.1).sum())}
        out["left_mass_mean"] = round(float(np.mean([s["left_mass"] for s in states])), 4)
    if all("left_mass_no_prev" in s for s in states):  # files made before the counterfactual lack it
        out["left_mass_no_prev_mean"] = round(float(np.mean([s["left_mass_no_prev"] for s in states])), 4)
        out["left_mass_mean_all"] = round(float(np.mean([s["left_mass"] for s in states])), 4)
    return out


def by_position(
    files: list[dict], turn: str, key: str = "left_mass", positions=range(-10, 11)
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mean of ``key`` over the stem states of ``files`` (agents' analysis files) whose crossing took
    ``turn`` ("left", "right" or "ended"), per position relative to the entry (``rel``, in states).

    Returns ``(positions (K,), means (K,), counts (K,))``; positions without a state are left out."""
    pos, means, counts = [], [], []
    for r in positions:
        v = [s[key] for f in files for s in f["states"]
             if s["kind"] == "stem" and s["turn"] == turn and s["rel"] == r and key in s]  # fmt: skip
        if v:
            pos.append(r)
            means.append(float(np.mean(v)))
            counts.append(len(v))
    return np.array(pos), np.array(means), np.array(counts)


def _median_state(cands: list[tuple], key: str) -> dict | None:
    """Of ``cands`` = [(agent, state)], the state whose ``key`` is the median (the lower middle of an even
    count; ties by agent, episode, step), as {agent, episode, t, valleys, range_extent, left_mass, rel}."""
    if not cands:
        return None
    cands = sorted(cands, key=lambda c: (c[1][key], c[0], c[1]["episode"], c[1]["t"]))
    n, st = cands[(len(cands) - 1) // 2]
    keep = ("valleys", "range_extent", "left_mass", "rel")
    return {"agent": n, "episode": st["episode"], "t": st["t"], **{k: st[k] for k in keep if k in st}}


def fig6_states(files: dict[str, dict], method: str = "da-ibc") -> dict:
    """The Fig. 6 analogue's two states, by rule.

    Junction, where the choice is made: for each finished stem crossing of ``method``'s agents, its most
    undecided state from ``LEAD`` states before the entry to the entry (the Boltzmann mass left of straight
    closest to 1/2; the earlier state on a tie); of those, the one whose 3-nat steering extent is the
    median. Red light: of their red-light stops, the one whose 3-nat steering extent is the median. The
    median (the lower middle of an even count; ties by agent, episode, step) keeps the picture typical.
    """
    mine = [(n, f) for n, f in sorted(files.items()) if n.startswith(method + "-")]
    crossings: dict[tuple, list] = {}
    for n, f in mine:
        for st in f["states"]:
            if (
                st["kind"] == "stem"
                and st["turn"] in ("left", "right")
                and -LEAD <= st["rel"] <= 0
                and "left_mass" in st
            ):
                crossings.setdefault((n, st["episode"], st["crossing"]), []).append(st)
    undecided = [
        (key[0], min(sts, key=lambda s: (abs(s["left_mass"] - 0.5), s["rel"])))
        for key, sts in sorted(crossings.items())
    ]
    red = [(n, st) for n, f in mine for st in f["states"] if st["kind"] == "red" and "range_extent" in st]
    return {
        "junction": _median_state(undecided, "range_extent"),
        "red_light": _median_state(red, "range_extent"),
    }


@torch.no_grad()
def landscape_at(agent, bev: np.ndarray, state: np.ndarray, n_grid: int = GRID, draws: int = 10,
                 seed: int = DFO_SEED) -> dict:  # fmt: skip
    """The agent's energy over the (steering, acceleration) grid at one observation, minus its minimum, and
    ``draws`` DFO decisions there: {"steer" (G,), "accel" (G,), "energy" (G accel, G steer), "points"
    (draws, 2)} (the Fig. 6 analogue's panel)."""
    steer, _, e = agent.energy_grid({"bev": bev[None], "state": state[None]}, n_grid)  # e: (accel, steer)
    obs = {"bev": np.repeat(bev[None], draws, 0), "state": np.repeat(state[None], draws, 0)}
    points = agent.act(obs, torch.Generator().manual_seed(seed)).numpy()  # (draws, 2)
    return {"steer": steer, "accel": steer.copy(), "energy": e - e.min(), "points": points}


def observation_at(drive_path, episode: int, t: int) -> tuple[np.ndarray, np.ndarray]:
    """The (bev (5, S, S), state (3,)) that a drive file kept for state ``t`` of ``episode``."""
    d = load_drive(drive_path)
    obs = d["obs"]
    if obs is None:
        raise ValueError(f"{drive_path} keeps no observations (the expert's drive)")
    hit = np.flatnonzero((obs["episode"] == episode) & (obs["t"] == t))
    if not len(hit):
        raise ValueError(f"{drive_path} keeps no observation of episode {episode}, state {t}")
    k = int(hit[0])
    return unpack_bev(obs["bev"][k : k + 1])[0], obs["state"][k].astype(np.float32)


def demonstrations(path) -> dict:
    """The stem crossings of the demonstrations (a ``DemoLog`` file): exits per stem, the expert's onsets."""
    from ibc_tutorial.driving.dataset import DemoLog

    log = DemoLog.load(path)
    crossings, onsets = [], {"left": [], "right": []}
    for e in np.unique(log.episode):
        sel = log.episode == e
        steer, poses = log.action[sel][:, 0], log.pose[sel]
        for c in stem_crossings(log.town, log.lane[sel], steer):
            crossings.append(c)
            if c["finished"] and c["turn"] in onsets:
                onsets[c["turn"]].append(steering_onset(c, poses, steer))
    exits = {str(k): v for k, v in sorted(stem_exit_counts(crossings).items())}
    return {
        "town": log.town,
        "samples": len(log),
        "junction_crossings": sum(
            len(junction_crossings(log.town, log.lane[log.episode == e], log.action[log.episode == e][:, 0]))
            for e in np.unique(log.episode)
        ),
        "stem_crossings": len(crossings),
        "left": sum(d["left"] for d in exits.values()),
        "right": sum(d["right"] for d in exits.values()),
        "per_stem": exits,
        "stems_both_ways": [a for a, d in exits.items() if d["left"] and d["right"]],
        "onset_m": {
            t: {"n": len(v), "median": round(float(np.nanmedian(v)), 2) if v else None}
            for t, v in onsets.items()
        },
    }


def summarise(out, data=None) -> dict:
    """``summary.json``: ``method_summary`` per method and the expert, the Fig. 6 states."""
    out = Path(out)
    files = {p.stem: json.loads(p.read_text()) for p in sorted((out / "analysis").glob("*.json"))}
    summary = {"methods": {}}
    for m in (*METHODS, "expert"):
        fs = [f for n, f in sorted(files.items()) if n == m or n.startswith(m + "-seed")]
        if fs:
            summary["methods"][m] = method_summary(fs)
    summary["fig6"] = fig6_states(files)
    if data is not None:
        summary["demonstrations"] = demonstrations(data)
    summary["made"] = {"commit": git_commit(), "at": now()}
    write_json(out / "summary.json", summary)
    return summary
