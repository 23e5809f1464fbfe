"""``ibc-tutorial families``: every policy family of Part I side by side, at the junction and the tree.

The study behind chapter 13, in one resumable folder (``FOLDER``, an ``experiments.runs.StudyFolder``):

1. **tuning**, on ``tune_seeds`` only: the flow policy trained for each of ``flow_train_steps`` and measured
   at each K of ``flow_steps`` Euler steps, DA-IBC with ranking NCE trained at each of ``rnce_settings``
   (σ of its counter-examples, training steps); all on the junction world. For each, the setting whose
   largest |mass − truth| over the tuning seeds and the three modes is smallest is chosen (a tie goes to
   the cheaper one: fewer steps, then the smaller K) (``choose``);
2. **the report**, on ``report_seeds``, never used to tune: the seven families of
   ``family_comparison.FAMILIES`` on the junction world (``family_comparison``, the flow's masses at
   every K too) and on the tree world (``family_tree``), the flow and R-NCE at the chosen settings;
3. **the cost per decision** of every way of acting, timed in this one process (``family_cost``).

Every run writes ``runs/<world>-<family>/seed<k>/run.json`` (``tuning/runs/...`` for the tuning), and
``results.json`` gathers them after every run (``collect``): per world and family the masses' mean and
standard deviation over seeds, the largest error, the Bhattacharyya coefficient, the tree's closed loop.
``load`` is what the chapter reads.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field, replace
from pathlib import Path

import torch

from ibc_tutorial.experiments.family_comparison import (
    FAMILIES,
    FamilyConfig,
    bhattacharyya,
    junction_data,
    junction_observations,
    mode_masses,
    train_family,
    true_mode_masses,
)
from ibc_tutorial.experiments.family_cost import CostConfig, decision_cost
from ibc_tutorial.experiments.family_tree import TreeStudyConfig, run_tree
from ibc_tutorial.experiments.runs import Run, StudyFolder, add_note, read_json_dict, write_json
from ibc_tutorial.parallel import imap_unordered
from ibc_tutorial.toy.junction import JunctionWorld
from ibc_tutorial.utils import check_int

RUN_FILE = "run.json"
"""A run's measures, written last: with it, the run is finished."""
COST = "cost.json"
"""The cost per decision of every way of acting."""
SETTINGS = "settings.json"
"""The study's settings, as given."""
ENTRIES = ("runs", "tuning", COST, SETTINGS, "results.json", "provenance.json", "PROVENANCE.md")
"""What the folder holds (``--force`` deletes these, and only these)."""
TUNING = "tuning"
"""The part of the folder that holds the tuning runs."""

FOLDER = StudyFolder(what="families study", command="ibc-tutorial families", entries=ENTRIES, done=RUN_FILE)
"""The study's folder: its checks, ``--force``, resuming, loading."""


@dataclass
class FamiliesSettings:
    """What the study trains and measures, and on which seeds."""

    tune_seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    """Seeds the settings are chosen on (never reported)."""
    report_seeds: tuple[int, ...] = (20, 21, 22, 23, 24)
    """Seeds of every reported result (never used to choose a setting)."""
    flow_train_steps: tuple[int, ...] = (2000, 6000)
    """Training steps tried for the flow policy (the others train 2000)."""
    flow_steps: tuple[int, ...] = (1, 4, 10, 20)
    """K, Euler steps, tried for the flow policy (on the same trained networks) and reported at each."""
    rnce_settings: tuple[tuple[float, int], ...] = ((0.1, 2000), (0.05, 2000), (0.1, 6000))
    """(σ of the counter-examples, training steps) tried for DA-IBC with ranking NCE."""
    families: FamilyConfig = field(default_factory=FamilyConfig)
    """The networks, training and measures every family shares (``family_comparison``)."""
    tree: TreeStudyConfig = field(default_factory=TreeStudyConfig)
    """The tree's data, decision points and closed loop (its ``families`` is replaced by the study's)."""
    cost: CostConfig = field(default_factory=CostConfig)
    """How the cost per decision is timed."""

    def __post_init__(self) -> None:
        for name in ("tune_seeds", "report_seeds", "flow_train_steps", "flow_steps"):
            values = tuple(
                check_int(f"settings.{name}", v, minimum=0 if "seeds" in name else 1)
                for v in getattr(self, name)
            )
            if not values:
                raise ValueError(f"settings.{name} must not be empty")
            setattr(self, name, values)
        if set(self.tune_seeds) & set(self.report_seeds):
            raise ValueError(
                f"settings.report_seeds must not share a seed with settings.tune_seeds, got "
                f"{sorted(set(self.tune_seeds) & set(self.report_seeds))}"
            )
        if not self.rnce_settings:
            raise ValueError("settings.rnce_settings must not be empty")
        self.rnce_settings = tuple(
            (float(s), check_int("settings.rnce_settings", n, minimum=1)) for s, n in self.rnce_settings
        )

    def to_dict(self) -> dict:
        """The settings as JSON (what ``settings.json`` holds and a resumed study must match)."""
        return json_ready(dataclasses.asdict(self))


