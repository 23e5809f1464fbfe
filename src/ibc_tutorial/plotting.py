"""Figures for the book.

``show(fig)`` is how every chapter displays a figure: it emits only a PNG (no
``<Figure size ...>`` text that nbval would compare) and closes the figure. Figure
functions below are grouped by chapter; each gives its axes titles, labels and units.
"""

from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg", force=False)
import matplotlib.pyplot as plt  # noqa: E402

DPI = 90
"""Resolution of figures stored in notebooks (keeps each chapter well under 3 MB)."""


def show(fig, *, dpi: int = DPI) -> None:
    """Display ``fig`` as a PNG only, then close it.

    In Jupyter this shows the picture; the output holds no text that nbval would compare.
    Outside IPython it does nothing but close the figure.
    """
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    try:
        from IPython import get_ipython
        from IPython.display import display
    except ImportError:  # pragma: no cover - IPython is always installed with jupyter
        return
    if get_ipython() is not None:
        display({"image/png": buf.getvalue()}, raw=True)


def save(fig, path, *, dpi: int = 120) -> None:
    """Save ``fig`` to ``path`` atomically (e.g. for the README) and close it."""
    from ibc_tutorial.utils import atomic_write_bytes

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


# =========================================================================== chapter 01: the tree
TREE_SIDE_COLORS = {-1: "C0", 1: "C1", 0: "C3"}
"""Colours of the tree chapters: passed on the left (blue), on the right (orange), collided (red)."""


def _draw_tree(ax, world) -> None:
    """The tree (green disc) and, dashed, the circle the car's centre must stay out of."""
    c = world.config
    ax.add_patch(plt.Circle((c.tree_x, 0.0), c.tree_radius, color="forestgreen", zorder=3))
    ax.add_patch(plt.Circle((c.tree_x, 0.0), world.clearance, fill=False, ls="--", lw=0.8, color="forestgreen", zorder=3))


def plot_tree_scene(world, states, modes, *, title: str = "Expert demonstrations in the tree world", max_episodes: int = 100, ax=None):
    """Expert trajectories ``states`` (E, T+1, 3) seen from above, coloured by ``modes`` (E,):
    0 passes on the left (blue), 1 on the right (orange); the tree as a green disc, the dashed
    circle marks where the car's disc would touch it."""
    fig, ax = (ax.figure, ax) if ax is not None else plt.subplots(figsize=(9, 3.6))
    s = states.numpy() if hasattr(states, "numpy") else states
    m = modes.numpy() if hasattr(modes, "numpy") else modes
    for e in range(min(len(s), max_episodes)):
        ax.plot(s[e, :, 0], s[e, :, 1], color="C0" if m[e] == 0 else "C1", lw=0.8, alpha=0.6)
    _draw_tree(ax, world)
    ax.plot([], [], color="C0", label=f"passes left ({int((m == 0).sum())})")
    ax.plot([], [], color="C1", label=f"passes right ({int((m == 1).sum())})")
    ax.set_xlabel("x (m, direction of travel)")
    ax.set_ylabel("y (m, left > 0)")
    ax.set_aspect("equal")
    ax.set_title(title)
    ax.legend(loc="lower left", fontsize=8)
    return fig


def plot_actions_by_distance(world, demos, *, predictions: dict | None = None, window: tuple | None = None, title: str = "What the policy sees, and what the experts did", max_points: int = 6000):
    """Each expert sample as a dot: the observation (distance to the tree, m) against the action
    (steering), coloured by the expert's side; optional ``predictions`` {name: (distances, actions)}
    drawn as lines, ``window`` = (low, high) m shaded. The x axis runs towards the tree."""
    import numpy as np

    fig, ax = plt.subplots(figsize=(9, 3.8))
    d = world.physical(demos.obs)[:, 0].numpy()
    a = demos.actions[:, 0].numpy()
    m = demos.mode.numpy()
    idx = np.random.default_rng(0).permutation(len(d))[:max_points]
    for mode, color, name in ((0, "C0", "passes left"), (1, "C1", "passes right")):
        sel = idx[m[idx] == mode]
        ax.scatter(d[sel], a[sel], s=3, color=color, alpha=0.35, label=f"expert, {name}", rasterized=True)
    if window is not None:
        ax.axvspan(window[0], window[1], color="0.85", zorder=0, label="window of the histogram")
    for i, (name, (x, y)) in enumerate((predictions or {}).items()):
        x = x.numpy() if hasattr(x, "numpy") else np.asarray(x)
        y = y.numpy() if hasattr(y, "numpy") else np.asarray(y)
        ax.plot(x.reshape(-1), y.reshape(-1), color=["k", "C3", "C2", "C4"][i % 4], lw=2, ls=["-", "--", "-.", ":"][i % 4], label=name)
    ax.axvline(0.0, color="forestgreen", lw=1.5)
    ax.text(0.0, 1.02, " tree", color="forestgreen", va="bottom", fontsize=8)
    ax.set_xlim(d.max() + 0.5, d.min() - 0.5)
    ax.set_ylim(-1.1, 1.15)
    ax.set_xlabel("observation: distance ahead to the tree (m)")
    ax.set_ylabel("steering (−1 right … +1 left)")
    ax.set_title(title)
    ax.legend(loc="lower left", fontsize=8, markerscale=3)
    return fig


def plot_action_histogram(actions, modes, *, title: str, bins: int = 40, mode_names=("passes left", "passes right")):
    """Histogram of the actions ``actions`` (N,) in [-1, 1], stacked by the experts' ``modes`` (N,)."""
    import numpy as np

    a = actions.numpy() if hasattr(actions, "numpy") else np.asarray(actions)
    m = modes.numpy() if hasattr(modes, "numpy") else np.asarray(modes)
    fig, ax = plt.subplots(figsize=(6.4, 3.4))
    ax.hist([a[m == 0], a[m == 1]], bins=bins, range=(-1, 1), stacked=True, color=["C0", "C1"], label=list(mode_names))
    ax.axvline(float(a.mean()), color="k", ls="--", lw=1.2, label=f"mean of all ({a.mean():+.2f})")
    ax.set_xlabel("steering (−1 right … +1 left)")
    ax.set_ylabel("number of samples")
    ax.set_title(title)
    ax.legend(fontsize=8)
    return fig


