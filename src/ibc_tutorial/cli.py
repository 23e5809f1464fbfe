"""The ``ibc-tutorial`` command line: every sub-command's arguments, in one place.

The CLI is the top layer (CONTRIBUTING.md, "Layers"): it parses the arguments, checks the paths
they name (``check_input_file``, ``check_output_file``, ``check_output_dir``: before any work,
``--out`` never overwritten without ``--force``), records the command line for the provenance
(``args.command_line``: the library never reads ``sys.argv``), and then calls the sub-command's
function in ``ibc_tutorial.experiments.subcommands``. Only the chosen sub-command's arguments are
added and its modules imported, so ``ibc-tutorial --version`` and ``--help`` are instant.

**User errors** (a bad argument or ``--set`` override, a damaged or foreign file, a folder that
holds other work, an output that cannot be written) are one line on stderr and exit code 2,
never a traceback: the library raises ``ValueError`` naming the argument or file, the checks
here raise ``UserError``, and ``main`` prints either. Ctrl-C prints one line too (exit code
130). ``IBC_TUTORIAL_DEBUG=1`` shows the traceback instead, for maintainers.

    ibc-tutorial collect   --town town01 --routes 10 --seed 0 --out data/town01.npz
    ibc-tutorial train     --method da-ibc --data data/town01.npz --seed 0 --out runs/da-ibc/seed0
    ibc-tutorial evaluate  --checkpoint runs/da-ibc/seed0/final.pt   # the table's: town02, routeless
    ibc-tutorial replicate --preset laptop --out book/results/laptop
    ibc-tutorial replicate --preset tiny --set dfo.n_samples=64 --out /tmp/tiny
    ibc-tutorial sweep-steering --preset laptop --out book/results/steering-sweep --workers 2 --threads 1
    ibc-tutorial replicate --preset laptop --commands --set command_branches=true \
        --out book/results/commands-branched
    ibc-tutorial routes --folder book/results/laptop --out book/results/laptop/on-routes
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import tempfile
from pathlib import Path

from ibc_tutorial import __version__

DEBUG_ENV = "IBC_TUTORIAL_DEBUG"
"""Set to 1 to see the traceback of a user error (for maintainers)."""
USER_ERROR = 2
"""Exit code of every user error (argparse's own, for bad command lines)."""
INTERRUPTED = 130
"""Exit code after Ctrl-C (128 + SIGINT)."""


class UserError(Exception):
    """An error of the user's, not of the program: ``main`` prints its one-line message and exits with 2."""


class _Parser(argparse.ArgumentParser):
    """argparse, with its errors on one line (no usage block)."""

    def error(self, message: str):
        self.exit(USER_ERROR, f"{self.prog}: {message} (see {self.prog} --help)\n")


# --------------------------------------------------------------------------- paths, checked before any work
def _nearest_existing(path: Path) -> Path:
    p = path.absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def _check_writable_dir(name: str, folder: Path, target: Path) -> None:
    """Refuse unless ``folder`` (an existing ancestor of ``target``) is a folder we can create files in."""
    if not folder.is_dir():
        raise UserError(f"{name}: cannot create {target}: {folder} is a file, not a folder")
    try:  # a real probe: os.access says yes to root even on a read-only file system
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".ibc-tutorial-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise UserError(
            f"{name}: cannot write to {folder} ({exc.strerror or exc}): choose another location"
        ) from None


def check_input_file(name: str, path, what: str = "file") -> Path:
    """``path`` must be a readable file (not a folder); UserError naming the argument otherwise."""
    path = Path(path)
    if path.is_dir():
        raise UserError(f"{name}: {path} is a folder, expected a {what}")
    if not path.is_file():
        raise UserError(f"{name}: no {what} at {path}")
    if not os.access(path, os.R_OK):
        raise UserError(f"{name}: {path} is not readable")
    return path


