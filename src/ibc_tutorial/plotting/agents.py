"""Figures of chapters 08-09: the agents' network, their training, and the replication of the
DA-IBC paper's results in town02 (trajectories, energy landscapes)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import FancyBboxPatch
from matplotlib.ticker import MaxNLocator

from ibc_tutorial.plotting.common import ACCEL_LABEL, STEER_LABEL, as_array, check_panels, finish, label_axes
from ibc_tutorial.plotting.town import draw_bev, plot_town
from ibc_tutorial.utils import check_positive

METHOD_COLORS = {"bc": "C0", "ibc": "C2", "da-ibc": "C3", "expert": "k"}
"""Colour of each method in the figures of chapters 08-09."""
METHOD_LABELS = {"bc": "BC (Beta)", "ibc": "IBC", "da-ibc": "DA-IBC", "expert": "expert"}
"""Name of each method in legends and titles."""


def plot_agent_architecture(
    bev_size: int = 64,
    channels=(16, 32, 32, 64),
    embed_dim: int = 256,
    head_hidden: int = 128,
    light_encoding: str = "flag",
):
    """The DA-IBC paper's Fig. 2 as boxes and arrows: BEV CNN and state MLP, concatenated, then the
    Beta head (BC) or the energy head with its factorised first layer (IBC, DA-IBC). ``light_encoding``
    ("flag": one "must stop" bit, or "intensity") names how the BEV's light channels are drawn."""
    lights = {"flag": "red/yellow = 1", "intensity": "by intensity"}.get(light_encoding, light_encoding)
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
    box(
        0.1,
        3.2,
        1.6,
        1.2,
        f"BEV\n5 x {bev_size} x {bev_size}\n(road, lanes,\nlights t-16, -9, -1\n{lights})",
        "#dde8f5",
    )
    box(
        2.1,
        3.2,
        2.0,
        1.2,
        "CNN: 3x3 stride-2 convs\n" + " -> ".join(convs[:2]) + "\n-> " + " -> ".join(convs[2:]),
        "#c6dbef",
    )
    box(4.5, 3.3, 1.3, 1.0, f"linear\n-> {embed_dim}", "#c6dbef")
    box(0.1, 1.3, 1.6, 1.0, "state (3)\nspeed, previous\nsteer, acceleration", "#e5f5e0")
    box(2.1, 1.3, 3.7, 1.0, f"MLP: 3 -> {embed_dim} -> {embed_dim}", "#c7e9c0")
    box(6.2, 2.2, 1.2, 1.2, f"z\nconcat\n{2 * embed_dim}", "#fdd0a2")
    box(7.9, 3.5, 2.9, 1.0, "BC: linear -> (α, β) per action\nBeta(α, β) on [-1, 1]  (eq. 1)", "#fcbba1")
    box(
        7.9,
        0.6,
        2.9,
        2.4,
        f"IBC / DA-IBC energy head:\nW_z z + b  (once per x)\n+ W_a y  (per candidate y)\nReLU -> "
        f"{head_hidden} -> ReLU\n-> E(x, y)  (scalar)",
        "#fcbba1",
    )
    box(6.2, 0.3, 1.2, 0.9, "action y\n(steer, acc)", "#f0f0f0")
    for x0, y0, x1, y1 in (
        (1.7, 3.8, 2.1, 3.8),
        (4.1, 3.8, 4.5, 3.8),
        (1.7, 1.8, 2.1, 1.8),
        (5.8, 3.8, 6.5, 3.4),
        (5.8, 1.8, 6.5, 2.2),
        (7.4, 3.0, 7.9, 3.9),
        (7.4, 2.6, 7.9, 2.2),
        (7.4, 0.75, 7.9, 1.2),
    ):
        arrow(x0, y0, x1, y1)
    ax.set_title("The agents' network (the DA-IBC paper's Fig. 2, at the laptop preset's sizes)")
    return fig


