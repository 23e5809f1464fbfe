"""Figures of chapter 12: where the demonstrations hold two answers at one state, do the agents keep both?

Every function takes what ``experiments.agents.two_answers.analyse`` writes: its summary (``summary.json``,
loaded as a dict) and/or its readings (``readings.npz``, any mapping of its keys, e.g. ``np.load``'s file):
``<agent>/forks/<key>`` and ``<agent>/approach/<key>`` per agent (``bc-seed0``, ``ibc-seed3``, ...;
``baseline/<agent>/...`` for the baseline replication's agents read at the same states), ``fig6/<method>``
and ``states/forks/<key>``. Steering is drawn in the book's convention (−1 left, +1 right).
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.transforms import blended_transform_factory

from ibc_tutorial.driving.energy_profiles import DEPTH, beta_density
from ibc_tutorial.optimizers.grid import symmetric_axis
from ibc_tutorial.plotting.agents import METHOD_COLORS, METHOD_LABELS
from ibc_tutorial.plotting.common import ACCEL_LABEL, STEER_LABEL, as_array, check_panels, label_axes
from ibc_tutorial.plotting.town import draw_bev
from ibc_tutorial.utils import check_int, check_positive

LEFT_COLOR, RIGHT_COLOR = "#00bcd4", "#8bc34a"
"""Colours of the left and right labels of a fork (visible on the energy maps and on white)."""
EXIT_COLORS = {"left": "C1", "right": "C4"}
"""Colours of the exits taken at the stems (as in ``plotting.agents.plot_exit_counts``)."""
ROWS = {"study": "this study (two-answers data)", "baseline": "baseline (laptop data)"}
"""The two replications of the summary, as the figures name them."""
GAP_LABEL = "label gap at the fork (steering units)"
"""Axis label of the distance in steering between a fork's two labels."""


# ------------------------------------------------------------------ helpers
def method_of(name: str) -> str:
    """The method of an agent name (``"da-ibc-seed3"`` or ``"baseline/da-ibc-seed3"`` -> ``"da-ibc"``)."""
    return name.rsplit("/", 1)[-1].rsplit("-seed", 1)[0]


def _seed(name: str) -> int:
    tail = name.rsplit("-seed", 1)[-1]
    return int(tail) if tail.isdigit() else 0


def agents_in(readings, prefix: str = "", key: str = "forks/profile") -> list[str]:
    """The agent names (with ``prefix``, e.g. ``"baseline/"``) whose ``<name>/<key>`` the readings hold, by
    method (BC, IBC, DA-IBC) then seed."""
    names = set()
    for k in readings.keys():
        if k.startswith(prefix) and k.endswith("/" + key):
            name = k[: -len(key) - 1]
            if "/" not in name[len(prefix) :] and not name.startswith(("states/", "fig6/")):
                names.add(name)
    return sort_agents(names)


def sort_agents(names) -> list[str]:
    """Agent names by method (BC, IBC, DA-IBC, then any other) and seed."""
    rank = {m: i for i, m in enumerate(METHOD_LABELS)}
    return sorted(names, key=lambda n: (rank.get(method_of(n), len(rank)), method_of(n), _seed(n)))


def _by_method(names) -> dict:
    out = {}
    for n in names:
        out.setdefault(method_of(n), []).append(n)
    return out


def _label_ticks(ax, labels: np.ndarray) -> None:
    """Short ticks at the bottom of ``ax`` at the steering of each fork's left and right labels (F, 2, 2)."""
    trans = blended_transform_factory(ax.transData, ax.transAxes)
    for side, color in ((0, LEFT_COLOR), (1, RIGHT_COLOR)):
        ax.vlines(labels[:, side, 0], 0, 0.05, transform=trans, colors=color, lw=1.5)


