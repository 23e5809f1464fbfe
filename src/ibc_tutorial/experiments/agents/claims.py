"""The DA-IBC paper's five claims (its sec. 4.3) and their verdicts on one replication folder (chapter 09).

The paper's results section makes five claims about its BC, IBC and DA-IBC agents trained in
town01 and driven in the unseen town02 (``CLAIMS``). ``judge_claims(folder)`` judges each on a
finished replication folder (``ibc-tutorial replicate --out FOLDER``), reading nothing but the
folder, with four verdicts (``ibc_tutorial.equivalence``): a claim "holds" if the 95 % interval of the
quantity it is about lies on its side of 0, "does not hold" if it lies on the other, is "equivalent within
±δ" if the two one-sided tests (TOST, Schuirmann 1987) show the quantity within ±δ, and "cannot tell at
this scale" otherwise. Each claim's δ, the smallest difference it cares about, is stated here before any
data are read (``DELTA_RULES``). A claim of several parts holds only if every part does (``combine``).

- claims 1-3 compare two methods by the difference of their means, with the crossed bootstrap of agents
  and starts (``crossed_bootstrap``: every agent drove the same starts, so the starts are a level of the
  bootstrap): claim 1 at the first evaluation during training (``metrics.jsonl``), claims 2 and 3 on the
  table's starts and on the held-out starts;
- claims 4 and 5 read the stem analysis of the folder (``stems/analysis/``: ``ibc-tutorial stems analyse
  --folder FOLDER --out FOLDER/stems``, on the table's episodes of every agent, which ``replicate`` records):
  claim 4 (the Fig. 5 analogue) compares the share of the minority exit, min(p, 1 - p) of the left share p
  of completed crossings from the stem of a T, DA-IBC minus BC (``stats.ratio_of_sums_difference``, the
  agents x episodes bootstrap); claim 5 (the Fig. 6 analogue, about *steering*) compares, per DA-IBC agent,
  the steering range within 3 nats of the energy's minimum at the stem's decision states (from the entry
  until the steering passes ±0.3, ``driving.stems.decision_window``) with the same range at its stops at red
  lights, the mean over agents of the difference with its bootstrap interval over agents. A folder without
  the stem analysis judges both "cannot tell", saying what is missing. (The book's first replication
  judged claim 4 by a permutation test over junction visits, which treated visits of one episode as
  independent, and claim 5 by ten DFO draws at one moment of one agent: chapter 09 says why not.)

``compare_verdicts(a, b)`` says which claims get the same verdict in two folders (chapter 09: are
the verdicts the same when the whole replication runs again on another CPU?). ``judge_stem_claims``
judges claims 4 and 5 on any stem analysis, e.g. the same agents driven again on another CPU.
``compare_folders(variant, reference)`` (``folder_comparison``, importable from here) compares two
replication folders' scores method by method on the seeds and starts they share (chapter 08's
ablations: each a replication whose ``--set`` overrides its ``PROVENANCE.md`` records).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ibc_tutorial import stats
from ibc_tutorial.equivalence import four_verdicts, judge_difference, tost
from ibc_tutorial.experiments.agents.folder_comparison import (  # noqa: F401  (chapter 08 imports them from here)
    STILL_M,
    FolderComparison,
    compare_folders,
)
from ibc_tutorial.experiments.agents.presets import Preset
from ibc_tutorial.experiments.agents.replication_folder import (
    EVALUATIONS,
    episode_table,
    load_results,
    run_dir,
)
from ibc_tutorial.experiments.agents.training_run import read_metrics
from ibc_tutorial.experiments.runs import read_json_dict
from ibc_tutorial.stats import minority  # noqa: F401  (chapters 08-09 import it from here)

CLAIMS = {
    1: "BC reaches higher scores sooner",
    2: "DA-IBC travels farther than IBC",
    3: "DA-IBC runs more red lights than BC",
    4: "DA-IBC takes different exits at a junction, BC does not",
    5: "DA-IBC's minima spread in steering at a junction, gather at a red light",
}
"""The DA-IBC paper's sec. 4.3 claims, by number: 1 from its Fig. 4, 2-3 from its table, 4 from its Fig. 5, 5
from
its Fig. 6."""

STARTS = {"final": "the table's starts", "heldout": "held-out starts"}
"""The final evaluations claims 2 and 3 are judged on, and how the parts name them."""
CLAIM_METHODS = ("bc", "ibc", "da-ibc")
"""The methods a folder must hold for the claims to be judged."""
STEM_ANALYSIS = "stems/analysis"
"""Where in a replication folder the stem analysis's per-agent files are (``stem_analysis.run_analysis``)."""
STEM_COMMAND = "ibc-tutorial stems analyse --folder {folder} --out {folder}/stems"
"""The command that makes them."""
SCORE_SHARE_DELTA = 0.1
"""δ of claims 1 and 2 as a share of the expert: a tenth of the expert's mean score (claim 1, per step of
the table's episodes times the steps of the first evaluation) or of its mean distance on the same starts
(claim 2)."""
RED_LIGHT_DELTA = math.log(0.9) / math.log(0.7)
"""δ of claim 3: the red lights per episode that cost a tenth of the score (0.7 ** δ = 0.9): 0.30."""
MINORITY_DELTA = 0.05
"""δ of claim 4: a tenth of 0.5, the minority share of an even choice between two exits."""
RANGE_DELTA = 0.05
"""δ of claim 5: one step of the 41-value steering grid the 3-nat range is read on (2 / 40)."""
DELTA_RULES = {
    1: f"{SCORE_SHARE_DELTA:.0%} of the expert's mean score, scaled to the first evaluation's episode length",
    2: f"{SCORE_SHARE_DELTA:.0%} of the expert's mean distance on the same starts",
    3: f"{RED_LIGHT_DELTA:.2f} red lights per episode, which cost a tenth of the score (0.7^δ = 0.9)",
    4: f"{MINORITY_DELTA:.2f} of the crossings, a tenth of an even choice's minority share (0.5)",
    5: f"{RANGE_DELTA:.2f} in steering, one step of the 41-value grid the energy is read on",
}
"""Each claim's δ in words: what "equivalent within ±δ" means for it, stated before the data are read."""
RANGE_KEY = "range_extent"
"""Claim 5's reading of a state's energy: the extent of the steering within 3 nats of its minimum
(``driving.energy_profiles.low_range``)."""


