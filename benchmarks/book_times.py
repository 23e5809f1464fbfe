#!/usr/bin/env python
"""Wall time of every chapter (and, with --exercises, every exercise notebook).

    python benchmarks/book_times.py                       # all of book/
    python benchmarks/book_times.py book/01_the_tree.ipynb --exercises

Each notebook runs top to bottom in a fresh kernel of this environment, on an in-memory copy:
nothing is written back (use tools/execute_notebooks.py to store outputs). Progress bars are
silenced as under the tests (TQDM_DISABLE=1). The goal is about 90 s per chapter on an
idle 2-core machine; rows above that are flagged. Times include the kernel's start.
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

ROOT = Path(__file__).resolve().parents[1]
LIMIT_S = 90.0
"""A chapter should run in about this many seconds on an idle 2-core machine."""


def notebooks(paths: list[str], with_exercises: bool) -> list[Path]:
    found: list[Path] = []
    targets = [Path(p) for p in paths] or [ROOT / "book"]
    if with_exercises and not paths:
        targets.append(ROOT / "exercises")
    for p in targets:
        if p.is_dir():
            found += sorted(q for q in p.glob("*.ipynb") if ".ipynb_checkpoints" not in q.parts)
        elif p.suffix == ".ipynb" and p.exists():
            found.append(p)
            twin = ROOT / "exercises" / p.name
            if with_exercises and p.parent.name == "book" and twin.exists():
                found.append(twin)
        else:
            raise SystemExit(f"not a notebook or folder: {p}")
    return found


def run(path: Path, timeout: int) -> tuple[float, str]:
    """Execute a copy of ``path``; return (seconds, "ok" or the error's first line)."""
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(
        nb, timeout=timeout, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}
    )
    t0 = time.perf_counter()
    try:
        client.execute()
        status = "ok"
    except CellExecutionError as exc:
        lines = [ln for ln in str(exc).splitlines() if ln.strip()]
        status = "FAILED: " + (lines[-1][:80] if lines else "error")
    return time.perf_counter() - t0, status


def main() -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("paths", nargs="*", help="notebooks or folders (default: book/)")
    parser.add_argument("--exercises", action="store_true", help="also time the exercise notebooks")
    parser.add_argument("--timeout", type=int, default=900, help="seconds allowed per cell")
    args = parser.parse_args()
    os.environ["TQDM_DISABLE"] = "1"
    rows = []
    for path in notebooks(args.paths, args.exercises):
        secs, status = run(path, args.timeout)
        flag = "  > 90 s" if secs > LIMIT_S else ""
        rows.append((path, secs, status))
        print(
            f"{str(path.relative_to(ROOT) if path.is_absolute() else path):45s} {secs:7.1f} s  "
            f"{status}{flag}",
            flush=True,
        )
    cores = os.cpu_count()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(
        f"{len(rows)} notebooks, {sum(r[1] for r in rows):.1f} s in all; {cores} CPU cores, "
        f"load average {load:.1f} at the end"
    )
    return 1 if any(r[2] != "ok" for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