# ------------------------------------------------------------------ 1. the label gaps
def _gap_row(d: dict) -> tuple[float, float, float, int]:
    """(min, median, max, count) of a ``data_forks`` dict (``gap``, ``crossings``) or a ``fork_summary``
    dict (``gap_min``, ``gap_median``, ``gap_max``, ``forks``)."""
    if "gap" in d:
        lo, med, hi = (float(x) for x in d["gap"])
        return lo, med, hi, int(d["crossings"])
    return float(d["gap_min"]), float(d["gap_median"]), float(d["gap_max"]), int(d["forks"])


def plot_fork_gaps(
    design: dict,
    baseline_design: dict | None = None,
    *,
    heldout: dict | None = None,
    gaps: dict | None = None,
    title: str = "How far apart the two labels of a fork are",
):
    """One row per data set: the range (line) and median (dot) of its forks' label gaps, counts beside.

    ``design``, ``baseline_design``: ``summary["design"]`` and ``summary["baseline_design"]``
    (``two_answers.data_forks``: the gap's min, median and max, the crossings); ``heldout``: optionally
    ``summary["heldout_forks"]``. ``gaps``: optional ``{"design" | "baseline" | "heldout": (N,) gaps}``,
    every fork drawn as a dot over its row (e.g. ``readings["states/forks/gap"]`` for the held-out ones).
    """
    rows = []
    if baseline_design is not None:
        rows.append(("baseline", "laptop data\n(chapters 08-11)", baseline_design, "crossings"))
    rows.append(("design", "two-answers data\n(stem twins, trained on)", design, "crossings"))
    if heldout is not None:
        rows.append(("heldout", "held-out forks\n(read, never trained on)", heldout, "forks"))
    fig, ax = plt.subplots(figsize=(8.6, 0.85 * len(rows) + 1.5))
    top = 0.0
    rng = np.random.default_rng(0)  # jitter of the dots only
    for i, (key, name, d, unit) in enumerate(rows):
        lo, med, hi, n = _gap_row(d)
        y = len(rows) - 1 - i
        color = {"baseline": "0.45", "design": "C3", "heldout": "C0"}[key]
        ax.plot([lo, hi], [y, y], color=color, lw=6, alpha=0.45, solid_capstyle="round")
        ax.plot(med, y, "o", color=color, ms=9, mec="k")
        if gaps is not None and key in gaps:
            g = as_array(gaps[key], float).ravel()
            ax.scatter(g, y + rng.uniform(-0.18, 0.18, len(g)), s=10, color="k", alpha=0.6, zorder=3)
        text = f"{lo:.3f} – {hi:.3f}, median {med:.3f}"
        ax.annotate(text, (hi, y), xytext=(12, 0), textcoords="offset points", va="center", fontsize=9)
        top = max(top, hi)
        rows[i] = f"{name}\n{n} {unit}"
    ax.set_yticks(range(len(rows))[::-1], rows, fontsize=9)
    ax.set_ylim(-0.6, len(rows) - 0.4)
    ax.set_xlim(0, top * 1.6)
    ax.grid(axis="x", alpha=0.3)
    ax.set_xlabel(GAP_LABEL)
    ax.set_title(title + "\n(line: smallest to largest gap, dot: median)", fontsize=11)
    fig.tight_layout()
    return fig


