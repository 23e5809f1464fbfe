"""Figures of the stems diagnosis (chapter 12): the minority exit at the stems under each change tried."""

from __future__ import annotations

import matplotlib.pyplot as plt

from ibc_tutorial.plotting.agents import METHOD_COLORS, METHOD_LABELS
from ibc_tutorial.plotting.common import check_panels, finish

METHOD_ORDER = ("bc", "ibc", "da-ibc")
"""The methods' order within a change's group of rows, top to bottom."""


def plot_minority_by_change(
    shares: dict,
    *,
    reference: float | None = None,
    reference_label: str = "",
    title: str = "The minority exit at a stem, with each change (95 % intervals)",
):
    """A dot plot, one group of rows per change and one row per method in it: the share of the minority exit
    at the stems with its interval, read left to right; the legend sits under the axes, off the data.

    ``shares``: ``{(change, method): (estimate, low, high)}`` (a ``stats.Interval``'s numbers), in the order
    the changes are to be read; ``reference``: a dashed vertical line (e.g. the expert's share), with
    ``reference_label`` in the legend."""
    check_panels("shares", shares)
    changes = list(dict.fromkeys(change for change, _ in shares))
    fig, ax = plt.subplots(figsize=(8.4, 0.2 * len(changes) + 0.22 * len(shares) + 1.5))
    y, ticks, drawn = 0.0, [], set()
    for change in changes:
        rows = [m for m in (*METHOD_ORDER, *sorted({m for _, m in shares})) if (change, m) in shares]
        rows = list(dict.fromkeys(rows))
        ticks.append((y - 0.4 * (len(rows) - 1) / 2, change))
        for m in rows:
            est, low, high = shares[change, m]
            label = METHOD_LABELS.get(m, m) if m not in drawn else None
            drawn.add(m)
            color = METHOD_COLORS.get(m, "0.4")
            ax.plot([low, high], [y, y], color=color, lw=2.2, alpha=0.7)
            ax.plot([est], [y], "o", color=color, ms=7, label=label)
            ax.text(high + 0.01, y, f"{est:.2f}", va="center", fontsize=9)
            y -= 0.4
        ax.axhline(y + 0.05, color="0.85", lw=0.8)  # between the groups
        y -= 0.3
    if reference is not None:
        ax.axvline(reference, color="0.3", ls="--", lw=1.2, label=f"{reference_label} ({reference:.2f})")
    ax.set_yticks([t for t, _ in ticks], [c for _, c in ticks], fontsize=10)
    ax.set_xlim(0, 0.62)
    ax.set_xlabel("share of the minority exit (0: always the same exit, 0.5: half each way)")
    ax.grid(alpha=0.3, axis="x")
    ax.set_ylim(y + 0.15, 0.3)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=4, fontsize=9, frameon=False)
    return finish(fig, True, title=title)