# --------------------------------------------------------------------------- the pieces
VERDICTS = stats.VERDICTS
"""The four verdicts a claim or a part gets."""
combine = stats.combine_verdicts
"""A claim of several parts: holds if every part does, does not hold if one part does not, equivalent
within ±δ if every part is, else cannot tell (``stats.combine_verdicts``)."""


def stem_files(folder) -> dict[str, dict]:
    """{driver: its stem-analysis file} of ``folder/stems/analysis`` ({} if there is none)."""
    return _analysis_files(Path(folder) / STEM_ANALYSIS, "re-run " + STEM_COMMAND.format(folder=folder))


def _analysis_files(d: Path, fix: str) -> dict[str, dict]:
    return {p.stem: read_json_dict(p, fix) for p in sorted(d.glob("*.json")) if p.name != "provenance.json"}


def _agents_of(files: dict[str, dict], method: str) -> list[dict]:
    return [f for n, f in sorted(files.items()) if n == method or n.startswith(method + "-seed")]


def stem_exit_tables(files: dict[str, dict], method: str) -> tuple[np.ndarray, np.ndarray]:
    """(left turns, completed stem crossings) per (agent, episode) of ``method``: (A, E) each."""
    agents = _agents_of(files, method)
    if not agents or len({len(f["episodes"]) for f in agents}) != 1:
        raise ValueError(
            f"the stem analysis holds no {method} agents, or agents with different episode counts"
        )
    left = np.array([[e["left"] for e in f["episodes"]] for f in agents], dtype=float)
    cross = np.array([[e["stem_crossings"] for e in f["episodes"]] for f in agents], dtype=float)
    return left, cross


@dataclass(frozen=True)
class StemCounts:
    """What one method's agents did at the stems of the T-junctions, read from a stem analysis."""

    method: str
    """The method read."""
    agents: int
    """Its agents in the analysis."""
    episodes: int
    """Their free-driving episodes, all together."""
    left: int
    """Left turns of the completed crossings from a stem."""
    crossings: int
    """Completed crossings from a stem."""
    minority: stats.Interval
    """The share of the minority exit, min(p, 1 - p) of the left share p, with its agents x episodes
    bootstrap interval (``stats.ratio_of_sums_interval``)."""
    ended_at_stem: int
    """Episodes that ended inside a crossing from a stem (in a building or off the road)."""
    agents_both: int
    """Agents that took a left and a right turn from stems (not necessarily at the same stem)."""
    agents_left_only: int
    """Agents with completed crossings from stems, every one of them a left turn."""
    valleys: tuple[int, ...]
    """The number of valleys of the energy over steering at every state read (energy agents; () for BC)."""