def plot_training_curves(
    curves: dict,
    *,
    key: str = "score",
    ylabel: str = "town02 score (m x 0.7^infractions)",
    title: str = "Score in town02 during training (mean ± std over seeds)",
    ax=None,
    reference: tuple[float, str] | None = None,
):
    """Score (or another key of ``curves[method][seed]``) against epoch: mean and ±1 std over seeds per
    method; ``reference`` = (value, label) draws a dashed line, e.g. the expert on the same episodes."""
    if ax is None:
        _, ax = plt.subplots(figsize=(7.5, 4.2))
    for method, per_seed in curves.items():
        if not per_seed:
            continue
        epochs = sorted(set.intersection(*(set(c["epoch"]) for c in per_seed.values())))
        vals = np.array(
            [[c[key][c["epoch"].index(e)] for e in epochs] for c in per_seed.values()]
        )  # (seeds, E)
        m, s = vals.mean(0), vals.std(0)
        color = METHOD_COLORS.get(method)
        ax.plot(
            epochs, m, "o-", color=color, label=f"{METHOD_LABELS.get(method, method)} ({len(vals)} seeds)"
        )
        ax.fill_between(epochs, m - s, m + s, color=color, alpha=0.2)
    if reference is not None:
        ax.axhline(reference[0], color=METHOD_COLORS["expert"], ls="--", lw=1.2, label=reference[1])
    label_axes(ax, "epoch", ylabel, title)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))  # epochs are whole numbers
    ax.legend()
    ax.grid(alpha=0.3)
    return ax.figure


def plot_loss_curves(curves: dict, *, title: str = "Training loss"):
    """One panel per method: loss per logged point (``curves[method] = (x, losses)``)."""
    n = check_panels("curves", curves)
    fig, axes = plt.subplots(1, n, figsize=(4.0 * n, 3.3), squeeze=False)
    for ax, (method, (x, loss)) in zip(axes[0], curves.items(), strict=True):
        ax.plot(x, loss, "o-", color=METHOD_COLORS.get(method))
        label_axes(
            ax,
            "epoch",
            "Beta NLL (eq. 1)" if method == "bc" else "InfoNCE (eq. 2)",
            METHOD_LABELS.get(method, method),
        )
        ax.grid(alpha=0.3)
    return finish(fig, True, title=title)


def plot_trajectories(
    town, trajectories: dict, *, titles: dict | None = None, suptitle: str = "Free driving in town02"
):
    """One map per entry of ``trajectories`` ({name: [xy (T, 2), ...]}), each episode a line,
    starts as dots."""
    n = check_panels("trajectories", trajectories)
    fig, axes = plt.subplots(1, n, figsize=(6.0 * n, 5.4), squeeze=False)
    for ax, (name, tracks) in zip(axes[0], trajectories.items(), strict=True):
        plot_town(town, ax=ax, title=(titles or {}).get(name, name), markers=False)
        for k, xy in enumerate(tracks):
            xy = as_array(xy)  # (T, 2)
            color = f"C{(3 * k + 1) % 10}"
            ax.plot(xy[:, 0], xy[:, 1], color=color, lw=1.8, alpha=0.85, label=f"episode {k}")
            ax.plot(xy[0, 0], xy[0, 1], "o", color=color, ms=7, mec="k")
            ax.plot(xy[-1, 0], xy[-1, 1], "X", color=color, ms=8, mec="k")
        if len(tracks) > 1:  # off the map, to its right
            ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    return finish(fig, True, title=suptitle + " (dot: start, cross: end)")


