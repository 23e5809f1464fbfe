"""The ``ibc-tutorial`` command line: every sub-command's arguments, in one place.

Each sub-command's work lives in a module with a ``run(args)`` function that checks its inputs
first, then does the work. The parser is built here; only the chosen sub-command's arguments
are added and its module imported, so ``ibc-tutorial --version`` and ``--help`` are instant.

    ibc-tutorial collect   --town town01 --routes 10 --seed 0 --out data/town01.npz
    ibc-tutorial train     --method da-ibc --data data/town01.npz --preset laptop --seed 0 --out runs/da-ibc/seed0
    ibc-tutorial evaluate  --checkpoint runs/da-ibc/seed0/final.pt --town town02 --episodes 10 --steps 3000
    ibc-tutorial replicate --preset laptop --out book/results/laptop
"""

from __future__ import annotations

import argparse
import importlib
import sys

from ibc_tutorial import __version__

THREADS_HELP = "torch CPU threads (default 0: torch's choice; 1 is fastest on a busy machine)"

# The argument functions below import their defaults and choices from the modules that own them,
# inside the function: those modules load torch and the simulator, and only the chosen
# sub-command's arguments are added (so ``--version`` and ``--help`` import none of them).


def _collect_arguments(p: argparse.ArgumentParser) -> None:
    from ibc_tutorial.driving.collect import CollectConfig  # deferred: loads the simulator
    from ibc_tutorial.driving.towns import TOWNS

    d = CollectConfig()
    p.add_argument("--town", default=d.town, choices=TOWNS, help="town to drive (default: %(default)s)")
    p.add_argument("--routes", type=int, default=d.routes, help="number of routes / episodes (default: %(default)s)")
    p.add_argument("--seed", type=int, default=d.seed, help="random seed (default: %(default)s)")
    p.add_argument("--out", required=True, help="where to write the demonstrations (.npz)")
    p.add_argument("--routeless", action="store_true", help="no fixed routes: random exits chosen on the way")
    p.add_argument("--min-minutes", type=float, default=d.min_minutes, help="shortest route (default: %(default)s)")
    p.add_argument("--max-minutes", type=float, default=d.max_minutes, help="longest route (default: %(default)s)")
    p.add_argument("--steer-noise", type=float, default=d.steer_noise, help="steering perturbation size (default: %(default)s)")


def _train_arguments(p: argparse.ArgumentParser) -> None:
    from ibc_tutorial.experiments.agents.presets import METHODS, PRESETS  # deferred: loads torch

    p.add_argument("--method", required=True, choices=METHODS, help="bc (Beta), ibc or da-ibc")
    p.add_argument("--data", required=True, help="demonstrations written by 'ibc-tutorial collect'")
    p.add_argument("--preset", default="laptop", help=f"{', '.join(PRESETS)} (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="training seed (default: %(default)s)")
    p.add_argument("--out", required=True, help="folder for the checkpoints and metrics.jsonl")
    p.add_argument("--epochs", type=int, default=None, help="override the preset's number of epochs")
    p.add_argument("--threads", type=int, default=0, help=THREADS_HELP)


def _evaluate_arguments(p: argparse.ArgumentParser) -> None:
    from ibc_tutorial.driving.towns import TOWNS  # deferred: loads the simulator
    from ibc_tutorial.experiments.agents.evaluate import EVAL_SEED

    p.add_argument("--checkpoint", required=True, help="an agent checkpoint written by 'ibc-tutorial train'")
    p.add_argument("--town", default="town02", choices=TOWNS, help="town to drive (default: %(default)s)")
    p.add_argument("--episodes", type=int, default=10, help="episodes, run side by side (default: %(default)s)")
    p.add_argument("--steps", type=int, default=3000, help="steps per episode, 0.1 s each (default: %(default)s)")
    p.add_argument("--seed", type=int, default=EVAL_SEED, help="seed of the first episode (default: %(default)s)")
    p.add_argument("--routeless", action="store_true", help="free driving: no route drawn for the episodes")
    p.add_argument("--out", default=None, help="optional JSON file for the per-episode results")
    p.add_argument("--threads", type=int, default=0, help=THREADS_HELP)


def _replicate_arguments(p: argparse.ArgumentParser) -> None:
    from ibc_tutorial.experiments.agents.presets import PRESETS  # deferred: loads torch

    p.add_argument("--preset", default="laptop", help=f"{', '.join(PRESETS)} (default: %(default)s)")
    p.add_argument("--out", required=True, help="folder for the data, runs, results and provenance")
    p.add_argument("--keep-checkpoints", action="store_true", help="keep every agent's final.pt")
    p.add_argument("--threads", type=int, default=0,
                   help=THREADS_HELP.replace("threads", "threads per process", 1))
    p.add_argument("--workers", type=int, default=1, help="training runs in parallel processes (default: %(default)s)")


# name -> (module with ``run(args)``, function adding the arguments, help)
SUBCOMMANDS: dict[str, tuple[str, object, str]] = {
    "collect": ("ibc_tutorial.driving.collect", _collect_arguments, "drive the expert and store demonstrations"),
    "train": ("ibc_tutorial.experiments.agents.train", _train_arguments, "train a BC, IBC or DA-IBC driving agent"),
    "evaluate": ("ibc_tutorial.experiments.agents.evaluate", _evaluate_arguments,
                 "drive a trained agent in closed loop and score it"),
    "replicate": ("ibc_tutorial.experiments.agents.replicate", _replicate_arguments,
                  "collect, train, evaluate: every result of chapters 08-09"),
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser; only ``command``'s arguments are added (importing what they need)."""
    parser = argparse.ArgumentParser(prog="ibc-tutorial", description="Implicit behavioral cloning tutorial: command line.")
    parser.add_argument("--version", action="version", version=f"ibc-tutorial {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (_module, add_arguments, help_text) in SUBCOMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        if name == command:
            add_arguments(p)
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
    module, _add, _help = SUBCOMMANDS[args.command]
    return int(importlib.import_module(module).run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