def plot_constant_losses(constants, losses: dict, *, minimisers: dict | None = None, flat: dict | None = None, title: str = "Loss of predicting one constant action for all the samples"):
    """Curves ``losses`` {name: (G,)} over the constant prediction ``constants`` (G,); ``minimisers``
    {name: value} marked with a dot, ``flat`` {name: (low, high)} shaded (an interval of minimisers)."""
    import numpy as np

    c = constants.numpy() if hasattr(constants, "numpy") else np.asarray(constants)
    fig, axes = plt.subplots(1, len(losses), figsize=(4.6 * len(losses), 3.4))
    axes = np.atleast_1d(axes)
    for i, (ax, (name, loss)) in enumerate(zip(axes, losses.items())):
        loss = loss.numpy() if hasattr(loss, "numpy") else np.asarray(loss)
        color = f"C{i + 2}"
        ax.plot(c, loss, color=color, lw=2)
        if flat and name in flat:
            lo, hi = flat[name]
            ax.axvspan(lo, hi, color=color, alpha=0.15, label=f"minimisers: [{lo:+.2f}, {hi:+.2f}]")
        if minimisers and name in minimisers:
            v = float(minimisers[name])
            ax.plot([v], [np.interp(v, c, loss)], "o", color="k", label=f"minimiser {v:+.2f}")
        ax.set_xlabel("constant prediction c (steering)")
        ax.set_ylabel(f"{name} loss")
        ax.set_title(name)
        ax.legend(fontsize=8, loc="upper center")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_tree_closed_loop(world, rollouts: dict, *, title: str = "Closed-loop rollouts in the tree world", max_episodes: int = 60):
    """One panel per policy ({name: Rollouts}): trajectories from above, coloured by how they pass
    the tree (left blue, right orange, collided red, with a cross where the car stopped)."""
    import numpy as np

    n = len(rollouts)
    fig, axes = plt.subplots(n, 1, figsize=(8.5, 2.2 * n), sharex=True, sharey=True)
    axes = np.atleast_1d(axes)
    for ax, (name, r) in zip(axes, rollouts.items()):
        side = world.pass_side(r).numpy()
        s = r.states.numpy()
        hit = r.collided.numpy()
        for e in range(min(len(s), max_episodes)):
            ax.plot(s[e, :, 0], s[e, :, 1], color=TREE_SIDE_COLORS[int(side[e])], lw=0.8, alpha=0.6)
            if hit[e]:
                ax.plot(s[e, -1, 0], s[e, -1, 1], "x", color="C3", ms=4)
        _draw_tree(ax, world)
        counts = ", ".join(f"{label} {float(np.mean(side == v)):.0%}" for v, label in ((-1, "left"), (1, "right"), (0, "collided")))
        ax.set_title(f"{name}: {counts} of {len(side)} episodes", fontsize=10)
        ax.set_ylabel("y (m, left > 0)")
        ax.set_aspect("equal")
    axes[-1].set_xlabel("x (m, direction of travel)")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def _draw_side_road(ax, world, x_end: float) -> None:
    """The drivable area of the side-road world in grey: the main road and the side road."""
    import math

    import numpy as np
    from matplotlib.patches import Polygon

    c = world.config
    w = c.road_half_width
    ax.add_patch(plt.Rectangle((-1.0, -w), x_end + 1.0, 2 * w, color="0.88", zorder=0))
    a = math.radians(c.side_angle_deg)
    u, nrm = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    b = np.array([c.branch_x, 0.0])
    length = (x_end - c.branch_x) / math.cos(a) + w
    corners = [b - w * nrm, b + w * nrm, b + w * nrm + length * u, b - w * nrm + length * u]
    ax.add_patch(Polygon(corners, closed=True, color="0.88", zorder=0))


def plot_side_road(world, rollouts: dict, *, title: str = "The side road", max_episodes: int = 60):
    """One panel per policy ({name: Rollouts}) over the roads: episodes that end on the main road
    (blue), on the side road (green), off the road (red)."""
    import numpy as np

    n = len(rollouts)
    fig, axes = plt.subplots(n, 1, figsize=(8.5, 2.8 * n), sharex=True, sharey=True)
    axes = np.atleast_1d(axes)
    for ax, (name, r) in zip(axes, rollouts.items()):
        s = r.states.numpy()
        main = world.stayed_on_main_road(r).numpy()
        side = world.took_side_road(r).numpy()
        _draw_side_road(ax, world, float(s[:, :, 0].max()) + 1.0)
        for e in range(min(len(s), max_episodes)):
            color = "C0" if main[e] else ("C2" if side[e] else "C3")
            ax.plot(s[e, :, 0], s[e, :, 1], color=color, lw=0.8, alpha=0.6)
        sw = world.swerve(r).numpy()
        stay = ~np.isnan(sw)
        mean = f"{np.nanmean(sw):.2f} m" if stay.any() else "n/a"
        ax.set_title(f"{name}: main road {main.mean():.0%}, side road {side.mean():.0%}, off road {r.collided.float().mean():.0%}; mean swerve {mean}", fontsize=10)
        ax.set_ylabel("y (m, left > 0)")
        ax.set_aspect("equal")
    axes[-1].set_xlabel("x (m, direction of travel)")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


# =========================================================================== chapter 02: explicit policies
def plot_beta_shapes(params, *, title: str = "Beta densities f(y'; α, β) of eq. 1"):
    """Densities of Beta(α, β) on the rescaled action y' = (y + 1)/2 in (0, 1), one curve per
    ``(alpha, beta)`` pair in ``params``; the y axis is cut at 4 (U-shapes go to infinity at the ends)."""
    import numpy as np
    import torch

    fig, ax = plt.subplots(figsize=(7, 4))
    z = torch.linspace(1e-3, 1 - 1e-3, 999, dtype=torch.float64)
    for a, b in params:
        dens = torch.distributions.Beta(torch.tensor(float(a), dtype=torch.float64), torch.tensor(float(b), dtype=torch.float64)).log_prob(z).exp()
        style = "--" if a < 1 and b < 1 else "-"
        ax.plot(z.numpy(), np.minimum(dens.numpy(), 10.0), style, label=f"α = {a:g}, β = {b:g}")
    ax.set_ylim(0, 4)
    ax.set_xlim(0, 1)
    ax.set_xlabel("rescaled action y' = (y + 1)/2 (y: steering, -1 = full right, +1 = full left)")
    ax.set_ylabel("density f(y'; α, β) (per unit y')")
    ax.set_title(title)
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5), title="dashed: U-shapes", title_fontsize=8)
    return fig


def _policy_point_actions(policy, obs):
    """{label: action} of the deterministic ways of acting of ``policy`` at ``obs`` (1, obs_dim)."""
    point_modes = {"deterministic", "mean", "mode", "argmax", "paper"}
    return {m: float(policy.act(obs, mode=m)[0, 0]) for m in policy.modes if m in point_modes}


def plot_action_distributions(policies, obs, data_actions, *, dim: int = 0, where: str = "", n_values: int = 801):
    """One panel per policy: the histogram of the expert's actions ``data_actions`` (M,) near the
    observation ``obs`` (1, obs_dim), the policy's predicted density of action dimension ``dim``
    there (``action_density``) and vertical lines at its deterministic actions.

    ``policies`` maps a name to an ``ExplicitPolicy``; ``where`` describes the place for the title.
    """
    import numpy as np
    import torch

    names = list(policies)
    fig, axes = plt.subplots(1, len(names), figsize=(3.6 * len(names), 3.4), sharey=True, squeeze=False)
    values = torch.linspace(-1, 1, n_values)
    data = np.asarray(data_actions, dtype=float).reshape(-1)
    colors = {"deterministic": "C3", "mean": "C3", "mode": "C2", "argmax": "C3", "paper": "C3"}
    ymax = 1.0
    for ax, name in zip(axes[0], names):
        policy = policies[name]
        ax.hist(data, bins=40, range=(-1, 1), density=True, color="0.75", label=f"expert data (n = {len(data)})")
        heights, _ = np.histogram(data, bins=40, range=(-1, 1), density=True)
        ymax = max(ymax, float(heights.max()))
        if policy.has_density:
            with torch.no_grad():
                dens = policy.action_density(obs, values)[0, :, dim].numpy()
            ax.plot(values.numpy(), dens, color="C0", lw=1.5, label="predicted density")
            ymax = max(ymax, float(np.quantile(dens, 0.995)))
        for mode, a in _policy_point_actions(policy, obs).items():
            ax.axvline(a, color=colors.get(mode, "C3"), ls="--", lw=1.5, label=f"act: {mode} = {a:+.2f}")
        ax.set_title(name)
        ax.set_xlabel("steering action y (-1 right, +1 left)")
        ax.set_xlim(-1, 1)
        ax.legend(fontsize=7, loc="upper left")
    axes[0, 0].set_ylabel("density (per unit action)")
    for ax in axes[0]:
        ax.set_ylim(0, 1.25 * ymax)
    fig.suptitle(f"Predicted action distribution vs expert data {where}".strip())
    fig.tight_layout()
    return fig


