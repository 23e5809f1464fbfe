"""What each departure from the paper does: the ablation folders read as one table (chapter 08).

An **ablation** is one ``replicate --set`` change of a preset: each folder here is the canonical ``laptop``
preset, or the 10-route variant ``ten-routes`` (the ``laptop`` preset with the paper's 10 routes and 8
epochs), with the overrides its row lists; its ``PROVENANCE.md`` records the command. ``ABLATIONS`` lists
them, each with the folder it is compared with: the two differ in the setting the row names.
``departure_rows`` checks that every folder's stored settings are its base preset with the row's
overrides, then compares the two folders' town02 scores method by method (``claims.compare_folders``:
the mean score with the row's first setting minus the second's, on the seeds and starts both hold, with
its 95 % two-level bootstrap interval over agents and episodes).
"""

from __future__ import annotations

from dataclasses import dataclass
from html import escape
from pathlib import Path

from ibc_tutorial.experiments.agents.claims import FolderComparison, compare_folders
from ibc_tutorial.experiments.agents.presets import LAPTOP, TEN_ROUTES, Preset, differences, with_overrides
from ibc_tutorial.experiments.agents.replication_folder import load_results

ABLATION_RUNS = ("methods=bc,da-ibc", "seeds=0,1,2", "heldout_episodes=0", "routeless_episodes=0")
"""The overrides of the smaller ablations: BC and DA-IBC, seeds 0-2, the table's evaluation only."""
BASES = {"laptop": LAPTOP, "ten-routes": TEN_ROUTES}
"""The presets an ablation may change, by name; each one's replication is the folder of that name."""


@dataclass(frozen=True)
class Ablation:
    """One ablation folder and the comparison that reads it."""

    label: str
    """The row's short name (``"held brakes"``), by which chapter 08 reads it."""
    folder: str
    """Its folder under the results root (``ablations/no-held-brakes``)."""
    departure: str
    """The setting the row measures, in words: the first setting against the second."""
    base: str
    """The preset (a key of ``BASES``) that the overrides change."""
    overrides: tuple[str, ...]
    """The ``--set`` overrides of ``base`` that made the folder."""
    other: str
    """The folder (under the results root) it is compared with, one setting away from this one."""
    laptop: str
    """What the book's ``laptop`` preset does about the setting, in words."""
    first: bool = False
    """Whether the row's effect is this folder minus ``other`` (True) or ``other`` minus this folder."""


TEN_ROUTE_CHANGES = ("collect.routes=10", "epochs=8", "seeds=0,1,2,3,4")
"""The overrides of ``laptop`` that ``ten-routes`` is (checked by a test)."""

ABLATIONS = (
    Ablation(
        "held brakes",
        "ablations/no-held-brakes",
        "held brakes in the demonstrations (brake_noise 1 vs 0)",
        "laptop",
        (*ABLATION_RUNS, "brake_noise=0"),
        "laptop",
        "held brakes (1.0)",
    ),
    Ablation(
        "lights",
        "ablations/intensity-lights",
        "lights as one bit vs drawn by intensity",
        "laptop",
        (*ABLATION_RUNS, "light_encoding=intensity"),
        "laptop",
        "one bit",
    ),
    Ablation(
        "schedule",
        "ablations/constant-schedule",
        "a cosine schedule vs a constant step size",
        "laptop",
        (*ABLATION_RUNS, "lr_schedule=constant"),
        "laptop",
        "cosine",
    ),
    Ablation(
        "routes and epochs",
        "ten-routes",
        "20 routes for 4 epochs vs the paper's 10 for 8 (as many gradient steps)",
        "laptop",
        TEN_ROUTE_CHANGES,
        "laptop",
        "20 routes, 4 epochs",
    ),
    Ablation(
        "the data",
        "ablations/half-epochs",
        "20 routes vs 10, both for 4 epochs (the data alone)",
        "ten-routes",
        ("epochs=4", "heldout_episodes=0", "routeless_episodes=0"),
        "laptop",
        "20 routes",
    ),
    Ablation(
        "the epochs",
        "ablations/half-epochs",
        "8 epochs vs 4, both on 10 routes (the epochs alone)",
        "ten-routes",
        ("epochs=4", "heldout_episodes=0", "routeless_episodes=0"),
        "ten-routes",
        "4 epochs",
    ),
    Ablation(
        "turns held",
        "ablations/turn-hold",
        "the expert's turns as it steers them vs begun together (turn_hold_m 0 vs 0.5)",
        "ten-routes",
        ("turn_hold_m=0.5", "seeds=0,1,2", "heldout_episodes=0", "routeless_episodes=0"),
        "ten-routes",
        "turns not held (0)",
    ),
)


