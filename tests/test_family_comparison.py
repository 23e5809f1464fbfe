"""experiments.family_comparison: every family trains and is measured (at a tiny size); the measures."""

import pytest
import torch

from ibc_tutorial.experiments import family_comparison as fc
from ibc_tutorial.toy.junction import JunctionWorld


def test_every_family_runs_and_reports_masses_at_a_tiny_size():
    config = fc.FamilyConfig(
        n_train=200,
        n_junctions=4,
        width=8,
        samples=20,
        grid_n=11,
        train=fc.train_config(steps=3, progress=False),
    )
    runs = fc.compare(fc.FAMILIES, seeds=(0,), config=config, workers=1)
    assert [r.family for r in runs] == list(fc.FAMILIES)
    for r in runs:
        assert len(r.masses) == 3 and all(0 <= m <= 1 for m in r.masses) and 0 <= r.bc <= 1
    summary = fc.summarize(runs)
    assert set(summary) == set(fc.FAMILIES) and summary["flow"]["seeds"] == 1


def test_the_truth_and_the_bhattacharyya_coefficient():
    truth = fc.true_mode_masses(JunctionWorld(), 0.15)
    assert torch.allclose(truth, torch.full((3,), 1 / 3), atol=1e-6)  # sharp modes: all the mass near them
    assert fc.bhattacharyya(truth, truth) == pytest.approx(1.0)
    assert fc.bhattacharyya(torch.tensor([1.0, 0.0, 0.0]), truth) == pytest.approx(3**-0.5, abs=1e-6)


def test_junction_observations_are_junctions():
    obs = fc.junction_observations(JunctionWorld(), fc.FamilyConfig(n_junctions=10))
    assert obs.shape == (10, 4) and (obs[:, 1] == 1).all()


def test_bad_inputs_name_the_argument():
    with pytest.raises(ValueError, match="family"):
        fc.make_policy("diffusion", JunctionWorld(), fc.FamilyConfig(), 0)
    with pytest.raises(ValueError, match="families"):
        fc.compare(("mae", "gan"), seeds=(0,))
    with pytest.raises(ValueError, match="config.samples"):
        fc.FamilyConfig(samples=0)
    with pytest.raises(ValueError, match="masses"):
        fc.bhattacharyya(torch.ones(4), torch.ones(3))
