"""Figures of Part II, chapters 04-06: DA-IBC's counter-examples, KDE weighting, DFO inference.

Actions of the 2-D problems are [steer, acceleration] in the action box [-1, 1]², drawn with
steering along x and acceleration along y.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import LogNorm

from ibc_tutorial.plotting.common import (
    ACCEL_LABEL,
    STEER_LABEL,
    as_array,
    check_panels,
    figure_and_axes,
    finish,
    label_axes,
)
from ibc_tutorial.plotting.multimodality import RolloutStyle, rollout_figure
from ibc_tutorial.utils import check_int, check_positive


# ======================================================================= chapter 04: DA-IBC counter-examples
def plot_counter_examples(
    expert_actions,
    situation,
    negatives: dict,
    *,
    situation_names=("cruise", "junction", "red light"),
    max_points: int = 3000,
):
    """Expert actions coloured by situation, then one panel per sampler with its counter-examples.

    Args:
        expert_actions: (M, 2) [steer, acceleration]; situation: (M,) int index into ``situation_names``.
        negatives: {sampler name: (K, 2) counter-examples}.
    """
    a = as_array(expert_actions)[:max_points]  # (M, 2)
    s = as_array(situation)[:max_points]  # (M,)
    n = 1 + len(negatives)
    fig, axes = plt.subplots(1, n, figsize=(3.6 * n, 3.6), sharex=True, sharey=True, squeeze=False)
    axes = axes[0]
    for k, name in enumerate(situation_names):
        axes[0].scatter(a[s == k, 0], a[s == k, 1], s=4, alpha=0.6, label=name)
    axes[0].set_title("expert actions")
    axes[0].legend(loc="lower left", fontsize=8, markerscale=3)
    for ax, (name, neg) in zip(axes[1:], negatives.items(), strict=True):
        neg = as_array(neg)[:max_points]  # (K, 2)
        ax.scatter(a[:, 0], a[:, 1], s=3, color="0.75", label="expert actions")
        ax.scatter(neg[:, 0], neg[:, 1], s=3, color="tab:red", alpha=0.5, label="counter-examples")
        ax.set_title(name)
        ax.legend(loc="lower left", fontsize=8, markerscale=3)
    for ax in axes:
        ax.set_xlim(-1.25, 1.25)
        ax.set_ylim(-1.25, 1.25)
        ax.add_patch(plt.Rectangle((-1, -1), 2, 2, fill=False, ls="--", color="k", lw=0.8))
        ax.set_xlabel(STEER_LABEL)
        ax.set_aspect("equal")
    axes[0].set_ylabel(ACCEL_LABEL)
    return finish(fig, True, title="Where the counter-examples fall (dashed: the action box [-1, 1]²)")


def plot_sigma_sweep(sigmas, values, *, uniform=None, ylabel: str, title: str):
    """A measure against the noise σ of DA-IBC's counter-examples (log axis), one dot per seed.

    Args:
        sigmas: (K,) the σ values; values: (K, S) the measure per σ and seed.
        uniform: optional (S,) the same measure with uniform counter-examples (drawn as a band).
    """
    v = as_array(values, float)  # (K, S)
    s = as_array(sigmas, float)  # (K,)
    fig, ax = plt.subplots(figsize=(6.0, 3.8))
    for j in range(v.shape[1]):
        ax.scatter(s, v[:, j], color="C1", s=14, alpha=0.6)
    ax.plot(
        s, v.mean(axis=1), color="C1", lw=2, marker="o", label="expert + N(0, σ²) (DA-IBC), mean over seeds"
    )
    if uniform is not None:
        u = as_array(uniform, float)
        ax.axhspan(u.min(), u.max(), color="C0", alpha=0.2)
        ax.axhline(u.mean(), color="C0", lw=2, label="uniform (IBC), mean and range over seeds")
    ax.set_xscale("log")
    label_axes(ax, "σ of the counter-examples' noise (action units)", ylabel, title, legend=True)
    return finish(fig, True)


def plot_energy_2d(energies, axis, *, title: str, unvisited=None, modes=None, argmin=None, ax=None):
    """An energy landscape over 2-D actions: x steer, y acceleration; low energy dark.

    Args:
        energies: (n, n) energies on ``axis`` × ``axis``, indexed [steer, acceleration].
        axis: (n,) the grid's values on each axis.
        unvisited: optional (n, n) bool, cells no counter-example visited (hatched).
        modes: optional (K, 2) the expert's valid actions (white circles).
        argmin: optional (2,) the grid argmin (a red cross).
    """
    e = as_array(energies, float)
    e = e - e.min()  # (n, n)
    x = as_array(axis, float)
    fig, ax, own = figure_and_axes(ax, (4.8, 4.2))
    mesh = ax.pcolormesh(x, x, e.T, cmap="viridis", shading="nearest", vmax=np.percentile(e, 95))
    fig.colorbar(mesh, ax=ax, label="E − min E (nats)")
    if unvisited is not None:
        u = as_array(unvisited, float)
        ax.contourf(x, x, u.T, levels=[0.5, 1.5], colors="none", hatches=["//"])
        ax.contour(x, x, u.T, levels=[0.5], colors="w", linewidths=0.8)
        # a legend entry for the hatching (contourf makes none)
        ax.add_patch(
            plt.Rectangle(
                (0, 0),
                0,
                0,
                facecolor="none",
                edgecolor="k",
                hatch="//",
                label="never visited by a counter-example",
            )
        )
    if modes is not None:
        m = as_array(modes, float)
        ax.scatter(
            m[:, 0], m[:, 1], s=80, facecolors="none", edgecolors="w", lw=1.5, label="expert's actions"
        )
    if argmin is not None:
        ax.scatter([argmin[0]], [argmin[1]], marker="x", s=80, color="red", lw=2, label="argmin of E")
    if modes is not None or argmin is not None or unvisited is not None:
        ax.legend(loc="lower right", fontsize=8)
    label_axes(ax, STEER_LABEL, ACCEL_LABEL, title)
    return finish(fig, own)


# =========================================================================== chapter 05: KDE weighting
def plot_kde_by_hand(data, grid, bandwidth: float, density):
    """Eq. 4 in one dimension: each data point's kernel 1/(M h) K((x − x_j)/h) and their sum ĝ(x).

    Args:
        data: (M,) the data points x_j; grid: (G,) where to draw; density: (G,) ĝ on ``grid``.
    """
    x = as_array(grid, float)
    d = as_array(data, float)
    m, h = len(d), check_positive("bandwidth", bandwidth)
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    for j, xj in enumerate(d):
        k = np.exp(-0.5 * ((x - xj) / h) ** 2) / np.sqrt(2 * np.pi) / (m * h)  # (G,) one term of eq. 4
        ax.plot(
            x, k, color="C0", lw=0.9, alpha=0.7, label="one kernel, 1/(Mh) K((x − x_j)/h)" if j == 0 else None
        )
    ax.plot(x, as_array(density, float), color="C1", lw=2.2, label="their sum: ĝ(x), eq. 4")
    ax.plot(d, np.zeros_like(d), "|", color="k", ms=14, mew=1.5, label="data points x_j")
    label_axes(
        ax,
        "action (steer)",
        "density (1 / action unit)",
        f"Kernel density estimate by hand: M = {m} points, h = {h:g}",
        legend=True,
    )
    return finish(fig, True)


def plot_kde_bandwidths(densities: dict, axis, actions=None, *, max_points: int = 1500):
    """One heat map of ĝ over the 2-D action box per bandwidth h (same colour scale: log density).

    Args:
        densities: {h: (n, n) ĝ on ``axis`` × ``axis``, indexed [steer, acceleration]}.
        axis: (n,) grid values; actions: optional (M, 2) the data, drawn as dots.
    """
    x = as_array(axis, float)
    n = check_panels("densities", densities)
    fig, axes = plt.subplots(1, n, figsize=(3.5 * n + 0.8, 3.6), sharex=True, sharey=True, squeeze=False)
    axes = axes[0]
    logs = {h: np.log10(np.maximum(as_array(d, float), 1e-6)) for h, d in densities.items()}
    vmax = max(v.max() for v in logs.values())
    vmin = vmax - 4
    for ax, (h, v) in zip(axes, logs.items(), strict=True):
        mesh = ax.pcolormesh(x, x, v.T, cmap="magma", shading="nearest", vmin=vmin, vmax=vmax)
        if actions is not None:
            a = as_array(actions, float)[:max_points]
            ax.scatter(a[:, 0], a[:, 1], s=1, color="c", alpha=0.4)
        ax.set_title(f"h = {h:g}")
        ax.set_xlabel(STEER_LABEL)
        ax.set_aspect("equal")
    axes[0].set_ylabel(ACCEL_LABEL)
    fig.colorbar(mesh, ax=list(axes), label="log10 ĝ(y) (density per unit area)")
    return finish(
        fig, False, title="KDE of the expert actions (eq. 4) for several bandwidths; dots: the actions"
    )


def plot_bandwidth_choice(bandwidths, heldout_loglik, rare_share, *, chosen: float = 0.2):
    """Two criteria against the bandwidth h: held-out log-likelihood of the KDE, and the share of rare
    actions in inverse-density-weighted minibatches.

    Args:
        bandwidths: (K,) h values; heldout_loglik: (K,) mean log ĝ at held-out actions (nats);
        rare_share: (K,) share of rare-situation samples in weighted minibatches.
    """
    h = as_array(bandwidths, float)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9.6, 3.6))
    a1.plot(h, as_array(heldout_loglik, float), marker="o")
    a2.plot(h, as_array(rare_share, float), marker="o", color="C1")
    for ax in (a1, a2):
        ax.set_xscale("log")
        ax.axvline(chosen, color="k", ls="--", lw=1, label=f"h = {chosen:g} (the paper)")
    label_axes(
        a1,
        "bandwidth h (action units)",
        "mean log ĝ(held-out action) (nats)",
        "How well ĝ predicts new actions",
        legend=True,
    )
    label_axes(
        a2,
        "bandwidth h (action units)",
        "share of rare situations in minibatches",
        "What the weights 1/ĝ do to minibatches",
        legend=True,
    )
    return finish(fig, True)


def plot_inverse_weights(actions, weights, *, max_points: int = 4000):
    """Expert actions coloured by their inverse-density weight w_i ∝ 1/ĝ(y_i) (log colour scale)."""
    a = as_array(actions, float)[:max_points]  # (M, 2)
    w = as_array(weights, float)
    w = w[:max_points] * len(w)  # (M,) 1 = the uniform weight
    fig, ax = plt.subplots(figsize=(5.2, 4.2))
    order = np.argsort(w)
    sc = ax.scatter(a[order, 0], a[order, 1], c=w[order], s=5, cmap="viridis", norm=LogNorm())
    fig.colorbar(sc, ax=ax, label="M · w_i (1 = the uniform weight)")
    ax.set_xlim(-1.05, 1.05)
    ax.set_ylim(-1.05, 1.05)
    ax.set_aspect("equal")
    label_axes(ax, STEER_LABEL, ACCEL_LABEL, "Inverse-density weights of the expert actions (eq. 5)")
    return finish(fig, True)


def plot_paired_gains(categories, gains, *, ylabel: str, title: str, xlabel: str = "", seeds=None):
    """Paired differences per seed: one column of dots per category, a tick at each column's median,
    and a line at zero (no difference). Paired by seed, the spread between seeds is not mixed in.

    Args:
        categories: K column labels.
        gains: (S, K) one difference per seed and category (e.g. NLL of run A - NLL of run B).
        seeds: optional S seed labels, written over the dots (the dots of one column are spread by seed).
    """
    g = as_array(gains, float)
    if g.ndim != 2 or g.shape[1] != len(categories):
        raise ValueError(f"gains must be (S, {len(categories)}), one column per category, got {g.shape}")
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    x = np.arange(len(categories))
    ax.axhline(0.0, color="k", lw=0.8)
    spread = (np.arange(len(g)) - (len(g) - 1) / 2) * min(0.08, 0.6 / max(len(g), 1))  # (S,) one x per seed
    for k in range(len(categories)):
        ax.scatter(x[k] + spread, g[:, k], color=f"C{k}", s=28, zorder=3)
        if seeds is not None:
            for dx, s, v in zip(spread, seeds, g[:, k], strict=True):
                ax.annotate(
                    str(s), (x[k] + dx, v), xytext=(0, 5), textcoords="offset points", fontsize=7, ha="center"
                )
        ax.hlines(
            np.median(g[:, k]),
            x[k] - 0.3,
            x[k] + 0.3,
            colors="k",
            lw=2,
            label="median over seeds" if k == 0 else None,
        )
    ax.set_xticks(x)
    ax.set_xticklabels(categories)
    ax.set_xlim(-0.5, len(categories) - 0.3)
    label_axes(ax, xlabel, ylabel, title, legend=True)
    return finish(fig, True)


def plot_weights_by_value(values, weights: dict, *, edges, xlabel: str, title: str, min_count: int = 5):
    """Per-sample weights against one action component (log scale), with their mean per bin.

    Every sample is a dot, so a single isolated sample shows as one dot, not as a bin's mean; the lines
    join the bin means only of bins holding at least ``min_count`` samples.

    Args:
        values: (M,) the action component (e.g. acceleration) of each sample.
        weights: {label: (M,) M·w per sample}.
        edges: (B + 1,) bin edges over ``values``.
    """
    v = as_array(values, float)
    e = as_array(edges, float)
    check_int("min_count", min_count, minimum=1)
    which = np.clip(np.searchsorted(e, v, side="right") - 1, 0, len(e) - 2)  # (M,) bin of each sample
    counts = np.bincount(which, minlength=len(e) - 1)
    centres = (e[:-1] + e[1:]) / 2
    fig, ax = plt.subplots(figsize=(7.6, 4.0))
    jitter = np.random.default_rng(0).uniform(-0.3, 0.3, len(v)) * (e[1] - e[0])  # only to spread dots
    for i, (label, w) in enumerate(weights.items()):
        w = as_array(w, float)
        if w.shape != v.shape:
            raise ValueError(f"weights[{label!r}] must have one value per sample, {v.shape}, got {w.shape}")
        ax.scatter(v + jitter, w, s=4, alpha=0.25, color=f"C{i}")
        means = np.array(
            [w[which == b].mean() if counts[b] >= min_count else np.nan for b in range(len(counts))]
        )
        ax.plot(centres, means, marker="o", color=f"C{i}", label=f"{label}: bin mean")
    ax.set_yscale("log")
    ax.axhline(1.0, color="k", ls=":", lw=1, label="1 = uniform sampling")
    label_axes(ax, xlabel, "M·w per sample (log scale)", title, legend=True, fontsize=8)
    ax.text(
        0.01,
        0.02,
        f"dots: every sample; lines: bins with at least {min_count} samples",
        transform=ax.transAxes,
        fontsize=8,
    )
    return finish(fig, True)


# =========================================================================== chapter 06: DFO inference
def draw_dfo_iteration(ax, trace, it: int, x, e, bins: int):
    """One iteration ``it`` (1-based) of a 1-D DFO ``trace`` on ``ax``: the population's histogram
    (share per bin), the energy ``e`` (G,) over the actions ``x`` (G,) in red on a twin axis, and on
    the last iteration the returned action, titled by how it was chosen (``trace.config.select``).
    Returns the twin (energy) axis."""
    it = check_int("it", it, minimum=1, maximum=len(trace.samples))
    s = trace.samples[it - 1].numpy()[:, 0]  # (N,) the population's actions
    lo, hi = float(x.min()), float(x.max())
    counts, edges = np.histogram(s, bins=check_int("bins", bins, minimum=1), range=(lo, hi))
    ax.bar(
        edges[:-1],
        counts / len(s),
        width=edges[1] - edges[0],
        align="edge",
        color="C0",
        alpha=0.7,
        label="samples ỹ_i",
    )
    ax.set_ylim(0, 1.05 * max(0.25, (counts / len(s)).max()))
    ax2 = ax.twinx()
    ax2.plot(x, e, color="C3", lw=1.5)
    ax2.set_ylim(e.min() - 0.5, e.min() + 1.3 * (np.percentile(e, 95) - e.min()) + 0.5)
    ax2.tick_params(axis="y", colors="C3", labelsize=7)
    if it == len(trace.samples):
        ax.axvline(float(trace.action[0]), color="k", lw=2, label="returned ŷ")
        how = "ŷ drawn from p̃" if trace.config.select == "sample" else "ŷ = argmax p̃ (lowest energy)"
        ax.set_title(f"iteration {it} (last)\n{how}", fontsize=9)
    else:
        ax.set_title(f"iteration {it}\nthen resample, noise σ = {trace.sigmas[it - 1]:.3g}", fontsize=9)
    ax.set_xlabel("action y")
    ax.legend(loc="upper center", fontsize=7)
    return ax2


def plot_dfo_iterations(
    trace,
    grid,
    energy,
    *,
    iterations=None,
    bins: int = 60,
    title: str = "Algorithm 1, iteration by iteration",
):
    """A 1-D energy landscape and the DFO population at each iteration (from ``dfo_trace``).

    Args:
        trace: a ``DFOTrace`` of a 1-D action problem.
        grid: (G,) actions; energy: (G,) E on ``grid``.
        iterations: which iterations to draw (1-based); all by default.
    """
    its = list(iterations) if iterations is not None else list(range(1, len(trace.samples) + 1))
    n = check_panels("iterations", its)
    fig, axes = plt.subplots(1, n, figsize=(3.0 * n, 3.3), sharey=True, squeeze=False)
    x = as_array(grid, float)
    e = as_array(energy, float)
    for ax, it in zip(axes[0], its, strict=True):
        energy_ax = draw_dfo_iteration(ax, trace, it, x, e, bins)
    axes[0, 0].set_ylabel("share of samples per bin")
    energy_ax.set_ylabel("energy E(x, y) (nats, red)", color="C3")
    return finish(fig, True, title=title)


def plot_valley_shares(
    n_iters,
    shares: dict,
    *,
    prediction=None,
    ylabel: str = "share of calls ending in the shallow valley",
    title: str = "",
):
    """Shares (e.g. of the shallow valley) against N_iters: one line per setting, optional prediction.

    Args:
        n_iters: (K,) iteration counts; shares: {label: (K,) measured shares};
        prediction: optional (K,) the share predicted by p(y|x)^k.
    """
    k = as_array(n_iters)
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    for i, (label, v) in enumerate(shares.items()):
        ax.plot(k, as_array(v, float), marker="o", color=f"C{i}", label=label)
    if prediction is not None:
        ax.plot(k, as_array(prediction, float), color="k", ls="--", lw=1.2, label="prediction: p(y|x)^k")
    ax.set_ylim(-0.02, max(0.6, ax.get_ylim()[1]))
    label_axes(ax, "N_iters (number of energy evaluations k)", ylabel, title, legend=True)
    return finish(fig, True)


def plot_populations_2d(
    energies, axis, populations: dict, *, modes=None, title: str = "", max_points: int = 600
):
    """Final populations of several optimisers over one 2-D energy landscape (one panel each).

    Args:
        energies: (n, n) energies on ``axis`` × ``axis`` (indexed [steer, acceleration]).
        populations: {label: (N, 2) samples}; modes: optional (K, 2) valid actions.
    """
    n = check_panels("populations", populations)
    fig, axes = plt.subplots(1, n, figsize=(4.4 * n, 3.9), sharex=True, sharey=True, squeeze=False)
    for ax, (label, pop) in zip(axes[0], populations.items(), strict=True):
        plot_energy_2d(energies, axis, title=label, modes=modes, ax=ax)
        p = as_array(pop, float)[:max_points]  # (N, 2)
        ax.scatter(p[:, 0], p[:, 1], s=4, color="r", alpha=0.5, label="samples")
        ax.legend(loc="lower right", fontsize=7)
    return finish(fig, True, title=title)


def _tree_counts(world, r) -> str:
    side = world.pass_side(r).numpy()
    left, right, hit = int((side == -1).sum()), int((side == 1).sum()), int((side == 0).sum())
    return f"left {left}, right {right}, collided or neither {hit} (of {len(side)})"


def plot_tree_rollouts(world, rollouts: dict, *, max_episodes: int = 60):
    """Closed-loop trajectories in the tree world, one panel per policy: passes left (blue), right
    (orange), collisions (red), the tree as a disc."""
    n = check_panels("rollouts", rollouts)
    return rollout_figure(
        world,
        rollouts,
        _tree_counts,
        title="Closed-loop rollouts of the energy model with DFO inference",
        figsize=(9.0, 2.1 * n + 0.6),
        style=RolloutStyle(max_episodes=max_episodes, crosses=False, alpha=0.7, fontsize=9),
    )