def plot_density_fits(data_actions, values, curves: dict, *, title: str, bins: int = 40):
    """Histogram (density) of ``data_actions`` (N,) in [-1, 1] with density curves ``curves``
    {label: (G,)} evaluated at ``values`` (G,) drawn over it."""
    import numpy as np

    data = np.asarray(data_actions, dtype=float).reshape(-1)
    v = values.numpy() if hasattr(values, "numpy") else np.asarray(values)
    fig, ax = plt.subplots(figsize=(6.8, 3.6))
    ax.hist(data, bins=bins, range=(-1, 1), density=True, color="0.75", label=f"expert actions (n = {len(data)})")
    top = 0.0
    for i, (label, dens) in enumerate(curves.items()):
        d = dens.numpy() if hasattr(dens, "numpy") else np.asarray(dens)
        ax.plot(v, d, color=f"C{i}", lw=2, label=label)
        top = max(top, float(np.quantile(d, 0.98)))
    heights, _ = np.histogram(data, bins=bins, range=(-1, 1), density=True)
    ax.set_ylim(0, 1.15 * max(top, float(heights.max())))
    ax.set_xlim(-1, 1)
    ax.set_xlabel("steering action y (-1 right, +1 left)")
    ax.set_ylabel("density (per unit action)")
    ax.set_title(title)
    ax.legend(fontsize=8, loc="upper center")
    return fig


def plot_rollout_grid(world, rollouts: dict, *, title: str, ncols: int = 2, max_episodes: int = 40):
    """Closed-loop trajectories of several policies ({name: Rollouts}) over the scene, one panel
    each, in a grid. Tree world: coloured by the side passed (left blue, right orange, collided
    red with a cross). Side-road world: ended on the main road (blue), on the side road (green),
    off the road (red with a cross)."""
    import numpy as np

    tree = hasattr(world, "pass_side")
    n = len(rollouts)
    nrows = -(-n // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(5.6 * ncols, 2.0 * nrows + 0.4), sharex=True, sharey=True, squeeze=False, layout="compressed")
    x_end = max(float(r.states[:, :, 0].max()) for r in rollouts.values()) + 1.0
    for ax, (name, r) in zip(axes.flat, rollouts.items()):
        s = r.states.numpy()
        hit = r.collided.numpy()
        if tree:
            side = world.pass_side(r).numpy()
            colors = [TREE_SIDE_COLORS[int(v)] for v in side]
            summary = f"collided {hit.mean():.0%}, left {np.mean(side == -1):.0%}, right {np.mean(side == 1):.0%}"
            _draw_tree(ax, world)
        else:
            main = world.stayed_on_main_road(r).numpy()
            took = world.took_side_road(r).numpy()
            colors = ["C0" if m else ("C2" if t else "C3") for m, t in zip(main, took)]
            summary = f"main {main.mean():.0%}, side road {took.mean():.0%}, off road {hit.mean():.0%}"
            _draw_side_road(ax, world, x_end)
        for e in range(min(len(s), max_episodes)):
            ax.plot(s[e, :, 0], s[e, :, 1], color=colors[e], lw=0.8, alpha=0.6)
            if hit[e]:
                ax.plot(s[e, -1, 0], s[e, -1, 1], "x", color="C3", ms=4)
        ax.set_title(f"{name}: {summary}", fontsize=9)
        ax.set_aspect("equal")
    for k in range(n, nrows * ncols):  # empty panels: hide them, label the axis of the panel above
        axes.flat[k].axis("off")
        if k - ncols >= 0:
            axes.flat[k - ncols].xaxis.set_tick_params(labelbottom=True)
            axes.flat[k - ncols].set_xlabel("x (m, direction of travel)")
    for ax in axes[:, 0]:
        ax.set_ylabel("y (m, left > 0)")
    for ax in axes[-1]:
        if ax.axison:
            ax.set_xlabel("x (m, direction of travel)")
    fig.suptitle(title)
    return fig


# =========================================================================== chapter 03: energy models and InfoNCE
def plot_energy_landscape(distances, actions, energies, *, expert=None, path=None, title: str = "The energy landscape", xlabel: str = "distance to the tree (m)", ylabel: str = "steering (-1 right ... +1 left)", ax=None):
    """E(x, y) with the observation along x and the action along y, shifted per observation so
    that its minimum over actions is 0 (dark = low energy = likely action).

    Args:
        distances: (n,) the observation parameter of each column (e.g. metres before the tree).
        actions: (G,) the action of each row.
        energies: (n, G) energies.
        expert: optional (x, y) arrays of expert samples to overlay as dots.
        path: optional (n,) action per column to draw as a red line (e.g. the argmin).

    The x axis runs from the largest distance (left) to the smallest, in the car's direction of travel.
    """
    import numpy as np

    e = np.asarray(energies, dtype=float)
    e = e - e.min(axis=1, keepdims=True)
    x, y = np.asarray(distances, dtype=float), np.asarray(actions, dtype=float)
    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(7.0, 3.8))
    else:
        fig = ax.figure
    mesh = ax.pcolormesh(x, y, e.T, cmap="viridis", shading="nearest", vmax=np.percentile(e, 90))
    fig.colorbar(mesh, ax=ax, label="E − min over actions (nats)")
    if expert is not None:
        ax.scatter(np.asarray(expert[0]), np.asarray(expert[1]), s=2, color="w", alpha=0.35, label="expert samples")
    if path is not None:
        ax.plot(x, np.asarray(path, dtype=float), color="red", lw=1.5, label="argmin over actions")
    if expert is not None or path is not None:
        ax.legend(loc="lower left", fontsize=8, markerscale=4, facecolor="0.55")
    ax.set_xlim(x.max(), x.min())  # far on the left: the car drives from left to right
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    if own:
        fig.tight_layout()
    return fig


def plot_energy_curves(actions, curves: dict, *, title: str, xlabel: str = "steering (-1 right ... +1 left)", probability: bool = True, ax=None):
    """Energy over actions for a few observations (one line each), as p(y|x) ∝ exp(-E) or as E.

    Args:
        actions: (G,) a regular grid of actions.
        curves: {label: (G,) energies}.
        probability: draw the normalised density exp(-E)/Z over the grid instead of E.
    """
    import numpy as np

    a = np.asarray(actions, dtype=float)
    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(6.0, 3.6))
    else:
        fig = ax.figure
    for i, (label, e) in enumerate(curves.items()):
        e = np.asarray(e, dtype=float)
        if probability:
            p = np.exp(-(e - e.min()))
            y = p / (p.sum() * (a[1] - a[0]))
        else:
            y = e
        ax.plot(a, y, color=f"C{i}", lw=1.6, label=label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("p(y | x) ∝ exp(−E) (per unit of action)" if probability else "E(x, y) (nats)")
    ax.set_title(title)
    ax.legend(fontsize=8)
    if own:
        fig.tight_layout()
    return fig


def plot_command_traces(dt: float, traces: dict, *, title: str = "Steering commands of one episode", ylabel: str = "steering command"):
    """Command sequences over time, one line per policy (to see what whiteness measures)."""
    import numpy as np

    fig, ax = plt.subplots(figsize=(7.0, 3.4))
    for i, (label, x) in enumerate(traces.items()):
        x = np.asarray(x, dtype=float).reshape(-1)
        ax.plot(np.arange(len(x)) * dt, x, color=f"C{i}", lw=1.2, label=label)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


# =========================================================================== chapter 04: DA-IBC counter-examples
def plot_counter_examples(expert_actions, situation, negatives: dict, *, situation_names=("cruise", "junction", "red light"), max_points: int = 3000):
    """Expert actions coloured by situation, then one panel per sampler with its counter-examples.

    Args:
        expert_actions: (M, 2) [steer, acceleration]; situation: (M,) int index into ``situation_names``.
        negatives: {sampler name: (K, 2) counter-examples}.
    """
    import numpy as np

    a = np.asarray(expert_actions)[:max_points]
    s = np.asarray(situation)[:max_points]
    n = 1 + len(negatives)
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 3.6), sharex=True, sharey=True)
    for k, name in enumerate(situation_names):
        axes[0].scatter(a[s == k, 0], a[s == k, 1], s=4, alpha=0.6, label=name)
    axes[0].set_title("expert actions")
    axes[0].legend(loc="lower left", fontsize=8, markerscale=3)
    for ax, (name, neg) in zip(axes[1:], negatives.items()):
        neg = np.asarray(neg)[:max_points]
        ax.scatter(a[:, 0], a[:, 1], s=3, color="0.75", label="expert actions")
        ax.scatter(neg[:, 0], neg[:, 1], s=3, color="tab:red", alpha=0.5, label="counter-examples")
        ax.set_title(name)
        ax.legend(loc="lower left", fontsize=8, markerscale=3)
    for ax in axes:
        ax.set_xlim(-1.25, 1.25)
        ax.set_ylim(-1.25, 1.25)
        ax.add_patch(plt.Rectangle((-1, -1), 2, 2, fill=False, ls="--", color="k", lw=0.8))
        ax.set_xlabel("steer (-1 left ... +1 right)")
        ax.set_aspect("equal")
    axes[0].set_ylabel("acceleration (< 0: braking)")
    fig.suptitle("Where the counter-examples fall (dashed: the action box [-1, 1]²)")
    fig.tight_layout()
    return fig


