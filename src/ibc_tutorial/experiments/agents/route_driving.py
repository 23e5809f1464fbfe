"""Agents on the town02 routes (chapter 11): the route-following evaluation of ``driving.route_following``.

``evaluate_on_routes(agent, ...)`` drives an ``Agent`` (or "expert") along every route of
``driving.route_following.ROUTES``; a command agent is given the route's commands, a routeless one
(chapter 09's) none, so its completion shows what luck at the junctions gives. An agent asked to drive
otherwise than it was trained is refused (``Agent.check_command``): a command agent without commands, a
routeless one with them. The rows (``RouteResult.row``) hold what ``evaluate.summarize_episodes`` reads
(seed, steps, distance, red lights, the paper's score, termination) besides route completion, the driving
score and the junction crossings, so the replication's files and tables read them as they read episodes.
"""

from __future__ import annotations

from ibc_tutorial.driving.route_following import ROUTES, drive_routes, summarize_routes
from ibc_tutorial.experiments.agents.agent import Agent
from ibc_tutorial.experiments.agents.evaluate import EVAL_SEED, EXPERT_BEV_SIZE, summarize_episodes
from ibc_tutorial.utils import check_int

ROUTE_SEED = EVAL_SEED
"""Seed of the first drive of the routes (drive ``k`` of every route: ``ROUTE_SEED + k``)."""


def evaluate_on_routes(
    agent: Agent | str,
    routes=tuple(ROUTES),
    *,
    drives: int = 1,
    seed: int = ROUTE_SEED,
    policy_seed: int = 0,
    commands: bool | None = None,
    max_steps: int | None = None,
    show_progress: bool | None = False,
) -> list[dict]:
    """Rows (``RouteResult.row``) of ``drives`` drives of every route in ``routes`` by ``agent``.

    ``commands``: give the route's commands (None: exactly when the agent takes them; an agent given what
    it does not take is refused by ``Agent.check_command`` at its first step). Drive ``k`` seeds the light
    phases with ``seed + k``; ``policy_seed`` the agent's DFO draws."""
    check_int("drives", drives, minimum=1)
    if agent == "expert":
        policy, bev_size, encoding, commands = "expert", EXPERT_BEV_SIZE, "intensity", False
    else:
        if not isinstance(agent, Agent):
            raise ValueError(f"agent must be an Agent or 'expert', got {type(agent).__name__}")
        commands = agent.takes_command if commands is None else bool(commands)
        policy, bev_size, encoding = (
            agent.policy(policy_seed),
            agent.preset.bev_size,
            agent.preset.light_encoding,
        )
    rows = []
    for k in range(drives):
        results = drive_routes(
            policy,
            list(routes),
            bev=(bev_size, encoding),
            seed=seed + k,
            commands=commands,
            max_steps=max_steps,
            show_progress=show_progress,
        )
        rows += [r.row() for r in results]
    return rows


def summarize_route_rows(rows: list[dict]) -> dict:
    """The paper's episode summary (``evaluate.summarize_episodes``) and the routes' (completion, driving
    score, ends, junction success per command: ``route_following.summarize_routes``) in one dict."""
    return {**summarize_episodes(rows), **summarize_routes(rows)}


def periodic_route_rows(agent: Agent, routes: int, steps: int, *, policy_seed: int) -> list[dict]:
    """The evaluation during training of a command agent: the first ``routes`` routes (at most all), each
    cut at ``steps`` steps."""
    names = tuple(ROUTES)[: max(1, min(int(routes), len(ROUTES)))]
    return evaluate_on_routes(agent, names, policy_seed=policy_seed, max_steps=steps)
