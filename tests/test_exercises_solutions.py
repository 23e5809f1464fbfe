"""Every exercise of every exercise notebook has a reference solution in
``ibc_tutorial.exercises.solutions``, shown by a collapsed cell right after its checker cell, and the
checker calls that solution correct."""

import json
import re
from pathlib import Path

import pytest

from ibc_tutorial.exercises import solutions

NOTEBOOKS = sorted(Path(__file__).parents[1].joinpath("exercises").glob("*.ipynb"))


def _exercises(path):
    """(checker module, checker name, the cell after it, the cell after that) per checker cell."""
    cells = json.loads(path.read_text())["cells"]
    for k, cell in enumerate(cells):
        m = re.search(r"\b(ch\d\d)\.(check_\w+)\(", "".join(cell["source"]))
        if cell["cell_type"] == "code" and m:
            yield m.group(1), m.group(2), cells[k + 1], cells[k + 2]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_every_exercise_has_a_collapsed_solution_cell(path):
    exercises = list(_exercises(path))
    headings = [
        c for c in json.loads(path.read_text())["cells"] if "".join(c["source"]).startswith("## Exercise")
    ]
    assert len(exercises) == len(headings) > 0
    for _, _, note, cell in exercises:
        assert note["cell_type"] == "markdown" and "**A solution.**" in "".join(note["source"])
        assert cell["cell_type"] == "code"
        assert cell["metadata"]["jupyter"] == {"source_hidden": True, "outputs_hidden": True}
        assert set(cell["metadata"]["tags"]) >= {"hide-input", "hide-output"}
        m = re.fullmatch(r"print\(inspect\.getsource\(solutions\.(\w+)\)\)", "".join(cell["source"]).strip())
        assert m and hasattr(solutions, m.group(1)), cell["source"]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_the_solution_shown_is_correct(path):
    import importlib

    for module, checker, _, cell in _exercises(path):
        name = re.search(r"solutions\.(\w+)", "".join(cell["source"])).group(1)
        check = getattr(importlib.import_module(f"ibc_tutorial.exercises.{module}"), checker)
        fb = check(getattr(solutions, name))
        assert fb.status == "correct", (path.name, checker, fb)
