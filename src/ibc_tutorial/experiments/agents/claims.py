"""The DA-IBC paper's five claims (its sec. 4.3) and their verdicts on one replication folder (chapter 09).

The paper's results section makes five claims about its BC, IBC and DA-IBC agents trained in
town01 and driven in the unseen town02 (``CLAIMS``). ``judge_claims(folder)`` judges each on a
finished replication folder (``ibc-tutorial replicate --out FOLDER``), reading nothing but the
folder, with the rule of ``ibc_tutorial.stats``: a claim is "holds" if the 95 % interval of the
quantity it is about lies on its side of the threshold, "does not hold" if it lies on the other,
"cannot tell at this scale" if it contains the threshold; a claim of several parts holds only if
every part does (``combine``).

- claims 1-3 compare two methods by the two-level (agents, episodes) bootstrap interval of the
  difference of their means (``stats.compare``): claim 1 at the first evaluation during training
  (``metrics.jsonl``), claims 2 and 3 on the table's starts and on the held-out starts;
- claim 4 is the free-driving exit test (``stats.exit_spread_test``, the Fig. 5 analogue);
- claim 5 reads the ten DFO draws at the two moments of DA-IBC's energy landscapes (the Fig. 6
  analogue): spread in steering at a junction, braking at a red light. Those intervals are over
  the draws at one moment of one agent: they test that landscape, not the method.

``compare_verdicts(a, b)`` says which claims get the same verdict in two folders (chapter 09: are
the verdicts the same when the whole replication runs again on another CPU?).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ibc_tutorial import stats
from ibc_tutorial.experiments.agents.layout import EVALUATIONS, run_dir
from ibc_tutorial.experiments.agents.presets import Preset
from ibc_tutorial.experiments.agents.results import episode_table, load_results
from ibc_tutorial.experiments.agents.run_folder import read_metrics
from ibc_tutorial.utils import check_int

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
FREE_METHODS = ("bc", "da-ibc")
"""The agents that drove freely (claim 4)."""
STEER_SPREAD = 0.1
"""Claim 5, junction: "spread along the steering axis" read as a standard deviation of the DFO draws' steering
above this."""


# --------------------------------------------------------------------------- the pieces
def combine(*verdicts: str) -> str:
    """A claim made of several parts holds if every part does, does not hold if one part does not, else cannot
    tell."""
    for v in verdicts:
        if v not in (stats.HOLDS, stats.DOES_NOT_HOLD, stats.CANNOT_TELL):
            raise ValueError(
                f"verdicts must be {stats.HOLDS!r}, {stats.DOES_NOT_HOLD!r} or {stats.CANNOT_TELL!r}, "
                f"got {v!r}"
            )
    if verdicts and all(v == stats.HOLDS for v in verdicts):
        return stats.HOLDS
    return stats.DOES_NOT_HOLD if stats.DOES_NOT_HOLD in verdicts else stats.CANNOT_TELL


def spread_interval(x, seed: int = 0, n_resamples: int = stats.DEFAULT_RESAMPLES) -> stats.Interval:
    """The (population) standard deviation of the 1-D ``x`` with a 95 % percentile bootstrap interval over its
    entries."""
    x = np.asarray(x, dtype=float)
    if x.ndim != 1 or len(x) < 2 or not np.isfinite(x).all():
        raise ValueError(f"x must be a finite 1-D array of at least 2 values, got shape {x.shape}")
    n_resamples = check_int("n_resamples", n_resamples, minimum=1)
    draws = np.random.default_rng(check_int("seed", seed, minimum=0)).integers(
        len(x), size=(n_resamples, len(x))
    )
    reps = x[draws].std(1)  # (R,)
    lo, hi = np.percentile(reps, [2.5, 97.5])
    return stats.Interval(float(x.std()), float(lo), float(hi), stats.LEVEL, n_resamples)


def first_eval_scores(folder, method: str, preset: Preset) -> np.ndarray:
    """(agents, episodes) scores of the first evaluation during training (epoch ``preset.eval_every``), from
    each
    agent's ``metrics.jsonl``; ValueError naming the file if its first entry is not that evaluation."""
    rows = []
    for seed in preset.seeds:
        d = run_dir(folder, method, seed)
        first = read_metrics(d)  # ValueError naming a damaged file
        if not first or first[0]["epoch"] != preset.eval_every or not first[0].get("episodes"):
            raise ValueError(
                f"{d / 'metrics.jsonl'} does not start with the evaluation of epoch {preset.eval_every} "
                "and its episodes: the run is not one of this replication's"
            )
        rows.append([float(e["score"]) for e in first[0]["episodes"]])
    if len({len(r) for r in rows}) != 1:
        raise ValueError(f"the {method} agents of {folder} have first evaluations of different lengths")
    return np.array(rows)  # (A, E)


