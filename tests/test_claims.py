"""The paper's claims judged on a replication folder (``experiments.agents.claims``), on the tiny preset."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from ibc_tutorial import cli, stats
from ibc_tutorial.experiments.agents.claims import (
    CLAIMS,
    ClaimVerdicts,
    combine,
    compare_verdicts,
    first_eval_scores,
    judge_claims,
    spread_interval,
)
from ibc_tutorial.experiments.agents.presets import TINY
from ibc_tutorial.experiments.agents.results import episode_table

SHIPPED = Path(__file__).resolve().parents[1] / "book" / "results" / "laptop"
VERDICTS = {stats.HOLDS, stats.DOES_NOT_HOLD, stats.CANNOT_TELL}


@pytest.fixture(scope="module")
def replicated(tmp_path_factory):
    out = tmp_path_factory.mktemp("claims") / "rep"
    assert cli.main(["replicate", "--preset", "tiny", "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def judged(replicated):
    return judge_claims(replicated)


def test_every_claim_gets_a_verdict(judged, replicated):
    assert isinstance(judged, ClaimVerdicts) and judged.folder == replicated and judged.preset == "tiny"
    assert list(judged.claims) == [1, 2, 3, 4, 5] == list(CLAIMS)
    for k, c in judged.claims.items():
        assert c.number == k and c.claim == CLAIMS[k] and c.verdict in VERDICTS
        assert all(isinstance(j, stats.Judgement) and j.verdict in VERDICTS for j in c.parts)
    assert [len(judged[k].parts) for k in (1, 2, 3)] == [
        2,
        2,
        2,
    ]  # tiny has held-out starts: both sets judged
    assert judged[4].parts == () and isinstance(judged.exit_test, stats.ExitTest)
    assert judged[4].verdict == judged.exit_test.verdict
    assert len(judged[5].parts) + len(judged[5].missing) == 2
    for k in (1, 2, 3):  # a claim of two parts: combined by the rule
        assert judged[k].verdict == combine(*(j.verdict for j in judged[k].parts))


def test_the_parts_are_computed_from_the_folder(judged, replicated):
    da = episode_table(replicated, "da-ibc", "red_light_infractions", "heldout").values  # (1, 1)
    bc = episode_table(replicated, "bc", "red_light_infractions", "heldout").values
    by_hand = stats.compare(da, bc, "DA-IBC runs more red lights than BC (held-out starts, per episode)")
    assert judged[3].parts[1] == by_hand
    first = first_eval_scores(replicated, "bc", TINY)  # (agents, eval_episodes)
    assert first.shape == (len(TINY.seeds), TINY.eval_episodes)
    line = json.loads((replicated / "runs" / "bc" / "seed0" / "metrics.jsonl").read_text().splitlines()[0])
    assert first[0].tolist() == [e["score"] for e in line["episodes"]]
    assert judged[1].parts[0].interval.estimate == pytest.approx(
        first.mean() - first_eval_scores(replicated, "ibc", TINY).mean()
    )


def test_a_folder_agrees_with_itself(judged, replicated):
    same = compare_verdicts(judged, replicated)  # a folder is judged as its ClaimVerdicts
    assert set(same) == set(CLAIMS) and all(a.same and a.first == a.second for a in same.values())


def test_bad_folders_are_refused(replicated, tmp_path):
    with pytest.raises(ValueError, match="not a folder"):
        judge_claims(tmp_path / "nowhere")
    with pytest.raises(ValueError, match="no results.json"):
        judge_claims(tmp_path)
    unfinished = tmp_path / "unfinished"
    shutil.copytree(replicated, unfinished)
    res = json.loads((unfinished / "results.json").read_text())
    (unfinished / "results.json").write_text(json.dumps(dict(res, complete=False)))
    with pytest.raises(ValueError, match=f"{unfinished}.*not a finished replication"):
        judge_claims(unfinished)
    (unfinished / "results.json").write_text(
        json.dumps({k: v for k, v in res.items() if k != "free_driving"})
    )
    with pytest.raises(ValueError, match="no free driving"):
        judge_claims(unfinished)
    with pytest.raises(ValueError, match="folder must be a path"):
        judge_claims(3)
    with pytest.raises(ValueError, match="b must be ClaimVerdicts"):
        compare_verdicts(judge_claims(replicated), {1: stats.HOLDS})


def test_the_rule_and_the_spread():
    assert combine(stats.HOLDS, stats.HOLDS) == stats.HOLDS
    assert combine(stats.HOLDS, stats.CANNOT_TELL) == stats.CANNOT_TELL
    assert combine(stats.CANNOT_TELL, stats.DOES_NOT_HOLD) == stats.DOES_NOT_HOLD
    with pytest.raises(ValueError, match="verdicts must be"):
        combine("maybe")
    x = np.array([-0.5, 0.5] * 5)  # std 0.5, every resample between 0 and 0.5
    s = spread_interval(x)
    assert s.estimate == pytest.approx(0.5) and 0.0 <= s.low <= s.high <= 0.5
    with pytest.raises(ValueError, match="1-D array"):
        spread_interval([1.0])


def test_the_shipped_replication_is_judged():
    if not (SHIPPED / "results.json").exists():
        pytest.skip("no shipped results")
    judged = judge_claims(SHIPPED)
    assert judged.preset == "laptop" and set(judged.verdicts) == set(CLAIMS)
    assert set(judged.verdicts.values()) <= VERDICTS and not judged[5].missing
