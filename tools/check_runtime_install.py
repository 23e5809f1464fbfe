#!/usr/bin/env python
"""Check an install of ibc-tutorial WITHOUT its dev extras: every module imports, every command helps.

    python -m venv /tmp/rt && /tmp/rt/bin/pip install -c environment.lock . \
        && /tmp/rt/bin/python tools/check_runtime_install.py

A module that imports a package declared only as a dev extra (scipy, pytest, nbval, ...) fails
here, where the CI's main environment (which installs the dev extras) cannot see it. Run from
outside the source tree's ``src`` so that the installed package is the one imported.
"""

from __future__ import annotations

import importlib
import pkgutil
import subprocess
import sys

import ibc_tutorial
from ibc_tutorial.cli import SUBCOMMANDS


def main() -> int:
    failures = []
    names = [m.name for m in pkgutil.walk_packages(ibc_tutorial.__path__, prefix="ibc_tutorial.")]
    names = [n for n in names if n != "ibc_tutorial.__main__"]  # running it is `python -m ibc_tutorial`
    for name in names:
        try:
            importlib.import_module(name)
        except Exception as e:  # noqa: BLE001 - report every failure, not only the first
            failures.append(f"import {name}: {type(e).__name__}: {e}")
    commands = [["--help"]] + [[name, "--help"] for name in SUBCOMMANDS]
    for args in commands:
        done = subprocess.run(["ibc-tutorial", *args], capture_output=True, text=True)
        if done.returncode != 0 or done.stderr.strip():
            failures.append(
                f"ibc-tutorial {' '.join(args)}: exit {done.returncode}: {done.stderr.strip()[-300:]}"
            )
    print(
        f"runtime install: imported {len(names)} modules, ran {len(commands)} --help commands,"
        f" {len(failures)} failures"
    )
    for f in failures:
        print("  " + f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
