"""Figures of Part I, chapters 01-03: the tree and the side road, explicit policies, energy models.

The closed-loop figures share one drawing, ``draw_rollouts``: the scene (the tree, or the roads of
the side-road world) and the trajectories coloured by their outcome.
"""

from __future__ import annotations

from dataclasses import dataclass

import matplotlib.pyplot as plt
import numpy as np
import torch
from matplotlib.lines import Line2D
from matplotlib.patches import Polygon

from ibc_tutorial.plotting.common import (
    STEER_LABEL,
    TIME_LABEL,
    X_LABEL,
    Y_LABEL,
    as_array,
    check_panels,
    figure_and_axes,
    finish,
    label_axes,
)
from ibc_tutorial.utils import check_int

TREE_SIDE_COLORS = {-1: "C0", 1: "C1", 0: "C3"}
"""Colours of the tree chapters, keyed by ``TreeWorld.pass_side`` (the sign of the steering that
takes a car there): passed on the left (-1, blue), on the right (+1, orange), collided (0, red)."""
TREE_MODE_COLORS = {"passes left": TREE_SIDE_COLORS[-1], "passes right": TREE_SIDE_COLORS[1]}
"""The same colours keyed by the tree experts' mode names (``TreeWorld.mode_names``), so that a
side has one colour in every figure."""
SIDE_ROAD_COLORS = {"main road": "C0", "side road": "C2", "off road": "C3"}
"""Colours of the side-road world: ended on the main road (blue), on the side road (green), off the road
(red)."""


# =================================================================== scenes and rollouts (chapters 01-03, 06)
def draw_tree(ax, world) -> None:
    """The tree (green disc) and, dashed, the circle the car's centre must stay out of."""
    c = world.config
    ax.add_patch(plt.Circle((c.tree_x, 0.0), c.tree_radius, color="forestgreen", zorder=3))
    ax.add_patch(
        plt.Circle(
            (c.tree_x, 0.0), world.clearance, fill=False, ls="--", lw=0.8, color="forestgreen", zorder=3
        )
    )


def draw_side_road(ax, world, x_end: float) -> None:
    """The drivable area of the side-road world in grey, up to ``x_end`` m: the main road and the side
    road, along ``world.side_direction`` (to the right, -y)."""
    c = world.config
    w = c.road_half_width
    ax.add_patch(plt.Rectangle((-1.0, -w), x_end + 1.0, 2 * w, color="0.88", zorder=0))
    u = as_array(world.side_direction, float)  # (2,) along the side road, away from the branch point
    nrm = np.array([-u[1], u[0]])  # (2,) across it
    b = np.array([c.branch_x, 0.0])
    length = (x_end - c.branch_x) / u[0] + w  # u[0] = cos of the angle between the roads
    corners = [b - w * nrm, b + w * nrm, b + w * nrm + length * u, b - w * nrm + length * u]
    ax.add_patch(Polygon(corners, closed=True, color="0.88", zorder=0))


def draw_tracks(ax, states, colors, *, max_episodes: int, ends=None, alpha: float = 0.6) -> None:
    """Trajectories ``states`` (E, T+1, >=2) seen from above, episode e in ``colors[e]``; a red
    cross at the last position of the episodes where ``ends`` (E,) bool is True."""
    max_episodes = check_int("max_episodes", max_episodes, minimum=0)
    s = as_array(states)
    for e in range(min(len(s), max_episodes)):
        ax.plot(s[e, :, 0], s[e, :, 1], color=colors[e], lw=0.8, alpha=alpha)
        if ends is not None and ends[e]:
            ax.plot(s[e, -1, 0], s[e, -1, 1], "x", color="C3", ms=4)


def rollout_colors(world, rollouts) -> list[str]:
    """The colour of each episode's outcome: the side passed in the tree world (``TREE_SIDE_COLORS``),
    where it ended in the side-road world (``SIDE_ROAD_COLORS``)."""
    if hasattr(world, "pass_side"):
        return [TREE_SIDE_COLORS[int(v)] for v in world.pass_side(rollouts)]
    main, took = world.stayed_on_main_road(rollouts), world.took_side_road(rollouts)
    names = [
        "main road" if m else ("side road" if t else "off road")
        for m, t in zip(main.tolist(), took.tolist(), strict=True)
    ]
    return [SIDE_ROAD_COLORS[n] for n in names]