def stem_counts(files: dict[str, dict], method: str, seed: int = 0) -> StemCounts:
    """``StemCounts`` of ``method`` from stem-analysis files ``files`` ({driver: file}, ``stem_files``)."""
    agents = _agents_of(files, method)
    left, cross = stem_exit_tables(files, method)  # (A, E) each
    per_agent_left, per_agent_cross = left.sum(1), cross.sum(1)  # (A,) each
    return StemCounts(
        method=method,
        agents=len(agents),
        episodes=int(left.size),
        left=int(left.sum()),
        crossings=int(cross.sum()),
        minority=stats.ratio_of_sums_interval(left, cross, transform=minority, seed=seed),
        ended_at_stem=int(sum(e["ended_at_stem"] for f in agents for e in f["episodes"])),
        agents_both=int(((per_agent_left > 0) & (per_agent_cross - per_agent_left > 0)).sum()),
        agents_left_only=int(((per_agent_left == per_agent_cross) & (per_agent_cross > 0)).sum()),
        valleys=tuple(int(s["valleys"]) for f in agents for s in f["states"] if "valleys" in s),
    )


def range_differences(files: dict[str, dict], method: str = "da-ibc", key: str = RANGE_KEY) -> np.ndarray:
    """(A,) per agent of ``method``: the mean ``key`` over its stem decision states minus the mean over its
    red-light stops (agents with no state of either kind are left out)."""
    out = []
    for f in _agents_of(files, method):
        stem = [s[key] for s in f["states"] if s["kind"] == "stem" and s["window"]]
        red = [s[key] for s in f["states"] if s["kind"] == "red"]
        if stem and red:
            out.append(float(np.mean(stem)) - float(np.mean(red)))
    return np.array(out)


def first_eval_scores(folder, method: str, preset: Preset) -> np.ndarray:
    """(agents, episodes) scores of the first evaluation during training (epoch ``preset.eval_every``), from
    each
    agent's ``metrics.jsonl``; ValueError naming the file if its first entry is not that evaluation."""
    rows, starts = [], set()
    for seed in preset.seeds:
        d = run_dir(folder, method, seed)
        first = read_metrics(d)  # ValueError naming a damaged file
        if not first or first[0]["epoch"] != preset.eval_every or not first[0].get("episodes"):
            raise ValueError(
                f"{d / 'metrics.jsonl'} does not start with the evaluation of epoch {preset.eval_every} "
                "and its episodes: the run is not one of this replication's"
            )
        rows.append([float(e["score"]) for e in first[0]["episodes"]])
        starts.add(tuple(e.get("seed") for e in first[0]["episodes"]))
    if len(starts) != 1:
        raise ValueError(f"the {method} agents of {folder} have first evaluations from other starts")
    return np.array(rows)  # (A, E), episode j of every agent from the same start


# --------------------------------------------------------------------------- the verdicts
@dataclass(frozen=True)
class ClaimVerdict:
    """One claim of the paper, judged on one folder."""

    number: int
    """The claim's number (a key of ``CLAIMS``)."""
    claim: str
    """The claim in words."""
    verdict: str
    """One of ``VERDICTS``."""
    parts: tuple[stats.Judgement, ...]
    """The parts it combines, each with its interval."""
    missing: tuple[str, ...] = ()
    """Parts the folder holds no data for (each counts as "cannot tell"), e.g. no stem analysis."""


@dataclass(frozen=True)
class ClaimVerdicts:
    """The five claims judged on one replication folder (``judge_claims``)."""

    folder: Path
    """The replication folder."""
    preset: str
    """The name of the preset it was made with (from its ``results.json``)."""
    claims: dict[int, ClaimVerdict]
    """Claim number -> its verdict and parts, in the order of ``CLAIMS``."""

    @property
    def verdicts(self) -> dict[int, str]:
        """Claim number -> verdict."""
        return {k: c.verdict for k, c in self.claims.items()}

    def __getitem__(self, number: int) -> ClaimVerdict:
        return self.claims[number]


