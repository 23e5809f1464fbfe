"""The figures of chapter 12 (plotting.two_answers) and its fork explorer, on a made-up analysis with the
layout of ``experiments.agents.two_answers.analyse``'s summary and readings."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from ibc_tutorial.plotting import two_answers as ta  # noqa: E402

F, N, G, A, S = 6, 26, 161, 21, 32  # forks, approach states (2 approaches x 13 distances), grid, BEV side


def _agent_rows(method, n, rng):
    rows = {}
    for seed in range(n):
        left, right = (int(x) for x in rng.integers(0, 12, 2))
        row = {
            "crossings": left + right,
            "left": left,
            "right": right,
            "stem_ends": int(rng.integers(0, 3)),
            "both_exits": left > 0 and right > 0,
            "approach_both_sides": 2,
            "approach_mass_readings": 4,
        }
        if method != "bc":
            row.update(
                approach_pairs=2, approach_two_valleys=int(rng.integers(0, 3)), forks=F, fork_two_valleys=1
            )
        rows[f"{method}-seed{seed}"] = row
    return rows


def _methods(agents):
    out = {}
    for name, row in agents.items():
        m = out.setdefault(ta.method_of(name), {})
        for key, value in row.items():
            if isinstance(value, (int, bool)):
                m[key] = m.get(key, 0) + int(value)
    return out


def fake_analysis(per_method=(2, 3), seed=0):
    """A summary and readings shaped like ``analyse``'s: ``per_method`` agents per method in the study
    and in the baseline."""
    rng = np.random.default_rng(seed)
    steer = np.linspace(-1, 1, G)
    summary = {
        "design": {"crossings": 240, "gap": [0.41, 0.43, 0.46]},
        "baseline_design": {"crossings": 25, "gap": [0.102, 0.107, 0.113]},
        "heldout_forks": {"forks": F, "gap_min": 0.42, "gap_median": 0.44, "gap_max": 0.45},
        "settings": {"mass_distances_m": [6.0, 4.5], "mass_floor": 0.2},
        "expert": {"left": 30, "right": 32, "crossings": 62, "stem_ends": 0},
        "fig6_fork": {"index": 2, "gap": 0.44},
    }
    readings = {
        "states/forks/labels": np.tile(np.array([[[-0.17, 0.04], [0.27, 0.04]]], np.float32), (F, 1, 1)),
        "states/forks/bev": rng.integers(0, 2, (F, 5, S, S)).astype(np.uint8),
        "states/forks/entry_m": np.full(F, 2.2),
        "states/forks/gap": np.full(F, 0.44),
        "fig6/ibc": rng.random((A, G)) * 20,
        "fig6/da-ibc": rng.random((A, G)) * 20,
    }
    for row, n in zip(("study", "baseline"), per_method, strict=True):
        agents = {}
        for method in ("bc", "ibc", "da-ibc"):
            agents.update(_agent_rows(method, n, rng))
        summary[row] = {"agents": agents, "methods": _methods(agents)}
        prefix = "" if row == "study" else "baseline/"
        for name in agents:
            if name.startswith("bc-"):
                readings[f"{prefix}{name}/forks/alpha"] = rng.uniform(5, 20, F).astype(np.float32)
                readings[f"{prefix}{name}/forks/beta"] = rng.uniform(5, 20, F).astype(np.float32)
                readings[f"{prefix}{name}/forks/mean"] = rng.uniform(-0.1, 0.1, F)
            else:
                centre = rng.uniform(-0.1, 0.1, (F, 1))
                prof = 40 * ((steer - centre) ** 2 - 0.05) ** 2
                readings[f"{prefix}{name}/forks/profile"] = (prof - prof.min(1, keepdims=True)).astype(
                    np.float32
                )
                readings[f"{prefix}{name}/forks/two_sided"] = rng.random(F) < 0.5
                readings[f"{prefix}{name}/forks/label_energy"] = rng.random((F, 2))
    return summary, readings


def titled(fig):
    """The figure's title (its suptitle, else its first axis's), its axes' x and y labels; then closed."""
    axes = [ax for ax in fig.axes if ax.get_visible() and ax.axison]
    title = fig._suptitle.get_text() if fig._suptitle is not None else axes[0].get_title()
    xl, yl = [ax.get_xlabel() for ax in axes], [ax.get_ylabel() for ax in axes]
    plt.close(fig)
    return title, xl, yl


def test_agent_names_are_found_and_sorted_by_method_then_seed():
    _, r = fake_analysis((2, 3))
    assert ta.agents_in(r) == ["ibc-seed0", "ibc-seed1", "da-ibc-seed0", "da-ibc-seed1"]
    assert ta.agents_in(r, key="forks/alpha") == ["bc-seed0", "bc-seed1"]
    assert len(ta.agents_in(r, "baseline/")) == 6
    assert ta.method_of("baseline/da-ibc-seed12") == "da-ibc"
    assert ta.sort_agents(["ibc-seed10", "bc-seed1", "ibc-seed2"]) == ["bc-seed1", "ibc-seed2", "ibc-seed10"]


def test_fork_gaps_one_row_per_data_set_with_counts():
    s, r = fake_analysis()
    fig = ta.plot_fork_gaps(
        s["design"], s["baseline_design"], heldout=s["heldout_forks"], gaps={"heldout": r["states/forks/gap"]}
    )
    ticks = [t.get_text() for t in fig.axes[0].get_yticklabels()]
    assert len(ticks) == 3 and "25 crossings" in ticks[0] and f"{F} forks" in ticks[2]
    title, xl, _ = titled(fig)
    assert title and xl == [ta.GAP_LABEL]
    assert len(titled(ta.plot_fork_gaps(s["design"]))[0])  # the designed data alone


