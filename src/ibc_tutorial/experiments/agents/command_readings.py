"""What an agent's output says at one state under each command (chapter 11's stem figure).

``reading(agent, obs, command)`` gives, at one observation, under one command (or none, for a routeless
agent):

* for an energy agent (IBC, DA-IBC), its energy over steering, the lowest over acceleration minus its
  minimum (the profile chapter 08 reads at the stems), the number of valleys within 3 nats separated by a
  1-nat barrier (``driving.energy_profiles.valleys``), the Boltzmann mass left of straight of the marginal
  over acceleration, and the argmin's steering;
* for BC, its Beta over steering (``energy_profiles.beta_shape``: shape, mean, mass left of straight).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from ibc_tutorial.driving.commands import command_index
from ibc_tutorial.driving.energy_profiles import beta_shape, read_grid
from ibc_tutorial.experiments.agents.checkpoints import load_agent
from ibc_tutorial.optimizers.grid import symmetric_axis
from ibc_tutorial.policies.encoders import to_tensor_obs

GRID = 81
"""Steering (and acceleration) values of the energy grid in [-1, 1]."""


def _batch(agent, obs: dict, command: str | None) -> dict:
    bev, state = np.asarray(obs["bev"]), np.asarray(obs["state"], dtype=np.float32)
    if bev.ndim != 3 or state.shape != (3,):
        raise ValueError(
            f"obs must hold one bev (5, S, S) and one state (3,), got {bev.shape} and {state.shape}"
        )
    batch = {"bev": bev[None], "state": state[None]}
    if command is not None:
        batch["command"] = np.array([command_index(command)], dtype=np.int64)
    agent.check_command(batch)  # a command agent needs one, a routeless agent must not get one
    return batch


@torch.no_grad()
def reading(agent, obs: dict, command: str | None, n_grid: int = GRID) -> dict:
    """The agent's output at ``obs`` (``{"bev": (5, S, S), "state": (3,)}``) under ``command`` (a name of
    ``driving.commands.COMMANDS``, or None for a routeless agent). See the module's docstring."""
    batch = _batch(agent, obs, command)
    if agent.method == "bc":
        alpha, beta = agent.network(to_tensor_obs(batch, agent.device))  # (1, 2) each: steer, acceleration
        a, b = float(alpha[0, 0]), float(beta[0, 0])
        shape = beta_shape(a, b)
        return {
            "alpha": a,
            "beta": b,
            "shape": shape["shape"],
            "mean": shape["mean"],
            "left_mass": shape["mass_left"],
        }
    _, _, e = agent.energy_grid(batch, n_per_dim=n_grid)  # (G,), (G,), (G accel, G steer)
    steer = symmetric_axis(n_grid, torch.float64).numpy()  # (G,) the grid's values, exactly (straight is 0)
    r = read_grid(steer, e)  # the one reading of an energy at a state (driving.energy_profiles)
    return {
        "steer": steer,
        "profile": r["profile"],
        "valleys": r["valleys"],
        "valley_steer": [round(v, 3) for v in r["valley_steer"]],
        "argmin_steer": r["argmin_steer"],
        "left_mass": r["left_mass"],
    }


def readings_by_command(agents: dict, states, commands=("left", "right", "follow")) -> dict:
    """Every agent's ``reading`` at every state, under each command (a routeless agent: no command).

    ``agents``: ``(method, seed)`` -> an agent told commands, ``(method, seed, "routeless")`` -> one
    that is not; ``states``: a list of ``(observation, where)``. Returns ``(method, seed, k, command)``
    -> the reading at ``states[k]``, with ``command`` ``"none"`` for a routeless agent.
    """
    readings = {}
    for (m, s, *routeless), agent in agents.items():
        for k, (obs, _) in enumerate(states):
            o = {"bev": obs["bev"], "state": obs["state"]}
            for c in (None,) if routeless else commands:
                readings[m, s, k, c or "none"] = reading(agent, o, c)
    return readings


def format_readings_table(readings: dict, methods, seeds, distances, label: dict) -> str:
    """Chapter 11's table: per method and state, each command's agents with two valleys and mean left mass."""
    columns = ("left", "right", "follow", "none")
    lines = [
        f"{'method':>7} {'state':>6} "
        + " ".join(f"{c:>22}" for c in ("left", "right", "follow", "none (routeless)"))
    ]
    for m in methods:
        for k, d in enumerate(distances):
            cells = []
            for c in columns:
                v = [readings[m, s, k, c]["valleys"] for s in seeds]
                lm = np.mean([readings[m, s, k, c]["left_mass"] for s in seeds])
                cells.append(f"{sum(x >= 2 for x in v)}/{len(v)} two; left {lm:4.2f}")
            lines.append(f"{label[m]:>7} {f'{d:g}m':>6} " + " ".join(f"{x:>22}" for x in cells))
    return "\n".join(lines)


def load_command_agents(command_folder, routeless_folder, methods, seeds) -> dict:
    """``readings_by_command``'s ``agents``: ``(method, seed)`` -> the agent of ``command_folder``,
    ``(method, seed, "routeless")`` -> the agent of the same method and seed in ``routeless_folder``
    (``runs/<method>/seed<k>/final.pt`` in each, loaded with ``checkpoints.load_agent``)."""
    agents = {}
    for m in methods:
        for s in seeds:
            for folder, key in ((command_folder, (m, s)), (routeless_folder, (m, s, "routeless"))):
                agents[key] = load_agent(Path(folder) / "runs" / m / f"seed{s}" / "final.pt")[0]
    return agents


BETA_COLUMNS = ("left", "right", "follow", "none")
"""The commands of BC's table (``format_beta_table``); "none": the routeless agent."""


def format_beta_table(readings: dict, seeds, distances) -> str:
    """Chapter 11's table of BC's Beta over steering: per state and command, the mean over ``seeds`` of its
    mean steering, and the shapes its agents' Betas have (``energy_profiles.beta_shape``)."""
    head = ("left", "right", "follow", "none (routeless)")
    lines = [f"{'state':>6} " + " ".join(f"{c:>30}" for c in head)]
    for k, d in enumerate(distances):
        cells = []
        for c in BETA_COLUMNS:
            rs = [readings["bc", s, k, c] for s in seeds]
            shapes = "/".join(sorted({r["shape"] for r in rs}))
            cells.append(f"mean {np.mean([r['mean'] for r in rs]):+.2f}, {shapes}")
        lines.append(f"{f'{d:g}m':>6} " + " ".join(f"{x:>30}" for x in cells))
    return "\n".join(lines)