def json_ready(value):
    """Tuples as lists, recursively (JSON's form)."""
    if isinstance(value, dict):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    return value


def slug(family: str) -> str:
    """A family's name in a folder's name ("da-ibc r-nce" -> "da-ibc-r-nce")."""
    return family.replace(" ", "-")


# ---------------------------------------------------------------------- the runs
def tuning_runs(settings: FamiliesSettings) -> list[Run]:
    """The tuning runs: the flow at each training length, R-NCE at each (σ, steps), on the tuning seeds."""
    methods = [f"flow-steps{n}" for n in settings.flow_train_steps]
    methods += [f"rnce-sigma{s:g}-steps{n}" for s, n in settings.rnce_settings]
    return [Run(m, s, TUNING) for m in methods for s in settings.tune_seeds]


def report_runs(settings: FamiliesSettings) -> list[Run]:
    """The reported runs: every family on both worlds, on the report seeds."""
    return [
        Run(f"{w}-{slug(f)}", s)
        for w in ("junction", "tree")
        for f in FAMILIES
        for s in settings.report_seeds
    ]


def junction_job(family: str, seed: int, config: FamilyConfig, flow_steps: tuple[int, ...]) -> dict:
    """Train ``family`` on the junction world; its masses, Bhattacharyya coefficient and, for the flow, its
    masses at every K of ``flow_steps`` (a job for ``parallel``)."""
    world = JunctionWorld()
    policy = train_family(family, world, junction_data(world, config), config, seed)
    obs = junction_observations(world, config)
    truth = true_mode_masses(world, config.radius)
    out = {"family": family, "seed": seed}
    masses = mode_masses(family, policy, obs, world, config, seed).mean(0)  # (3,)
    out.update(masses=masses.tolist(), bc=bhattacharyya(masses, truth))
    if family == "flow":
        by_k = {
            k: mode_masses(family, policy, obs, world, config, seed, n_steps=k).mean(0) for k in flow_steps
        }
        out["by_k"] = {str(k): {"masses": m.tolist(), "bc": bhattacharyya(m, truth)} for k, m in by_k.items()}
    return out


def tree_job(family: str, seed: int, config: TreeStudyConfig) -> dict:
    """``family_tree.run_tree`` as a dict (a job for ``parallel``)."""
    return dataclasses.asdict(run_tree(family, seed, config))


def family_config(settings: FamiliesSettings, family: str, chosen: dict) -> FamilyConfig:
    """The shared config with ``chosen``'s settings for the flow and R-NCE (``choose``)."""
    base = settings.families
    if family == "flow":
        steps = chosen["flow"]["train_steps"]
        return replace(
            base, train=replace(base.train, steps=steps), flow=replace(base.flow, n_steps=chosen["flow"]["K"])
        )
    if family == "da-ibc r-nce":
        r = chosen["da-ibc r-nce"]
        return replace(base, neg_sigma=r["sigma"], train=replace(base.train, steps=r["train_steps"]))
    return base