# ------------------------------------------------------------------ 2. the Fig. 6 analogue
def plot_fork_landscapes(
    readings,
    summary: dict,
    methods=("ibc", "da-ibc"),
    *,
    bc: str | None = None,
    clip: float = 10.0,
    title: str | None = None,
):
    """The DA-IBC paper's Fig. 6 at the chapter's fork (``summary["fig6_fork"]["index"]``): what the agent
    sees, BC's Beta over steering (its mean is what BC acts with), and per energy method the energy over
    (steering, acceleration) minus its minimum (``readings["fig6/<method>"]``, clipped at ``clip`` nats),
    the fork's two labels marked on each. ``bc``: the BC agent drawn (default: the first BC agent read)."""
    check_positive("clip", clip)
    check_panels("methods", methods)
    k = int(summary["fig6_fork"]["index"])
    labels = as_array(readings["states/forks/labels"], float)[k]  # (2, 2): left, right x steer, accel
    gap = float(summary["fig6_fork"].get("gap", labels[1, 0] - labels[0, 0]))
    if bc is None:
        found = [n for n in agents_in(readings, key="forks/alpha") if method_of(n) == "bc"]
        bc = found[0] if found else None
    maps = [as_array(readings[f"fig6/{m}"], float) for m in methods]  # (A, G) each
    map_rows = (len(maps) + 1) // 2
    fig = plt.figure(figsize=(9.4, 3.1 + 3.5 * map_rows), layout="constrained")
    top, bottom = fig.subfigures(2, 1, height_ratios=[3.1, 3.5 * map_rows + 0.4])
    ax_bev, ax_bc = top.subplots(1, 2, width_ratios=[1, 2.4])
    draw_bev(ax_bev, as_array(readings["states/forks/bev"])[k])
    ax_bev.set_title("what the agents see", fontsize=10)
    entry = float(readings["states/forks/entry_m"][k])
    ax_bev.set_xlabel(f"BEV, car heading up,\n{entry:.1f} m before the entry", fontsize=8)

    s = np.linspace(-1, 1, 401)[1:-1]  # (399,) inside (-1, 1), where a U-shaped Beta stays finite
    if bc is not None:
        a, b = float(readings[f"{bc}/forks/alpha"][k]), float(readings[f"{bc}/forks/beta"][k])
        p = beta_density(s, a, b)
        ax_bc.plot(s, p, color=METHOD_COLORS["bc"], lw=2, label=f"Beta(α={a:.1f}, β={b:.1f})")
        mean = 2 * a / (a + b) - 1
        ax_bc.axvline(mean, color="k", ls="--", lw=1.5, label=f"its mean {mean:+.2f}:\nwhat BC steers")
        ax_bc.set_ylim(0, min(float(np.max(p[np.isfinite(p)])) * 1.15, 12.0))
        bc_title = f"{METHOD_LABELS['bc']} ({bc}): its density over steering"
    else:
        bc_title = "no BC agent in the readings"
    for side, color, name in ((0, LEFT_COLOR, "left label"), (1, RIGHT_COLOR, "right label")):
        ax_bc.axvline(labels[side, 0], color=color, lw=2.5, label=f"{name} {labels[side, 0]:+.2f}")
    ax_bc.set_xlim(-1, 1)
    label_axes(ax_bc, STEER_LABEL, "density (per unit of steering)", bc_title)
    ax_bc.title.set_fontsize(10)
    ax_bc.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))

    ax_maps = np.atleast_1d(bottom.subplots(map_rows, min(len(maps), 2), squeeze=False).ravel())
    for ax in ax_maps[len(maps) :]:
        ax.set_visible(False)
    vmax = min(clip, max(float((e - e.min()).max()) for e in maps))  # a small range keeps its contrast
    image = None
    for ax, m, e in zip(ax_maps, methods, maps, strict=False):
        steer = symmetric_axis(e.shape[1]).numpy()
        accel = symmetric_axis(e.shape[0]).numpy()
        ds, da = steer[1] - steer[0], accel[1] - accel[0]
        e = e - e.min()
        image = ax.imshow(
            np.minimum(e, clip),
            origin="lower",
            aspect="auto",
            cmap="magma",
            vmin=0,
            vmax=vmax,
            extent=(-1 - ds / 2, 1 + ds / 2, -1 - da / 2, 1 + da / 2),
            interpolation="nearest",
        )
        a_min, s_min = np.unravel_index(np.argmin(e), e.shape)
        ax.axvline(0, color="w", ls=":", lw=1)
        ax.plot(steer[s_min], accel[a_min], "X", color="w", mec="k", ms=10, label="lowest energy on the grid")
        ax.plot(*labels[0], "<", color=LEFT_COLOR, mec="k", ms=11, label="left label")
        ax.plot(*labels[1], ">", color=RIGHT_COLOR, mec="k", ms=11, label="right label")
        label_axes(ax, STEER_LABEL, ACCEL_LABEL, f"{METHOD_LABELS.get(m, m)}: E(x, y) − min E")
        ax.title.set_fontsize(10)
    if image is not None:
        bottom.colorbar(
            image, ax=list(ax_maps[: len(maps)]), label=f"energy above the minimum (nats, ≤ {clip:g})"
        )
        handles, names = ax_maps[0].get_legend_handles_labels()
        bottom.legend(handles, names, loc="outside lower center", ncol=3, fontsize=9)
    fig.suptitle(title or f"The Fig. 6 analogue at held-out fork {k} (label gap {gap:.2f}, the median fork)")
    return fig