def check_output_file(name: str, path, *, force: bool = False) -> Path:
    """``path`` must be a file we may write: not a folder, in a writable folder, and, unless ``force``,
    not an existing file (nothing is overwritten unless asked)."""
    path = Path(path)
    if path.is_dir():
        raise UserError(f"{name}: {path} is a folder, expected a file name")
    if path.exists() and not force:
        raise UserError(f"{name}: {path} exists: choose another name, or pass --force to overwrite it")
    parent = _nearest_existing(path.parent)
    _check_writable_dir(name, parent, path)
    return path


def check_output_dir(name: str, path) -> Path:
    """``path`` must be a folder we can write in, or a path where one can be created (no file in the way)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UserError(f"{name}: {path} is a file, expected a folder")
    _check_writable_dir(name, _nearest_existing(path), path)
    return path


def check_arguments(args: argparse.Namespace) -> None:
    """The arguments every command shares, checked before the paths: ``--device`` (a device this machine
    has), ``--threads`` >= 0, ``--workers`` >= 1 (``ValueError`` naming the argument)."""
    from ibc_tutorial.utils import check_device, check_int  # deferred: loads torch

    if getattr(args, "device", None) is not None:
        check_device("--device", args.device)
    if getattr(args, "threads", None) is not None:
        check_int("--threads", args.threads, minimum=0)
    if getattr(args, "workers", None) is not None:
        check_int("--workers", args.workers, minimum=1)


def check_paths(command: str, args: argparse.Namespace) -> None:
    """The paths a sub-command's arguments name, checked before any work (``UserError`` naming the
    argument)."""
    force = bool(getattr(args, "force", False))
    if command == "collect":
        check_output_file("--out", args.out, force=force)
    elif command == "train":
        check_input_file("--data", args.data, "demonstration file (.npz)")
        check_output_dir("--out", args.out)
    elif command == "evaluate":
        if getattr(args, "crossings", False) and not args.out:
            raise UserError("--crossings needs --out (the crossings are written there, not printed)")
        if args.out:
            check_output_file("--out", args.out, force=force)
        check_input_file("--checkpoint", args.checkpoint, "agent checkpoint (.pt)")
    elif command in ("replicate", "replicate-steering", "sweep-steering"):
        check_output_dir("--out", args.out)
    elif command == "stems":
        for name in ("dfo_samples", "dfo_iters", "episodes", "steps"):
            if getattr(args, name) is not None and getattr(args, name) < 1:
                raise UserError(
                    f"--{name.replace('_', '-')} must be a positive integer, got {getattr(args, name)}"
                )
        if not Path(args.folder, "runs").is_dir():
            raise UserError(f"--folder must be a replication folder with runs/, got {args.folder}")
        check_output_dir("--out", args.out)
    elif command == "families":
        check_output_dir("--out", args.out)
    elif command == "two-answers":
        check_output_dir("--out", args.out)
        if args.baseline is not None and not Path(args.baseline, "runs").is_dir():
            raise UserError(f"--baseline must be a replication folder with runs/, got {args.baseline}")
    elif command == "starts":
        if not Path(args.folder, "runs").is_dir():
            raise UserError(f"--folder must be a replication folder with runs/, got {args.folder}")
        check_output_dir("--out", args.out)
    elif command == "routes":
        if args.drives < 1:
            raise UserError(f"--drives must be a positive integer, got {args.drives}")
        if not Path(args.folder, "runs").is_dir():
            raise UserError(f"--folder must be a replication folder with runs/, got {args.folder}")
        check_output_dir("--out", args.out)


THREADS_HELP = "torch CPU threads (default 0: torch's choice; 1 is fastest on a busy machine)"
SET_HELP = (
    "override one setting of the preset, FIELD=VALUE, repeatable: a field of the preset (epochs=3) or of "
    "the library config it makes (dfo.n_samples=1024, collect.routes=2, train.lr=3e-4, bev.size=32); "
    "checked before any work, recorded in the provenance"
)
DEVICE_HELP = (
    "where the networks run: cpu, cuda, cuda:N or mps (default: %(default)s; the random draws stay on "
    "the CPU's seeded generators)"
)

# The argument functions below import their defaults and choices from the modules that own them,
# inside the function: those modules load torch and the simulator, and only the chosen
# sub-command's arguments are added (so ``--version`` and ``--help`` import none of them).


def _collect_arguments(p: argparse.ArgumentParser) -> None:
    from ibc_tutorial.driving.collect import CollectConfig  # deferred: loads the simulator
    from ibc_tutorial.driving.towns import TOWNS

    d = CollectConfig()
    p.add_argument("--town", default=d.town, choices=TOWNS, help="town to drive (default: %(default)s)")
    p.add_argument(
        "--routes", type=int, default=d.routes, help="number of routes / episodes (default: %(default)s)"
    )
    p.add_argument("--seed", type=int, default=d.seed, help="random seed (default: %(default)s)")
    p.add_argument("--out", required=True, help="where to write the demonstrations (.npz)")
    p.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    p.add_argument("--routeless", action="store_true", help="no fixed routes: random exits chosen on the way")
    p.add_argument(
        "--min-minutes", type=float, default=d.min_minutes, help="shortest route (default: %(default)s)"
    )
    p.add_argument(
        "--max-minutes", type=float, default=d.max_minutes, help="longest route (default: %(default)s)"
    )
    p.add_argument(
        "--steer-noise",
        type=float,
        default=d.steer_noise,
        help="steering perturbation size (default: %(default)s)",
    )
    p.add_argument(
        "--brake-noise",
        type=float,
        default=d.brake_noise,
        help="braking perturbation strength in [0, 1] (default: %(default)s; the laptop preset's data: 1.0)",
    )


def _train_arguments(p: argparse.ArgumentParser) -> None:
    from ibc_tutorial.experiments.agents.presets import ALL_METHODS, PRESETS  # deferred: loads torch

    p.add_argument(
        "--method",
        required=True,
        choices=ALL_METHODS,
        help="bc (Beta), ibc, da-ibc, flow (flow matching) or da-ibc-rnce (DA-IBC with ranking NCE)",
    )
    p.add_argument("--data", required=True, help="demonstrations written by 'ibc-tutorial collect'")
    p.add_argument("--preset", default="laptop", choices=PRESETS, help="settings (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="training seed (default: %(default)s)")
    p.add_argument(
        "--out",
        required=True,
        help="folder for the checkpoints and metrics.jsonl; an interrupted "
        "run of the same settings there is resumed",
    )
    p.add_argument("--epochs", type=int, default=None, help="override the preset's number of epochs")
    p.add_argument(
        "--set", action="append", default=[], metavar="FIELD=VALUE", dest="overrides", help=SET_HELP
    )
    p.add_argument("--force", action="store_true", help="start over: delete the run already in --out")
    p.add_argument("--threads", type=int, default=0, help=THREADS_HELP)
    p.add_argument("--device", default="cpu", help=DEVICE_HELP)


def _evaluate_arguments(p: argparse.ArgumentParser) -> None:
    from ibc_tutorial.driving.towns import TOWNS  # deferred: loads the simulator
    from ibc_tutorial.experiments.agents.evaluate import EVAL_SEED

    p.add_argument("--checkpoint", required=True, help="an agent checkpoint written by 'ibc-tutorial train'")
    p.add_argument("--town", default="town02", choices=TOWNS, help="town to drive (default: %(default)s)")
    p.add_argument(
        "--episodes",
        type=int,
        default=None,
        help="episodes, run side by side (default: the checkpoint preset's final_episodes, as the table)",
    )
    p.add_argument(
        "--steps",
        type=int,
        default=None,
        help="steps per episode, 0.1 s each (default: the checkpoint preset's final_steps, as the table)",
    )
    p.add_argument(
        "--seed", type=int, default=EVAL_SEED, help="seed of the first episode (default: %(default)s)"
    )
    p.add_argument(
        "--policy-seed",
        type=int,
        default=None,
        help="seed of the agent's DFO draws (default: the agent's training seed, as the table)",
    )
    routes = p.add_mutually_exclusive_group()
    routes.add_argument(
        "--routed", action="store_true", help="draw a route for each episode (not the book's protocol)"
    )
    routes.add_argument(
        "--routeless", action="store_true", help="no route drawn, as the book's protocol (the default)"
    )
    p.add_argument("--out", default=None, help="optional JSON file for the per-episode results")
    p.add_argument(
        "--crossings",
        action="store_true",
        help="also record every junction crossing of every episode, with the steering applied during it "
        "(driving.analysis.junction_crossings), in --out, and for an energy agent its energy over "
        "steering in the crossings that ended in a building (driving them again; chapter 08)",
    )
    p.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    p.add_argument("--threads", type=int, default=0, help=THREADS_HELP)
    p.add_argument("--device", default="cpu", help=DEVICE_HELP)


def _study_arguments(
    p: argparse.ArgumentParser, presets: tuple, study: str, runs: str, purposes: dict | None = None
) -> None:
    """What both studies' commands share: --preset, --out, --force, --threads and --workers; ``purposes``:
    each preset's line for --help (what it is for, how long it takes)."""
    listed = "".join(f"; {name}: {purposes[name]}" for name in presets if name in (purposes or {}))
    p.add_argument(
        "--preset",
        default="laptop",
        choices=presets,
        help="settings (default: %(default)s)" + listed.replace("%", "%%"),
    )
    p.add_argument(
        "--out",
        required=True,
        help="folder for the data, runs, results and provenance; an interrupted "
        f"{study} of the same preset there is resumed",
    )
    p.add_argument("--force", action="store_true", help=f"start over: delete the {study} already in --out")
    p.add_argument(
        "--threads", type=int, default=0, help=THREADS_HELP.replace("threads", "threads per process", 1)
    )
    p.add_argument(
        "--workers", type=int, default=1, help=f"{runs} in parallel processes (default: %(default)s)"
    )