def plot_learning_curves(steps, curves: dict, *, ylabel: str, title: str, references: dict | None = None):
    """One colour per method: thin lines per seed, a thick line for the mean over seeds.

    Args:
        steps: (T,) steps of the evaluations.
        curves: {method: (S, T) values for S seeds}.
        references: optional {label: value} horizontal lines (e.g. the expert's own NLL).
    """
    import numpy as np

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for i, (name, values) in enumerate(curves.items()):
        v = np.asarray(values, dtype=float)
        color = f"C{i}"
        for row in v:
            ax.plot(steps, row, color=color, lw=0.8, alpha=0.4)
        ax.plot(steps, v.mean(axis=0), color=color, lw=2.2, label=f"{name} (mean of {len(v)} seeds)")
    for j, (label, value) in enumerate((references or {}).items()):
        ax.axhline(value, color="k", ls=[":", "--", "-."][j % 3], lw=1, label=label)
    ax.set_xlabel("training step")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_sigma_sweep(sigmas, values, *, uniform=None, ylabel: str, title: str):
    """A measure against the noise σ of DA-IBC's counter-examples (log axis), one dot per seed.

    Args:
        sigmas: (K,) the σ values; values: (K, S) the measure per σ and seed.
        uniform: optional (S,) the same measure with uniform counter-examples (drawn as a band).
    """
    import numpy as np

    v = np.asarray(values, dtype=float)
    s = np.asarray(sigmas, dtype=float)
    fig, ax = plt.subplots(figsize=(6.0, 3.8))
    for j in range(v.shape[1]):
        ax.scatter(s, v[:, j], color="C1", s=14, alpha=0.6)
    ax.plot(s, v.mean(axis=1), color="C1", lw=2, marker="o", label="expert + N(0, σ²) (DA-IBC), mean over seeds")
    if uniform is not None:
        u = np.asarray(uniform, dtype=float)
        ax.axhspan(u.min(), u.max(), color="C0", alpha=0.2)
        ax.axhline(u.mean(), color="C0", lw=2, label="uniform (IBC), mean and range over seeds")
    ax.set_xscale("log")
    ax.set_xlabel("σ of the counter-examples' noise (action units)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_energy_2d(energies, axis, *, title: str, unvisited=None, modes=None, argmin=None, ax=None):
    """An energy landscape over 2-D actions: x steer, y acceleration; low energy dark.

    Args:
        energies: (n, n) energies on ``axis`` × ``axis``, indexed [steer, acceleration].
        axis: (n,) the grid's values on each axis.
        unvisited: optional (n, n) bool, cells no counter-example visited (hatched).
        modes: optional (K, 2) the expert's valid actions (white circles).
        argmin: optional (2,) the grid argmin (a red cross).
    """
    import numpy as np

    e = np.asarray(energies, dtype=float)
    x = np.asarray(axis, dtype=float)
    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(4.8, 4.2))
    else:
        fig = ax.figure
    mesh = ax.pcolormesh(x, x, (e - e.min()).T, cmap="viridis", shading="nearest", vmax=np.percentile(e - e.min(), 95))
    fig.colorbar(mesh, ax=ax, label="E − min E (nats)")
    if unvisited is not None:
        u = np.asarray(unvisited, dtype=float)
        ax.contourf(x, x, u.T, levels=[0.5, 1.5], colors="none", hatches=["//"])
        ax.contour(x, x, u.T, levels=[0.5], colors="w", linewidths=0.8)
    if modes is not None:
        m = np.asarray(modes, dtype=float)
        ax.scatter(m[:, 0], m[:, 1], s=80, facecolors="none", edgecolors="w", lw=1.5, label="expert's actions")
    if argmin is not None:
        ax.scatter([argmin[0]], [argmin[1]], marker="x", s=80, color="red", lw=2, label="argmin of E")
    if modes is not None or argmin is not None:
        ax.legend(loc="lower right", fontsize=8)
    ax.set_xlabel("steer (-1 left ... +1 right)")
    ax.set_ylabel("acceleration (< 0: braking)")
    ax.set_title(title)
    if own:
        fig.tight_layout()
    return fig


# =========================================================================== chapters 05-06: KDE weighting, DFO inference
def plot_bars(categories, series: dict, *, ylabel: str, title: str, points: dict | None = None, reference: dict | None = None, ax=None):
    """Grouped bars: one group per category, one bar per series (e.g. shares of situations per sampler).

    Args:
        categories: K group labels.
        series: {label: (K,) bar heights}.
        points: optional {label: (S, K) values per seed} drawn as dots on that series' bars.
        reference: optional {label: (K,) values} drawn as short black ticks over each group.
    """
    import numpy as np

    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(6.4, 3.8))
    else:
        fig = ax.figure
    k = len(categories)
    n = len(series)
    width = 0.8 / n
    x = np.arange(k)
    for i, (label, values) in enumerate(series.items()):
        pos = x - 0.4 + width * (i + 0.5)
        ax.bar(pos, np.asarray(values, dtype=float), width=width * 0.95, color=f"C{i}", label=label)
        if points is not None and label in points:
            p = np.asarray(points[label], dtype=float)
            for row in p:
                ax.scatter(pos, row, color="k", s=10, zorder=3)
    for j, (label, values) in enumerate((reference or {}).items()):
        v = np.asarray(values, dtype=float)
        ax.hlines(v, x - 0.45, x + 0.45, colors="k", linestyles=["--", ":"][j % 2], lw=1.2, label=label)
    ax.set_xticks(x)
    ax.set_xticklabels(categories)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=8)
    if own:
        fig.tight_layout()
    return fig