def test_fork_landscapes_draw_the_bev_bc_and_each_energy_map():
    s, r = fake_analysis()
    fig = ta.plot_fork_landscapes(r, s)
    titles = [ax.get_title() for ax in fig.axes]
    assert any("IBC" in t for t in titles) and any("DA-IBC" in t for t in titles)
    assert any("bc-seed0" in t for t in titles) and "what the agents see" in titles
    bc = next(ax for ax in fig.axes if "bc-seed0" in ax.get_title())
    assert {"left label -0.17", "right label +0.27"} <= {t.get_text() for t in bc.get_legend().get_texts()}
    assert any("nats" in ax.get_ylabel() for ax in fig.axes)  # the colour bar
    title, xl, yl = titled(fig)
    assert "fork 2" in title and any(xl) and any(yl)
    with pytest.raises(ValueError, match="clip"):
        ta.plot_fork_landscapes(r, s, clip=0)


def test_profiles_at_forks_one_panel_per_method_and_replication():
    s, r = fake_analysis((2, 3))
    fig = ta.plot_profiles_at_forks(r, list(s["study"]["agents"]))
    assert len(fig.axes) == 4  # (study, baseline) x (IBC, DA-IBC)
    assert "IBC, this study: 2 agents" in fig.axes[0].get_title()
    assert "DA-IBC, baseline: 3 agents" in fig.axes[3].get_title()
    assert len(fig.axes[0].lines) >= 2 * F
    title, xl, yl = titled(fig)
    assert title and any(xl) and any(yl)
    assert len(ta.plot_profiles_at_forks(r, ["ibc-seed0"], baseline_names=[]).axes) == 1
    plt.close("all")
    with pytest.raises(ValueError, match="energy agent"):
        ta.plot_profiles_at_forks(r, ["bc-seed0"], baseline_names=[])


def test_fork_profiles_at_one_fork():
    _, r = fake_analysis()
    fig = ta.plot_fork_profiles(r, ta.agents_in(r) + ta.agents_in(r, "baseline/"), 1)
    assert fig.axes[0].get_title().startswith("Held-out fork 1: label gap 0.44")
    title, xl, yl = titled(fig)
    assert xl[0] and yl[0]
    with pytest.raises(ValueError, match="fork"):
        ta.plot_fork_profiles(r, ["ibc-seed0"], F)


def test_stem_exits_bars_per_agent_with_the_experts_split():
    s, _ = fake_analysis((2, 3))
    fig = ta.plot_stem_exits(s)
    study, base = fig.axes[:2]
    assert [t.get_text() for t in study.get_xticklabels()] == ["0", "1"] * 3
    assert len(base.get_xticklabels()) == 9
    assert study.get_title() == ta.ROWS["study"] and base.get_title() == ta.ROWS["baseline"]
    heights = [p.get_height() for p in study.patches][:4]  # BC: seeds 0 and 1 left, then right
    bc0 = s["study"]["agents"]["bc-seed0"]
    assert heights[0] == bc0["left"] and heights[2] == bc0["right"]
    ticks = study.collections[0].get_segments()  # the expert's split on each bar: 30/62 of its height
    assert ticks[0][0][1] == pytest.approx((bc0["left"] + bc0["right"]) * 30 / 62)
    assert "expert's left share (30/62)" in [t.get_text() for t in fig.legends[0].get_texts()]
    title, xl, yl = titled(fig)
    assert title and all(xl) and all(yl)
    del s["baseline"]
    assert len(ta.plot_stem_exits(s).axes) == 1
    plt.close("all")
    with pytest.raises(ValueError, match="summary"):
        ta.plot_stem_exits({})


def test_approach_two_valleys_shares_with_the_target():
    s, _ = fake_analysis()
    fig = ta.plot_approach_two_valleys(s, target=0.6)
    ax1, ax2 = fig.axes
    assert [t.get_text() for t in ax1.get_xticklabels()] == ["IBC", "DA-IBC"]
    assert [t.get_text() for t in ax2.get_xticklabels()] == ["BC (Beta)", "IBC", "DA-IBC"]
    assert any(line.get_ydata()[0] == 0.6 for line in ax1.lines)
    assert "/" in ax1.texts[0].get_text()  # counts above the bars
    title, xl, yl = titled(fig)
    assert title and all(xl) and all(yl)
    with pytest.raises(ValueError, match="summary"):
        ta.plot_approach_two_valleys({})


def test_fork_explorer_redraws_on_the_slider_and_the_dropdown():
    from ibc_tutorial.widgets import fork_explorer

    _, r = fake_analysis()
    names = ta.agents_in(r)
    box = fork_explorer(r, names)
    fork, agent = box.children[0].children
    image = box.children[-1]
    first = image.value
    assert first[:4] == b"\x89PNG" and fork.max == F - 1
    assert list(agent.options) == ["all agents", *names]
    fork.value = 3
    second = image.value
    agent.value = names[0]
    assert first != second != image.value
    with pytest.raises(ValueError, match="energy agent"):
        fork_explorer(r, ["bc-seed0"])


def test_plot_twin_steering_marks_the_fork():
    from ibc_tutorial.plotting.two_answers import plot_twin_steering

    t = {
        "entry_m": np.linspace(8, 1, 20),
        "recorded": np.r_[np.zeros(12), -0.2 * np.ones(8)],
        "twin": np.r_[np.zeros(12), 0.25 * np.ones(8)],
        "fork": 12,
    }
    fig = plot_twin_steering({"a crossing": t})
    ax = fig.axes[0]
    assert ax.get_title() == "a crossing" and "entry" in ax.get_xlabel()
    assert any("label gap 0.45" in txt.get_text() for txt in ax.texts)
    with pytest.raises(ValueError, match="traces"):
        plot_twin_steering({})