# --------------------------------------------------------------------------- the verdicts
@dataclass(frozen=True)
class ClaimVerdict:
    """One claim of the paper, judged on one folder."""

    number: int
    """The claim's number (a key of ``CLAIMS``)."""
    claim: str
    """The claim in words."""
    verdict: str
    """``stats.HOLDS``, ``stats.DOES_NOT_HOLD`` or ``stats.CANNOT_TELL``."""
    parts: tuple[stats.Judgement, ...]
    """The parts it combines, each with its interval (claim 4: none, its test is ``exit_test``)."""
    exit_test: stats.ExitTest | None = None
    """Claim 4's free-driving exit test, DA-IBC against BC (None for the other claims)."""
    missing: tuple[str, ...] = ()
    """Parts the folder holds no data for (each counts as "cannot tell"), e.g. a landscape moment not
    found."""


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

    @property
    def exit_test(self) -> stats.ExitTest:
        """Claim 4's exit test."""
        return self.claims[4].exit_test

    def __getitem__(self, number: int) -> ClaimVerdict:
        return self.claims[number]


def _check_folder(folder) -> tuple[Path, dict, dict, Preset]:
    """The folder's ``load_results``, checked to be a finished replication of the three methods with its
    figures."""
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
    fd = res.get("free_driving")
    if (
        not isinstance(fd, dict)
        or not all(m in fd for m in FREE_METHODS)
        or not isinstance(res.get("landscapes"), dict)
    ):
        raise ValueError(
            f"folder {folder} has no free driving or energy landscapes in its results.json "
            f"(claims 4 and 5 need them): {again}"
        )
    return folder, res, loaded["landscapes"], preset


def judge_claims(folder) -> ClaimVerdicts:
    """Judge the DA-IBC paper's sec. 4.3 claims (``CLAIMS``) on a finished replication folder.

    Reads only ``folder``: its ``results.json`` (the preset, the free driving, the landscapes'
    moments), ``landscapes.npz`` and every run's ``metrics.jsonl``, ``final_eval.json`` and
    ``heldout_eval.json``. Every interval is the default 95 % one of ``stats`` with its default
    resamples and seed 0, so the same folder always gives the same verdicts. ValueError naming the
    folder if it is not a finished replication of the three methods with its Fig. 5/6 analogues.
    """
    folder, res, ls, preset = _check_folder(folder)
    evaluations = [ev for ev in EVALUATIONS if ev == "final" or preset.heldout_episodes > 0]

    def on_each_start_set(above: str, below: str, key: str, claim: str, unit: str) -> tuple:
        """``above``'s mean ``key`` (in ``unit``) against ``below``'s, one comparison per set of starts."""
        return tuple(
            stats.compare(  # (agents, episodes) values of each method
                episode_table(folder, above, key, ev).values,
                episode_table(folder, below, key, ev).values,
                f"{claim} ({STARTS[ev]}, {unit})",
            )
            for ev in evaluations
        )

    claims: dict[int, ClaimVerdict] = {}

    # claim 1 (Fig. 4): BC's mean score above each energy-based method's at the first evaluation
    first = {m: first_eval_scores(folder, m, preset) for m in CLAIM_METHODS}  # (A, E_eval) each
    parts1 = tuple(
        stats.compare(first["bc"], first[m], f"BC > {m.upper()} at the first evaluation")
        for m in ("ibc", "da-ibc")
    )
    # claim 2 (the table): DA-IBC's mean distance above IBC's, on each set of starts
    parts2 = on_each_start_set("da-ibc", "ibc", "distance_m", "DA-IBC drives farther than IBC", "m")
    # claim 3 (the table): DA-IBC's mean red lights run per episode above BC's, on each set of starts
    parts3 = on_each_start_set(
        "da-ibc", "bc", "red_light_infractions", "DA-IBC runs more red lights than BC", "per episode"
    )
    for k, parts in ((1, parts1), (2, parts2), (3, parts3)):
        claims[k] = ClaimVerdict(k, CLAIMS[k], combine(*(j.verdict for j in parts)), parts)

    # claim 4 (Fig. 5): DA-IBC leaves the same approach by different exits more than BC, beyond chance
    visits = {m: [v for e in res["free_driving"][m]["episodes"] for v in e["visits"]] for m in FREE_METHODS}
    test = stats.exit_spread_test(visits["da-ibc"], visits["bc"])
    claims[4] = ClaimVerdict(4, CLAIMS[4], test.verdict, (), exit_test=test)

    # claim 5 (Fig. 6): at the junction moment the DFO draws spread in steering; at the red light they brake
    parts5, missing = [], []
    if res["landscapes"].get("junction") and "junction_points" in ls:
        junc = np.asarray(ls["junction_points"], dtype=float)  # (n_inferences, 2): (steer, acceleration)
        parts5.append(
            stats.judge(
                f"junction: steering std of DFO's draws above {STEER_SPREAD:g}",
                spread_interval(junc[:, 0]),
                STEER_SPREAD,
            )
        )
    else:
        missing.append("no junction moment in the free driving")
    if res["landscapes"].get("red_light") and "red_light_points" in ls:
        red = np.asarray(ls["red_light_points"], dtype=float)  # (n_inferences, 2)
        parts5.append(
            stats.judge(
                "red light: DFO's draws brake (minus mean acceleration above 0)",
                stats.mean_interval(-red[None, :, 1]),
                0.0,
            )
        )  # (1, n_inferences): one "agent"
    else:
        missing.append("no red-light moment in the free driving")
    v5 = combine(*(j.verdict for j in parts5), *(stats.CANNOT_TELL for _ in missing))
    claims[5] = ClaimVerdict(5, CLAIMS[5], v5, tuple(parts5), missing=tuple(missing))
    return ClaimVerdicts(folder, preset.name, dict(sorted(claims.items())))


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