def plot_kde_by_hand(data, grid, bandwidth: float, density):
    """Eq. 4 in one dimension: each data point's kernel 1/(M h) K((x − x_j)/h) and their sum ĝ(x).

    Args:
        data: (M,) the data points x_j; grid: (G,) where to draw; density: (G,) ĝ on ``grid``.
    """
    import numpy as np

    x = np.asarray(grid, dtype=float)
    d = np.asarray(data, dtype=float)
    m, h = len(d), float(bandwidth)
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    for j, xj in enumerate(d):
        k = np.exp(-0.5 * ((x - xj) / h) ** 2) / np.sqrt(2 * np.pi) / (m * h)
        ax.plot(x, k, color="C0", lw=0.9, alpha=0.7, label="one kernel, 1/(Mh) K((x − x_j)/h)" if j == 0 else None)
    ax.plot(x, np.asarray(density, dtype=float), color="C1", lw=2.2, label="their sum: ĝ(x), eq. 4")
    ax.plot(d, np.zeros_like(d), "|", color="k", ms=14, mew=1.5, label="data points x_j")
    ax.set_xlabel("action (steer)")
    ax.set_ylabel("density (1 / action unit)")
    ax.set_title(f"Kernel density estimate by hand: M = {m} points, h = {h:g}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_kde_bandwidths(densities: dict, axis, actions=None, *, max_points: int = 1500):
    """One heat map of ĝ over the 2-D action box per bandwidth h (same colour scale: log density).

    Args:
        densities: {h: (n, n) ĝ on ``axis`` × ``axis``, indexed [steer, acceleration]}.
        axis: (n,) grid values; actions: optional (M, 2) the data, drawn as dots.
    """
    import numpy as np

    x = np.asarray(axis, dtype=float)
    n = len(densities)
    fig, axes = plt.subplots(1, n, figsize=(3.5 * n + 0.8, 3.6), sharex=True, sharey=True)
    axes = np.atleast_1d(axes)
    logs = {h: np.log10(np.maximum(np.asarray(d, dtype=float), 1e-6)) for h, d in densities.items()}
    vmax = max(v.max() for v in logs.values())
    vmin = vmax - 4
    for ax, (h, v) in zip(axes, logs.items()):
        mesh = ax.pcolormesh(x, x, v.T, cmap="magma", shading="nearest", vmin=vmin, vmax=vmax)
        if actions is not None:
            a = np.asarray(actions, dtype=float)[:max_points]
            ax.scatter(a[:, 0], a[:, 1], s=1, color="c", alpha=0.4)
        ax.set_title(f"h = {h:g}")
        ax.set_xlabel("steer (-1 left ... +1 right)")
        ax.set_aspect("equal")
    axes[0].set_ylabel("acceleration (< 0: braking)")
    fig.colorbar(mesh, ax=list(axes), label="log10 ĝ(y) (density per unit area)")
    fig.suptitle("KDE of the expert actions (eq. 4) for several bandwidths; dots: the actions")
    return fig


def plot_bandwidth_choice(bandwidths, heldout_loglik, rare_share, *, chosen: float = 0.2):
    """Two criteria against the bandwidth h: held-out log-likelihood of the KDE, and the share of rare
    actions in inverse-density-weighted minibatches.

    Args:
        bandwidths: (K,) h values; heldout_loglik: (K,) mean log ĝ at held-out actions (nats);
        rare_share: (K,) share of rare-situation samples in weighted minibatches.
    """
    import numpy as np

    h = np.asarray(bandwidths, dtype=float)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9.6, 3.6))
    a1.plot(h, np.asarray(heldout_loglik, dtype=float), marker="o")
    a1.set_ylabel("mean log ĝ(held-out action) (nats)")
    a1.set_title("How well ĝ predicts new actions")
    a2.plot(h, np.asarray(rare_share, dtype=float), marker="o", color="C1")
    a2.set_ylabel("share of rare situations in minibatches")
    a2.set_title("What the weights 1/ĝ do to minibatches")
    for ax in (a1, a2):
        ax.set_xscale("log")
        ax.axvline(chosen, color="k", ls="--", lw=1, label=f"h = {chosen:g} (the paper)")
        ax.set_xlabel("bandwidth h (action units)")
        ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_inverse_weights(actions, weights, *, max_points: int = 4000):
    """Expert actions coloured by their inverse-density weight w_i ∝ 1/ĝ(y_i) (log colour scale)."""
    import numpy as np
    from matplotlib.colors import LogNorm

    a = np.asarray(actions, dtype=float)[:max_points]
    w = np.asarray(weights, dtype=float)[:max_points] * len(np.asarray(weights))
    fig, ax = plt.subplots(figsize=(5.2, 4.2))
    order = np.argsort(w)
    sc = ax.scatter(a[order, 0], a[order, 1], c=w[order], s=5, cmap="viridis", norm=LogNorm())
    fig.colorbar(sc, ax=ax, label="M · w_i (1 = the uniform weight)")
    ax.set_xlim(-1.05, 1.05)
    ax.set_ylim(-1.05, 1.05)
    ax.set_aspect("equal")
    ax.set_xlabel("steer (-1 left ... +1 right)")
    ax.set_ylabel("acceleration (< 0: braking)")
    ax.set_title("Inverse-density weights of the expert actions (eq. 5)")
    fig.tight_layout()
    return fig


def plot_dfo_iterations(trace, grid, energy, *, iterations=None, bins: int = 60, title: str = "Algorithm 1, iteration by iteration"):
    """A 1-D energy landscape and the DFO population at each iteration (from ``inference.dfo_trace``).

    Args:
        trace: a ``DFOTrace`` of a 1-D action problem.
        grid: (G,) actions; energy: (G,) E on ``grid``.
        iterations: which iterations to draw (1-based); all by default.
    """
    import numpy as np

    its = list(iterations) if iterations is not None else list(range(1, len(trace.samples) + 1))
    fig, axes = plt.subplots(1, len(its), figsize=(3.0 * len(its), 3.3), sharey=True)
    axes = np.atleast_1d(axes)
    x = np.asarray(grid, dtype=float)
    e = np.asarray(energy, dtype=float)
    for ax, it in zip(axes, its):
        energy_ax = _draw_dfo_iteration(ax, trace, it, x, e, bins)
    axes[0].set_ylabel("share of samples per bin")
    energy_ax.set_ylabel("energy E(x, y) (red)", color="C3")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def _draw_dfo_iteration(ax, trace, it: int, x, e, bins: int):
    import numpy as np

    s = trace.samples[it - 1].numpy()[:, 0]
    lo, hi = float(x.min()), float(x.max())
    counts, edges = np.histogram(s, bins=bins, range=(lo, hi))
    ax.bar(edges[:-1], counts / len(s), width=edges[1] - edges[0], align="edge", color="C0", alpha=0.7, label="samples ỹ_i")
    ax.set_ylim(0, 1.05 * max(0.25, (counts / len(s)).max()))
    ax2 = ax.twinx()
    ax2.plot(x, e, color="C3", lw=1.5)
    ax2.set_ylim(e.min() - 0.5, e.min() + 1.3 * (np.percentile(e, 95) - e.min()) + 0.5)
    ax2.tick_params(axis="y", colors="C3", labelsize=7)
    last = it == len(trace.samples)
    sigma = trace.sigmas[it - 1]
    if last:
        ax.axvline(float(trace.action[0]), color="k", lw=2, label="returned ŷ")
        ax.set_title(f"iteration {it} (last)\nŷ drawn from p̃", fontsize=9)
    else:
        ax.set_title(f"iteration {it}\nthen resample, noise σ = {sigma:.3g}", fontsize=9)
    ax.set_xlabel("action y")
    ax.legend(loc="upper center", fontsize=7)
    return ax2


def plot_valley_shares(n_iters, shares: dict, *, prediction=None, ylabel: str = "share of calls ending in the shallow valley", title: str = ""):
    """Shares (e.g. of the shallow valley) against N_iters: one line per setting, optional prediction.

    Args:
        n_iters: (K,) iteration counts; shares: {label: (K,) measured shares};
        prediction: optional (K,) the share predicted by p(y|x)^k.
    """
    import numpy as np

    k = np.asarray(n_iters)
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    for i, (label, v) in enumerate(shares.items()):
        ax.plot(k, np.asarray(v, dtype=float), marker="o", color=f"C{i}", label=label)
    if prediction is not None:
        ax.plot(k, np.asarray(prediction, dtype=float), color="k", ls="--", lw=1.2, label="prediction: p(y|x)^k")
    ax.set_xlabel("N_iters (number of energy evaluations k)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.set_ylim(-0.02, max(0.6, ax.get_ylim()[1]))
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_lines(x, series: dict, *, xlabel: str, ylabel: str, title: str, logx: bool = False, logy: bool = False, ax=None, markers: bool = True):
    """Several lines against one x axis (e.g. hit rate against the number of samples, one per init)."""
    import numpy as np

    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(6.0, 3.8))
    else:
        fig = ax.figure
    for i, (label, v) in enumerate(series.items()):
        xs = np.asarray(x[label] if isinstance(x, dict) else x, dtype=float)
        ax.plot(xs, np.asarray(v, dtype=float), marker="o" if markers else None, ms=4, color=f"C{i}", label=label)
    if logx:
        ax.set_xscale("log")
        if not isinstance(x, dict):  # label the x values themselves, not the decades
            from matplotlib.ticker import NullFormatter

            xs = np.asarray(x, dtype=float)
            ax.set_xticks(xs)
            ax.set_xticklabels([f"{v:g}" for v in xs])
            ax.xaxis.set_minor_formatter(NullFormatter())
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=8)
    if own:
        fig.tight_layout()
    return fig


