"""Figures of chapter 11: routes coloured by their commands, intervals per driver group, success per
command, and an agent's output under each command."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Patch

from ibc_tutorial.plotting.common import (
    STEER_LABEL,
    as_array,
    check_panels,
    figure_and_axes,
    finish,
    label_axes,
)
from ibc_tutorial.plotting.town import plot_town

COMMAND_COLORS = {"follow": "#111111", "left": "#1f77b4", "straight": "#2ca02c", "right": "#d62728"}
"""Colour of each route command (``driving.commands.COMMANDS``) on a map."""


def plot_route_commands(town, xy, commands, *, marks=None, ax=None, title: str = "A route and its commands"):
    """A drive's path on the map coloured by the command given at each point, with ``marks``
    (``{label: (x, y)}``, e.g. the stems crossed) annotated.

    ``xy``: (T, 2) positions (m); ``commands``: (T,) indices into ``driving.commands.COMMANDS``."""
    xy = as_array(xy, float)
    commands = as_array(commands).astype(int).ravel()
    if xy.ndim != 2 or xy.shape[1] != 2 or len(commands) != len(xy):
        raise ValueError(f"xy must be (T, 2) and commands (T,), got {xy.shape} and {commands.shape}")
    if len(commands) and (commands.min() < 0 or commands.max() >= len(COMMAND_COLORS)):
        raise ValueError(f"commands must be indices into {tuple(COMMAND_COLORS)}")
    fig, ax, own = figure_and_axes(ax, (6.4, 5.4))
    plot_town(town, ax=ax, title=title)
    names = tuple(COMMAND_COLORS)
    change = np.flatnonzero(np.diff(commands)) + 1  # first index of each run of one command
    for a, b in zip(np.r_[0, change], np.r_[change, len(commands)], strict=True):
        name = names[commands[a]]
        ax.plot(xy[a : min(b + 1, len(xy)), 0], xy[a : min(b + 1, len(xy)), 1], color=COMMAND_COLORS[name],
                lw=2.6 if name != "follow" else 1.6, solid_capstyle="butt")  # fmt: skip
    ax.plot(*xy[0], "o", color="k", ms=6, label="start")
    ax.plot(*xy[-1], "s", color="k", ms=6, label="end")
    for name, colour in COMMAND_COLORS.items():
        ax.plot([], [], color=colour, lw=2.6, label=name)
    for label, (x, y) in (marks or {}).items():
        ax.annotate(label, (x, y), xytext=(6, 6), textcoords="offset points", fontsize=8,
                    bbox=dict(boxstyle="round,pad=0.2", fc="w", alpha=0.8))  # fmt: skip
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0), title="command", title_fontsize=8)
    return finish(fig, own)


def plot_intervals(rows: dict, *, xlabel: str, title: str, reference: float | None = None, ax=None):
    """One row per group: its estimate (dot) and interval (bar), e.g. the mean driving score of each
    method with and without commands. ``rows``: ``{label: Interval}`` (``stats.Interval``), drawn top
    to bottom; ``reference``: a vertical line (e.g. the expert's value)."""
    n = check_panels("rows", rows)
    fig, ax, own = figure_and_axes(ax, (8.5, 0.45 * n + 1.6))
    y = np.arange(n)[::-1]
    for k, iv in zip(y, rows.values(), strict=True):
        ax.plot([iv.low, iv.high], [k, k], color="C0", lw=3, solid_capstyle="round")
        ax.plot(iv.estimate, k, "o", color="k", ms=5)
    if reference is not None:
        ax.axvline(reference, color="0.3", ls="--", lw=1, label=f"expert ({reference:g})")
        ax.legend(fontsize=8, loc="lower right")
    ax.set_yticks(y)
    ax.set_yticklabels(list(rows))
    ax.set_xlabel(xlabel)
    ax.set_title(title)
    ax.grid(axis="x", alpha=0.3)
    return finish(fig, own)


def plot_success_by_command(success: dict, *, title: str = "Commanded exit taken, per command", ax=None):
    """Grouped bars: per method (group), per command (bar), the success rate with its interval.

    ``success``: ``{method: {command: Interval or None}}`` (None: no crossing had that command)."""
    check_panels("success", success)
    commands = [c for c in ("left", "straight", "right", "all") if any(c in v for v in success.values())]
    fig, ax, own = figure_and_axes(ax, (8.0, 3.6))
    width = 0.8 / len(commands)
    x = np.arange(len(success))
    for i, c in enumerate(commands):
        pos = x - 0.4 + width * (i + 0.5)
        for xp, rates in zip(pos, success.values(), strict=True):
            iv = rates.get(c)
            if iv is None:
                continue
            colour = COMMAND_COLORS.get(c, "0.6")
            ax.bar(xp, iv.estimate, width=width * 0.95, color=colour, alpha=0.85)
            ax.errorbar(xp, iv.estimate, yerr=[[iv.estimate - iv.low], [iv.high - iv.estimate]], color="k",
                        capsize=2, lw=1)  # fmt: skip
    handles = [Patch(color=COMMAND_COLORS.get(c, "0.6"), alpha=0.85, label=c) for c in commands]
    handles.append(ax.axhline(0.95, color="0.3", ls=":", lw=1, label="95 %"))
    ax.set_xticks(x)
    ax.set_xticklabels(list(success))
    ax.set_ylim(0, 1.05)
    label_axes(ax, "method", "share of crossings, commanded exit taken", title)
    ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    return finish(fig, own)


def plot_command_curves(panels: dict, x, *, ylabel: str, title: str, clip: float | None = None):
    """One panel per state (e.g. a distance before the stem), one curve per command over steering.

    ``panels``: ``{panel title: {command or label: (G,) values}}`` over ``x`` (G,) steering values; a
    command's curve takes its colour (``COMMAND_COLORS``), any other label (e.g. "no command (routeless)")
    is drawn dashed grey. ``clip``: values drawn at most this (energies), None for none. Two panels per row,
    one legend for all of them below the panels (off the curves)."""
    n = check_panels("panels", panels)
    x = as_array(x, float).ravel()
    cols = min(2, n)
    rows = -(-n // cols)  # ceil
    fig, axes = plt.subplots(
        rows, cols, figsize=(4.6 * cols, 3.0 * rows + 0.5), squeeze=False, sharex=True, sharey=True
    )
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    for ax, (name, curves) in zip(axes.ravel(), panels.items(), strict=False):
        for label, v in curves.items():
            v = as_array(v, float).ravel()
            if v.shape != x.shape:
                raise ValueError(
                    f"panels[{name!r}][{label!r}] must hold one value per steering value ({len(x)})"
                )
            if clip is not None:
                v = np.minimum(v, clip)
            if label in COMMAND_COLORS:
                ax.plot(x, v, color=COMMAND_COLORS[label], lw=1.6, label=label)
            else:
                ax.plot(x, v, color="0.5", ls="--", lw=1.4, label=label)
        ax.axvline(0, color="0.3", lw=0.8, ls=":")
        if clip is not None:
            ax.set_ylim(0, clip)
        k = list(panels).index(name)
        last_row = k + cols >= n  # no panel below it
        label_axes(ax, STEER_LABEL if last_row else "", ylabel if k % cols == 0 else "", name)
        ax.tick_params(labelbottom=last_row)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.suptitle(title)
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=9, frameon=False)
    fig.tight_layout(rect=(0, 0.4 / (3.0 * rows + 0.5), 1, 1))
    return fig