def job_for(run: Run, settings: FamiliesSettings, chosen: dict | None):
    """The call that makes ``run``: a ``functools.partial`` of a job of this module."""
    base = settings.families
    if run.part == TUNING:
        if run.method.startswith("flow-steps"):
            steps = int(run.method.removeprefix("flow-steps"))
            config = replace(base, train=replace(base.train, steps=steps))
            return functools.partial(junction_job, "flow", run.seed, config, settings.flow_steps)
        sigma, steps = run.method.removeprefix("rnce-sigma").split("-steps")
        config = replace(base, neg_sigma=float(sigma), train=replace(base.train, steps=int(steps)))
        return functools.partial(junction_job, "da-ibc r-nce", run.seed, config, ())
    world, name = run.method.split("-", 1)
    family = next(f for f in FAMILIES if slug(f) == name)
    config = family_config(settings, family, chosen)
    if world == "junction":
        return functools.partial(junction_job, family, run.seed, config, settings.flow_steps)
    return functools.partial(tree_job, family, run.seed, replace(settings.tree, families=config))


# ---------------------------------------------------------------------- choosing and summarising
def max_error(masses: list[list[float]], truth: list[float]) -> float:
    """The largest |mass − truth| over seeds (rows) and modes."""
    return max(abs(m - t) for row in masses for m, t in zip(row, truth, strict=True))


def choose(out, settings: FamiliesSettings) -> tuple[dict, dict]:
    """From the finished tuning runs: ({"flow": {"train_steps", "K"}, "da-ibc r-nce": {"sigma",
    "train_steps"}}, the table of every candidate's largest error over the tuning seeds)."""
    truth = true_mode_masses(JunctionWorld(), settings.families.radius).tolist()
    table = {}
    for n in settings.flow_train_steps:
        rows = [read_run(out, Run(f"flow-steps{n}", s, TUNING)) for s in settings.tune_seeds]
        for k in settings.flow_steps:
            table[f"flow, {n} steps, K={k}"] = max_error([r["by_k"][str(k)]["masses"] for r in rows], truth)
    for s, n in settings.rnce_settings:
        rows = [read_run(out, Run(f"rnce-sigma{s:g}-steps{n}", seed, TUNING)) for seed in settings.tune_seeds]
        table[f"r-nce, sigma {s:g}, {n} steps"] = max_error([r["masses"] for r in rows], truth)
    flow = min(
        ((n, k) for n in settings.flow_train_steps for k in settings.flow_steps),
        key=lambda nk: (round(table[f"flow, {nk[0]} steps, K={nk[1]}"], 6), nk[0], nk[1]),
    )
    rnce = min(
        settings.rnce_settings,
        key=lambda sn: (round(table[f"r-nce, sigma {sn[0]:g}, {sn[1]} steps"], 6), sn[1]),
    )
    chosen = {
        "flow": {"train_steps": flow[0], "K": flow[1]},
        "da-ibc r-nce": {"sigma": rnce[0], "train_steps": rnce[1]},
    }
    return chosen, table


def read_run(out, run: Run) -> dict:
    """A finished run's ``run.json``."""
    return read_json_dict(FOLDER.run_dir(out, run) / RUN_FILE, "delete the run's folder and re-run the study")


def summarize(rows: list[dict], truth: list[float]) -> dict:
    """Over seeds: the masses' mean and standard deviation per mode, the largest error, whether every mode
    of every seed lies within 0.1 of the truth, the Bhattacharyya coefficient's mean and its standard
    deviation."""
    m = torch.tensor([r["masses"] for r in rows], dtype=torch.float64)  # (S, K)
    bc = torch.tensor([r["bc"] for r in rows], dtype=torch.float64)  # (S,)
    err = max_error(m.tolist(), truth)
    return {
        "seeds": [r["seed"] for r in rows],
        "masses": m.tolist(),
        "mean": m.mean(0).tolist(),
        "std": (m.std(0) if len(m) > 1 else torch.zeros(m.shape[1])).tolist(),
        "max_error": err,
        "within_0.1": bool(err <= 0.1),
        "bc_mean": float(bc.mean()),
        "bc_std": float(bc.std()) if len(bc) > 1 else 0.0,
    }


