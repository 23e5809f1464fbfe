"""Two runs of one replication compared (chapter 09's re-run under the older CPU's kernels)."""

from pathlib import Path

import numpy as np

from ibc_tutorial import stats
from ibc_tutorial.experiments.agents.claims import compare_verdicts, judge_claims, stem_counts, stem_files
from ibc_tutorial.experiments.agents.replication_folder import episode_table, load_results
from ibc_tutorial.experiments.agents.rerun_comparison import (
    expert_shares,
    format_agreement,
    format_expert_shares,
    format_stem_counts,
    format_visit_count_tests,
    stem_counts_by_run,
    visit_count_tests,
)

RESULTS = Path(__file__).resolve().parents[1] / "book" / "results"
NATIVE, EMULATED = RESULTS / "ten-routes", RESULTS / "ten-routes-emulated"


def test_expert_shares_are_each_runs_ratio_over_the_second_runs_expert():
    shares = expert_shares(NATIVE, EMULATED, ("bc", "da-ibc"), "heldout")
    expert = episode_table(EMULATED, "expert", "score", "heldout").values[0]
    for folder, got in ((NATIVE, shares.first), (EMULATED, shares.second)):
        want = stats.ratio_interval(episode_table(folder, "da-ibc", "score", "heldout").values, expert)
        assert got["da-ibc"] == want
    assert list(shares.first) == ["bc", "da-ibc"] and shares.same_expert  # the expert uses no torch
    text = format_expert_shares(shares, "held-out starts").splitlines()
    assert text[0] == "share of the expert's mean score, held-out starts:"
    assert text[2].startswith("  bc ") and str(shares.second["bc"]) in text[2]
    assert text[-1] == "  the expert's episodes are the same in both runs"


def test_a_folder_against_itself_has_the_same_shares():
    shares = expert_shares(NATIVE, NATIVE, ("ibc",))
    assert shares.first == shares.second and shares.same_expert


def test_visit_count_tests_pool_every_agents_visits_per_method():
    tests = visit_count_tests({"native": NATIVE, "emulated": EMULATED})
    assert list(tests) == ["native", "emulated"]
    free = load_results(EMULATED)["results"]["free_driving"]
    visits = {m: [x for e in free[m]["episodes"] for x in e["visits"]] for m in ("bc", "da-ibc")}
    want = stats.exit_spread_test(visits["da-ibc"], visits["bc"])
    assert tests["emulated"].verdict == want.verdict and np.isclose(
        tests["emulated"].p_greater, want.p_greater
    )
    swapped = visit_count_tests({"native": NATIVE}, a="bc", b="da-ibc")["native"]
    assert swapped.p_greater != tests["native"].p_greater  # the order of the methods matters


def test_format_visit_count_tests_one_line_per_run():
    tests = visit_count_tests({"native": NATIVE, "emulated": EMULATED})
    lines = format_visit_count_tests(tests).splitlines()
    assert len(lines) == 2 and lines[1].startswith("the visit-count test, emulated: ")
    assert f"p = {tests['native'].p_greater:.4f}" in lines[0]


def test_format_agreement_details_claim_3_and_says_why_a_claim_was_not_judged():
    first, second = judge_claims(NATIVE), judge_claims(EMULATED)
    lines = format_agreement(compare_verdicts(first, second), first, second).splitlines()
    heads = [line for line in lines if not line.startswith("     ")]
    assert [h.split(".")[0] for h in heads] == ["1", "2", "3", "4", "5"]
    missing = [k for k in range(1, 6) if second[k].missing]
    assert all("not judged on the re-run" in heads[k - 1] for k in missing)
    parts = len(first.claims[3].parts) + len(second.claims[3].parts)
    assert len(lines) == 5 + parts  # only claim 3 detailed: the judged verdicts agree
    none = format_agreement(compare_verdicts(first, second), first, second, detail=())
    assert len(none.splitlines()) == 5


def test_stem_counts_by_run_and_its_table_on_the_shipped_stems():
    files = stem_files(RESULTS / "laptop")
    counts = stem_counts_by_run({"native": files, "again": files}, ("bc", "da-ibc"))
    assert counts["da-ibc"]["native"] == stem_counts(files, "da-ibc") == counts["da-ibc"]["again"]
    lines = format_stem_counts(counts).splitlines()
    assert lines[0] == "" and len(lines) == 3 + 2 and lines[2].split() == ["native", "again"] * 3
    bc = counts["bc"]["native"]
    assert lines[3].split()[0] == "bc" and f"{bc.left}/{bc.crossings}" in lines[3]