def plot_energy_landscapes(panels: list, steer, accel, *, suptitle: str = "Energy landscapes of DA-IBC"):
    """Per panel (title, E (A, S) over accel x steer, points (K, 2), bev (5, S, S) or None): the BEV and E
    with the points."""
    check_panels("panels", panels)
    fig, axes = plt.subplots(
        len(panels),
        2,
        figsize=(9.5, 4.1 * len(panels)),
        squeeze=False,
        gridspec_kw={"width_ratios": [1, 1.5]},
    )
    for (ax_b, ax_e), (title, e, points, bev) in zip(axes, panels, strict=True):
        if bev is not None:
            draw_bev(ax_b, bev)
        ax_b.set_xticks([])
        ax_b.set_yticks([])
        ax_b.set_title("what the agent sees")
        e = as_array(e)  # (A, S)
        cs = ax_e.contourf(steer, accel, e - e.min(), levels=20, cmap="viridis")
        fig.colorbar(cs, ax=ax_e, label="E(x, y) - min E")
        ax_e.axvline(0.0, color="w", ls="--", lw=1)
        p = as_array(points)  # (K, 2)
        ax_e.scatter(
            p[:, 0],
            p[:, 1],
            c="red",
            s=28,
            edgecolors="white",
            linewidths=0.8,
            label=f"{len(p)} DFO inferences (white dashes: zero steering)",
            clip_on=False,  # a draw at the box's edge (full braking: -1) is drawn whole, over the frame
            zorder=5,
        )
        label_axes(ax_e, f"y_1: {STEER_LABEL}", f"y_2: {ACCEL_LABEL}", title)
        ax_e.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), frameon=False)
    return finish(fig, True, title=suptitle)


def plot_exit_counts(counts: dict, *, title: str = "Exits taken at each junction approach"):
    """Per method, one stacked bar per junction approach: how many visits left it by each exit.

    ``counts``: ``{method: {approach: {"left": n, "straight": n, "right": n}}}``
    (``driving.analysis.exit_counts``).
    Only approaches that some method visited are drawn, in the same order in every panel."""
    n = check_panels("counts", counts)
    approaches = sorted({int(a) for c in counts.values() for a in c})
    fig, axes = plt.subplots(
        n, 1, figsize=(max(6.0, 0.45 * len(approaches) + 2.0), 2.6 * n), squeeze=False, sharex=True
    )
    x = np.arange(len(approaches))
    for ax, (method, per) in zip(axes[:, 0], counts.items(), strict=True):
        bottom = np.zeros(len(approaches))
        for turn, color in (("left", "C1"), ("straight", "0.6"), ("right", "C4")):
            h = np.array([per.get(a, {}).get(turn, 0) for a in approaches], dtype=float)
            ax.bar(x, h, bottom=bottom, color=color, label=turn, width=0.7)
            bottom += h
        ax.set_xticks(x, [str(a) for a in approaches])
        label_axes(
            ax,
            "junction approach (id)",
            "visits",
            METHOD_LABELS.get(method, method),
            legend=True,
            loc="upper right",
            fontsize=8,
        )
        ax.grid(alpha=0.3, axis="y")
    return finish(fig, True, title=title)


def plot_labels_at_rest(
    labels: dict, *, title: str = "The expert's acceleration labels in states at rest", bins: int = 20
):
    """One histogram per dataset of the expert's acceleration labels in the states where the car is at rest.

    ``labels``: ``{name: (N,) acceleration labels in [-1, 1]}``; each histogram shows the share of the
    dataset's states at rest in each bin, so datasets of different sizes compare."""
    n = check_panels("labels", labels)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.2), squeeze=False, sharey=True)
    edges = np.linspace(-1, 1, bins + 1)
    for ax, (name, acc) in zip(axes[0], labels.items(), strict=True):
        acc = as_array(acc, float).ravel()  # (N,)
        ax.hist(acc, bins=edges, weights=np.full(len(acc), 1.0 / max(len(acc), 1)), color="C0")
        go = float((acc > 0.2).mean()) if len(acc) else 0.0
        label_axes(
            ax,
            ACCEL_LABEL,
            "share of the states at rest",
            f"{name}\n{len(acc)} states at rest, {go:.0%} say go",
        )
        ax.grid(alpha=0.3, axis="y")
    return finish(fig, True, title=title)