def collect(out, settings: FamiliesSettings) -> dict:
    """``results.json``: the tuning (once finished), and per world and family the summary of its finished
    report runs (the tree's closed loop per seed beside it), and the cost (once measured)."""
    out = Path(out)
    res: dict = {"settings": settings.to_dict(), "tune_seeds": list(settings.tune_seeds)}
    res["report_seeds"] = list(settings.report_seeds)
    if not FOLDER.todo(out, tuning_runs(settings)):
        res["chosen"], res["tuning"] = choose(out, settings)
    junction_truth = true_mode_masses(JunctionWorld(), settings.families.radius).tolist()
    res["truth"] = {"junction": junction_truth}
    for world in ("junction", "tree"):
        res[world] = {}
        for f in FAMILIES:
            runs = [Run(f"{world}-{slug(f)}", s) for s in settings.report_seeds]
            rows = [read_run(out, r) for r in runs if FOLDER.is_done(out, r)]
            if not rows:
                continue
            truth = junction_truth if world == "junction" else rows[0]["truth"]
            res["truth"][world] = truth
            summary = summarize(rows, truth)
            if world == "tree":
                summary["loop"] = {k: [r[k] for r in rows] for k in ("collided", "right", "left")}
            if world == "junction" and f == "flow":
                summary["by_k"] = {
                    k: summarize([{**r["by_k"][k], "seed": r["seed"]} for r in rows], truth)
                    for k in rows[0]["by_k"]
                }
            res[world][f] = summary
    if (out / COST).exists():
        res["cost"] = read_json_dict(out / COST, "delete it and re-run the study")
    return res


# ---------------------------------------------------------------------- the command
def run_study(
    out,
    settings: FamiliesSettings | None = None,
    *,
    workers: int = 1,
    threads: int = 1,
    command: str = "",
    force: bool = False,
    note: str | None = None,
) -> dict:
    """The study into ``out`` (module docstring): checked, cleared with ``force``, resumed where it
    stopped; ``note`` is added to the provenance's notes."""
    settings = FamiliesSettings() if settings is None else settings
    out = Path(out)
    workers = check_int("workers", workers, minimum=1)
    threads = check_int("threads", threads, minimum=1)
    if force:
        FOLDER.clear(out)
    if FOLDER.check_entries(out) and (out / SETTINGS).exists():
        FOLDER.check_settings(
            out,
            lambda s: s == settings.to_dict(),
            lambda s: "a study of other settings",
            files=(SETTINGS,),
            key=None,
        )
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / SETTINGS, settings.to_dict())
    torch.set_num_threads(threads)
    tuning, report = tuning_runs(settings), report_runs(settings)
    prov = FOLDER.provenance(
        out,
        tuning + report,
        title="the families study (chapter 13)",
        command=command,
        preset=settings.to_dict(),
        differences={},
        reference="the defaults of FamiliesSettings",
    )

    def run_all(runs, chosen, save) -> None:
        todo = FOLDER.todo(out, runs)
        calls = [functools.partial(_tagged, i, job_for(r, settings, chosen)) for i, r in enumerate(todo)]
        for i, result in imap_unordered(calls, workers=workers, threads=threads):
            run = todo[i]
            path = FOLDER.run_dir(out, run)
            path.mkdir(parents=True, exist_ok=True)
            write_json(path / RUN_FILE, result)
            print(f"{run.name} done", flush=True)
            save(False)

    def work(save) -> None:
        run_all(tuning, None, save)
        chosen, _ = choose(out, settings)
        print(f"chosen on seeds {list(settings.tune_seeds)}: {chosen}", flush=True)
        run_all(report, chosen, save)
        if not (out / COST).exists():
            write_json(out / COST, decision_cost(settings.families, settings.cost))

    results = FOLDER.run(out, prov, {}, lambda complete: collect(out, settings), work)
    seeds_note = (
        f"settings chosen on seeds {list(settings.tune_seeds)} (tuning/), every reported result on seeds "
        f"{list(settings.report_seeds)}"
    )
    noted = read_json_dict(out / "provenance.json", "delete it and re-run the study").get("notes") or []
    for text in (seeds_note, note):
        if text and text not in noted:
            add_note(out, text)
    return results


def _tagged(index: int, call):
    """``(index, call())``: which call a result of ``imap_unordered`` belongs to."""
    return index, call()


def load(out) -> dict:
    """What chapter 13 reads: ``results.json`` and ``provenance.json`` of a finished study."""
    return FOLDER.load(out)