# ------------------------------------------------------------------ 3. the profiles at the forks
def plot_profiles_at_forks(
    readings,
    names,
    *,
    baseline_names=None,
    clip: float = 12.0,
    title: str = "Energy over steering at every held-out fork, every agent",
):
    """Per energy method (columns) and replication (rows: ``names``, then ``baseline_names``), every agent's
    steering profile (the lowest energy over acceleration minus its minimum, ``<name>/forks/profile``) at
    every held-out fork as a thin line, with the valley criterion's depth (3 nats) and the labels' steering
    as ticks. ``baseline_names``: default the ``baseline/`` agents the readings hold (none: one row)."""
    check_positive("clip", clip)
    groups = {"study": _by_method(n for n in names if f"{n}/forks/profile" in readings)}
    if baseline_names is None:
        baseline_names = agents_in(readings, "baseline/")
    base = _by_method(n for n in baseline_names if f"{n}/forks/profile" in readings)
    if base:
        groups["baseline"] = base
    methods = [m for m in METHOD_LABELS if any(m in g for g in groups.values())]
    if not methods:
        raise ValueError("names must hold at least one energy agent with forks/profile readings")
    labels = as_array(readings["states/forks/labels"], float)  # (F, 2, 2)
    ncol, nrow = len(methods), len(groups)
    size = (min(4.8 * ncol, 9.4), 3.0 * nrow + 0.9)
    fig, axes = plt.subplots(
        nrow, ncol, figsize=size, squeeze=False, sharex=True, sharey=True, layout="constrained"
    )
    for r, (row, by_method) in enumerate(groups.items()):
        for c, m in enumerate(methods):
            ax = axes[r, c]
            agents = by_method.get(m, [])
            two = total = 0
            for n in agents:
                prof = as_array(readings[f"{n}/forks/profile"], float)  # (F, G)
                steer = symmetric_axis(prof.shape[1]).numpy()
                alpha = max(0.08, min(0.5, 8.0 / (len(prof) * len(agents))))
                color = METHOD_COLORS.get(m, "0.3")
                ax.plot(steer, np.minimum(prof, clip).T, color=color, lw=0.7, alpha=alpha)
                if f"{n}/forks/two_sided" in readings:
                    two += int(np.sum(as_array(readings[f"{n}/forks/two_sided"], bool)))
                total += len(prof)
            ax.axhline(DEPTH, color="k", ls="--", lw=1.2)
            ax.axvline(0, color="0.4", ls=":", lw=1)
            _label_ticks(ax, labels)
            ax.set_xlim(-1, 1)
            ax.set_ylim(0, clip)
            where = ROWS[row].split(" (")[0]
            ax.set_title(
                f"{METHOD_LABELS.get(m, m)}, {where}: {len(agents)} agents\n"
                f"{two} of {total} profiles with a valley each side",
                fontsize=9.5,
            )
            ax.set_xlabel(STEER_LABEL if r == nrow - 1 else "")
            ax.set_ylabel(f"E − min E (nats, ≤ {clip:g})" if c == 0 else "")
    handles = [
        Line2D([], [], color="0.3", lw=0.8, label="one agent at one fork"),
        Line2D([], [], color="k", ls="--", lw=1.2, label=f"{DEPTH:g} nats: the valley criterion's depth"),
        Line2D([], [], color=LEFT_COLOR, lw=2, label="left labels (steering)"),
        Line2D([], [], color=RIGHT_COLOR, lw=2, label="right labels (steering)"),
    ]
    fig.legend(handles=handles, loc="outside lower center", ncol=2, fontsize=9)
    fig.suptitle(title)
    return fig


