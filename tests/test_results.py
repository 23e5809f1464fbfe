"""experiments.agents.replication_folder: reading a replication folder (episode tables, shipped results)."""

import json
from pathlib import Path

import numpy as np
import pytest

from ibc_tutorial import stats
from ibc_tutorial.driving.analysis import exit_counts
from ibc_tutorial.experiments.agents.replication_folder import episode_table

SHIPPED = Path(__file__).resolve().parents[1] / "book" / "results" / "laptop"


# --------------------------------------------------------------------------- reading a replication folder
def write_eval(folder, method, seed, rows, name="final_eval.json"):
    d = Path(folder) / "runs" / method / ("" if seed is None else f"seed{seed}")
    d.mkdir(parents=True, exist_ok=True)
    eps = [
        {
            "seed": s,
            "steps": 3000,
            "distance_m": dist,
            "red_light_infractions": n,
            "score": dist * 0.7**n,
            "termination": "",
        }
        for s, dist, n in rows
    ]
    (d / name).write_text(json.dumps({"summary": {"episodes": len(eps)}, "episodes": eps}))


def test_episode_table_reads_every_agent_in_seed_order(tmp_path):
    write_eval(tmp_path, "bc", 10, [(1000, 100.0, 0), (1001, 200.0, 1)])
    write_eval(tmp_path, "bc", 2, [(1000, 300.0, 2), (1001, 400.0, 0)])
    t = episode_table(tmp_path, "bc")
    assert t.agents == (2, 10) and t.starts == (1000, 1001)
    assert np.allclose(t.values, [[300 * 0.49, 400], [100, 140]])
    assert episode_table(tmp_path, "bc", "red_light_infractions").values.tolist() == [[2, 0], [0, 1]]


def test_episode_table_reads_the_expert_and_the_heldout_starts(tmp_path):
    write_eval(tmp_path, "da-ibc", 0, [(1000, 100.0, 0), (1001, 200.0, 1)])
    write_eval(tmp_path, "da-ibc", 0, [(30000, 50.0, 0)], name="heldout_eval.json")
    write_eval(tmp_path, "expert", None, [(1000, 400.0, 0), (1001, 500.0, 0)])
    write_eval(tmp_path, "expert", None, [(30000, 600.0, 0)], name="heldout_eval.json")
    agents, expert = episode_table(tmp_path, "da-ibc"), episode_table(tmp_path, "expert")
    assert (
        expert.values.tolist() == [[400.0, 500.0]]
        and expert.agents == (0,)
        and expert.starts == agents.starts
    )
    r = stats.ratio_interval(agents.values, expert.values[0], n_resamples=200)
    assert r.estimate == pytest.approx((100 + 140) / 900)
    held = episode_table(tmp_path, "da-ibc", evaluation="heldout")
    assert held.values.tolist() == [[50.0]] and held.starts == (30000,)
    assert episode_table(tmp_path, "expert", evaluation="heldout").values.tolist() == [[600.0]]


def test_episode_table_refuses_other_starts_and_missing_runs(tmp_path):
    write_eval(tmp_path, "ibc", 0, [(1000, 100.0, 0), (1001, 200.0, 1)])
    write_eval(tmp_path, "ibc", 1, [(1001, 100.0, 0), (1000, 200.0, 1)])
    with pytest.raises(ValueError, match="other starts"):
        episode_table(tmp_path, "ibc")
    with pytest.raises(ValueError, match="no runs"):
        episode_table(tmp_path, "da-ibc")
    with pytest.raises(ValueError, match="no runs"):
        episode_table(tmp_path, "expert")
    with pytest.raises(ValueError, match="key"):
        episode_table(tmp_path, "ibc", "speed")
    with pytest.raises(ValueError, match="evaluation"):
        episode_table(tmp_path, "ibc", evaluation="town01")
    (tmp_path / "runs" / "ibc" / "seed0" / "final_eval.json").write_text("{not json")
    with pytest.raises(ValueError, match="damaged"):
        episode_table(tmp_path, "ibc")


shipped = pytest.mark.skipif(
    not (SHIPPED / "results.json").is_file(),
    reason="no shipped replication in book/results/laptop (remade by ibc-tutorial replicate)",
)


@shipped
def test_episode_table_reads_the_shipped_results():
    methods = sorted(p.name for p in (SHIPPED / "runs").iterdir() if p.is_dir())
    tables = {m: episode_table(SHIPPED, m) for m in methods}
    for m, t in tables.items():
        n_agents = 1 if m == "expert" else len(list((SHIPPED / "runs" / m).glob("seed*/final_eval.json")))
        assert t.values.shape[0] == n_agents >= 1 and len(t.starts) == t.values.shape[1]
        assert (t.values >= 0).all() and t.starts == tables[methods[0]].starts


