"""experiments.family_tree, family_cost and family_study (``ibc-tutorial families``) at a tiny size."""

import json

import pytest
import torch

from ibc_tutorial.cli import main
from ibc_tutorial.experiments import family_comparison as fc
from ibc_tutorial.experiments import family_cost, family_study, family_tree

TINY = fc.FamilyConfig(
    n_train=200, n_junctions=4, width=8, samples=20, grid_n=11, train=fc.train_config(steps=3, progress=False)
)
TINY_TREE = family_tree.TreeStudyConfig(families=TINY, episodes=10, heldout_episodes=10, drive_episodes=5)
TINY_COST = family_cost.CostConfig(
    batch=4, repeats=2, warmup=0, flow_steps=(1, 2), dfo_samples=8, dfo_iters=1
)


def tiny_settings(**changes):
    base = dict(
        tune_seeds=(0,),
        report_seeds=(1,),
        flow_train_steps=(3, 6),
        flow_steps=(1, 2),
        rnce_settings=((0.1, 3), (0.05, 3)),
        families=TINY,
        tree=TINY_TREE,
        cost=TINY_COST,
    )
    return family_study.FamiliesSettings(**{**base, **changes})


def test_the_decision_points_are_where_the_experts_split():
    world = family_tree.tree_world()
    obs, modes, truth = family_tree.decision_points(world, family_tree.TreeStudyConfig())
    assert obs.shape[1] == 2 and modes.shape == (len(obs), 2, 1)
    assert modes[0, 0, 0] > 0.8 and modes[0, 1, 0] < -0.8  # passing right (+), passing left (-)
    assert (truth - 0.5).abs().max() < 0.1 and truth.sum() > 0.95  # half each, nearly all near its mode
    assert obs[:, 1].abs().max() < 0.3  # the previous steering is still near 0


def test_every_family_runs_at_the_tree_at_a_tiny_size():
    for family in fc.FAMILIES:
        r = family_tree.run_tree(family, 0, TINY_TREE)
        assert len(r.masses) == 2 and 0 <= r.bc <= 1 + 1e-6
        assert r.collided + r.right + r.left == pytest.approx(1.0)


def test_the_regression_averages_at_the_tree():
    # one action per observation: at the decision points it is near neither mode
    masses = fc.masses_near(
        "mae",
        fc.make_policy("mae", family_tree.tree_world(), TINY, 0),
        torch.zeros(3, 2),
        torch.tensor([[[0.95], [-0.95]]]).expand(3, 2, 1),
        TINY,
        0,
    )
    assert masses.shape == (3, 2) and (masses.sum(1) <= 1).all()


def test_the_cost_counts_every_way_of_acting():
    rows = family_cost.decision_cost(TINY, TINY_COST)
    assert rows["mae"]["head"] == 1 and rows["energy, grid"]["head"] == 11**2
    assert rows["energy, DFO"]["head"] == 8 and rows["flow, K=2"]["head"] == 2
    assert all(r["cpu_us"] > 0 and r["evaluations_ratio"] >= 1 for r in rows.values())


def test_the_study_runs_resumes_and_refuses_other_settings(tmp_path, capsys):
    out = tmp_path / "families"
    results = family_study.run_study(out, tiny_settings(), command="test", note="a test")
    assert set(results["chosen"]) == {"flow", "da-ibc r-nce"}
    assert len(results["tuning"]) == 2 * 2 + 2  # flow: steps x K; R-NCE: two settings
    for world in ("junction", "tree"):
        assert set(results[world]) == set(fc.FAMILIES) and results[world]["flow"]["seeds"] == [1]
    assert set(results["junction"]["flow"]["by_k"]) == {"1", "2"}
    assert set(results["tree"]["ibc"]["loop"]) == {"collided", "right", "left"}
    assert "mae" in results["cost"] and "a test" in (out / "PROVENANCE.md").read_text()
    again = family_study.run_study(out, tiny_settings(), command="test")  # nothing left to do
    assert again["junction"] == results["junction"]
    assert family_study.load(out)["results"]["report_seeds"] == [1]
    with pytest.raises(ValueError, match="other settings"):
        family_study.run_study(out, tiny_settings(report_seeds=(2,)))


def test_the_choice_goes_to_the_smallest_error_then_the_cheaper(tmp_path):
    settings = tiny_settings()
    for run in family_study.tuning_runs(settings):
        d = family_study.FOLDER.run_dir(tmp_path, run)
        d.mkdir(parents=True)
        good = [1 / 3] * 3
        masses = good if run.method in ("flow-steps6", "rnce-sigma0.05-steps3") else [0.9, 0.05, 0.05]
        by_k = {"1": {"masses": [0.9, 0.05, 0.05]}, "2": {"masses": masses}}
        (d / family_study.RUN_FILE).write_text(json.dumps({"masses": masses, "by_k": by_k}))
    chosen, table = family_study.choose(tmp_path, settings)
    assert chosen == {"flow": {"train_steps": 6, "K": 2}, "da-ibc r-nce": {"sigma": 0.05, "train_steps": 3}}
    assert table["flow, 6 steps, K=2"] == pytest.approx(0.0, abs=1e-6)


def test_bad_settings_name_the_field():
    with pytest.raises(ValueError, match="report_seeds"):
        tiny_settings(report_seeds=(0,))
    with pytest.raises(ValueError, match="flow_steps"):
        tiny_settings(flow_steps=(0,))
    with pytest.raises(ValueError, match="decision_distance"):
        family_tree.TreeStudyConfig(decision_distance=0)


def test_the_command_line_checks_its_seeds(tmp_path, capsys):
    assert main(["families", "--out", str(tmp_path / "f"), "--seeds", "a,b"]) == 2
    assert "--seeds" in capsys.readouterr().err


def test_the_figures_of_chapter_13_draw_from_a_tiny_study(tmp_path):
    import matplotlib.pyplot as plt

    from ibc_tutorial.plotting import families as figs

    res = family_study.run_study(tmp_path / "families", tiny_settings(), command="test")
    town = {
        "study": {
            "methods": {
                "bc": {"minority": [0.01, 0.0, 0.05], "network_evaluations_per_decision": {"head": 1}},
                "flow": {"minority": [0.33, 0.2, 0.48], "network_evaluations_per_decision": {"head": 64}},
            }
        }
    }
    for fig in (figs.plot_coverage_cost(res, town), figs.plot_coverage_cost(res), figs.plot_tree_loop(res)):
        assert fig.axes
    assert figs.plot_flow_steps(res).axes
    plt.close("all")


def test_the_live_example_trains_and_samples_at_a_tiny_size():
    from ibc_tutorial.experiments import flow_toy

    data = flow_toy.two_gaussians(100, torch.Generator().manual_seed(0))
    assert data["obs"].shape == (100, 1) and (data["actions"].abs() <= 1).all()
    assert (data["actions"] > 0).any() and (data["actions"] < 0).any()  # both answers
    policy = flow_toy.train_flow(0, n=100, steps=5, width=8)
    samples = flow_toy.samples_by_k(policy, (1, 3), n=7)
    assert set(samples) == {1, 3} and samples[3].shape == (7,)
    with pytest.raises(ValueError, match="centre"):
        flow_toy.two_gaussians(10, torch.Generator(), centre=0)