def _check_folder(folder) -> tuple[Path, dict, Preset]:
    """The folder's ``load_results``, checked to be a finished replication of the three methods."""
    if not isinstance(folder, (str, Path)):
        raise ValueError(f"folder must be a path to a replication folder, got {type(folder).__name__}")
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(
            f"folder {folder} is not a folder: expected a replication folder (ibc-tutorial replicate --out)"
        )
    loaded = load_results(folder)  # ValueError naming a missing or damaged file
    res, prov = loaded["results"], loaded["provenance"]
    try:
        preset = Preset.from_dict(res["preset"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(
            f"{folder / 'results.json'} has no valid preset ({exc}): not a replication's results"
        ) from None
    again = f"run 'ibc-tutorial replicate --preset {preset.name} --out {folder}' to finish it"
    if not (res.get("complete") and prov.get("complete")):
        raise ValueError(
            f"folder {folder} is not a finished replication (results.json or provenance.json says it is "
            f"not complete): {again}"
        )
    if not set(CLAIM_METHODS) <= set(preset.methods):
        raise ValueError(
            f"folder {folder} trained {', '.join(preset.methods)} only: the claims need "
            f"{', '.join(CLAIM_METHODS)} (an ablation folder is not judged)"
        )
    return folder, res, preset


def judge_claims(folder) -> ClaimVerdicts:
    """Judge the DA-IBC paper's sec. 4.3 claims (``CLAIMS``) on a finished replication folder.

    Reads only ``folder``: its ``results.json`` (the preset), every run's ``metrics.jsonl``,
    ``final_eval.json`` and ``heldout_eval.json``, and the stem analysis (``STEM_ANALYSIS``). Every
    interval is the default 95 % one of ``stats`` with its default resamples and seed 0, so the same
    folder always gives the same verdicts. ValueError naming the folder if it is not a finished
    replication of the three methods.
    """
    folder, res, preset = _check_folder(folder)
    evaluations = [ev for ev in EVALUATIONS if ev == "final" or preset.heldout_episodes > 0]

    expert = {ev: episode_table(folder, "expert", "distance_m", ev).values[0] for ev in evaluations}  # (E,)

    def on_each_start_set(above: str, below: str, key: str, claim: str, unit: str, delta) -> tuple:
        """``above``'s mean ``key`` (in ``unit``) against ``below``'s, one comparison per set of starts;
        ``delta(ev)``: the claim's δ on that set."""
        parts = []
        for ev in evaluations:
            a, b = episode_table(folder, above, key, ev), episode_table(folder, below, key, ev)
            if a.starts != b.starts:
                raise ValueError(f"{folder}: {above} and {below} were evaluated from other starts ({ev})")
            parts.append(judge_difference(a.values, b.values, f"{claim} ({STARTS[ev]}, {unit})", delta(ev)))
        return tuple(parts)

    claims: dict[int, ClaimVerdict] = {}

    # claim 1 (Fig. 4): BC's mean score above each energy-based method's at the first evaluation (its starts:
    # the first ones of the table's, the same for every agent); δ: a tenth of the expert's score per step
    first = {m: first_eval_scores(folder, m, preset) for m in CLAIM_METHODS}  # (A, E_eval) each
    expert_score = episode_table(folder, "expert", "score").values.mean()
    delta1 = SCORE_SHARE_DELTA * expert_score * preset.eval_steps / preset.final_steps
    parts1 = tuple(
        judge_difference(first["bc"], first[m], f"BC > {m.upper()} at the first evaluation", delta1)
        for m in ("ibc", "da-ibc")
    )
    # claim 2 (the table): DA-IBC's mean distance above IBC's, on each set of starts (the expert's distance
    # is its score: it runs no red light)
    parts2 = on_each_start_set(
        "da-ibc", "ibc", "distance_m", "DA-IBC drives farther than IBC", "m",
        lambda ev: SCORE_SHARE_DELTA * expert[ev].mean(),
    )  # fmt: skip
    # claim 3 (the table): DA-IBC's mean red lights run per episode above BC's, on each set of starts
    parts3 = on_each_start_set(
        "da-ibc", "bc", "red_light_infractions", "DA-IBC runs more red lights than BC", "per episode",
        lambda ev: RED_LIGHT_DELTA,
    )  # fmt: skip
    for k, parts in ((1, parts1), (2, parts2), (3, parts3)):
        claims[k] = ClaimVerdict(k, CLAIMS[k], combine(*(j.verdict for j in parts)), parts)

    # claims 4 and 5: the stem analysis of every agent's table episodes
    claims.update(stem_claims(stem_files(folder), folder / STEM_ANALYSIS, STEM_COMMAND.format(folder=folder)))
    return ClaimVerdicts(folder, preset.name, dict(sorted(claims.items())))


def stem_claims(files: dict[str, dict], where, make: str) -> dict[int, ClaimVerdict]:
    """Claims 4 and 5 judged on stem-analysis files (``stem_files``) read from ``where``; ``make`` is the
    command that makes them, named in what is missing."""
    claims: dict[int, ClaimVerdict] = {}
    have = {m: bool(_agents_of(files, m)) for m in ("bc", "da-ibc")}
    no_stems = f"no stem analysis of the {{}} agents in {where} ({make})"
    # claim 4 (Fig. 5): DA-IBC takes the minority exit of a stem more often than BC
    tables = {m: stem_exit_tables(files, m) for m, h in have.items() if h}  # (left, crossings), (A, E) each
    empty = [m for m, (_, c) in tables.items() if c.sum() == 0]
    if len(tables) == 2 and not empty:
        (la, ca), (lb, cb) = tables["da-ibc"], tables["bc"]
        est, reps = stats.ratio_of_sums_difference_replicates(la, ca, lb, cb, transform=minority)
        parts4 = (_judged("minority exit at a stem: DA-IBC's share - BC's", est, reps, MINORITY_DELTA),)
        claims[4] = ClaimVerdict(4, CLAIMS[4], parts4[0].verdict, parts4)
    else:
        gone = [no_stems.format(m) for m, h in have.items() if not h]
        gone += [f"no completed crossing from a stem by the {m} agents" for m in empty]
        claims[4] = ClaimVerdict(4, CLAIMS[4], stats.CANNOT_TELL, (), missing=tuple(gone))
    # claim 5 (Fig. 6): DA-IBC's low-energy steering is wider at a stem's decision than at a red stop
    diffs = range_differences(files) if have["da-ibc"] else np.zeros(0)
    if len(diffs) >= 2:
        reps = stats.bootstrap_means(diffs[:, None])  # (A, 1): the bootstrap over agents
        claim5 = "3-nat steering range: stem decision states - red stops (DA-IBC)"
        parts5 = (_judged(claim5, float(diffs.mean()), reps, RANGE_DELTA),)
        claims[5] = ClaimVerdict(5, CLAIMS[5], parts5[0].verdict, parts5)
    else:
        why = (
            no_stems.format("da-ibc") if not have["da-ibc"] else "fewer than 2 DA-IBC agents with both states"
        )
        claims[5] = ClaimVerdict(5, CLAIMS[5], stats.CANNOT_TELL, (), missing=(why,))
    return claims


def _judged(claim: str, estimate: float, replicates: np.ndarray, delta: float) -> stats.Judgement:
    """The four-verdict ``Judgement`` of "the quantity is above 0" from its bootstrap resamples."""
    interval = stats.percentile_interval(estimate, replicates, stats.LEVEL)
    eq = tost(estimate, replicates, delta)
    return stats.Judgement(claim, interval, 0.0, four_verdicts(interval, eq), eq.delta, eq.interval, eq.p)


def judge_stem_claims(analysis) -> dict[int, ClaimVerdict]:
    """Claims 4 and 5 on a stem analysis folder (``ibc-tutorial stems analyse --out OUT``: ``OUT/analysis``),
    e.g. the same agents driven again on another CPU; ValueError if it is not a folder."""
    analysis = Path(analysis)
    if not analysis.is_dir():
        raise ValueError(f"analysis must be a stem analysis folder (stems analyse --out OUT: OUT/analysis), "
                         f"got {analysis}")  # fmt: skip
    make = f"ibc-tutorial stems analyse --out {analysis.parent}"
    return stem_claims(_analysis_files(analysis, "re-run " + make), analysis, make)


# --------------------------------------------------------------------------- two folders
class Agreement(NamedTuple):
    """One claim's verdicts in two folders."""

    first: str
    """The verdict in the first folder."""
    second: str
    """The verdict in the second."""
    same: bool
    """Whether they are the same."""


def compare_verdicts(a, b) -> dict[int, Agreement]:
    """Claim number -> the verdicts in ``a`` and ``b`` and whether they agree.

    ``a``, ``b``: ``ClaimVerdicts`` or replication folders (judged with ``judge_claims``), e.g. the
    native run and the same replication re-run under an emulated older CPU.
    """
    judged = []
    for name, x in (("a", a), ("b", b)):
        if isinstance(x, (str, Path)):
            x = judge_claims(x)
        if not isinstance(x, ClaimVerdicts):
            raise ValueError(f"{name} must be ClaimVerdicts or a replication folder, got {type(x).__name__}")
        judged.append(x)
    va, vb = (j.verdicts for j in judged)
    return {k: Agreement(va[k], vb[k], va[k] == vb[k]) for k in CLAIMS}