def plot_fork_profiles(readings, names, fork: int, *, clip: float = 12.0):
    """At one held-out fork (``fork``), the steering profiles of the energy agents ``names`` (one line each,
    coloured by method), the fork's two labels and the 3-nat depth marked (``widgets.fork_explorer``'s
    picture)."""
    check_positive("clip", clip)
    labels = as_array(readings["states/forks/labels"], float)  # (F, 2, 2)
    k = check_int("fork", fork, minimum=0, maximum=len(labels) - 1)
    names = [n for n in names if f"{n}/forks/profile" in readings]
    if not names:
        raise ValueError("names must hold at least one energy agent with forks/profile readings")
    fig, ax = plt.subplots(figsize=(7.6, 3.8))
    few, shown = len(names) <= 8, set()  # few: one colour and legend entry per agent, else per method
    for i, n in enumerate(names):
        p = as_array(readings[f"{n}/forks/profile"], float)[k]  # (G,)
        m, style = method_of(n), "--" if n.startswith("baseline/") else "-"
        group = METHOD_LABELS.get(m, m) + (" (baseline)" if style == "--" else "")
        label = n if few else (None if group in shown else group)
        shown.add(group)
        color = f"C{i % 10}" if few else METHOD_COLORS.get(m, "0.3")
        ax.plot(symmetric_axis(len(p)).numpy(), np.minimum(p, clip), style, color=color, lw=1.4, label=label)
    ax.axhline(DEPTH, color="k", ls="--", lw=1, label=f"{DEPTH:g} nats (valley depth)")
    for side, color, name in ((0, LEFT_COLOR, "left label"), (1, RIGHT_COLOR, "right label")):
        ax.axvline(
            labels[k, side, 0], color=color, lw=2.5, alpha=0.8, label=f"{name} {labels[k, side, 0]:+.2f}"
        )
    ax.set_xlim(-1, 1)
    ax.set_ylim(0, clip)
    gap = labels[k, 1, 0] - labels[k, 0, 0]
    title = f"Held-out fork {k}: label gap {gap:.2f}"
    if "states/forks/entry_m" in readings:
        title += f", {float(readings['states/forks/entry_m'][k]):.1f} m before the entry"
    label_axes(ax, STEER_LABEL, f"E − min E (nats, ≤ {clip:g})", title)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    return fig