def _every_second_visit_by_the_next_exit(visits):
    """``visits`` with every second visit of each approach leaving by the next exit (left -> straight ->
    right -> left): an agent that splits its visits of every approach about half and half."""
    turns = ("left", "straight", "right")
    seen: dict[int, int] = {}
    out = []
    for v in visits:
        k = seen[v["approach"]] = seen.get(v["approach"], -1) + 1
        out.append(dict(v, turn=v["turn"] if k % 2 == 0 else turns[(turns.index(v["turn"]) + 1) % 3]))
    return out


@shipped
def test_exit_test_gives_the_right_verdict_on_the_shipped_free_driving():
    """Three verdicts known beforehand, on the shipped first-seed agents' junction visits: the book's
    own test (DA-IBC 3 of 71 visits by a minority exit, BC 0 of 76, at the 15 approaches both visited
    twice or more) cannot tell; BC's visits against the same visits with every second one turned
    elsewhere (36 of 80 by a minority exit) holds, and the other way round does not hold."""
    res = json.loads((SHIPPED / "results.json").read_text())
    fd = res["free_driving"]
    a, b = ([v for e in fd[m]["episodes"] for v in e["visits"]] for m in ("da-ibc", "bc"))
    t = stats.exit_spread_test(a, b)  # chapter 09's call: p = 0.0825, above the 0.025 of a 95 % level
    assert t.approaches == 15 and t.visits == (71, 76) and t.statistic == pytest.approx(3 / 71 - 0 / 76)
    assert t.p_greater == pytest.approx(0.0825, abs=5e-5) and t.p_less == 1.0
    assert t.verdict == stats.CANNOT_TELL
    split = _every_second_visit_by_the_next_exit(b)
    assert stats.exit_spread(split) == (36, 80) and stats.exit_spread(b) == (0, 80)
    assert len(exit_counts(split)) == len(exit_counts(b)) == 16
    more = stats.exit_spread_test(split, b, n_permutations=2_000)
    assert more.statistic == pytest.approx(36 / 80) and more.p_greater < 0.001 and more.p_less == 1.0
    assert more.verdict == stats.HOLDS
    less = stats.exit_spread_test(b, split, n_permutations=2_000)
    assert less.statistic == pytest.approx(-36 / 80) and less.p_less < 0.001 and less.p_greater == 1.0
    assert less.verdict == stats.DOES_NOT_HOLD


# --------------------------------------------------------------------------- bad arguments
@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: stats.mean_interval([1.0, 2.0]), "scores"),
        (lambda: stats.mean_interval([[1.0, np.nan]]), "scores"),
        (lambda: stats.mean_interval(np.zeros((0, 3))), "scores"),
        (lambda: stats.mean_interval([["a"]]), "scores"),
        (lambda: stats.mean_interval([[1.0]], n_resamples=0), "n_resamples"),
        (lambda: stats.mean_interval([[1.0]], level=1.0), "level"),
        (lambda: stats.mean_interval([[1.0]], seed=-1), "seed"),
        (lambda: stats.difference_interval([[1.0]], [1.0]), "scores_b"),
        (lambda: stats.ratio_interval([[1.0, 2.0]], [1.0]), "expert"),
        (lambda: stats.ratio_interval([[1.0, 2.0]], [1.0, 0.0]), "expert"),
        (lambda: stats.verdict((0.0, 1.0)), "interval"),
        (lambda: stats.verdict(stats.Interval(0.5, 0.0, 1.0), float("nan")), "threshold"),
        (lambda: exit_counts([{"approach": 1, "turn": "u-turn"}]), "turn"),
        (lambda: exit_counts([{"turn": "left"}]), "visits"),
        (lambda: stats.exit_spread([], min_visits=0), "min_visits"),
        (lambda: stats.exit_spread_test([], [], n_permutations=0), "n_permutations"),
    ],
)
def test_bad_arguments_name_the_argument(call, name):
    with pytest.raises(ValueError, match=name):
        call()


def test_judge_names_a_bad_threshold():
    with pytest.raises(ValueError, match="threshold"):
        stats.judge("claim", stats.Interval(0.5, 0.0, 1.0), "high")


@pytest.mark.parametrize("n_agents, between, coverage", [(3, 200.0, 0.86), (5, 200.0, 0.90), (5, 0.0, 0.98)])
def test_coverage_of_the_mean_interval(n_agents, between, coverage):
    # the numbers in bootstrap_means' docstring (10 and 20 agents: 0.93 and 0.94, too slow to test here)
    rng = np.random.default_rng(22)
    n = 400
    hits = 0
    for k in range(n):
        x = 800 + between * rng.normal(size=(n_agents, 1)) + 300 * rng.normal(size=(n_agents, 10))
        iv = stats.mean_interval(x, n_resamples=2000, seed=k)
        hits += iv.low <= 800 <= iv.high
    assert hits / n == pytest.approx(coverage, abs=0.005)
