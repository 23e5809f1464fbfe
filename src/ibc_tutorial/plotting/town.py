"""Figures of chapter 07: the towns, their lights, the car, the bird's-eye view, the expert's drives
and the demonstration dataset. Maps are in the world frame: x east, y north (metres)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap

from ibc_tutorial.driving.bev import CHANNELS, get_raster
from ibc_tutorial.driving.render import bev_to_rgb, draw_ego, town_rgb
from ibc_tutorial.plotting.common import (
    ACCEL_LABEL,
    STEER_LABEL,
    TIME_LABEL,
    as_array,
    check_panels,
    finish,
    label_axes,
)
from ibc_tutorial.utils import check_positive

LIGHT_COLORS = ("#2ca02c", "#ffbf00", "#d62728")
"""Colours of the light states 0 green, 1 yellow, 2 red."""


def draw_bev(ax, bev) -> None:
    """A bird's-eye view (5, S, S) in colour with the car drawn in, without ticks."""
    ax.imshow(draw_ego(bev_to_rgb(as_array(bev))), interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks([])


def plot_town(
    town,
    *,
    stop_flags=None,
    ax=None,
    title: str | None = None,
    step: int = 2,
    margin: float = 8.0,
    markers: bool = True,
):
    """A town's map: roads (grey), lane boundaries (white), buildings (brown), stop lines coloured
    red where ``stop_flags`` (L,) is True and green elsewhere (white if None), and with
    ``markers`` a dot on each light so that it shows at the scale of a whole town."""
    if ax is None:
        _, ax = plt.subplots(figsize=(6.0, 5.2))
    img, extent = town_rgb(get_raster(town.name), stop_flags, step=step)
    ax.imshow(img, extent=extent, interpolation="nearest")
    if markers and stop_flags is not None:
        pos = np.array([np.array(s.entry) - 0.6 * np.array(s.direction) for s in town.stop_lines])  # (L, 2)
        colour = np.where(np.asarray(stop_flags, dtype=bool), "#e02020", "#20c040")
        ax.scatter(pos[:, 0], pos[:, 1], c=colour, s=14, edgecolors="k", linewidths=0.4, zorder=3)
    x0, y0, x1, y1 = town.extent
    ax.set_xlim(x0 - margin, x1 + margin)
    ax.set_ylim(y0 - margin, y1 + margin)
    label_axes(ax, "x (m, east)", "y (m, north)", title if title is not None else town.name)
    return ax.figure


def _map_figure(town, figsize: tuple, title: str):
    """A new figure with one axis showing ``town``'s map (no light markers)."""
    fig, ax = plt.subplots(figsize=figsize)
    plot_town(town, ax=ax, title=title)
    return fig, ax


def plot_towns(towns, stop_flags: dict | None = None):
    """Both towns side by side at the same scale, with their lights at one moment."""
    check_panels("towns", towns)
    widths = [t.size[0] for t in towns]
    fig, axes = plt.subplots(
        1, len(towns), figsize=(11, 5.0), gridspec_kw={"width_ratios": widths}, squeeze=False
    )
    for ax, town in zip(axes[0], towns, strict=True):
        flags = None if stop_flags is None else stop_flags[town.name]
        w, h = town.size
        n_red = "" if flags is None else f", {int(np.sum(flags))} of {town.n_lights} lights red or yellow"
        plot_town(
            town,
            stop_flags=flags,
            ax=ax,
            title=f"{town.name}: {w:.0f} x {h:.0f} m, {town.n_junctions} T-junctions{n_red}",
        )
        ax.title.set_fontsize(9)
    return finish(fig, True)


def plot_junction(town, node: int, *, radius: float = 30.0, stop_flags=None, title: str = ""):
    """One junction up close: the lanes with their direction, the dense waypoints, the stop lines."""
    fig, ax = plt.subplots(figsize=(6.0, 6.0))
    plot_town(town, stop_flags=stop_flags, ax=ax, step=1, title=title, markers=False)
    cx, cy = town.nodes[node]
    colours = {"straight": "C0", "left": "C1", "right": "C2"}
    drawn = set()
    for lane in town.lanes:
        pts = lane.points  # (P, 2)
        near = np.hypot(pts[:, 0] - cx, pts[:, 1] - cy) < radius
        if not near.any():
            continue
        c = colours[lane.turn] if lane.kind == "connector" else "C4"
        label = f"connector: {lane.turn}" if lane.kind == "connector" else "road lane"
        ax.plot(pts[near, 0], pts[near, 1], ".", ms=3, color=c, label=None if label in drawn else label)
        drawn.add(label)
        k = np.flatnonzero(near)
        if len(k) > 2:
            i = k[len(k) // 2]
            d = np.array([np.cos(lane.headings[i]), np.sin(lane.headings[i])])
            ax.annotate(
                "", xy=pts[i] + 1.5 * d, xytext=pts[i], arrowprops=dict(arrowstyle="->", color=c, lw=1.2)
            )
    ax.set_xlim(cx - radius, cx + radius)
    ax.set_ylim(cy - radius, cy + radius)
    ax.legend(loc="lower left", fontsize=7, framealpha=0.9)
    return finish(fig, True)


def plot_light_timeline(
    states, *, dt: float = 0.1, labels=None, title: str = "The three heads of one junction"
):
    """Light states (T, H) (0 green, 1 yellow, 2 red) as coloured bars against time."""
    states = as_array(states)
    T, H = states.shape
    fig, ax = plt.subplots(figsize=(9.0, 0.6 * H + 1.2))
    ax.imshow(
        states.T,
        aspect="auto",
        cmap=ListedColormap(LIGHT_COLORS),
        vmin=0,
        vmax=2,
        interpolation="nearest",
        extent=(0, T * dt, H - 0.5, -0.5),
    )
    ax.set_yticks(range(H))
    ax.set_yticklabels(labels if labels is not None else [f"head {h}" for h in range(H)])
    ax.set_xlabel(TIME_LABEL)
    ax.set_title(title + " (green, yellow, red)")
    return finish(fig, True)


def plot_step_and_turn(t, speed, reference, trajectories: dict, *, radii: dict | None = None):
    """Left: speed against time (step response) with a reference; right: paths under constant steering."""
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    a.plot(t, speed, label="simulated car")
    a.plot(t, reference, "k--", lw=1, label="3 m/s² up, then 8 m/s² down (no drag)")
    label_axes(
        a, TIME_LABEL, "speed (m/s)", "Step response: full throttle for 5 s, then full brake", legend=True
    )
    for i, (label, xy) in enumerate(trajectories.items()):
        xy = as_array(xy)  # (T, 2)
        b.plot(xy[:, 0], xy[:, 1], color=f"C{i}", label=label)
        if radii is not None and label in radii:
            cx, cy, r = radii[label]
            b.add_patch(plt.Circle((cx, cy), r, fill=False, ls=":", color=f"C{i}", lw=1))
    b.set_aspect("equal")
    label_axes(b, "x (m)", "y (m)", "Turns at 4 m/s (dotted: L / tan(δ) circles)", legend=True)
    return finish(fig, True)


def plot_bev_channels(
    bev,
    small=None,
    *,
    light_levels=None,
    level_names=None,
    title: str = "The bird's-eye view of one moment",
):
    """After the paper's Fig. 1(b-d): the five channels in colour with the car (and the small view), then
    each channel in grey levels, with a colour bar that names the light channels' levels.

    Args:
        bev: (5, S, S) the view; small: optional (5, s, s) the same field at a smaller size.
        light_levels: the values the light channels take for a drawn line, e.g. (0.3, 0.6, 1.0); by
            default one level, 1 (a one-bit encoding).
        level_names: a name per level, e.g. ("green", "yellow", "red").
    """
    if (light_levels is None) != (level_names is None) or (
        light_levels is not None and len(light_levels) != len(level_names)
    ):
        raise ValueError("light_levels and level_names must be given together, one name per level")
    fig = plt.figure(figsize=(11, 7.4))
    gs = fig.add_gridspec(2, 5, height_ratios=[1.75, 1])
    top = fig.add_subplot(gs[0, :3])
    draw_bev(top, bev)
    top.set_title(f"all five channels, {bev.shape[1]}x{bev.shape[2]} (car in blue)", fontsize=10)
    top.set_ylabel(f"{bev.shape[1]} px = {bev.shape[1] / 5:.1f} m")
    if small is not None:
        right = fig.add_subplot(gs[0, 3:])
        draw_bev(right, small)
        right.set_title(f"the same field at {small.shape[1]}x{small.shape[2]}", fontsize=10)
    light_axes = []  # the axes of channels 2-4
    for c in range(5):
        ax = fig.add_subplot(gs[1, c])
        image = ax.imshow(bev[c], cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_title(f"{c}: {CHANNELS[c]}", fontsize=9)
        if c >= 2:
            light_axes.append(ax)
    # the grey levels of the light channels: which value stands for which light state
    levels = [0.0, *light_levels] if light_levels is not None else [0.0, 1.0]
    names = ["no line", *level_names] if level_names is not None else ["no line", "light"]
    cax = light_axes[-1].inset_axes([1.06, 0.0, 0.07, 1.0])  # beside the last light channel
    bar = fig.colorbar(image, cax=cax, ticks=levels)
    bar.ax.set_yticklabels([f"{name} {v:g}" for name, v in zip(names, levels, strict=True)], fontsize=8)
    bar.set_label("light channels: value", fontsize=8)
    return finish(fig, True, title=title)


def plot_drive(town, xy, actions, speed, *, dt: float = 0.1, title: str = "An expert drive", waits=None):
    """An episode on the map (colour = time) and its actions and speed against time."""
    xy, actions, speed = as_array(xy), as_array(actions), as_array(speed)  # (T, 2), (T, 2), (T,)
    fig = plt.figure(figsize=(12, 6.0))
    gs = fig.add_gridspec(3, 2, width_ratios=[1.0, 1.25])
    ax = fig.add_subplot(gs[:, 0])
    plot_town(town, ax=ax, title=title)
    t = np.arange(len(xy)) * dt
    sc = ax.scatter(xy[:, 0], xy[:, 1], c=t, s=2, cmap="viridis")
    fig.colorbar(sc, ax=ax, label=TIME_LABEL, shrink=0.7)
    names = [
        ("steering\n(−1 left … +1 right)", actions[:, 0]),
        ("acceleration\n(< 0: braking)", actions[:, 1]),
        ("speed (m/s)", speed),
    ]
    for k, (name, v) in enumerate(names):
        a = fig.add_subplot(gs[k, 1])
        a.plot(t, v, lw=0.7, color=f"C{k}")
        a.set_ylabel(name, fontsize=11)
        a.tick_params(labelsize=10)
        if k < 2:
            a.set_ylim(-1.05, 1.05)
            a.set_xticklabels([])
    a.set_xlabel(TIME_LABEL, fontsize=11)
    return finish(fig, True)


def plot_light_stop(
    t, gap, speed, light_states, *, gap_no_brake=None, title: str = "The expert at a red light"
):
    """Distance to the stop line and speed against time, the light's state as the background."""
    t, gap, speed, light_states = map(as_array, (t, gap, speed, light_states))
    fig, (a, b) = plt.subplots(2, 1, figsize=(8.5, 5.0), sharex=True)
    for ax in (a, b):
        start = 0
        for i in range(1, len(t) + 1):
            if i == len(t) or light_states[i] != light_states[start]:
                ax.axvspan(t[start], t[i - 1], color=LIGHT_COLORS[int(light_states[start])], alpha=0.15, lw=0)
                start = i
    a.plot(t, gap, label="expert")
    if gap_no_brake is not None:
        a.plot(t[: len(gap_no_brake)], gap_no_brake, "--", label="half throttle, ignoring the light")
    a.axhline(0, color="k", lw=0.8)
    a.set_ylim(min(-10, np.nanmin(gap)), np.nanmax(gap) + 2)
    a.legend(fontsize=11)
    a.set_title(title + " (background: the light's state)", fontsize=12)
    b.plot(t, speed, color="C2")
    b.set_ylabel("speed (m/s)", fontsize=12)
    b.set_xlabel(TIME_LABEL, fontsize=12)
    a.set_ylabel("front bumper to\nstop line (m)", fontsize=12)
    for ax in (a, b):
        ax.tick_params(labelsize=11)
    return finish(fig, True)


def plot_routes(town, routes_xy, *, title: str = "The demonstration routes", arrow_every_m: float = 40.0):
    """Each route's path on the map in its own colour, its start marked, with an arrow for the
    direction of travel every ``arrow_every_m`` metres along it."""
    arrow_every_m = check_positive("arrow_every_m", arrow_every_m)
    fig, ax = _map_figure(town, (8.5, 7.0), title)
    cmap = plt.get_cmap("tab10")
    for k, xy in enumerate(routes_xy):
        xy = as_array(xy)  # (T, 2)
        color = cmap(k % 10)
        ax.plot(xy[:, 0], xy[:, 1], color=color, lw=1.8, alpha=0.85, label=f"route {k}")
        ax.plot(xy[0, 0], xy[0, 1], "o", color=color, ms=7, mec="k")
        step = np.linalg.norm(np.diff(xy, axis=0), axis=1)  # (T-1,) metres per step
        s = np.r_[0.0, np.cumsum(step)]  # (T,) arc length
        for d in np.arange(arrow_every_m / 2, s[-1] - 1.0, arrow_every_m):
            i = int(np.searchsorted(s, d))
            j = int(np.searchsorted(s, d + 1.0))  # a point about a metre further on
            if j < len(xy) and i < j:
                ax.annotate(
                    "",
                    xy=xy[j],
                    xytext=xy[i],
                    arrowprops=dict(arrowstyle="-|>", color=color, lw=1.2, mutation_scale=14),
                )
    ax.legend(
        fontsize=10,
        loc="center left",
        bbox_to_anchor=(1.0, 0.5),
        title="arrows: direction\nof travel",
        title_fontsize=9,
    )
    return finish(fig, True)


def plot_action_histograms(actions, *, title: str = "The expert's actions in the dataset"):
    """Histograms of steering and acceleration (log counts)."""
    actions = as_array(actions)  # (N, 2)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    for ax, k, name in zip(axes, range(2), (STEER_LABEL, ACCEL_LABEL), strict=True):
        ax.hist(actions[:, k], bins=np.linspace(-1, 1, 81), color=f"C{k}")
        ax.set_yscale("log")
        ax.set_xlabel(name)
        ax.set_ylabel("samples (log scale)")
    return finish(fig, True, title=title)


def plot_exit_map(town, counts: dict, *, title: str = "Exits taken at each junction approach"):
    """The map with, at every junction approach the data drives through, how often it left by each
    exit (L left, S straight, R right); approaches left by two different exits are boxed in red.

    ``counts``: ``{approach: {"left": n, "straight": n, "right": n}}`` (``driving.analysis.exit_counts``)."""
    fig, ax = _map_figure(town, (11.0, 9.4), title)
    letters = {"left": "L", "straight": "S", "right": "R"}
    for ap_id, c in counts.items():
        ap = town.approaches[ap_id]
        # place the label 18 m before the junction and 4 m to the right of the approaching lane, so that
        # the labels of the two lanes of one short road do not cover each other
        d = np.asarray(ap.direction, dtype=float)
        p = np.asarray(ap.entry) - d * 18.0 + np.array([d[1], -d[0]]) * 4.0
        text = " ".join(f"{letters[k]}{c[k]}" for k in ("left", "straight", "right") if c.get(k))
        multi = sum(n > 0 for n in c.values()) > 1
        ax.text(
            p[0],
            p[1],
            text,
            fontsize=9.5,
            fontweight="bold" if multi else "normal",
            ha="center",
            va="center",
            bbox=dict(
                boxstyle="round,pad=0.2", fc="white", ec="red" if multi else "0.6", lw=1.4 if multi else 0.6
            ),
        )
    return finish(fig, True)


def plot_bev_samples(bevs, actions, states, *, title: str = "Samples of the Dataset, rendered on demand"):
    """A row of BEVs (N, 5, S, S) with their state and the expert's action."""
    n = check_panels("bevs", bevs)
    fig, axes = plt.subplots(1, n, figsize=(2.6 * n, 3.4), squeeze=False)
    for ax, bev, a, s in zip(axes[0], bevs, actions, states, strict=True):
        draw_bev(ax, bev)
        ax.set_title(f"v {s[0]:.1f} m/s\nsteer {a[0]:+.2f}, acc {a[1]:+.2f}", fontsize=11)
    return finish(fig, True, title=title)