def draw_rollouts(
    ax,
    world,
    rollouts,
    *,
    max_episodes: int = 60,
    x_end: float | None = None,
    crosses: bool = True,
    alpha: float = 0.6,
) -> None:
    """One panel of closed-loop ``rollouts`` in the tree or the side-road ``world``: the scene
    (roads up to ``x_end`` m, by default just past the furthest position), the first
    ``max_episodes`` trajectories coloured by outcome (``rollout_colors``), with ``crosses`` a
    red cross where an episode collided."""
    if x_end is None:
        x_end = float(rollouts.states[:, :, 0].max()) + 1.0
    if hasattr(world, "pass_side"):
        draw_tree(ax, world)
    else:
        draw_side_road(ax, world, x_end)
    ends = rollouts.collided.tolist() if crosses else None
    draw_tracks(
        ax,
        rollouts.states,
        rollout_colors(world, rollouts),
        max_episodes=max_episodes,
        ends=ends,
        alpha=alpha,
    )
    ax.set_aspect("equal")


def outcome_key(world, *, crosses: bool = True) -> list:
    """Legend handles of the outcome colours of ``rollout_colors`` in ``world`` (the tree or the
    side road), and, with ``crosses``, of the red cross where an episode collided."""
    if hasattr(world, "pass_side"):
        items = [
            ("passed on the left", TREE_SIDE_COLORS[-1]),
            ("passed on the right", TREE_SIDE_COLORS[1]),
            ("collided", TREE_SIDE_COLORS[0]),
        ]
    else:
        items = [
            (f"ended on the {name}" if name != "off road" else "left the road", color)
            for name, color in SIDE_ROAD_COLORS.items()
        ]
    handles = [Line2D([], [], color=color, lw=1.5, label=label) for label, color in items]
    if crosses:
        handles.append(Line2D([], [], color="C3", marker="x", ls="none", ms=4, label="where it collided"))
    return handles


@dataclass(frozen=True)
class RolloutStyle:
    """How ``rollout_figure`` draws each panel (``draw_rollouts``' options and the panel titles)."""

    max_episodes: int = 60
    """Episodes drawn per panel (the first ones)."""
    crosses: bool = True
    """Mark where an episode collided with a cross."""
    alpha: float = 0.6
    """Opacity of the trajectories."""
    fontsize: float = 10
    """Font size of the panel titles."""


