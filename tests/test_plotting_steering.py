"""The figures of chapter 10 (plotting.steering)."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from ibc_tutorial.plotting.steering import Fig5Options, plot_fig5_analogue, plot_study_metrics  # noqa: E402


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
    rng = np.random.default_rng(0)
    scores = {"ebm": rng.normal(size=(5, 7)), "mdn": 50 * rng.normal(size=(5, 7))}
    steer = {"ebm": np.zeros(5), "mdn": np.zeros(5), "regression": np.full(5, 0.2)}
    bev = np.zeros((5, 32, 32), np.float32)
    options = Fig5Options(bev=bev, titles={"ebm": "EBM"}, junction_s=0.2, clip_nats=10)
    fig = plot_fig5_analogue(t, grid, steer, scores, np.zeros(5), options)
    panels = [ax for ax in fig.axes if ax.get_title()]
    assert [ax.get_title() for ax in panels] == [
        "the observation at the junction entry",
        "EBM",
        "mdn",
        "regression",
    ]
    assert len(panels[1].images) == 1 and len(panels[3].images) == 0
    # the paper's layout: steering across, time down; the regression's output on the same axes
    assert panels[1].get_xlabel().startswith("steering") and panels[1].get_ylabel() == "time (s)"
    assert np.allclose(panels[3].lines[0].get_xdata(), 0.2)
    assert panels[3].get_ylim()[0] > panels[3].get_ylim()[1]  # time runs down
    # one colour scale for every scored panel, in nats above each time step's minimum
    assert [im.get_clim() for ax in panels[1:3] for im in ax.images] == [(0.0, 10.0), (0.0, 10.0)]
    row = panels[2].images[0].get_array()[0]
    assert float(np.min(row)) == 0.0
    with pytest.raises(ValueError, match="steer"):
        plot_fig5_analogue(t, grid, {}, {}, np.zeros(5))
    with pytest.raises(ValueError, match="clip_nats"):
        plot_fig5_analogue(t, grid, steer, scores, np.zeros(5), Fig5Options(clip_nats=0))
    with pytest.raises(ValueError, match="shape"):
        plot_fig5_analogue(t, grid, steer, {"ebm": np.zeros((4, 7))}, np.zeros(5))


def test_dose_response():
    from ibc_tutorial.plotting.steering import plot_dose_response

    v = np.array([[0.0, 0.1, 0.0], [0.2, 0.3, 0.1], [0.5, 0.4, 0.6]])  # (3 shares, 3 seeds)
    fig = plot_dose_response([0.15, 0.31, 0.63], {"ebm": "EBM"}, {"side mass": {"ebm": v, "mdn": v / 2}})
    ax = fig.axes[0]
    assert ax.get_xlabel() and ax.get_ylabel() == "side mass" and fig._suptitle.get_text()
    assert len(ax.lines) == 2 and list(ax.lines[0].get_ydata()) == pytest.approx([1 / 30, 0.2, 0.5])
    plt.close(fig)
    with pytest.raises(ValueError, match="shares, seeds"):
        plot_dose_response([0.1, 0.2], {}, {"x": {"ebm": v}})
    with pytest.raises(ValueError, match="measures"):
        plot_dose_response([0.1], {}, {})