def _replicate_arguments(p: argparse.ArgumentParser) -> None:
    from ibc_tutorial.experiments.agents.presets import PRESETS, PURPOSES  # deferred: loads torch

    _study_arguments(p, tuple(PRESETS), "replication", runs="training runs", purposes=PURPOSES)
    p.add_argument(
        "--set", action="append", default=[], metavar="FIELD=VALUE", dest="overrides", help=SET_HELP
    )
    p.add_argument("--device", default="cpu", help=DEVICE_HELP + "; every worker uses it")
    p.add_argument(
        "--commands",
        action="store_true",
        help="agents taking a route command, driven on the town02 routes (chapter 11; --set commands=true)",
    )


def _replicate_steering_arguments(p: argparse.ArgumentParser) -> None:
    from ibc_tutorial.experiments.steering.presets import PRESETS, PURPOSES  # deferred: loads torch

    _study_arguments(p, tuple(PRESETS), "study", runs="runs", purposes=PURPOSES)
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        dest="overrides",
        help=SET_HELP.replace(
            "(dfo.n_samples=1024, collect.routes=2, train.lr=3e-4, bev.size=32)", "(train.lr=3e-4)"
        ),
    )
    p.add_argument(
        "--device", default="cpu", choices=("cpu",), help="where to train (the study is sized for a CPU)"
    )