def plot_crossing_steering(
    crossings: dict, *, title: str = "Steering during each junction crossing in town02"
):
    """One panel per agent kind: each junction crossing as a point (most leftward, most rightward steering).

    ``crossings``: ``{name: {label: (N, 2)}}``, the (``steer_min``, ``steer_max``) of the crossings of each
    kind (``driving.analysis.junction_crossings``), e.g. by the exit taken; a label that starts with "ended"
    is drawn as red crosses (crossings the car did not finish)."""
    n = check_panels("crossings", crossings)
    fig, axes = plt.subplots(1, n, figsize=(4.0 * n, 3.9), squeeze=False, sharex=True, sharey=True)
    for ax, (name, groups) in zip(axes[0], crossings.items(), strict=True):
        check_panels(f"crossings[{name!r}]", groups)
        k = 0
        for label, points in groups.items():
            pts = as_array(points, float).reshape(-1, 2)  # (N, 2): most leftward, most rightward steering
            if label.startswith("ended"):
                ax.scatter(
                    pts[:, 0],
                    pts[:, 1],
                    s=70,
                    marker="x",
                    color="C3",
                    zorder=3,
                    label=f"{label} ({len(pts)})",
                )
            else:
                ax.scatter(pts[:, 0], pts[:, 1], s=8, alpha=0.5, color=f"C{k}", label=f"{label} ({len(pts)})")
                k += 1
        ax.plot([-1, 1], [-1, 1], color="0.7", lw=0.8)  # steer_max >= steer_min: points lie above it
        label_axes(
            ax,
            "most leftward steering (−1 … +1)",
            "most rightward steering (−1 … +1)",
            name,
            legend=True,
            loc="upper left",
            fontsize=7,
        )
        ax.set_xlim(-1.05, 1.05)
        ax.set_ylim(-1.05, 1.05)
        ax.grid(alpha=0.3)
    return finish(fig, True, title=title)


def plot_crossing_energies(
    panels: dict,
    steer,
    *,
    clip: float = 10.0,
    dt: float = 0.1,
    title: str = "Energy over steering in the crossings that ended in a building",
):
    """One panel per crossing: its energy over steering (relative to each state's minimum) against time.

    ``panels``: ``{title: (T, G) energies}`` (``energy_by_steer`` of ``evaluate --crossings``), over the
    steering values ``steer`` (G,); shown up to ``clip`` nats, darker = lower, with each state's
    lowest-energy steering as a line. Time runs down, from the first state of the crossing."""
    n = check_panels("panels", panels)
    check_positive("clip", clip)
    check_positive("dt", dt)
    steer = as_array(steer, float).ravel()  # (G,)
    cols = min(n, 3)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.0 * cols, 3.4 * rows), squeeze=False, sharex=True)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    image = None
    for ax, (name, energies) in zip(axes.ravel(), panels.items(), strict=False):
        e = as_array(energies, float).reshape(-1, len(steer))  # (T, G)
        if len(e) == 0:
            raise ValueError(f"panels[{name!r}] must hold at least one state's energies")
        t = np.arange(len(e)) * dt
        image = ax.imshow(
            np.minimum(e, clip),
            aspect="auto",
            cmap="viridis_r",
            vmin=0,
            vmax=clip,
            origin="upper",
            extent=(steer[0], steer[-1], t[-1] + dt, 0),
        )
        ax.plot(steer[e.argmin(axis=1)], t + dt / 2, color="C3", lw=1.2, label="lowest energy")
        label_axes(ax, STEER_LABEL, "time (s)", name, legend=True, loc="lower right", fontsize=7)
    fig.subplots_adjust(left=0.07, right=0.84, top=0.86 if rows == 1 else 0.9, wspace=0.3, hspace=0.45)
    cax = fig.add_axes((0.87, 0.15, 0.02, 0.7))
    fig.colorbar(image, cax=cax, label=f"energy above the state's minimum (nats, ≤ {clip:g})")
    fig.suptitle(title)
    return fig