def plot_populations_2d(energies, axis, populations: dict, *, modes=None, title: str = "", max_points: int = 600):
    """Final populations of several optimisers over one 2-D energy landscape (one panel each).

    Args:
        energies: (n, n) energies on ``axis`` × ``axis`` (indexed [steer, acceleration]).
        populations: {label: (N, 2) samples}; modes: optional (K, 2) valid actions.
    """
    import numpy as np

    n = len(populations)
    fig, axes = plt.subplots(1, n, figsize=(4.4 * n, 3.9), sharex=True, sharey=True)
    axes = np.atleast_1d(axes)
    for ax, (label, pop) in zip(axes, populations.items()):
        plot_energy_2d(energies, axis, title=label, modes=modes, ax=ax)
        p = np.asarray(pop, dtype=float)[:max_points]
        ax.scatter(p[:, 0], p[:, 1], s=4, color="r", alpha=0.5, label="samples")
        ax.legend(loc="lower right", fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_tree_rollouts(world, rollouts: dict, *, max_episodes: int = 60):
    """Closed-loop trajectories in the tree world, one panel per policy: passes left (blue), right
    (orange), collisions (red), the tree as a disc."""
    import numpy as np

    n = len(rollouts)
    fig, axes = plt.subplots(n, 1, figsize=(9.0, 2.1 * n + 0.6), sharex=True, sharey=True)
    axes = np.atleast_1d(axes)
    c = world.config
    for ax, (label, r) in zip(axes, rollouts.items()):
        side = world.pass_side(r).numpy()
        s = r.states.numpy()
        for e in range(min(len(s), max_episodes)):
            color = {-1: "C0", 1: "C1", 0: "C3"}[int(side[e])]
            ax.plot(s[e, :, 0], s[e, :, 1], color=color, lw=0.8, alpha=0.7)
        ax.add_patch(plt.Circle((c.tree_x, 0.0), c.tree_radius, color="g"))
        left, right, hit = int((side == -1).sum()), int((side == 1).sum()), int((side == 0).sum())
        ax.set_title(f"{label}: left {left}, right {right}, collided or neither {hit} (of {len(side)})", fontsize=9)
        ax.set_aspect("equal")
        ax.set_ylabel("y (m, left > 0)")
    axes[-1].set_xlabel("x (m)")
    fig.suptitle("Closed-loop rollouts of the energy model with DFO inference")
    fig.tight_layout()
    return fig


# =========================================================================== chapter 07: the car and the town
def plot_town(town, *, stop_flags=None, ax=None, title: str | None = None, step: int = 2, margin: float = 8.0,
              markers: bool = True):
    """A town's map: roads (grey), lane boundaries (white), buildings (brown), stop lines coloured
    red where ``stop_flags`` (L,) is True and green elsewhere (white if None), and with
    ``markers`` a dot on each light so that it shows at the scale of a whole town."""
    import numpy as np

    from ibc_tutorial.driving.bev import get_raster
    from ibc_tutorial.driving.render import town_rgb

    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(6.0, 5.2))
    img, extent = town_rgb(get_raster(town.name), stop_flags, step=step)
    ax.imshow(img, extent=extent, interpolation="nearest")
    if markers and stop_flags is not None:
        pos = np.array([np.array(s.entry) - 0.6 * np.array(s.direction) for s in town.stop_lines])
        colour = np.where(np.asarray(stop_flags, dtype=bool), "#e02020", "#20c040")
        ax.scatter(pos[:, 0], pos[:, 1], c=colour, s=14, edgecolors="k", linewidths=0.4, zorder=3)
    x0, y0, x1, y1 = town.extent
    ax.set_xlim(x0 - margin, x1 + margin)
    ax.set_ylim(y0 - margin, y1 + margin)
    ax.set_xlabel("x (m, east)")
    ax.set_ylabel("y (m, north)")
    ax.set_title(title if title is not None else town.name)
    return ax.figure


def plot_towns(towns, stop_flags: dict | None = None):
    """Both towns side by side at the same scale, with their lights at one moment."""
    import numpy as np

    widths = [t.size[0] for t in towns]
    fig, axes = plt.subplots(1, len(towns), figsize=(11, 5.0), gridspec_kw={"width_ratios": widths})
    for ax, town in zip(np.atleast_1d(axes), towns):
        flags = None if stop_flags is None else stop_flags[town.name]
        w, h = town.size
        n_red = "" if flags is None else f", {int(np.sum(flags))} of {town.n_lights} lights red or yellow"
        plot_town(town, stop_flags=flags, ax=ax, title=f"{town.name}: {w:.0f} x {h:.0f} m, {town.n_junctions} T-junctions{n_red}")
        ax.title.set_fontsize(9)
    fig.tight_layout()
    return fig


def plot_junction(town, node: int, *, radius: float = 30.0, stop_flags=None, title: str = ""):
    """One junction up close: the lanes with their direction, the dense waypoints, the stop lines."""
    import numpy as np

    fig, ax = plt.subplots(figsize=(6.0, 6.0))
    plot_town(town, stop_flags=stop_flags, ax=ax, step=1, title=title, markers=False)
    cx, cy = town.nodes[node]
    colours = {"straight": "C0", "left": "C1", "right": "C2"}
    drawn = set()
    for lane in town.lanes:
        pts = lane.points
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
            ax.annotate("", xy=pts[i] + 1.5 * d, xytext=pts[i], arrowprops=dict(arrowstyle="->", color=c, lw=1.2))
    ax.set_xlim(cx - radius, cx + radius)
    ax.set_ylim(cy - radius, cy + radius)
    ax.legend(loc="lower left", fontsize=7, framealpha=0.9)
    fig.tight_layout()
    return fig


def plot_light_timeline(states, *, dt: float = 0.1, labels=None, title: str = "The three heads of one junction"):
    """Light states (T, H) (0 green, 1 yellow, 2 red) as coloured bars against time."""
    import numpy as np
    from matplotlib.colors import ListedColormap

    states = np.asarray(states)
    T, H = states.shape
    fig, ax = plt.subplots(figsize=(9.0, 0.6 * H + 1.2))
    cmap = ListedColormap(["#2ca02c", "#ffbf00", "#d62728"])
    ax.imshow(states.T, aspect="auto", cmap=cmap, vmin=0, vmax=2, interpolation="nearest", extent=(0, T * dt, H - 0.5, -0.5))
    ax.set_yticks(range(H))
    ax.set_yticklabels(labels if labels is not None else [f"head {h}" for h in range(H)])
    ax.set_xlabel("time (s)")
    ax.set_title(title + " (green, yellow, red)")
    fig.tight_layout()
    return fig


