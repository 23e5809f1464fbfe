"""The ``ibc-tutorial`` command line.

Each sub-command lives in the module that owns its work and registers itself here through
``SUBCOMMANDS``: a mapping from name to ``(module, add_arguments, run)`` names, imported lazily so
that ``ibc-tutorial --version`` is instant.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from ibc_tutorial import __version__

# name -> (module path, function that adds arguments to a sub-parser, function that runs it)
SUBCOMMANDS: dict[str, tuple[str, str, str, str]] = {
    "collect": ("ibc_tutorial.driving.collect", "add_arguments", "run", "drive the expert and store demonstrations"),
    "train": ("ibc_tutorial.agent_training", "add_arguments", "run", "train a BC, IBC or DA-IBC driving agent"),
    "evaluate": ("ibc_tutorial.evaluation", "add_arguments", "run", "drive a trained agent in closed loop and score it"),
    "replicate": ("ibc_tutorial.replicate", "add_arguments", "run", "collect, train, evaluate: every result of chapters 08-09"),
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser; only ``command``'s module is imported (to add its arguments)."""
    parser = argparse.ArgumentParser(prog="ibc-tutorial", description="Implicit behavioral cloning tutorial: command line.")
    parser.add_argument("--version", action="version", version=f"ibc-tutorial {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, add_args, _run, help_text) in SUBCOMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        if name == command:
            getattr(importlib.import_module(module), add_args)(p)
    return parser


def _command_in(argv: list[str]) -> str | None:
    """The sub-command named in ``argv`` (its first word that is not an option), if any."""
    for word in argv:
        if not word.startswith("-"):
            return word if word in SUBCOMMANDS else None
    return None


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_command_in(argv))
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    module, _add, run, _help = SUBCOMMANDS[args.command]
    return int(getattr(importlib.import_module(module), run)(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
