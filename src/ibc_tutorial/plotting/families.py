"""Figures of chapter 13: which policy families keep both answers on the toys, at what cost per decision?

The functions take what ``experiments.family_study`` writes (its ``results.json``, loaded as a dict), the
town's summary of chapter 12 (``two-answers/analysis/summary.json``, a dict), or the live example's samples
(``experiments.flow_toy.samples_by_k``).
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from ibc_tutorial.plotting.common import as_array, label_axes

FAMILY_COLORS = {
    "mae": "C7",
    "mdn": "C8",
    "beta": "C0",
    "ibc": "C2",
    "da-ibc": "C3",
    "da-ibc r-nce": "C5",
    "flow": "C1",
}
"""Colour of each family (the town's method names map onto them by ``TOWN_FAMILY``)."""
FAMILY_LABELS = {
    "mae": "MAE regression",
    "mdn": "MDN",
    "beta": "Beta",
    "ibc": "IBC",
    "da-ibc": "DA-IBC",
    "da-ibc r-nce": "DA-IBC, R-NCE",
    "flow": "flow",
}
"""Name of each family in legends."""
TOWN_FAMILY = {"bc": "beta", "ibc": "ibc", "da-ibc": "da-ibc", "da-ibc-rnce": "da-ibc r-nce", "flow": "flow"}
"""The town's methods (chapter 12) as families."""
COST_WAY = {
    "mae": "mae",
    "mdn": "mdn",
    "beta": "beta",
    "ibc": "energy, grid",
    "da-ibc": "energy, grid",
    "da-ibc r-nce": "energy, grid",
}
"""The way of acting (``family_cost.WAYS``) whose cost each family pays on the toys (the flow's: its K)."""


def family_cost(results: dict, family: str) -> dict:
    """The cost row of ``family`` in a families study's results (the flow at its chosen K)."""
    way = f"flow, K={results['chosen']['flow']['K']}" if family == "flow" else COST_WAY[family]
    return results["cost"][way]


def plot_flow_samples(samples: dict, modes=(-0.6, 0.6), *, ks=None, bins: int = 60):
    """Histograms of the live example's samples, one panel per K (``samples``: {K: (n,) samples}), the
    target's two modes marked."""
    ks = list(samples) if ks is None else list(ks)
    fig, axes = plt.subplots(1, len(ks), figsize=(2.6 * len(ks) + 0.6, 2.8), sharey=True, squeeze=False)
    for ax, k in zip(axes[0], ks, strict=True):
        draw_flow_histogram(ax, as_array(samples[k]), modes, bins)
        label_axes(
            ax, "action", "share of samples" if ax is axes[0, 0] else "", f"K = {k} Euler step{'s' * (k > 1)}"
        )
    fig.suptitle("A flow policy's samples on a target with two answers, by the number of Euler steps")
    fig.tight_layout()
    return fig


def draw_flow_histogram(ax, samples: np.ndarray, modes, bins: int = 60) -> None:
    """One histogram of samples on [-1, 1] (shares of the samples), the target's modes as dashed lines."""
    weights = np.full(len(samples), 1.0 / len(samples))
    ax.hist(samples, bins=bins, range=(-1, 1), weights=weights, color="C1")
    for m in modes:
        ax.axvline(m, color="k", ls="--", lw=1)
    ax.set_xlim(-1, 1)


def plot_flow_histogram(samples, k: int, modes=(-0.6, 0.6)):
    """One K's histogram (the explorer's figure)."""
    fig, ax = plt.subplots(figsize=(5.5, 3.0))
    draw_flow_histogram(ax, as_array(samples), modes)
    ax.set_ylim(0, 0.5)
    label_axes(
        ax,
        "action (steering units)",
        "share of samples",
        f"Flow samples with K = {k} Euler step{'s' * (k > 1)}",
    )
    fig.tight_layout()
    return fig


def plot_coverage_cost(results: dict, town: dict | None = None):
    """Mode coverage against the head evaluations per decision: the junction's Bhattacharyya coefficient
    (mean ± standard deviation over the report seeds) and, with ``town`` (chapter 12's summary), the
    town's minority exit at the stems (with its 95 % interval), each family one point."""
    n = 2 if town is not None else 1
    fig, axes = plt.subplots(1, n, figsize=(5.2 * n + 0.4, 4.0), squeeze=False)
    ax = axes[0, 0]
    for f, s in results["junction"].items():
        x = family_cost(results, f)["head"]
        ax.errorbar(
            x, s["bc_mean"], yerr=s["bc_std"], fmt="o", color=FAMILY_COLORS[f], label=FAMILY_LABELS[f]
        )
    ax.set_xscale("log")
    ax.set_ylim(-0.02, 1.05)
    label_axes(
        ax,
        "head evaluations per decision (log scale)",
        "Bhattacharyya coefficient with the expert",
        "Junction world: three answers",
    )
    if town is not None:
        ax = axes[0, 1]
        for m, s in town["study"]["methods"].items():
            f = TOWN_FAMILY.get(m)
            if f is None:
                continue
            est, lo, hi = s["minority"]
            x = s["network_evaluations_per_decision"]["head"]
            ax.errorbar(
                x, est, yerr=[[est - lo], [hi - est]], fmt="s", color=FAMILY_COLORS[f], label=FAMILY_LABELS[f]
            )
        ax.axhline(0.5, color="k", ls=":", lw=1, label="both exits half and half")
        ax.set_xscale("log")
        ax.set_ylim(-0.02, 0.55)
        label_axes(
            ax,
            "head evaluations per decision (log scale)",
            "minority exit at the stems (share)",
            "Town (chapter 12): two exits",
        )
    handles, labels = [], []
    for a in axes[0]:
        for h, lab in zip(*a.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8, bbox_to_anchor=(0.5, 0.0))
    fig.suptitle("Keeping the answers against the cost of a decision")
    fig.tight_layout(rect=(0, 0.13, 1, 1))
    return fig


def plot_tree_loop(results: dict):
    """The tree's closed loop per family: the shares of episodes that hit the tree, passed right and passed
    left, the mean over the report seeds (stacked) with every seed's share of collisions as a dot."""
    tree = results["tree"]
    fams = list(tree)
    fig, ax = plt.subplots(figsize=(7.5, 3.6))
    x = np.arange(len(fams))
    bottom = np.zeros(len(fams))
    for key, color, label in (
        ("collided", "k", "hit the tree"),
        ("right", "C4", "passed right"),
        ("left", "C1", "passed left"),
    ):
        v = np.array([np.mean(tree[f]["loop"][key]) for f in fams])
        ax.bar(x, v, bottom=bottom, color=color, alpha=0.7 if key != "collided" else 0.85, label=label)
        bottom += v
    for i, f in enumerate(fams):
        hits = tree[f]["loop"]["collided"]
        ax.plot(
            np.full(len(hits), i + 0.3),
            hits,
            "o",
            ms=3,
            color="C3",
            label="one seed's collisions" if i == 0 else None,
        )
    ax.set_xticks(x, [FAMILY_LABELS[f] for f in fams], rotation=20)
    ax.set_ylim(0, 1)
    label_axes(ax, "", "share of 200 episodes", "At the tree, closed loop (mean over seeds)")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    return fig


def plot_flow_steps(results: dict):
    """The junction's flow policy at each K of Euler steps: its mass on each mode and elsewhere (mean and
    standard deviation over the report seeds), the truth dashed."""
    by_k = results["junction"]["flow"]["by_k"]
    ks = sorted(by_k, key=int)
    truth = results["truth"]["junction"]
    fig, ax = plt.subplots(figsize=(6.0, 3.6))
    names = ("left", "straight", "right")
    for j, name in enumerate(names):
        mean = [by_k[k]["mean"][j] for k in ks]
        std = [by_k[k]["std"][j] for k in ks]
        ax.errorbar([int(k) for k in ks], mean, yerr=std, marker="o", capsize=3, label=name)
    rest = [1 - sum(by_k[k]["mean"]) for k in ks]
    ax.plot([int(k) for k in ks], rest, "k^-", label="elsewhere")
    ax.axhline(truth[0], color="k", ls="--", lw=1, label="the expert, each mode")
    ax.set_xscale("log")
    ax.set_xticks([int(k) for k in ks], ks)
    ax.set_ylim(0, 1)
    label_axes(
        ax,
        "K, Euler steps per sample (log scale)",
        "mass (share of samples)",
        "The flow policy at the junction, by K",
    )
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    return fig