# ------------------------------------------------------------------ 4. the exits in closed loop
def plot_stem_exits(summary: dict, *, title: str = "Exits at the stems in the agents' table drives (town02)"):
    """Per agent (grouped by method; rows: this study, then the baseline if the summary has one) its stem
    crossings as stacked bars, left and right (``summary[row]["agents"][name]["left" | "right"]``), the
    episodes that ended at a stem written above in red, and the expert's split (``summary["expert"]``) as a
    black tick on every bar: where its left part would end if the agent turned left as often as the expert."""
    rows = [r for r in ("study", "baseline") if r in summary]
    if not rows:
        raise ValueError("summary must hold 'study' (and optionally 'baseline') readings")
    expert = summary.get("expert") or {}
    e_total = expert.get("left", 0) + expert.get("right", 0)
    fig, axes = plt.subplots(len(rows), 1, figsize=(9.4, 2.8 * len(rows) + 0.9), squeeze=False,
                             sharey=True, layout="constrained")  # fmt: skip
    for ax, row in zip(axes[:, 0], rows, strict=True):
        agents = summary[row]["agents"]
        x, ticks, labels = 0.0, [], []
        for m, names in _by_method(sort_agents(agents)).items():
            xs = x + np.arange(len(names))
            left = np.array([agents[n].get("left", 0) for n in names], dtype=float)
            right = np.array([agents[n].get("right", 0) for n in names], dtype=float)
            edge = METHOD_COLORS.get(m, "k")
            ax.bar(xs, left, color=EXIT_COLORS["left"], width=0.75, edgecolor=edge, lw=1.5)
            ax.bar(xs, right, bottom=left, color=EXIT_COLORS["right"], width=0.75, edgecolor=edge, lw=1.5)
            if e_total:
                ax.hlines((left + right) * expert["left"] / e_total, xs - 0.45, xs + 0.45, colors="k", lw=2)
            ends = [agents[n].get("stem_ends", 0) for n in names]
            for xp, e, h in zip(xs, ends, left + right, strict=True):
                if e:
                    ax.annotate(f"{e}", (xp, h), xytext=(0, 2), textcoords="offset points", ha="center",
                                va="bottom", color="C3", fontsize=9, fontweight="bold")  # fmt: skip
            # the method's name under its seeds
            ax.annotate(METHOD_LABELS.get(m, m), (xs.mean(), 0), xycoords=ax.get_xaxis_transform(),
                        xytext=(0, -17), textcoords="offset points", ha="center", va="top", fontsize=9,
                        color=edge, fontweight="bold")  # fmt: skip
            ticks += list(xs)
            labels += [str(_seed(n)) for n in names]
            x = xs[-1] + 1.8  # a gap between methods
        ax.set_xticks(ticks, labels, fontsize=8)
        ax.set_ylim(0, max(1.0, *(a.get("left", 0) + a.get("right", 0) for a in agents.values())) * 1.18)
        ax.set_ylabel("stem crossings")
        ax.set_xlabel("agent (seed), under its method", labelpad=18)
        ax.set_title(ROWS[row], fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    handles = [
        Patch(color=EXIT_COLORS["left"], label="left exit"),
        Patch(color=EXIT_COLORS["right"], label="right exit"),
        Line2D([], [], color="C3", marker="$n$", ls="", ms=9, label="n episodes ended at a stem"),
    ]
    if e_total:
        handles.append(
            Line2D([], [], color="k", lw=2, label=f"expert's left share ({expert['left']}/{e_total})")
        )
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=8.5)
    fig.suptitle(title)
    return fig


# ------------------------------------------------------------------ 5. two valleys on the approach
def _share_bars(ax, summary, methods, num: str, den: str) -> None:
    rows = [r for r in ("study", "baseline") if r in summary]
    width = 0.8 / len(rows)
    for j, row in enumerate(rows):
        for i, m in enumerate(methods):
            d = summary[row]["methods"].get(m)
            if d is None or not d.get(den):
                continue
            share = d[num] / d[den]
            xp = i - 0.4 + width * (j + 0.5)
            ax.bar(
                xp,
                share,
                width=width * 0.92,
                color=METHOD_COLORS.get(m, "0.5"),
                alpha=1.0 if row == "study" else 0.45,
                hatch=None if row == "study" else "//",
                edgecolor="k",
                lw=0.8,
            )
            ax.text(xp, share + 0.02, f"{d[num]}/{d[den]}", ha="center", va="bottom", fontsize=8,
                    bbox=dict(boxstyle="square,pad=0.1", fc="w", ec="none", alpha=0.8))  # fmt: skip
    ax.set_xticks(range(len(methods)), [METHOD_LABELS.get(m, m) for m in methods])
    ax.set_ylim(0, 1.15)
    ax.set_xlim(-0.6, len(methods) - 0.4)
    ax.grid(axis="y", alpha=0.3)


