"""Figures of chapter 10, the steering-EBM paper's road-following study in the town.

- ``plot_study_metrics``: one panel per metric (crashes per km, W_cmd, swerve rate), a bar per
  model for the mean over seeds, a dot per seed, and the paper's value as a black tick;
- ``plot_fig5_analogue``: the off-policy figure in the layout of the paper's Fig. 5 (steering
  across, time down, the observation beside), one panel per model along 5 s of an expert pass of
  a side road: its energy over steering (or −log of its density) on one shared colour scale, its
  steering output as a line, the expert's as a dashed line.
"""

from __future__ import annotations

from dataclasses import dataclass

import matplotlib.pyplot as plt
import numpy as np

from ibc_tutorial.plotting.common import STEER_LABEL, TIME_LABEL, as_array, check_panels
from ibc_tutorial.plotting.town import draw_bev


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
    for ax, (ylabel, values) in zip(axes[0], metrics.items(), strict=True):
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


@dataclass(frozen=True)
class Fig5Options:
    """What ``plot_fig5_analogue`` draws besides the models' panels."""

    bev: object = None
    """Optional (5, S, S) observation shown in a first panel (the paper's camera image)."""
    titles: dict | None = None
    """Optional {model: panel title}."""
    junction_s: float | None = None
    """Optional time (s) at which the expert enters the junction: a dotted line across every panel."""
    clip_nats: float = 30.0
    """The top of the shared colour scale (nats above the minimum); larger gaps saturate."""
    title: str = "Steering along 5 s of an expert pass of a side road"
    """The figure's title."""


def plot_fig5_analogue(time_s, grid, steer: dict, scores: dict, expert, options: Fig5Options = Fig5Options()):
    """The paper's Fig. 5 layout: one panel per model, steering across, time running down.

    Each scored model's panel is an image of its score over the steering grid (energy, or −log
    density: lower = preferred), shown as nats above that time step's minimum on ONE colour scale
    shared by every scored panel, so that a colour means the same gap in every panel. Every panel
    (the regression's too, on the same axes) draws the model's output as a line and the expert's
    as a dashed line, and a horizontal line where the expert enters the junction.

    Args:
        time_s: (T,) seconds along the window (the vertical axis, downwards).
        grid: (G,) the steering values the scores are given at (the horizontal axis).
        steer: {model: (T,) its steering output}; one panel per entry.
        scores: {model: (T, G) energy or −log density}; models without an entry get the lines only.
        expert: (T,) the expert's steering along the window.
        options: the observation panel, titles, junction line, colour scale and title (``Fig5Options``).
    """
    bev, titles, junction_s, clip_nats, title = (
        options.bev,
        options.titles,
        options.junction_s,
        options.clip_nats,
        options.title,
    )
    n = check_panels("steer", steer)
    t = as_array(time_s, float)
    g = as_array(grid, float)
    ex = as_array(expert, float)
    if not (isinstance(clip_nats, (int, float)) and clip_nats > 0):
        raise ValueError(f"clip_nats must be a positive number of nats, got {clip_nats!r}")
    missing = [m for m in scores if m not in steer]
    if missing:
        raise ValueError(f"scores has models without a steering output in steer: {missing}")
    first = 1 if bev is not None else 0
    panels = n + first
    cols = min(4, panels)
    rows = (panels + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.6 * rows), squeeze=False)
    flat = [ax for row in axes for ax in row]
    if bev is not None:
        draw_bev(flat[0], bev)
        flat[0].set_title("the observation at the junction entry", fontsize=9)
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.1
    image = None
    for k, (model, out) in enumerate(steer.items()):
        ax = flat[first + k]
        if model in scores:
            e = as_array(scores[model], float)  # (T, G)
            if e.shape != (len(t), len(g)):
                raise ValueError(f"scores[{model!r}] must have shape {(len(t), len(g))}, got {e.shape}")
            rel = e - e.min(axis=1, keepdims=True)  # (T, G) nats above each time step's minimum
            image = ax.imshow(
                rel,
                origin="upper",
                aspect="auto",
                cmap="viridis_r",
                extent=(g[0], g[-1], t[-1] + dt / 2, t[0] - dt / 2),
                vmin=0.0,
                vmax=float(clip_nats),
            )
        ax.plot(as_array(out, float), t, color="r", lw=1.5, label="model's output")
        ax.plot(ex, t, color="w" if model in scores else "k", ls="--", lw=1.2, label="expert")
        ax.axvline(0.0, color="0.6", lw=0.6)
        if junction_s is not None:
            ax.axhline(junction_s, color="0.5", lw=1, ls=":", label="junction entered")
        ax.set_xlim(-1.0, 1.0)
        ax.set_ylim(t[-1] + dt / 2, t[0] - dt / 2)
        ax.set_xlabel(STEER_LABEL, fontsize=8)
        ax.set_ylabel(TIME_LABEL)
        ax.set_title((titles or {}).get(model, model), fontsize=9)
        ax.legend(fontsize=7, loc="lower left")
    for ax in flat[first + n :]:
        ax.axis("off")
    fig.suptitle(title)
    fig.tight_layout()
    if image is not None:
        fig.colorbar(
            image,
            ax=flat,
            extend="max",
            shrink=0.8,
            label="score above its minimum at that time (nats)",
        )
    return fig


def plot_dose_response(shares, labels: dict, measures: dict, *, title: str = "The side-road share, swept"):
    """One panel per measure: its mean over seeds against the side-road share of the data, a line per model,
    a dot per seed.

    Args:
        shares: the (K,) side-road shares measured in the data, in the order of the values.
        labels: {model: legend label}.
        measures: {axis label (with units): {model: (K, S) per share, per seed}}.
    """
    n = check_panels("measures", measures)
    x = as_array(shares, float).ravel()  # (K,)
    fig, axes = plt.subplots(1, n, figsize=(4.4 * n, 3.8), squeeze=False)
    for ax, (ylabel, per_model) in zip(axes[0], measures.items(), strict=True):
        for i, (model, values) in enumerate(per_model.items()):
            v = as_array(values, float)  # (K, S)
            if v.ndim != 2 or len(v) != len(x):
                raise ValueError(f"measures[{ylabel!r}][{model!r}] must be (shares, seeds), got {v.shape}")
            ax.plot(x, v.mean(axis=1), "o-", color=f"C{i}", label=labels.get(model, model))
            for k in range(v.shape[1]):
                ax.scatter(x, v[:, k], color=f"C{i}", s=10, alpha=0.5)
        ax.set_xlabel("side-road share of the passes in the data")
        ax.set_ylabel(ylabel)
        ax.set_title(ylabel.split(" (")[0])
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    return fig