def _stems_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "step",
        choices=("drive", "analyse"),
        help="drive: free driving of every shipped agent and the expert (resumable); analyse: the energy, "
        "Beta and DFO readings at every stem crossing and red stop, then summary.json (resumable)",
    )
    p.add_argument("--folder", default="book/results/laptop", help="replication folder with runs/ and data/")
    p.add_argument(
        "--out", default="book/results/laptop/stems", help="where drives/, analysis/ and summary.json go"
    )
    p.add_argument("--episodes", type=int, default=5, help="free-driving episodes per driver (drive)")
    p.add_argument("--steps", type=int, default=3000, help="steps per episode, 10 per second (drive)")
    p.add_argument("--only", nargs="*", default=None, help="drive only these (e.g. da-ibc-seed0 expert)")
    p.add_argument(
        "--dfo-select",
        choices=("argmax", "sample"),
        help="drive: the energy agents' final DFO draw changed (argmax: the lowest energy; sample: ~ p)",
    )
    p.add_argument("--dfo-samples", type=int, help="drive: the energy agents' DFO samples changed")
    p.add_argument("--dfo-iters", type=int, help="drive: the energy agents' DFO iterations changed")
    p.add_argument(
        "--table-seeds",
        action="store_true",
        help="drive: each agent's DFO draws seeded with its training seed, as the table's episodes that "
        "replicate records (default: seed 0)",
    )
    p.add_argument(
        "--summary-only", action="store_true", help="analyse: only pool the analysis files into summary.json"
    )


