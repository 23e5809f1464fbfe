"""Figures of chapter 10, the steering-EBM paper's road-following study in the town.

- ``plot_study_metrics``: one panel per metric (crashes per km, W_cmd, swerve rate), a bar per
  model for the mean over seeds, a dot per seed, and the paper's value as a black tick;
- ``plot_fig5_analogue``: the off-policy figure like the paper's Fig. 5, one panel per model
  along 5 s of an expert pass of a side road: its energy over steering (or −log of its density)
  as an image, its steering output as a line, the expert's as a dashed line.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from ibc_tutorial.plotting.common import STEER_LABEL, TIME_LABEL, as_array, check_panels


def plot_study_metrics(
    models, labels: dict, metrics: dict, *, paper: dict | None = None, title: str = "The road-following study"
):
    """Bars of the mean over seeds with a dot per seed, one panel per metric.

    Args:
        models: the M model keys, in the order of the bars.
        labels: {model: short label for the x axis}.
        metrics: {axis label (with units): {model: (S,) values per seed}}.
        paper: optional {axis label: {model: value}}, the paper's numbers drawn as black ticks.
    """
    n = check_panels("metrics", metrics)
    models = list(models)
    if not models:
        raise ValueError("models must name at least one model")
    fig, axes = plt.subplots(1, n, figsize=(4.4 * n, 3.8), squeeze=False)
    x = np.arange(len(models))
    for ax, (ylabel, values) in zip(axes[0], metrics.items()):
        means = [float(np.mean(as_array(values[m], float))) for m in models]
        ax.bar(x, means, width=0.7, color=[f"C{i}" for i in range(len(models))], alpha=0.7)
        for i, m in enumerate(models):
            v = as_array(values[m], float)  # (S,)
            ax.scatter(
                np.full(len(v), x[i]), v, color="k", s=12, zorder=3, label="one seed" if i == 0 else None
            )
        ref = (paper or {}).get(ylabel)
        if ref:
            pts = [(i, ref[m]) for i, m in enumerate(models) if ref.get(m) is not None]
            ax.hlines(
                [p[1] for p in pts],
                [p[0] - 0.4 for p in pts],
                [p[0] + 0.4 for p in pts],
                colors="k",
                linestyles="--",
                lw=1.5,
                label="the paper",
            )
        ax.set_xticks(x)
        ax.set_xticklabels([labels.get(m, m) for m in models], rotation=30, ha="right", fontsize=8)
        ax.set_xlabel("model")
        ax.set_ylabel(ylabel)
        ax.set_title(ylabel.split(" (")[0])
        ax.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_fig5_analogue(
    time_s,
    grid,
    steer: dict,
    scores: dict,
    expert,
    *,
    titles: dict | None = None,
    junction_s: float | None = None,
    title: str = "Steering along 5 s of an expert pass of a side road",
):
    """One panel per model: its scores over the steering grid against time, and its output.

    Args:
        time_s: (T,) seconds along the window.
        grid: (G,) the steering values the scores are given at.
        steer: {model: (T,) its steering output}; one panel per entry.
        scores: {model: (T, G) energy (or −log density; lower = preferred)}; models without an
            entry (the regression) get the output line only.
        expert: (T,) the expert's steering along the window.
        titles: optional {model: panel title}.
        junction_s: optional time (s) at which the expert enters the junction (a vertical line).
    """
    n = check_panels("steer", steer)
    t = as_array(time_s, float)
    g = as_array(grid, float)
    ex = as_array(expert, float)
    cols = min(3, n)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.4 * rows), squeeze=False)
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.1
    for k, (model, out) in enumerate(steer.items()):
        ax = axes[k // cols][k % cols]
        if model in scores:
            e = as_array(scores[model], float)  # (T, G)
            # per time step, the scores relative to their minimum: each column shows its own shape
            rel = e - e.min(axis=1, keepdims=True)
            im = ax.imshow(
                rel.T,
                origin="lower",
                aspect="auto",
                cmap="viridis_r",
                extent=(t[0] - dt / 2, t[-1] + dt / 2, g[0], g[-1]),
                vmin=0.0,
                vmax=max(float(np.percentile(rel, 90)), 1e-6),
            )
            fig.colorbar(im, ax=ax, label="score − its minimum")
        ax.plot(t, as_array(out, float), color="r", lw=1.5, label="model's output")
        ax.plot(t, ex, color="w" if model in scores else "k", ls="--", lw=1.2, label="expert")
        if junction_s is not None:
            ax.axvline(junction_s, color="0.5", lw=1, ls=":", label="junction entered")
        ax.set_ylim(-1.0, 1.0)
        ax.set_xlabel(TIME_LABEL)
        ax.set_ylabel(STEER_LABEL, fontsize=8)
        ax.set_title((titles or {}).get(model, model), fontsize=9)
        ax.legend(fontsize=7, loc="lower left")
    for k in range(n, rows * cols):
        axes[k // cols][k % cols].axis("off")
    fig.suptitle(title)
    fig.tight_layout()
    return fig