def plot_step_and_turn(t, speed, reference, trajectories: dict, *, radii: dict | None = None):
    """Left: speed against time (step response) with a reference; right: paths under constant steering."""
    import numpy as np

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    a.plot(t, speed, label="simulated car")
    a.plot(t, reference, "k--", lw=1, label="3 m/s² up, then 8 m/s² down (no drag)")
    a.set_xlabel("time (s)")
    a.set_ylabel("speed (m/s)")
    a.set_title("Step response: full throttle for 5 s, then full brake")
    a.legend(fontsize=8)
    for i, (label, xy) in enumerate(trajectories.items()):
        xy = np.asarray(xy)
        b.plot(xy[:, 0], xy[:, 1], color=f"C{i}", label=label)
        if radii is not None and label in radii:
            cx, cy, r = radii[label]
            b.add_patch(plt.Circle((cx, cy), r, fill=False, ls=":", color=f"C{i}", lw=1))
    b.set_aspect("equal")
    b.set_xlabel("x (m)")
    b.set_ylabel("y (m)")
    b.set_title("Turns at 4 m/s (dotted: L / tan(δ) circles)")
    b.legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_bev_channels(bev, small=None, *, title: str = "The bird's-eye view of one moment"):
    """The paper's Fig. 1(b-d): the five channels in colour with the car (and the small view), then each channel."""
    import numpy as np

    from ibc_tutorial.driving.bev import CHANNELS
    from ibc_tutorial.driving.render import bev_to_rgb, draw_ego

    fig = plt.figure(figsize=(11, 7.4))
    gs = fig.add_gridspec(2, 5, height_ratios=[1.75, 1])
    top = [fig.add_subplot(gs[0, :3])] + ([fig.add_subplot(gs[0, 3:])] if small is not None else [])
    top[0].imshow(draw_ego(bev_to_rgb(bev)), interpolation="nearest")
    top[0].set_title(f"all five channels, {bev.shape[1]}x{bev.shape[2]} (car in blue)", fontsize=10)
    if small is not None:
        top[1].imshow(draw_ego(bev_to_rgb(small)), interpolation="nearest")
        top[1].set_title(f"the same field at {small.shape[1]}x{small.shape[2]}", fontsize=10)
    bottom = [fig.add_subplot(gs[1, c]) for c in range(5)]
    for c, ax in enumerate(bottom):
        ax.imshow(bev[c], cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        ax.set_title(f"{c}: {CHANNELS[c]}", fontsize=9)
    for ax in top + bottom:
        ax.set_xticks([])
        ax.set_yticks([])
    top[0].set_ylabel(f"{bev.shape[1]} px = {bev.shape[1] / 5:.1f} m")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_drive(town, xy, actions, speed, *, dt: float = 0.1, title: str = "An expert drive", waits=None):
    """An episode on the map (colour = time) and its actions and speed against time."""
    import numpy as np

    xy, actions, speed = np.asarray(xy), np.asarray(actions), np.asarray(speed)
    fig = plt.figure(figsize=(11, 5.0))
    gs = fig.add_gridspec(3, 2, width_ratios=[1.0, 1.25])
    ax = fig.add_subplot(gs[:, 0])
    plot_town(town, ax=ax, title=title)
    sc = ax.scatter(xy[:, 0], xy[:, 1], c=np.arange(len(xy)) * dt, s=2, cmap="viridis")
    fig.colorbar(sc, ax=ax, label="time (s)", shrink=0.7)
    t = np.arange(len(xy)) * dt
    names = [("steer (+ right)", actions[:, 0]), ("acceleration (- brake)", actions[:, 1]), ("speed (m/s)", speed)]
    for k, (name, v) in enumerate(names):
        a = fig.add_subplot(gs[k, 1])
        a.plot(t, v, lw=0.7, color=f"C{k}")
        a.set_ylabel(name, fontsize=8)
        if k < 2:
            a.set_ylim(-1.05, 1.05)
            a.set_xticklabels([])
    a.set_xlabel("time (s)")
    fig.tight_layout()
    return fig


def plot_light_stop(t, gap, speed, light_states, *, gap_no_brake=None, title: str = "The expert at a red light"):
    """Distance to the stop line and speed against time, the light's state as the background."""
    import numpy as np

    t, gap, speed, light_states = map(np.asarray, (t, gap, speed, light_states))
    fig, (a, b) = plt.subplots(2, 1, figsize=(8.5, 5.0), sharex=True)
    colours = {0: "#2ca02c", 1: "#ffbf00", 2: "#d62728"}
    for ax in (a, b):
        start = 0
        for i in range(1, len(t) + 1):
            if i == len(t) or light_states[i] != light_states[start]:
                ax.axvspan(t[start], t[i - 1], color=colours[int(light_states[start])], alpha=0.15, lw=0)
                start = i
    a.plot(t, gap, label="expert")
    if gap_no_brake is not None:
        a.plot(t[: len(gap_no_brake)], gap_no_brake, "--", label="half throttle, ignoring the light")
    a.axhline(0, color="k", lw=0.8)
    a.set_ylabel("front bumper to\nstop line (m)")
    a.set_ylim(min(-10, np.nanmin(gap)), np.nanmax(gap) + 2)
    a.legend(fontsize=8)
    a.set_title(title + " (background: the light's state)")
    b.plot(t, speed, color="C2")
    b.set_ylabel("speed (m/s)")
    b.set_xlabel("time (s)")
    fig.tight_layout()
    return fig


def plot_routes(town, routes_xy, *, title: str = "The demonstration routes"):
    """Each route's path on the map in its own colour, its start marked."""
    import numpy as np

    fig, ax = plt.subplots(figsize=(7.5, 6.4))
    plot_town(town, ax=ax, title=title)
    cmap = plt.get_cmap("tab10")
    for k, xy in enumerate(routes_xy):
        xy = np.asarray(xy)
        ax.plot(xy[:, 0], xy[:, 1], color=cmap(k % 10), lw=1.6, alpha=0.8, label=f"route {k}")
        ax.plot(xy[0, 0], xy[0, 1], "o", color=cmap(k % 10), ms=6, mec="k")
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.0, 0.5))
    fig.tight_layout()
    return fig


def plot_action_histograms(actions, *, title: str = "The expert's actions in the dataset"):
    """Histograms of steering and acceleration (log counts)."""
    import numpy as np

    actions = np.asarray(actions)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    for ax, k, name in zip(axes, range(2), ("steering (+ right)", "acceleration (- brake)")):
        ax.hist(actions[:, k], bins=np.linspace(-1, 1, 81), color=f"C{k}")
        ax.set_yscale("log")
        ax.set_xlabel(name)
        ax.set_ylabel("samples (log scale)")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_exit_counts(town, counts: dict, *, title: str = "Exits taken at each junction approach"):
    """The map with, at every junction approach the data drives through, how often it left by each
    exit (L left, S straight, R right); approaches left by two different exits are boxed in red."""
    import numpy as np

    fig, ax = plt.subplots(figsize=(8.0, 6.8))
    plot_town(town, ax=ax, title=title)
    letters = {"left": "L", "straight": "S", "right": "R"}
    for ap_id, c in counts.items():
        ap = town.approaches[ap_id]
        back = -ap.direction  # place the label on the approach, 14 m before the junction
        p = np.asarray(ap.entry) + back * 14.0
        text = " ".join(f"{letters[k]}{c[k]}" for k in ("left", "straight", "right") if c.get(k))
        multi = len(c) > 1
        ax.text(p[0], p[1], text, fontsize=6.5, ha="center", va="center",
                bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="red" if multi else "0.6", lw=1.4 if multi else 0.6))
    fig.tight_layout()
    return fig


