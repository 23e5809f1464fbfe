"""Figure helpers shared by several parts of the book: axis labels, array conversion, figures that
may draw into a given axis, and three generic figures (lines, grouped bars, learning curves)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import NullFormatter

from ibc_tutorial.utils import check_int

STEER_LABEL = "steering (−1 left … +1 right)"
"""Axis label of a steering action, in the book's convention (+1 turns right)."""
ACCEL_LABEL = "acceleration (< 0: braking)"
"""Axis label of the acceleration action of the driving problems."""
X_LABEL = "x (m, direction of travel)"
"""Axis label of the toy worlds' x coordinate."""
Y_LABEL = "y (m, left > 0)"
"""Axis label of the toy worlds' y coordinate (right-handed frame: y > 0 to the car's left)."""
TIME_LABEL = "time (s)"
"""Axis label of time."""


def as_array(x, dtype=None) -> np.ndarray:
    """``x`` (a tensor, an array or a sequence) as a NumPy array, optionally of ``dtype``."""
    if hasattr(x, "detach"):  # a torch.Tensor
        x = x.detach().cpu().numpy()
    return np.asarray(x, dtype=dtype)


def check_panels(name: str, panels) -> int:
    """The number of entries of ``panels`` (one panel each), at least 1, else ValueError naming ``name``."""
    return check_int(f"the number of entries of {name}", len(panels), minimum=1)


def figure_and_axes(ax, figsize: tuple):
    """``(fig, ax, own)``: a new figure of ``figsize`` with one axis if ``ax`` is None (``own``
    True), else ``ax`` and its figure (``own`` False: the caller's figure, left as it is)."""
    if ax is None:
        fig, ax = plt.subplots(figsize=figsize)
        return fig, ax, True
    return ax.figure, ax, False


def finish(fig, own: bool, *, title: str | None = None):
    """Tight layout for a figure the function made itself (``own``); an optional suptitle first."""
    if title is not None:
        fig.suptitle(title)
    if own:
        fig.tight_layout()
    return fig


def label_axes(ax, xlabel: str, ylabel: str, title: str, *, legend: bool = False, **legend_kwargs) -> None:
    """Set the axis labels and the title of ``ax``; with ``legend``, a legend (fontsize 8 by default)."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    if legend:
        ax.legend(**{"fontsize": 8, **legend_kwargs})


def plot_lines(
    x,
    series: dict,
    *,
    xlabel: str,
    ylabel: str,
    title: str,
    logx: bool = False,
    logy: bool = False,
    ax=None,
):
    """Several lines against one x axis (e.g. hit rate against the number of samples, one per init).

    Args:
        x: (K,) shared x values, a few settings compared, each marked with a dot; or {label: (K_label,)},
            one x axis per series, curves drawn as plain lines.
        series: {label: (K,) y values}.
    """
    check_panels("series", series)
    fig, ax, own = figure_and_axes(ax, (6.0, 3.8))
    shared = not isinstance(x, dict)
    for i, (label, v) in enumerate(series.items()):
        xs = as_array(x if shared else x[label], float)
        ax.plot(xs, as_array(v, float), marker="o" if shared else None, ms=4, color=f"C{i}", label=label)
    if logx:
        ax.set_xscale("log")
        if shared:  # label the x values themselves, not the decades
            xs = as_array(x, float)
            ax.set_xticks(xs)
            ax.set_xticklabels([f"{v:g}" for v in xs])
            ax.xaxis.set_minor_formatter(NullFormatter())
    if logy:
        ax.set_yscale("log")
    label_axes(ax, xlabel, ylabel, title, legend=True)
    return finish(fig, own)


def plot_bars(
    categories,
    series: dict,
    *,
    ylabel: str,
    title: str,
    points: dict | None = None,
    reference: dict | None = None,
    ax=None,
):
    """Grouped bars: one group per category, one bar per series (e.g. shares of situations per sampler).

    Args:
        categories: K group labels.
        series: {label: (K,) bar heights}.
        points: optional {label: (S, K) values per seed} drawn as dots on that series' bars.
        reference: optional {label: (K,) values} drawn as short black ticks over each group.
    """
    n = check_panels("series", series)
    fig, ax, own = figure_and_axes(ax, (6.4, 3.8))
    width = 0.8 / n
    x = np.arange(len(categories))
    for i, (label, values) in enumerate(series.items()):
        pos = x - 0.4 + width * (i + 0.5)
        ax.bar(pos, as_array(values, float), width=width * 0.95, color=f"C{i}", label=label)
        if points is not None and label in points:
            for row in as_array(points[label], float):
                ax.scatter(pos, row, color="k", s=10, zorder=3)
    for j, (label, values) in enumerate((reference or {}).items()):
        ax.hlines(
            as_array(values, float),
            x - 0.45,
            x + 0.45,
            colors="k",
            linestyles=["--", ":"][j % 2],
            lw=1.2,
            label=label,
        )
    ax.set_xticks(x)
    ax.set_xticklabels(categories)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=8)
    return finish(fig, own)


def plot_learning_curves(steps, curves: dict, *, ylabel: str, title: str, references: dict | None = None):
    """One colour per method: thin lines per seed, a thick line for the mean over seeds.

    Args:
        steps: (T,) steps of the evaluations.
        curves: {method: (S, T) values for S seeds}.
        references: optional {label: value} horizontal lines (e.g. the expert's own NLL).
    """
    check_panels("curves", curves)
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for i, (name, values) in enumerate(curves.items()):
        v = as_array(values, float)
        color = f"C{i}"
        for row in v:
            ax.plot(steps, row, color=color, lw=0.8, alpha=0.4)
        ax.plot(steps, v.mean(axis=0), color=color, lw=2.2, label=f"{name} (mean of {len(v)} seeds)")
    for j, (label, value) in enumerate((references or {}).items()):
        ax.axhline(value, color="k", ls=[":", "--", "-."][j % 3], lw=1, label=label)
    label_axes(ax, "training step", ylabel, title, legend=True)
    return finish(fig, True)