def ablation_command(ablation: Ablation) -> str:
    """The ``replicate`` command that makes ``ablation``'s folder (its overrides of its base preset)."""
    sets = " ".join(f"--set {o}" for o in ablation.overrides)
    return f"ibc-tutorial replicate --preset {ablation.base} {sets} --out book/results/{ablation.folder}"


def check_ablation(results, ablation: Ablation) -> None:
    """ValueError naming the folder unless its stored settings are its base preset with its overrides."""
    folder = Path(results) / ablation.folder
    stored = Preset.from_dict(load_results(folder)["provenance"]["preset"])
    wanted = with_overrides(BASES[ablation.base], list(ablation.overrides))
    diff = differences(stored, wanted)
    if diff:
        raise ValueError(f"{folder}: its settings are not {ablation.base} with {ablation.overrides}: {diff}")


@dataclass(frozen=True)
class DepartureRow:
    """One ablation's measured effect: the first setting's score minus the second's, per method."""

    ablation: Ablation
    """The row's ablation."""
    command: str
    """The command that made the ablation's folder (``ablation_command``)."""
    methods: dict[str, FolderComparison]
    """Per method both folders hold: scores, red lights, standing still and the score difference."""


def departure_rows(results, ablations: tuple[Ablation, ...] = ABLATIONS) -> list[DepartureRow]:
    """Every ablation of ``ablations`` checked (``check_ablation``) and compared with its choice's folder, on
    the methods, seeds and starts both hold; ``results`` is the results root (``book/results``)."""
    results = Path(results)
    rows = []
    for a in ablations:
        check_ablation(results, a)
        first, second = results / a.other, results / a.folder
        if a.first:
            first, second = second, first
        shared = [m for m in ("bc", "ibc", "da-ibc") if _has(first, m) and _has(second, m)]
        if not shared:
            raise ValueError(f"{first} and {second} hold no method in common")
        compared = compare_folders(first, second, methods=tuple(shared))
        rows.append(DepartureRow(a, ablation_command(a), {c.method: c for c in compared}))
    return rows


def _has(folder: Path, method: str) -> bool:
    return (folder / "runs" / method).is_dir()


def effect_text(c: FolderComparison | None) -> str:
    """``+304 [+67, +550] holds`` (score points, rounded), or ``-`` if the method was not run."""
    if c is None:
        return "-"
    d = c.difference
    short = {"holds": "holds", "does not hold": "does not hold", "cannot tell at this scale": "cannot tell"}
    return f"{d.estimate:+.0f} [{d.low:+.0f}, {d.high:+.0f}] {short[c.verdict]}"


def departure_table(rows: list[DepartureRow]) -> str:
    """The rows as an HTML table (the setting, the laptop preset's, the folder, the effect on each method's
    score), then each folder's command, wrapped to ``WRAP`` characters, in a ``<pre>`` block: HTML, which
    Jupyter and the web edition both render."""
    head = [
        "first setting vs second: score difference, 95 % interval",
        "laptop preset",
        "folder",
        "BC",
        "IBC",
    ]
    cells = [f"<th>{escape(h)}</th>" for h in (*head, "DA-IBC")]
    lines = ["<table>", f"<thead><tr>{''.join(cells)}</tr></thead>", "<tbody>"]
    for r in rows:
        effects = [effect_text(r.methods.get(m)) for m in ("bc", "ibc", "da-ibc")]
        row = [
            escape(r.ablation.departure),
            escape(r.ablation.laptop),
            f"<code>{escape(r.ablation.folder)}</code>",
        ]
        row += [escape(e) for e in effects]
        lines.append("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>")
    lines += [
        "</tbody>",
        "</table>",
        "<pre>" + escape("\n".join(wrap_command(r.command) for r in rows)) + "</pre>",
    ]
    return "\n".join(lines)


WRAP = 88
"""Characters per line of a wrapped command."""


def wrap_command(command: str, width: int = WRAP) -> str:
    """``command`` over several lines of at most ``width`` characters (where a word allows; an option stays
    with its value), each line but the last ending in `` \\``, the next ones indented by four spaces."""
    words: list[str] = []
    for word in command.split(" "):
        if words and words[-1].startswith("--") and " " not in words[-1] and not word.startswith("--"):
            words[-1] += " " + word  # an option and its value
        else:
            words.append(word)
    lines, line = [], ""
    for word in words:
        if line and len(line) + 1 + len(word) + 2 > width:
            lines.append(line + " \\")
            line = "    " + word
        else:
            line = f"{line} {word}" if line else word
    return "\n".join([*lines, line])