def plot_approach_two_valleys(
    summary: dict,
    *,
    target: float = 0.6,
    title: str = "Both answers kept on the approach to the town02 stems",
):
    """Two panels, per method, this study's bars beside the baseline's (hatched), counts above: the share of
    (agent, stem approach) pairs whose profile has a valley each side of straight at some distance
    (``approach_two_valleys`` / ``approach_pairs``; energy methods), with the ``target`` line; and the share
    of readings at the mass distances (6 and 4.5 m) with at least 0.2 Boltzmann (or Beta) mass on each side
    (``approach_both_sides`` / ``approach_mass_readings``)."""
    rows = [r for r in ("study", "baseline") if r in summary]
    if not rows:
        raise ValueError("summary must hold 'study' (and optionally 'baseline') readings")
    present = {m for r in rows for m in summary[r]["methods"]}
    methods = [m for m in METHOD_LABELS if m in present]
    energy = [m for m in methods if any("approach_pairs" in summary[r]["methods"].get(m, {}) for r in rows)]
    fig, (ax1, ax2) = plt.subplots(
        1,
        2,
        figsize=(9.6, 3.9),
        layout="constrained",
        gridspec_kw={"width_ratios": [max(len(energy), 1), len(methods)]},
    )
    _share_bars(ax1, summary, energy, "approach_two_valleys", "approach_pairs")
    ax1.axhline(target, color="C3", ls="--", lw=1.5)
    ax1.set_ylabel("share of (agent, approach) pairs")
    ax1.set_title("a valley each side of straight,\nat some distance from 8 to 2 m", fontsize=10)
    ax1.set_xlabel("method")
    _share_bars(ax2, summary, methods, "approach_both_sides", "approach_mass_readings")
    dist = summary.get("settings", {}).get("mass_distances_m", [6.0, 4.5])
    floor = summary.get("settings", {}).get("mass_floor", 0.2)
    ax2.set_ylabel("share of readings")
    ax2.set_title(
        f"≥ {floor:g} of the mass on each side,\nat {' and '.join(f'{d:g}' for d in dist)} m", fontsize=10
    )
    ax2.set_xlabel("method")
    handles = [Patch(facecolor="0.5", edgecolor="k", label=ROWS["study"])]
    if "baseline" in rows:
        handles.append(Patch(facecolor="0.5", alpha=0.45, hatch="//", edgecolor="k", label=ROWS["baseline"]))
    handles.append(Line2D([], [], color="C3", ls="--", lw=1.5, label=f"target: {target:g} of the pairs"))
    fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize=9)
    fig.suptitle(title + " (counts above the bars)")
    return fig


def plot_twin_steering(traces: dict, *, title: str = "A stem crossing and its twin: the steering labels"):
    """One panel per entry of ``traces`` (``{name: driving.forks.fork_traces(...)}``): the steering label of
    the recorded crossing and of its twin (its turn flipped) against the distance before the junction entry,
    the fork marked, and the label gap there written in the panel."""
    if not traces:
        raise ValueError("traces must hold at least one crossing")
    fig, axes = plt.subplots(1, len(traces), figsize=(4.6 * len(traces), 3.4), sharey=True, squeeze=False)
    for ax, (name, t) in zip(axes[0], traces.items(), strict=True):
        x = np.asarray(t["entry_m"])
        ax.plot(x, t["recorded"], "-o", ms=3, color="C0", label="recorded crossing")
        ax.plot(x, t["twin"], "--o", ms=3, color="C3", label="its twin (other turn)")
        k = int(t["fork"])
        gap = abs(float(t["recorded"][k]) - float(t["twin"][k]))
        ax.axvline(x[k], color="0.4", ls=":", lw=1)
        ax.text(
            0.03,
            0.95,
            f"fork: {x[k]:.1f} m before the entry\nlabel gap {gap:.2f}",
            transform=ax.transAxes,
            va="top",
            fontsize=8,
        )
        ax.set_xlim(max(x.max(), 6.0), min(x.min(), 0.0))  # the car drives towards the entry: left to right
        ax.axhline(0, color="0.8", lw=0.8)
        ax.set_title(name)
        ax.set_xlabel("distance before the junction entry (m)")
    axes[0, 0].set_ylabel(STEER_LABEL)
    axes[0, -1].legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return fig