def rollout_figure(
    world,
    rollouts: dict,
    summary,
    *,
    title: str,
    figsize: tuple,
    ncols: int = 1,
    style: RolloutStyle = RolloutStyle(),
    compressed: bool = False,
):
    """Closed-loop ``rollouts`` ({name: Rollouts}) of several policies, one ``draw_rollouts`` panel
    each in ``ncols`` columns, titled ``f"{name}: {summary(world, rollouts[name])}"``, drawn as
    ``style`` says; empty panels are hidden; the colour key (``outcome_key``) sits in the first
    panel. ``compressed`` lays the figure out with matplotlib's compressed layout instead of
    ``tight_layout``."""
    if not isinstance(style, RolloutStyle):
        raise ValueError(f"style must be a RolloutStyle, got {type(style).__name__}")
    n = check_panels("rollouts", rollouts)
    ncols = check_int("ncols", ncols, minimum=1)
    nrows = -(-n // ncols)
    fig, axes = plt.subplots(
        nrows,
        ncols,
        figsize=figsize,
        sharex=True,
        sharey=True,
        squeeze=False,
        layout="compressed" if compressed else None,
    )
    x_end = max(float(r.states[:, :, 0].max()) for r in rollouts.values()) + 1.0
    for ax, (name, r) in zip(
        axes.flat, rollouts.items(), strict=False
    ):  # more axes than panels: the rest are hidden
        draw_rollouts(
            ax,
            world,
            r,
            max_episodes=style.max_episodes,
            x_end=x_end,
            crosses=style.crosses,
            alpha=style.alpha,
        )
        ax.set_title(f"{name}: {summary(world, r)}", fontsize=style.fontsize)
    for k in range(n, nrows * ncols):  # empty panels: hide them, label the axis of the panel above
        axes.flat[k].axis("off")
        if k - ncols >= 0:
            axes.flat[k - ncols].xaxis.set_tick_params(labelbottom=True)
            axes.flat[k - ncols].set_xlabel(X_LABEL)
    for ax in axes[:, 0]:
        ax.set_ylabel(Y_LABEL)
    for ax in axes[-1]:
        if ax.axison:
            ax.set_xlabel(X_LABEL)
    axes.flat[0].legend(
        handles=outcome_key(world, crosses=style.crosses),
        loc="upper left",
        fontsize=7,
        framealpha=0.9,
        title="colour: outcome",
        title_fontsize=7,
    )
    return finish(fig, not compressed, title=title)


def _tree_shares(world, r) -> str:
    side = world.pass_side(r).numpy()
    counts = ", ".join(
        f"{label} {float(np.mean(side == v)):.0%}"
        for v, label in ((-1, "left"), (1, "right"), (0, "collided"))
    )
    return f"{counts} of {len(side)} episodes"


def _side_road_shares(world, r) -> str:
    main, side = world.stayed_on_main_road(r).numpy(), world.took_side_road(r).numpy()
    sw = world.swerve(r).numpy()
    mean = f"{np.nanmean(sw):.2f} m" if (~np.isnan(sw)).any() else "n/a"
    off = r.collided.float().mean()
    return f"main road {main.mean():.0%}, side road {side.mean():.0%}, off road {off:.0%}; mean swerve {mean}"


def _grid_shares(world, r) -> str:
    """Counts of the episodes' outcomes, "k of n" (a rounded share would call 199 of 200 "100 %")."""
    hit = r.collided.numpy()
    n = len(hit)
    if hasattr(world, "pass_side"):
        side = world.pass_side(r).numpy()
        left, right = int(np.sum(side == -1)), int(np.sum(side == 1))
        return f"collided {int(hit.sum())} of {n}, left {left}, right {right}"
    main, took = world.stayed_on_main_road(r).numpy(), world.took_side_road(r).numpy()
    return f"of {n}: main {int(main.sum())}, side road {int(took.sum())}, off road {int(hit.sum())}"


# =========================================================================== chapter 01: the tree
def _mode_colors(mode_names) -> list[str]:
    """The colour of each mode: the tree's from ``TREE_MODE_COLORS``, else C0, C1, ... in order."""
    return [TREE_MODE_COLORS.get(name, f"C{k}") for k, name in enumerate(mode_names)]


def plot_tree_scene(
    world,
    states,
    modes,
    *,
    title: str = "Expert demonstrations in the tree world",
    max_episodes: int = 100,
    ax=None,
):
    """Expert trajectories ``states`` (E, T+1, 3) seen from above, coloured by ``modes`` (E,),
    indices into ``world.mode_names`` (0 passes on the right, orange; 1 on the left, blue, as
    in ``TREE_MODE_COLORS``); the tree as a green disc, the dashed circle marks where the car's
    disc would touch it."""
    fig, ax, _ = figure_and_axes(ax, (9, 3.6))
    m = as_array(modes)
    colors = _mode_colors(world.mode_names)
    draw_tracks(ax, states, [colors[int(v)] for v in m], max_episodes=max_episodes)
    draw_tree(ax, world)
    for mode, (name, color) in enumerate(zip(world.mode_names, colors, strict=True)):
        ax.plot([], [], color=color, label=f"{name} ({int((m == mode).sum())})")
    ax.set_aspect("equal")
    label_axes(ax, X_LABEL, Y_LABEL, title, legend=True, loc="lower left")
    return fig


def plot_actions_by_distance(
    world,
    demos,
    *,
    predictions: dict | None = None,
    window: tuple | None = None,
    title: str = "What the policy sees, and what the experts did",
    max_points: int = 6000,
):
    """Each expert sample as a dot: the observation (distance to the tree, m) against the action
    (steering), coloured by the expert's side (``world.mode_names``, ``TREE_MODE_COLORS``);
    optional ``predictions`` {name: (distances, actions)} drawn as lines, ``window`` = (low, high)
    m shaded. The x axis runs towards the tree."""
    fig, ax = plt.subplots(figsize=(9, 3.8))
    d = as_array(world.physical(demos.obs)[:, 0])
    a = as_array(demos.actions[:, 0])
    m = as_array(demos.mode)
    idx = np.random.default_rng(0).permutation(len(d))[:max_points]
    for mode, (name, color) in enumerate(zip(world.mode_names, _mode_colors(world.mode_names), strict=True)):
        sel = idx[m[idx] == mode]
        ax.scatter(d[sel], a[sel], s=3, color=color, alpha=0.35, label=f"expert, {name}", rasterized=True)
    if window is not None:
        ax.axvspan(window[0], window[1], color="0.85", zorder=0, label="window of the histogram")
    for i, (name, (x, y)) in enumerate((predictions or {}).items()):
        ax.plot(
            as_array(x).reshape(-1),
            as_array(y).reshape(-1),
            color=["k", "C3", "C2", "C4"][i % 4],
            lw=2,
            ls=["-", "--", "-.", ":"][i % 4],
            label=name,
        )
    ax.axvline(0.0, color="forestgreen", lw=1.5)
    ax.text(0.0, 1.02, " tree", color="forestgreen", va="bottom", fontsize=8)
    ax.set_xlim(d.max() + 0.5, d.min() - 0.5)
    ax.set_ylim(-1.1, 1.15)
    label_axes(
        ax,
        "observation: distance ahead to the tree (m)",
        STEER_LABEL,
        title,
        legend=True,
        loc="lower left",
        markerscale=3,
    )
    return fig


def plot_action_histogram(actions, modes, *, title: str, bins: int = 40, mode_names=None):
    """Histogram of the actions ``actions`` (N,) in [-1, 1], stacked by the experts' ``modes`` (N,),
    indices into ``mode_names`` (by default the tree world's, ``TreeWorld.mode_names``)."""
    if mode_names is None:
        from ibc_tutorial.toy.tree import TreeWorld

        mode_names = TreeWorld.mode_names
    a, m = as_array(actions), as_array(modes)
    fig, ax = plt.subplots(figsize=(6.4, 3.4))
    ax.hist(
        [a[m == k] for k in range(len(mode_names))],
        bins=check_int("bins", bins, minimum=1),
        range=(-1, 1),
        stacked=True,
        color=_mode_colors(mode_names),
        label=list(mode_names),
    )
    ax.axvline(float(a.mean()), color="k", ls="--", lw=1.2, label=f"mean of all ({a.mean():+.2f})")
    label_axes(ax, STEER_LABEL, "number of samples", title, legend=True)
    return fig


def plot_constant_losses(
    constants,
    losses: dict,
    *,
    minimisers: dict | None = None,
    flat: dict | None = None,
    title: str = "Loss of predicting one constant action for all the samples",
):
    """Curves ``losses`` {name: (G,)} over the constant prediction ``constants`` (G,); ``minimisers``
    {name: value} marked with a dot, ``flat`` {name: (low, high)} shaded (an interval of minimisers)."""
    n = check_panels("losses", losses)
    c = as_array(constants)
    fig, axes = plt.subplots(1, n, figsize=(4.6 * n, 3.4), squeeze=False)
    for i, (ax, (name, loss)) in enumerate(zip(axes[0], losses.items(), strict=True)):
        loss = as_array(loss)
        color = f"C{i + 2}"
        ax.plot(c, loss, color=color, lw=2)
        if flat and name in flat:
            lo, hi = flat[name]
            ax.axvspan(lo, hi, color=color, alpha=0.15, label=f"minimisers: [{lo:+.2f}, {hi:+.2f}]")
        if minimisers and name in minimisers:
            v = float(minimisers[name])
            ax.plot([v], [np.interp(v, c, loss)], "o", color="k", label=f"minimiser {v:+.2f}")
        label_axes(
            ax, "constant prediction c (steering)", f"{name} loss", name, legend=True, loc="upper center"
        )
    return finish(fig, True, title=title)


def plot_tree_closed_loop(
    world, rollouts: dict, *, title: str = "Closed-loop rollouts in the tree world", max_episodes: int = 60
):
    """One panel per policy ({name: Rollouts}): trajectories from above, coloured by how they pass
    the tree (``TREE_SIDE_COLORS``: left blue, right orange, collided red, with a cross where
    the car stopped)."""
    n = check_panels("rollouts", rollouts)
    return rollout_figure(
        world,
        rollouts,
        _tree_shares,
        title=title,
        figsize=(8.5, 2.2 * n),
        style=RolloutStyle(max_episodes=max_episodes),
    )


def plot_side_road(world, rollouts: dict, *, title: str = "The side road", max_episodes: int = 60):
    """One panel per policy ({name: Rollouts}) over the roads: episodes that end on the main road
    (blue), on the side road (green), off the road (red)."""
    n = check_panels("rollouts", rollouts)
    return rollout_figure(
        world,
        rollouts,
        _side_road_shares,
        title=title,
        figsize=(8.5, 2.8 * n),
        style=RolloutStyle(max_episodes=max_episodes, crosses=False),
    )


# =========================================================================== chapter 02: explicit policies
def plot_beta_shapes(params, *, title: str = "Beta densities f(y'; α, β) of eq. 1"):
    """Densities of Beta(α, β) on the rescaled action y' = (y + 1)/2 in (0, 1), one curve per
    ``(alpha, beta)`` pair in ``params``; the y axis is cut at 4 (U-shapes go to infinity at the ends)."""
    fig, ax = plt.subplots(figsize=(7, 4))
    z = torch.linspace(1e-3, 1 - 1e-3, 999, dtype=torch.float64)
    for a, b in params:
        dens = (
            torch.distributions.Beta(
                torch.tensor(float(a), dtype=torch.float64), torch.tensor(float(b), dtype=torch.float64)
            )
            .log_prob(z)
            .exp()
        )
        style = "--" if a < 1 and b < 1 else "-"
        ax.plot(z.numpy(), np.minimum(dens.numpy(), 10.0), style, label=f"α = {a:g}, β = {b:g}")
    ax.set_ylim(0, 4)
    ax.set_xlim(0, 1)
    label_axes(
        ax,
        "rescaled action y' = (y + 1)/2 (y: steering, −1 = full left, +1 = full right)",
        "density f(y'; α, β) (per unit y')",
        title,
    )
    ax.legend(
        fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5), title="dashed: U-shapes", title_fontsize=8
    )
    return fig


