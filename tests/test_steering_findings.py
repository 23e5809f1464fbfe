"""Chapter 10's findings: per-seed comparisons by Welch's interval, combined by stats.combine_verdicts."""

import numpy as np
import pytest

from ibc_tutorial import stats
from ibc_tutorial.experiments.steering.findings import above, against_all, one_above, seed_values

LABELS = {"a": "A", "b": "B", "c": "C"}
PER_SEED = {"a": [3.0, 3.1, 2.9], "b": [1.0, 1.1, 0.9], "c": [2.0, 4.0, 0.5]}


def test_above_is_welchs_comparison_with_the_values_in_its_claim():
    j = above(PER_SEED, "a", "b", LABELS)
    reference = stats.compare_few(np.array(PER_SEED["a"]), np.array(PER_SEED["b"]))
    assert j.verdict == stats.HOLDS and j.interval == reference.interval
    assert j.claim == "  A [3, 3.1, 2.9] above B [1, 1.1, 0.9]"
    assert seed_values(PER_SEED, "c") == "[2, 4, 0.5]"


def test_a_finding_holds_only_if_every_comparison_does():
    f = against_all(PER_SEED, "a", ["a", "b", "c"], LABELS, "A is highest")
    assert [j.claim.split(" above ")[1].split()[0] for j in f.comparisons] == ["B", "C"]  # itself left out
    assert f.comparisons[0].verdict == stats.HOLDS and f.comparisons[1].verdict == stats.CANNOT_TELL
    assert f.verdict == stats.CANNOT_TELL
    low = against_all(PER_SEED, "b", ["a", "b"], LABELS, "B is lowest", lower=True)
    assert low.verdict == stats.HOLDS and low.comparisons[0].claim.startswith("  A ")
    wrong = one_above(PER_SEED, "b", "a", LABELS, "B above A")
    assert wrong.verdict == stats.DOES_NOT_HOLD
    assert str(wrong).splitlines()[0] == "B above A: DOES NOT HOLD" and len(str(wrong).splitlines()) == 2


def test_bad_models_are_refused_by_name():
    with pytest.raises(ValueError, match="model must be one of"):
        above(PER_SEED, "a", "z", LABELS)
    with pytest.raises(ValueError, match="others must name at least one model"):
        against_all(PER_SEED, "a", iter(["a"]), LABELS, "alone")


def test_combine_verdicts_is_the_rule_for_parts():
    H, N, E, C = stats.HOLDS, stats.DOES_NOT_HOLD, stats.EQUIVALENT, stats.CANNOT_TELL
    assert stats.combine_verdicts(H, H) == H and stats.combine_verdicts(E, E) == E
    assert stats.combine_verdicts(H, N) == N and stats.combine_verdicts(C, N) == N
    assert stats.combine_verdicts(H, C) == C and stats.combine_verdicts(H, E) == C
    assert stats.combine_verdicts() == C
    with pytest.raises(ValueError, match="verdicts must be one of"):
        stats.combine_verdicts("maybe")
