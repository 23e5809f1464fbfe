"""Figures of chapter 09: the replication's free driving (one episode per map) and each method's share of the
expert's score start by start, with its intervals with and without the starts as a level of the bootstrap."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from ibc_tutorial.plotting.agents import METHOD_COLORS, METHOD_LABELS
from ibc_tutorial.plotting.common import as_array, check_panels, label_axes
from ibc_tutorial.plotting.town import plot_town
from ibc_tutorial.utils import check_positive

METHOD_MARKERS = {"bc": "o", "ibc": "s", "da-ibc": "^"}
"""Marker of each method where several share one axis (besides its colour)."""


def plot_free_driving(
    town,
    trajectories: dict,
    *,
    panel_titles: dict | None = None,
    titles: dict | None = None,
    suptitle: str = "Free driving in town02",
    columns: int = 5,
):
    """Small multiples: for each entry of ``trajectories`` ({name: [xy (T, 2), ...]}) a block of small maps,
    one episode per map, in rows of ``columns``, its path in the method's colour (dot: start, cross: end).

    ``titles``: {name: the block's title}; ``panel_titles``: {name: [one title per episode]} (default
    "episode k"). One path per map: ten episodes on one map cannot be told apart at a column's width."""
    n = check_panels("trajectories", trajectories)
    columns = int(check_positive("columns", columns))
    rows = {name: -(-len(tracks) // columns) for name, tracks in trajectories.items()}  # ceil
    if min(len(t) for t in trajectories.values()) == 0:
        raise ValueError("trajectories must hold at least one episode per entry")
    fig = plt.figure(
        figsize=(2.1 * columns, 2.25 * sum(rows.values()) + 0.55 * n + 0.4), layout="constrained"
    )
    blocks = fig.subfigures(n, 1, height_ratios=[r + 0.3 for r in rows.values()], squeeze=False)[:, 0]
    for block, (name, tracks) in zip(blocks, trajectories.items(), strict=True):
        axes = block.subplots(rows[name], columns, squeeze=False)
        color = METHOD_COLORS.get(name, "C1")
        names = (panel_titles or {}).get(name) or [f"episode {k}" for k in range(len(tracks))]
        for k, ax in enumerate(axes.ravel()):
            if k >= len(tracks):
                ax.set_visible(False)
                continue
            plot_town(town, ax=ax, title=names[k], markers=False)
            xy = as_array(tracks[k])  # (T, 2)
            ax.plot(xy[:, 0], xy[:, 1], color=color, lw=1.6)
            ax.plot(xy[0, 0], xy[0, 1], "o", color=color, ms=6, mec="k")
            ax.plot(xy[-1, 0], xy[-1, 1], "X", color="w", ms=7, mec="k")
            ax.title.set_fontsize(8)
            ax.tick_params(labelsize=6)
            ax.set_xlabel("x (m, east)" if k // columns == rows[name] - 1 else "", fontsize=7)
            ax.set_ylabel("y (m, north)" if k % columns == 0 else "", fontsize=7)
        block.suptitle((titles or {}).get(name, METHOD_LABELS.get(name, name)), fontsize=10)
    fig.suptitle(suptitle + " (one episode per map; dot: start, cross: end)")
    return fig


def plot_share_by_start(shares: dict, starts, intervals: dict, *, title: str):
    """Left: each method's mean over its agents as a share of the expert's score at each start ({method: (E,)}
    over ``starts`` (E,), the environment seeds); right: each method's share over all starts with the
    intervals of ``intervals`` ({method: {label: stats.Interval}}, e.g. agents only, agents and starts)."""
    n = check_panels("shares", shares)
    starts = [str(s) for s in starts]
    fig, (ax, ax_i) = plt.subplots(1, 2, figsize=(10.0, 4.2), gridspec_kw={"width_ratios": [1.6, 1]})
    x = np.arange(len(starts))
    for k, (m, v) in enumerate(shares.items()):
        v = as_array(v, float).ravel()  # (E,)
        if v.shape != x.shape:
            raise ValueError(f"shares[{m!r}] must hold one share per start ({len(starts)})")
        marker, color = METHOD_MARKERS.get(m, "o"), METHOD_COLORS.get(m, f"C{k}")
        ax.plot(x + (k - (n - 1) / 2) * 0.12, v, marker, color=color, ms=6, label=METHOD_LABELS.get(m, m))
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="the expert")
    ax.set_xticks(x, starts, rotation=60, fontsize=7)
    label_axes(ax, "start (environment seed)", "method's mean / expert's score", "At each start")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(0.0, -0.32), ncol=n + 1, frameon=False)
    labels = list(next(iter(intervals.values())))  # the same labels for every method
    for k, d in enumerate(intervals.values()):
        for j, lab in enumerate(labels):
            i = d[lab]
            y = k + (j - (len(labels) - 1) / 2) * 0.22
            err = [[i.estimate - i.low], [i.high - i.estimate]]
            color = f"C{7 + j}" if j else "0.2"
            ax_i.errorbar(
                i.estimate, y, xerr=err, fmt="o", capsize=3, color=color, label=lab if k == 0 else None
            )
    ax_i.axvline(1.0, color="k", lw=0.8, ls="--")
    ax_i.set_yticks(range(len(intervals)), [METHOD_LABELS.get(m, m) for m in intervals])
    ax_i.invert_yaxis()
    label_axes(ax_i, "share of the expert's mean score", "method", "Over all starts, 95 % intervals")
    ax_i.legend(fontsize=8, loc="upper left", bbox_to_anchor=(0.0, -0.2), frameon=False)
    fig.suptitle(title)
    fig.tight_layout()
    return fig