def _policy_point_actions(policy, obs):
    """{label: action} of the deterministic ways of acting of ``policy`` at ``obs`` (1, obs_dim)."""
    point_modes = {"deterministic", "mean", "mode", "argmax", "paper"}
    return {m: float(policy.act(obs, mode=m)[0, 0]) for m in policy.modes if m in point_modes}


def _data_histogram(ax, data, bins: int, label: str) -> float:
    """Grey density histogram of ``data`` (N,) over [-1, 1]; returns its highest bar (per unit action)."""
    heights, _, _ = ax.hist(
        data,
        bins=check_int("bins", bins, minimum=1),
        range=(-1, 1),
        density=True,
        color="0.75",
        label=f"{label} (n = {len(data)})",
    )
    return float(np.max(heights))


def plot_action_distributions(
    policies, obs, data_actions, *, dim: int = 0, where: str = "", n_values: int = 801
):
    """One panel per policy: the histogram of the expert's actions ``data_actions`` (M,) near the
    observation ``obs`` (1, obs_dim), the policy's predicted density of action dimension ``dim``
    there (``action_density``) and vertical lines at its deterministic actions.

    ``policies`` maps a name to an ``ExplicitPolicy``; ``where`` describes the place for the title.
    """
    n = check_panels("policies", policies)
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 3.4), sharey=True, squeeze=False)
    values = torch.linspace(-1, 1, check_int("n_values", n_values, minimum=2))
    data = as_array(data_actions, float).reshape(-1)
    colors = {"deterministic": "C3", "mean": "C3", "mode": "C2", "argmax": "C3", "paper": "C3"}
    ymax = 1.0
    for ax, (name, policy) in zip(axes[0], policies.items(), strict=True):
        ymax = max(ymax, _data_histogram(ax, data, 40, "expert data"))
        if policy.has_density:
            with torch.no_grad():
                dens = policy.action_density(obs, values)[0, :, dim].numpy()  # (n_values,)
            ax.plot(values.numpy(), dens, color="C0", lw=1.5, label="predicted density")
            ymax = max(ymax, float(np.quantile(dens, 0.995)))
        for mode, a in _policy_point_actions(policy, obs).items():
            ax.axvline(a, color=colors.get(mode, "C3"), ls="--", lw=1.5, label=f"act: {mode} = {a:+.2f}")
        ax.set_title(name)
        ax.set_xlabel(STEER_LABEL)
        ax.set_xlim(-1, 1)
        ax.legend(fontsize=7, loc="upper left")
    axes[0, 0].set_ylabel("density (per unit action)")
    for ax in axes[0]:
        ax.set_ylim(0, 1.25 * ymax)
    return finish(fig, True, title=f"Predicted action distribution vs expert data {where}".strip())