def _two_answers_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--out",
        required=True,
        help="folder of the study: the replication of the two-answers preset (resumed if interrupted), then "
        "its readings in <out>/analysis",
    )
    p.add_argument(
        "--threads", type=int, default=0, help=THREADS_HELP.replace("threads", "threads per process", 1)
    )
    p.add_argument(
        "--workers", type=int, default=1, help="training runs in parallel processes (default: %(default)s)"
    )
    p.add_argument(
        "--baseline",
        default=None,
        help="a replication folder whose agents are read at the same states too "
        "(chapter 12: book/results/laptop)",
    )
    p.add_argument(
        "--methods",
        default=None,
        help="methods to add to the study's replication, comma-separated (flow,da-ibc-rnce): trained on its "
        "data with its settings beside its agents, which are not retrained (resumable; recorded in "
        "added_methods.json and the folder's provenance notes)",
    )


def _families_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, help="folder of the study (resumed if interrupted)")
    p.add_argument(
        "--seeds", default="20,21,22,23,24", help="seeds of the reported results (default: %(default)s)"
    )
    p.add_argument(
        "--tune-seeds",
        default="0,1,2,3,4",
        help="seeds the flow's and R-NCE's settings are chosen on, never reported (default: %(default)s)",
    )
    p.add_argument("--threads", type=int, default=1, help="torch threads per process (default: %(default)s)")
    p.add_argument(
        "--workers", type=int, default=1, help="training runs in parallel processes (default: %(default)s)"
    )
    p.add_argument("--force", action="store_true", help="start over: delete the study already in --out")
    p.add_argument("--note", default=None, help="a note for the provenance (e.g. what else the machine ran)")


def _routes_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--folder", default="book/results/laptop", help="replication folder with runs/")
    p.add_argument(
        "--out", default="book/results/laptop/on-routes", help="where each driver's <name>.json goes"
    )
    p.add_argument("--drives", type=int, default=1, help="drives of every route per driver")
    p.add_argument("--only", nargs="*", default=None, help="drive only these (e.g. da-ibc-seed0 expert)")
    p.add_argument(
        "--heldout-seed",
        type=int,
        default=None,
        help="drive routes drawn afresh from this seed instead of the six fixed routes (chapter 11's check)",
    )
    p.add_argument(
        "--heldout-routes", type=int, default=8, help="with --heldout-seed: how many (default: %(default)s)"
    )


def _starts_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--folder", default="book/results/laptop", help="replication folder with runs/")
    p.add_argument(
        "--out", default="book/results/laptop/more-starts", help="where each driver's <name>.json goes"
    )
    p.add_argument("--seed", type=int, default=40000, help="seed of the first start (default: %(default)s)")
    p.add_argument("--episodes", type=int, default=10, help="starts, one episode each (default: %(default)s)")
    p.add_argument("--steps", type=int, default=3000, help="steps per episode (default: %(default)s)")
    p.add_argument("--only", nargs="*", default=None, help="drive only these (e.g. da-ibc-seed0 expert)")


def _sweep_steering_arguments(p: argparse.ArgumentParser) -> None:
    from ibc_tutorial.experiments.steering.sweep import SWEEP  # deferred: loads torch

    def listed(values) -> str:
        return ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in values)

    _replicate_steering_arguments(p)
    p.add_argument(
        "--shares",
        default=listed(SWEEP.shares),
        help="side-road shares, comma-separated, each in (0, 1] (default: %(default)s)",
    )
    p.add_argument(
        "--models", default=listed(SWEEP.models), help="models trained at every share (default: %(default)s)"
    )
    p.add_argument("--seeds", default=listed(SWEEP.seeds), help="training seeds (default: %(default)s)")
    p.add_argument(
        "--sessions",
        type=int,
        default=SWEEP.sessions,
        help="driving sessions per trained model (default: %(default)s)",
    )
    for action in p._actions:  # the study's help, said of the sweep
        if action.dest == "out":
            action.help = "folder of the sweep; an interrupted sweep of the same settings there is resumed"
        elif action.dest == "force":
            action.help = "start over: delete the sweep already in --out"


