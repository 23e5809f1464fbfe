#!/usr/bin/env python
"""Execute notebooks in place, top to bottom, each in a fresh kernel of this environment.

    python tools/execute_notebooks.py book/01_the_tree.ipynb          # one chapter
    python tools/execute_notebooks.py book exercises                  # everything

Run this after editing a chapter and commit the result: `pytest --nbval` re-runs each
notebook and compares its fresh text outputs with the stored ones. Progress bars are
silenced (tqdm's TQDM_DISABLE=1, as under the tests), widget state and timing metadata are
not stored, and a notebook that raises is left unchanged on disk.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient
from nbclient.exceptions import CellExecutionError

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
from ibc_tutorial.utils import QUIET_ENV, atomic_write_bytes  # noqa: E402


def find_notebooks(paths: list[str]) -> list[Path]:
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            out += sorted(q for q in p.rglob("*.ipynb") if ".ipynb_checkpoints" not in q.parts)
        elif p.suffix == ".ipynb" and p.exists():
            out.append(p)
        else:
            raise SystemExit(f"not a notebook or folder: {p}")
    return out


def execute(path: Path, timeout: int) -> float:
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(
        nb,
        timeout=timeout,
        kernel_name="python3",
        resources={"metadata": {"path": str(path.parent)}},
        record_timing=False,
        store_widget_state=True,  # needed for Output widgets; the state is stripped below
    )
    t0 = time.perf_counter()
    client.execute()
    elapsed = time.perf_counter() - t0
    nb.metadata.pop("widgets", None)
    for cell in nb.cells:
        cell.metadata.pop("execution", None)
    nbformat.validate(nb)
    atomic_write_bytes(path, (nbformat.writes(nb) + "\n").encode())
    return elapsed


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("paths", nargs="+", help="notebooks or folders of notebooks")
    parser.add_argument("--timeout", type=int, default=600, help="seconds allowed per cell")
    args = parser.parse_args()
    os.environ[QUIET_ENV] = "1"
    failed = 0
    for path in find_notebooks(args.paths):
        try:
            secs = execute(path, args.timeout)
            print(f"{path}: executed in {secs:.1f} s")
        except CellExecutionError as exc:
            failed += 1
            print(f"{path}: FAILED (left unchanged)\n{str(exc)[-3000:]}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