def plot_density_fits(data_actions, values, curves: dict, *, title: str, bins: int = 40):
    """Histogram (density) of ``data_actions`` (N,) in [-1, 1] with density curves ``curves``
    {label: (G,)} evaluated at ``values`` (G,) drawn over it."""
    data = as_array(data_actions, float).reshape(-1)
    v = as_array(values)
    fig, ax = plt.subplots(figsize=(6.8, 3.6))
    top = _data_histogram(ax, data, bins, "expert actions")
    for i, (label, dens) in enumerate(curves.items()):
        d = as_array(dens)
        ax.plot(v, d, color=f"C{i}", lw=2, label=label)
        top = max(top, float(np.quantile(d, 0.98)))
    ax.set_ylim(0, 1.15 * top)
    ax.set_xlim(-1, 1)
    label_axes(ax, STEER_LABEL, "density (per unit action)", title, legend=True, loc="upper center")
    return fig


def plot_rollout_grid(world, rollouts: dict, *, title: str, ncols: int = 2, max_episodes: int = 40):
    """Closed-loop trajectories of several policies ({name: Rollouts}) over the scene, one panel
    each, in a grid. Tree world: coloured by the side passed (left blue, right orange, collided
    red with a cross). Side-road world: ended on the main road (blue), on the side road (green),
    off the road (red with a cross)."""
    n = check_panels("rollouts", rollouts)
    ncols = check_int("ncols", ncols, minimum=1)
    nrows = -(-n // ncols)
    return rollout_figure(
        world,
        rollouts,
        _grid_shares,
        title=title,
        figsize=(5.6 * ncols, 2.0 * nrows + 0.4),
        ncols=ncols,
        style=RolloutStyle(max_episodes=max_episodes, fontsize=9),
        compressed=True,
    )


# ====================================================================== chapter 03: energy models and InfoNCE
def plot_energy_landscape(
    distances,
    actions,
    energies,
    *,
    expert=None,
    path=None,
    title: str = "The energy landscape",
    labels: tuple[str, str] = ("distance to the tree (m)", STEER_LABEL),
    ax=None,
):
    """E(x, y) with the observation along x and the action along y, shifted per observation so
    that its minimum over actions is 0 (dark = low energy = likely action).

    Args:
        distances: (n,) the observation parameter of each column (e.g. metres before the tree).
        actions: (G,) the action of each row.
        energies: (n, G) energies.
        expert: optional (x, y) arrays of expert samples to overlay as dots.
        path: optional (n,) action per column to draw as a red line (e.g. the argmin).
        labels: the x and y axis labels.

    The x axis runs from the largest distance (left) to the smallest, in the car's direction of travel.
    """
    e = as_array(energies, float)
    e = e - e.min(axis=1, keepdims=True)  # (n, G)
    x, y = as_array(distances, float), as_array(actions, float)
    fig, ax, own = figure_and_axes(ax, (7.0, 3.8))
    mesh = ax.pcolormesh(x, y, e.T, cmap="viridis", shading="nearest", vmax=np.percentile(e, 90))
    fig.colorbar(mesh, ax=ax, label="E − min over actions (nats)")
    if expert is not None:
        ax.scatter(
            as_array(expert[0]), as_array(expert[1]), s=2, color="w", alpha=0.35, label="expert samples"
        )
    if path is not None:
        ax.plot(x, as_array(path, float), color="red", lw=1.5, label="argmin over actions")
    if expert is not None or path is not None:
        ax.legend(loc="lower left", fontsize=8, markerscale=4, facecolor="0.55")
    ax.set_xlim(x.max(), x.min())  # far on the left: the car drives from left to right
    label_axes(ax, *labels, title)
    return finish(fig, own)


def plot_energy_curves(
    actions, curves: dict, *, title: str, xlabel: str = STEER_LABEL, probability: bool = True, ax=None
):
    """Energy over actions for a few observations (one line each), as p(y|x) ∝ exp(-E) or as E.

    Args:
        actions: (G,) a regular grid of actions.
        curves: {label: (G,) energies}.
        probability: draw the normalised density exp(-E)/Z over the grid instead of E.
    """
    a = as_array(actions, float)
    fig, ax, own = figure_and_axes(ax, (6.0, 3.6))
    for i, (label, e) in enumerate(curves.items()):
        e = as_array(e, float)
        if probability:
            p = np.exp(-(e - e.min()))
            y = p / (p.sum() * (a[1] - a[0]))
        else:
            y = e
        ax.plot(a, y, color=f"C{i}", lw=1.6, label=label)
    ylabel = "p(y | x) ∝ exp(−E) (per unit of action)" if probability else "E(x, y) (nats)"
    label_axes(ax, xlabel, ylabel, title, legend=True)
    return finish(fig, own)


def plot_command_traces(
    dt: float,
    traces: dict,
    *,
    title: str = "Steering commands of one episode",
    ylabel: str = "steering command",
    reference: str | None = None,
    shade: tuple[float, float] | None = None,
):
    """Command sequences over time (to see what whiteness measures), one panel per policy, stacked
    on a shared time axis, so that traces that nearly coincide stay apart and readable.

    Args:
        dt: seconds between commands.
        traces: {label: (T,) commands}, one panel each, in order.
        reference: a key of ``traces`` (e.g. the experts) drawn thin and grey in every other
            panel as well, to compare against; None = no reference.
        shade: (start, end) in seconds, shaded in every panel (e.g. the window a measure uses);
            None = nothing shaded.
    """
    check_panels("traces", traces)
    if shade is not None and not (len(shade) == 2 and 0 <= shade[0] < shade[1]):
        raise ValueError(f"shade must be (start, end) seconds with 0 <= start < end, got {shade!r}")
    if reference is not None and reference not in traces:
        raise ValueError(f"reference must be one of the keys of traces {list(traces)}, got {reference!r}")
    n = len(traces)
    fig, axes = plt.subplots(n, 1, figsize=(7.0, 0.6 + 1.25 * n), sharex=True, sharey=True, squeeze=False)
    ref = None if reference is None else as_array(traces[reference], float).reshape(-1)
    for i, (ax, (label, x)) in enumerate(zip(axes[:, 0], traces.items(), strict=True)):
        x = as_array(x, float).reshape(-1)
        if ref is not None and label != reference:
            ax.plot(np.arange(len(ref)) * dt, ref, color="0.6", lw=0.9, label=reference)
        ax.plot(np.arange(len(x)) * dt, x, color=f"C{i}", lw=1.4, label=label)
        ax.axhline(0.0, color="0.85", lw=0.6, zorder=0)
        if shade is not None:
            ax.axvspan(*shade, color="0.92", zorder=-1, label="measured" if i == 0 else None)
        ax.set_ylim(-1.1, 1.1)
        ax.legend(loc="upper left", fontsize=7, ncol=2, frameon=False)
    axes[-1, 0].set_xlabel(TIME_LABEL)
    axes[n // 2, 0].set_ylabel(ylabel)  # one label for the shared axis, beside the middle panel
    axes[0, 0].set_title(title)
    return finish(fig, True)


def plot_response_map(
    prev,
    responses: dict,
    *,
    title: str,
    xlabel: str = "previous steering (−1 left … +1 right)",
    ylabel: str = "next steering command (−1 left … +1 right)",
    seen: tuple[float, float] | None = None,
    seen_label: str = "previous steering of the experts here",
):
    """What a policy fed its previous action does with it: the next command against the previous
    one at one observation, one line per policy, with the diagonal of a policy that copies
    (dashed). Where a line crosses the diagonal, the command repeats itself: a fixed point.

    Args:
        prev: (N,) previous actions.
        responses: {label: (N,) commands at those previous actions}.
        seen: (low, high) previous actions shaded, labelled ``seen_label`` (e.g. the range the
            demonstrations hold at this observation); None = nothing shaded.
    """
    if seen is not None and not (len(seen) == 2 and -1 <= seen[0] < seen[1] <= 1):
        raise ValueError(f"seen must be (low, high) with -1 <= low < high <= 1, got {seen!r}")
    x = as_array(prev, float).reshape(-1)
    fig, ax = plt.subplots(figsize=(5.6, 4.2))
    if seen is not None:
        ax.axvspan(*seen, color="0.9", zorder=-1, label=seen_label)
    ax.plot([-1, 1], [-1, 1], "--", color="0.5", lw=1.0, label="copies the previous action")
    for i, (label, y) in enumerate(responses.items()):
        y = as_array(y, float).reshape(-1)
        if y.shape != x.shape:
            raise ValueError(f"responses[{label!r}] must have shape {x.shape}, got {y.shape}")
        ax.plot(x, y, color=f"C{i}", lw=1.6, label=label)
    ax.set_xlim(-1, 1)
    ax.set_ylim(-1.05, 1.05)
    label_axes(ax, xlabel, ylabel, title, legend=True)
    return finish(fig, True)