def plot_stem_exit_shares(
    shares: dict,
    *,
    reference: float | None = 0.5,
    ylabel: str = "share of left turns",
    title: str = "Left turns of the completed crossings from the stem of a T (95 % intervals)",
    reference_label: str = "both exits alike",
):
    """One bar per group with its interval: the share of left turns at the stems of the Ts.

    ``shares``: ``{label: (estimate, low, high)}`` (a ``stats.Interval``'s numbers), e.g. one entry per
    method and replication; a label starting with a method's name takes that method's colour.
    ``reference``: a dashed line (None: none), the expert's even choice at 0.5; ``reference_label``: what it
    marks, after its value in the legend."""
    n = check_panels("shares", shares)
    fig, ax = plt.subplots(figsize=(max(5.5, 1.1 * n + 2.0), 3.6))
    for k, (label, (est, low, high)) in enumerate(shares.items()):
        method = next((m for m in sorted(METHOD_COLORS, key=len, reverse=True) if label.startswith(m)), None)
        color = METHOD_COLORS.get(method, "0.5")
        ax.bar(k, est, color=color, alpha=0.75, width=0.65)
        ax.errorbar(k, est, yerr=[[est - low], [high - est]], color="k", capsize=4, lw=1.2)
        ax.text(k, high + 0.02, f"{est:.2f}", ha="center", va="bottom", fontsize=8)
    if reference is not None:
        ax.axhline(reference, color="0.3", ls="--", lw=1, label=f"{reference:g}: {reference_label}")
    ax.set_xticks(range(n), list(shares), rotation=20, ha="right", fontsize=8)
    ax.set_ylim(0, 1.05)
    label_axes(ax, "agents", ylabel, "", legend=reference is not None, loc="upper right", fontsize=8)
    ax.grid(alpha=0.3, axis="y")
    return finish(fig, True, title=title)


def plot_left_mass_by_position(
    curves: dict,
    *,
    dt_label: str = "states from the junction entry (0.1 s each; negative: before it)",
    title: str = "Probability of steering left, along the crossings from a stem",
):
    """Lines of the mean probability mass left of straight against the state's position in the crossing.

    ``curves``: ``{label: (positions (K,), means (K,))}``, e.g. one line per exit taken and replication;
    a label containing "left" is drawn solid, "right" dashed."""
    check_panels("curves", curves)
    fig, ax = plt.subplots(figsize=(7.0, 3.8))
    for k, (label, (pos, mean)) in enumerate(curves.items()):
        pos, mean = as_array(pos, float).ravel(), as_array(mean, float).ravel()
        if pos.shape != mean.shape:
            raise ValueError(f"curves[{label!r}] must hold positions and means of one length")
        ls = "--" if "right" in label else "-"
        ax.plot(pos, mean, ls, marker="o", ms=3, color=f"C{k // 2}", label=label)
    ax.axvline(0, color="0.4", lw=1)
    ax.axhline(0.5, color="0.6", lw=0.8, ls=":")
    ax.set_ylim(-0.03, 1.03)
    label_axes(ax, dt_label, "mass left of straight", "", legend=True, loc="center left", fontsize=7)
    ax.grid(alpha=0.3)
    return finish(fig, True, title=title)


def plot_steering_profiles(
    profiles: dict,
    steer,
    *,
    clip: float = 15.0,
    title: str = "Energy over steering at the stem's decision and at a red light (Fig. 6 analogue)",
):
    """One panel per state: its energy over steering (the lowest over acceleration, minus its minimum), the
    3-nat band shaded, a line at zero steering (the paper's Fig. 6 layout).

    ``profiles``: ``{title: (G,) energies}`` over the steering values ``steer`` (G,)."""
    n = check_panels("profiles", profiles)
    check_positive("clip", clip)
    steer = as_array(steer, float).ravel()
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.4), squeeze=False, sharey=True)
    for ax, (name, e) in zip(axes[0], profiles.items(), strict=True):
        e = as_array(e, float).ravel()
        if e.shape != steer.shape:
            raise ValueError(f"profiles[{name!r}] must hold one energy per steering value ({len(steer)})")
        ax.plot(steer, np.minimum(e, clip), color="C3", lw=1.5)
        ax.fill_between(steer, 0, 3, where=e <= 3, color="C1", alpha=0.3, label="within 3 nats")
        ax.axvline(0, color="0.3", lw=1, ls="--", label="zero steering")
        ax.set_ylim(0, clip)
        label_axes(ax, STEER_LABEL, f"energy above the minimum (nats, ≤ {clip:g})", name, legend=True,
                   loc="upper center", fontsize=7)  # fmt: skip
    return finish(fig, True, title=title)