def plot_bev_samples(bevs, actions, states, *, title: str = "Samples of the Dataset, rendered on demand"):
    """A row of BEVs (N, 5, S, S) with their state and the expert's action."""
    import numpy as np

    from ibc_tutorial.driving.render import bev_to_rgb, draw_ego

    n = len(bevs)
    fig, axes = plt.subplots(1, n, figsize=(2.3 * n, 2.9))
    for ax, bev, a, s in zip(np.atleast_1d(axes), bevs, actions, states):
        ax.imshow(draw_ego(bev_to_rgb(np.asarray(bev))), interpolation="nearest")
        ax.set_title(f"v {s[0]:.1f} m/s\nsteer {a[0]:+.2f}, acc {a[1]:+.2f}", fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(title)
    fig.tight_layout()
    return fig


# =========================================================================== chapters 08-09: training the agents, the replication
METHOD_COLORS = {"bc": "C0", "ibc": "C2", "da-ibc": "C3", "expert": "k"}
METHOD_LABELS = {"bc": "BC (Beta)", "ibc": "IBC", "da-ibc": "DA-IBC", "expert": "expert"}


def plot_agent_architecture(bev_size: int = 64, channels=(16, 32, 32, 64), embed_dim: int = 256, head_hidden: int = 128):
    """The DA-IBC paper's Fig. 2 as boxes and arrows: BEV CNN and state MLP, concatenated, then the
    Beta head (BC) or the energy head with its factorised first layer (IBC, DA-IBC)."""
    from matplotlib.patches import FancyBboxPatch

    fig, ax = plt.subplots(figsize=(11, 4.6))
    ax.set_xlim(0, 11)
    ax.set_ylim(0, 5)
    ax.axis("off")

    def box(x, y, w, h, text, color):
        ax.add_patch(FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0.05", fc=color, ec="k", lw=1))
        ax.text(x + w / 2, y + h / 2, text, ha="center", va="center", fontsize=8.5)

    def arrow(x0, y0, x1, y1):
        ax.annotate("", xy=(x1, y1), xytext=(x0, y0), arrowprops=dict(arrowstyle="->", lw=1.2))

    side, convs = bev_size, []
    for c in channels:
        side = (side + 1) // 2
        convs.append(f"{c}x{side}x{side}")
    box(0.1, 3.2, 1.6, 1.2, f"BEV\n5 x {bev_size} x {bev_size}\n(road, lanes,\nred lights t-16, -9, -1)", "#dde8f5")
    box(2.1, 3.2, 2.0, 1.2, "CNN: 3x3 stride-2 convs\n" + " -> ".join(convs[:2]) + "\n-> " + " -> ".join(convs[2:]), "#c6dbef")
    box(4.5, 3.3, 1.3, 1.0, f"linear\n-> {embed_dim}", "#c6dbef")
    box(0.1, 1.3, 1.6, 1.0, "state (3)\nspeed, previous\nsteer, acceleration", "#e5f5e0")
    box(2.1, 1.3, 3.7, 1.0, f"MLP: 3 -> {embed_dim} -> {embed_dim}", "#c7e9c0")
    box(6.2, 2.2, 1.2, 1.2, f"z\nconcat\n{2 * embed_dim}", "#fdd0a2")
    box(7.9, 3.5, 2.9, 1.0, "BC: linear -> (α, β) per action\nBeta(α, β) on [-1, 1]  (eq. 1)", "#fcbba1")
    box(7.9, 0.6, 2.9, 2.4, f"IBC / DA-IBC energy head:\nW_z z + b  (once per x)\n+ W_a y  (per candidate y)\nReLU -> {head_hidden} -> ReLU\n-> E(x, y)  (scalar)", "#fcbba1")
    box(6.2, 0.3, 1.2, 0.9, "action y\n(steer, acc)", "#f0f0f0")
    arrow(1.7, 3.8, 2.1, 3.8)
    arrow(4.1, 3.8, 4.5, 3.8)
    arrow(1.7, 1.8, 2.1, 1.8)
    arrow(5.8, 3.8, 6.5, 3.4)
    arrow(5.8, 1.8, 6.5, 2.2)
    arrow(7.4, 3.0, 7.9, 3.9)
    arrow(7.4, 2.6, 7.9, 2.2)
    arrow(7.4, 0.75, 7.9, 1.2)
    ax.set_title("The agents' network (the DA-IBC paper's Fig. 2, at the laptop preset's sizes)")
    return fig


def plot_training_curves(curves: dict, *, key: str = "score", ylabel: str = "town02 score (m x 0.7^infractions)",
                         title: str = "Score in town02 during training (mean ± std over seeds)", ax=None):
    """Score (or another key of ``curves[method][seed]``) against epoch: mean and ±1 std over seeds per method."""
    import numpy as np

    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for method, per_seed in curves.items():
        if not per_seed:
            continue
        epochs = sorted(set.intersection(*(set(c["epoch"]) for c in per_seed.values())))
        vals = np.array([[c[key][c["epoch"].index(e)] for e in epochs] for c in per_seed.values()])  # (seeds, E)
        m, s = vals.mean(0), vals.std(0)
        color = METHOD_COLORS.get(method)
        ax.plot(epochs, m, "o-", color=color, label=f"{METHOD_LABELS.get(method, method)} ({len(vals)} seeds)")
        ax.fill_between(epochs, m - s, m + s, color=color, alpha=0.2)
    ax.set_xlabel("epoch")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend()
    ax.grid(alpha=0.3)
    return ax.figure


def plot_loss_curves(curves: dict, *, title: str = "Training loss"):
    """One panel per method: loss per logged point (``curves[method] = (x, losses)``)."""
    fig, axes = plt.subplots(1, len(curves), figsize=(4.0 * len(curves), 3.3), squeeze=False)
    for ax, (method, (x, loss)) in zip(axes[0], curves.items()):
        ax.plot(x, loss, "o-", color=METHOD_COLORS.get(method))
        ax.set_xlabel("epoch")
        ax.set_ylabel("Beta NLL (eq. 1)" if method == "bc" else "InfoNCE (eq. 2)")
        ax.set_title(METHOD_LABELS.get(method, method))
        ax.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_trajectories(town, trajectories: dict, *, titles: dict | None = None, suptitle: str = "Free driving in town02"):
    """One map per entry of ``trajectories`` ({name: [xy (T, 2), ...]}), each episode a line, starts as dots."""
    import numpy as np

    n = len(trajectories)
    fig, axes = plt.subplots(1, n, figsize=(6.0 * n, 5.4), squeeze=False)
    for ax, (name, tracks) in zip(axes[0], trajectories.items()):
        plot_town(town, ax=ax, title=(titles or {}).get(name, name), markers=False)
        for k, xy in enumerate(tracks):
            xy = np.asarray(xy)
            ax.plot(xy[:, 0], xy[:, 1], color=f"C{(3 * k + 1) % 10}", lw=1.8, alpha=0.85, label=f"episode {k}")
            ax.plot(xy[0, 0], xy[0, 1], "o", color=f"C{(3 * k + 1) % 10}", ms=7, mec="k")
            ax.plot(xy[-1, 0], xy[-1, 1], "X", color=f"C{(3 * k + 1) % 10}", ms=8, mec="k")
        ax.legend(fontsize=8, loc="upper right")
    fig.suptitle(suptitle + " (dot: start, cross: end)")
    fig.tight_layout()
    return fig


def plot_energy_landscapes(panels: list, steer, accel, *, suptitle: str = "Energy landscapes of DA-IBC"):
    """Per panel (title, E (A, S) over accel x steer, points (K, 2), bev (5, S, S) or None): the BEV and E with the points."""
    import numpy as np

    from ibc_tutorial.driving.render import bev_to_rgb, draw_ego

    fig, axes = plt.subplots(len(panels), 2, figsize=(9.5, 4.1 * len(panels)), squeeze=False,
                             gridspec_kw={"width_ratios": [1, 1.5]})
    for (ax_b, ax_e), (title, e, points, bev) in zip(axes, panels):
        if bev is not None:
            ax_b.imshow(draw_ego(bev_to_rgb(np.asarray(bev))), interpolation="nearest")
        ax_b.set_xticks([])
        ax_b.set_yticks([])
        ax_b.set_title("what the agent sees")
        e = np.asarray(e)
        cs = ax_e.contourf(steer, accel, e - e.min(), levels=20, cmap="viridis")
        fig.colorbar(cs, ax=ax_e, label="E(x, y) - min E")
        p = np.asarray(points)
        ax_e.scatter(p[:, 0], p[:, 1], c="red", s=28, edgecolors="white", linewidths=0.8, label=f"{len(p)} DFO inferences")
        ax_e.set_xlabel("steering y_1 (+ right)")
        ax_e.set_ylabel("acceleration y_2 (- brake)")
        ax_e.set_title(title)
        ax_e.legend(loc="lower right", fontsize=8)
    fig.suptitle(suptitle)
    fig.tight_layout()
    return fig