COMMANDS = "ibc_tutorial.experiments.subcommands"
"""The module holding each sub-command's work, a function of the parsed arguments."""

# name -> (function of ``COMMANDS`` taking the parsed arguments, function adding the arguments, help)
SUBCOMMANDS: dict[str, tuple[str, object, str]] = {
    "collect": (
        "collect",
        _collect_arguments,
        "drive the expert and store demonstrations",
    ),
    "train": (
        "train",
        _train_arguments,
        "train a BC, IBC or DA-IBC driving agent",
    ),
    "evaluate": (
        "evaluate",
        _evaluate_arguments,
        "drive a trained agent in closed loop and score it",
    ),
    "replicate": (
        "replicate",
        _replicate_arguments,
        "collect, train, evaluate: every result of chapters 08-09",
    ),
    "replicate-steering": (
        "replicate_steering",
        _replicate_steering_arguments,
        "the steering-EBM paper's road-following study: every result of chapter 10",
    ),
    "stems": (
        "stems",
        _stems_arguments,
        "the stems of the T-junctions: every shipped agent driven freely, the energy where it chooses",
    ),
    "two-answers": (
        "two_answers",
        _two_answers_arguments,
        "chapter 12's study: agents trained where a stem is a state with two answers, and read there "
        "(about an hour on 2 cores with --workers 2 --threads 1)",
    ),
    "families": (
        "families",
        _families_arguments,
        "chapter 13's study: seven policy families at the junction and the tree, and their cost per decision "
        "(about 15 minutes on one core)",
    ),
    "routes": (
        "routes",
        _routes_arguments,
        "every agent of a replication folder, and the expert, driven on the town02 routes (resumable)",
    ),
    "starts": (
        "starts",
        _starts_arguments,
        "every agent of a replication folder, and the expert, driven from more town02 starts (resumable)",
    ),
    "sweep-steering": (
        "sweep_steering",
        _sweep_steering_arguments,
        "the road-following study at several side-road shares, each model driven in several sessions",
    ),
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser; only ``command``'s arguments are added (importing what they need)."""
    parser = _Parser(prog="ibc-tutorial", description="Implicit behavioral cloning tutorial: command line.")
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
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version (0), or a bad command line (2, one line: ``_Parser.error``)
        return int(exc.code or 0)
    if args.command is None:
        parser.print_help()
        return 0
    function, _add, _help = SUBCOMMANDS[args.command]
    debug = os.environ.get(DEBUG_ENV, "").strip().lower() not in ("", "0", "false")
    prog = f"ibc-tutorial {args.command}"
    args.command_line = " ".join(["ibc-tutorial", *argv])  # the provenance's command
    try:
        check_arguments(args)
        check_paths(args.command, args)
        return int(getattr(importlib.import_module(COMMANDS), function)(args) or 0)
    except KeyboardInterrupt:
        if debug:
            raise
        resumable = args.command in (
            "train",
            "replicate",
            "replicate-steering",
            "sweep-steering",
            "two-answers",
            "families",
        )
        print(
            f"{prog}: interrupted; "
            + ("re-run the same command to resume" if resumable else "nothing was written"),
            file=sys.stderr,
        )
        return INTERRUPTED
    except (
        UserError,
        ValueError,
        OSError,
    ) as exc:  # ValueError: the library's checks name the argument or file
        if debug:
            raise
        print(f"{prog}: {_one_line(exc)}", file=sys.stderr)
        return USER_ERROR


def _one_line(exc: BaseException) -> str:
    """The message of ``exc`` on one line; an OSError names its file and the system's reason."""
    if isinstance(exc, OSError):
        where = exc.filename if exc.filename is not None else ""
        text = f"cannot access {where}: {exc.strerror or exc}" if where else f"{exc.strerror or exc}"
    else:
        text = str(exc) or type(exc).__name__
    return " ".join(text.split())


if __name__ == "__main__":
    sys.exit(main())
