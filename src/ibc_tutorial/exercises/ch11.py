"""Checkers for ``exercises/11_route_commands.ipynb``: the command rule, junction success and luck.

- ``check_command(fn)``: the command a car is given (``driving.commands``' rule),
  ``fn(kind, distance_m, next_turn, connector_turn) -> str``.
- ``check_junction_success(fn)``: the success rate per command over route drives,
  ``fn(rows) -> {"left": r, "straight": r, "right": r, "all": r}`` (None where no crossing had it).
- ``check_chance_crossings(fn)``: the crossings a car that picks exits at random passes before its
  first wrong turn, on average, ``fn(exits) -> float``.

Each compares the reader's function with the library's on chosen cases and, when they differ, tests
the usual mistakes one by one to name the one made, without giving the answer away.
"""

from __future__ import annotations

import math

from ibc_tutorial.driving.commands import COMMAND_DISTANCE_M, COMMANDS
from ibc_tutorial.driving.route_following import chance_crossings, junction_success
from ibc_tutorial.exercises.core import Feedback, close, correct, hint, number_answer, run_check

# --------------------------------------------------------------------------- 1. the command rule
KINDS = ("approach", "road", "junction connector", "corner connector")
"""Where a car can be: on a junction's approach lane, on another road lane, inside a junction (on one of
its connector lanes), or on a corner's connector (a corner has one way out)."""


def _command_ref(kind, distance_m, next_turn, connector_turn, *, strict=False, limit=COMMAND_DISTANCE_M,
                 connector_rule=True, corner_rule=True) -> str:  # fmt: skip
    if kind == "junction connector":
        return connector_turn if connector_rule else next_turn
    if kind == "corner connector":
        return "follow" if corner_rule else connector_turn
    if kind == "road":
        return "follow"
    far = distance_m >= limit if strict else distance_m > limit
    return "follow" if far else next_turn


COMMAND_CASES = [
    # (kind, distance to the junction's entry (m), the route's next turn, the connector's own turn)
    ("approach", 45.0, "left", None),
    ("approach", 12.5, "left", None),
    ("approach", 3.0, "right", None),
    ("approach", -0.4, "straight", None),  # past the stop line, not yet on the connector
    ("approach", 20.0, "right", None),  # exactly 20 m: within
    ("approach", 20.5, "right", None),
    ("approach", 19.0, "straight", None),
    ("road", 5.0, "left", None),  # a road lane that is not a junction approach: no junction ahead
    ("junction connector", 0.0, "right", "left"),  # inside the junction: the connector's turn
    ("corner connector", 0.0, "left", "right"),  # a corner is not a choice
]
_COMMAND_MISTAKES = [
    (dict(strict=True), "exactly 20 m"),
    (dict(limit=10.0), "20 m"),
    (dict(limit=30.0), "20 m"),
    (dict(connector_rule=False), "inside a junction"),
    (dict(corner_rule=False), "corner"),
]


def check_command(fn) -> Feedback:
    """Check ``fn(kind, distance_m, next_turn, connector_turn)`` against the rule of ``driving.commands``."""

    def check() -> Feedback:
        answers = []
        for case in COMMAND_CASES:
            out = fn(*case)
            if not isinstance(out, str) or out not in COMMANDS:
                return hint(f"return one of {COMMANDS} (a string), got {out!r} for {case}")
            answers.append(out)
        refs = [_command_ref(*c) for c in COMMAND_CASES]
        if answers == refs:
            return correct(
                "That is the rule every sample of the demonstrations and every step of a route is given."
            )
        for kwargs, words in _COMMAND_MISTAKES:
            if answers == [_command_ref(*c, **kwargs) for c in COMMAND_CASES]:
                return hint(f"look again at this part of the rule: {words}.")
        if all(a == "follow" for a, c in zip(answers, COMMAND_CASES, strict=True) if c[0] == "approach"):
            return hint("on an approach lane, near enough to the junction, the command is the route's turn.")
        if "follow" not in answers:
            return hint(
                "far from a junction (and on a road lane that leads to none) there is no turn to give."
            )
        wrong = next(c for c, a, r in zip(COMMAND_CASES, answers, refs, strict=True) if a != r)
        return hint(f"for {wrong} your command is not the rule's; go through the four kinds one by one.")

    return run_check(check, "`command`")


