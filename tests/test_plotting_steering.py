"""The figures of chapter 10 (plotting.steering)."""

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from ibc_tutorial.plotting.steering import plot_fig5_analogue, plot_study_metrics  # noqa: E402


def test_study_metrics_draws_one_panel_per_metric_with_labels():
    models = ["ebm", "regression"]
    metrics = {
        "crashes per km (1/km)": {"ebm": [0.0, 1.0, 2.0], "regression": [0.5, 0.5, 0.5]},
        "swerve rate": {"ebm": [0.1, 0.2, 0.3], "regression": [0.8, 0.9, 1.0]},
    }
    fig = plot_study_metrics(models, {"ebm": "EBM"}, metrics, paper={"swerve rate": {"ebm": 0.44}})
    axes = fig.axes
    assert len(axes) == 2
    assert axes[0].get_ylabel() == "crashes per km (1/km)" and axes[0].get_xlabel() == "model"
    heights = [p.get_height() for p in axes[0].patches]
    assert heights == pytest.approx([1.0, 0.5])  # the means over seeds
    assert [t.get_text() for t in axes[0].get_xticklabels()] == ["EBM", "regression"]
    assert fig._suptitle.get_text()


def test_study_metrics_refuses_empty_inputs():
    with pytest.raises(ValueError, match="metrics"):
        plot_study_metrics(["ebm"], {}, {})
    with pytest.raises(ValueError, match="models"):
        plot_study_metrics([], {}, {"w": {}})


def test_fig5_analogue_panels_images_and_lines():
    t = np.arange(5) * 0.1
    grid = np.linspace(-1, 1, 7)
    scores = {"ebm": np.random.default_rng(0).normal(size=(5, 7))}
    steer = {"ebm": np.zeros(5), "regression": np.full(5, 0.2)}
    fig = plot_fig5_analogue(t, grid, steer, scores, np.zeros(5), titles={"ebm": "EBM"}, junction_s=0.2)
    panels = [ax for ax in fig.axes if ax.get_title()]
    assert [ax.get_title() for ax in panels] == ["EBM", "regression"]
    assert len(panels[0].images) == 1 and len(panels[1].images) == 0
    assert np.allclose(panels[1].lines[0].get_ydata(), 0.2)
    assert panels[0].get_xlabel() == "time (s)"
    with pytest.raises(ValueError, match="steer"):
        plot_fig5_analogue(t, grid, {}, {}, np.zeros(5))