# --------------------------------------------------------------------------- 2. junction success
def _row(*crossings):
    return {"crossings": [{"approach": 0, "command": c, "taken": t} for c, t in crossings]}


SUCCESS_CASES = [
    [
        _row(("left", "left"), ("left", "straight"), ("right", "right")),
        _row(("straight", "straight"), ("left", "left"), ("left", "left"), ("right", "")),
        _row(("left", "left")),
    ],
    [_row(("straight", "straight"), ("straight", "right")), _row()],  # no left or right crossing at all
]


def _rates(rows, *, per_route=False, skip_unfinished=False, zero_if_none=False):
    out = {}
    for command in (*COMMANDS[1:], "all"):
        per = []
        for r in rows:
            cs = [c for c in r["crossings"] if command in ("all", c["command"])]
            if skip_unfinished:
                cs = [c for c in cs if c["taken"]]
            per.append((sum(c["taken"] == c["command"] for c in cs), len(cs)))
        if per_route:
            rates = [t / n for t, n in per if n]
            out[command] = sum(rates) / len(rates) if rates else (0.0 if zero_if_none else None)
        else:
            t, n = sum(p[0] for p in per), sum(p[1] for p in per)
            out[command] = t / n if n else (0.0 if zero_if_none else None)
    return out


def _same_rates(out, ref) -> bool:
    for k, v in ref.items():
        if v is None or out.get(k) is None:
            if v is not None or out.get(k) is not None:
                return False
        elif not close(out[k], v, rtol=1e-6, atol=1e-9):
            return False
    return True


def check_junction_success(fn) -> Feedback:
    """Check ``fn(rows)``: per command, the crossings whose commanded exit was taken over all crossings with
    that command, pooled over the rows; None where no crossing had it."""

    def check() -> Feedback:
        for rows in SUCCESS_CASES:
            out = fn([dict(r) for r in rows])
            if not isinstance(out, dict) or set(out) != {*COMMANDS[1:], "all"}:
                return hint('return a dict with the keys "left", "straight", "right" and "all".')
            lib = {k: v["rate"] for k, v in junction_success(rows).items()}
            if _same_rates(out, lib):
                continue
            if _same_rates(out, _rates(rows, zero_if_none=True)):
                return hint("a command no crossing had has no rate: 0 would say the car failed at it.")
            if _same_rates(out, _rates(rows, per_route=True)):
                return hint(
                    "a route with one crossing would weigh as much as one with ten: pool the crossings."
                )
            if _same_rates(out, _rates(rows, skip_unfinished=True)):
                return hint(
                    'a crossing with no exit taken ("": the route ended inside the junction) is a crossing '
                    "the car did not complete as commanded; keep it."
                )
            return hint("for these rows your rates differ: taken as commanded over crossings, per command.")
        return correct("Pooled over crossings, as LBC's and CARLA's tables report success per command.")

    return run_check(check, "`junction_success`")


# --------------------------------------------------------------------------- 3. what luck gives
EXITS_CASES = [[2, 3, 3, 2, 3], [3], [2, 2, 2, 2], [3, 2, 3, 3, 3, 2, 3]]


def check_chance_crossings(fn) -> Feedback:
    """Check ``fn(exits)``: the expected crossings passed before the first wrong exit, exits at random."""

    def check() -> Feedback:
        for exits in EXITS_CASES:
            out = number_answer(fn(list(exits)), "chance_crossings")
            if isinstance(out, Feedback):
                return out
            ref = chance_crossings(exits)
            if close(out, ref, rtol=1e-6, atol=1e-9):
                continue
            if close(out, sum(1.0 / e for e in exits), rtol=1e-6, atol=1e-9):
                return hint(
                    "to pass the k-th crossing the car must have passed every one before it: multiply the "
                    "chances along the route."
                )
            if close(out, math.prod(1.0 / e for e in exits), rtol=1e-6, atol=1e-9):
                return hint(
                    "that is the chance to pass them all; the question asks how many are passed on average."
                )
            if close(out, ref + 1.0, rtol=1e-6, atol=1e-9) or close(out, ref - 1.0, rtol=1e-6, atol=1e-9):
                return hint("count the crossings passed: the first term is the chance to pass the first one.")
            return hint(
                f"for exits {exits} your expectation is {out:.4f}; sum, over k, the chance to pass k."
            )
        return correct(
            "That is the baseline chapter 11 sets beside the crossings its routeless agents passed."
        )

    return run_check(check, "`chance_crossings`")
