"""The plotting package: figures build on tiny synthetic inputs with titles and axis labels, steering
axes use the book's convention, and ``show`` emits a PNG only."""

from pathlib import Path
from types import SimpleNamespace

import matplotlib.pyplot as plt
import numpy as np
import pytest
import torch

from ibc_tutorial import plotting
from ibc_tutorial.optimizers.dfo import DFOConfig
from ibc_tutorial.plotting import agents, common, ingredients, multimodality, replication, town
from ibc_tutorial.toy import SideRoadWorld, TreeWorld

PACKAGE = Path(plotting.__file__).parent


def assert_labelled(fig, *, ylabel: bool = True):
    """The figure has a title (its own, or its top axis's) and labelled axes; then close it."""
    axes = [ax for ax in fig.axes if ax.get_visible() and ax.axison and ax.get_label() != "<colorbar>"]
    assert fig._suptitle is not None or axes[0].get_title()
    assert any(ax.get_xlabel() for ax in axes)
    if ylabel:
        assert any(ax.get_ylabel() for ax in axes)
    plt.close(fig)


# --------------------------------------------------------------------------- the package
def test_show_emits_a_png_only_and_closes(monkeypatch):
    import IPython
    import IPython.display

    fig, ax = plt.subplots()  # before the patch: pyplot asks IPython for its shell when it makes a figure
    ax.plot([0, 1], [0, 1])
    shown = []
    monkeypatch.setattr(IPython, "get_ipython", lambda: object())
    monkeypatch.setattr(IPython.display, "display", lambda obj, raw=False: shown.append((obj, raw)))
    plotting.show(fig)
    assert len(shown) == 1
    obj, raw = shown[0]
    assert raw and list(obj) == ["image/png"] and obj["image/png"].startswith(b"\x89PNG")
    assert not plt.fignum_exists(fig.number)


def test_show_outside_ipython_only_closes_and_save_writes_a_png(tmp_path):
    fig, _ = plt.subplots()
    plotting.show(fig)
    assert not plt.fignum_exists(fig.number)
    fig, _ = plt.subplots()
    plotting.save(fig, tmp_path / "sub" / "f.png")
    assert (tmp_path / "sub" / "f.png").read_bytes().startswith(b"\x89PNG")
    with pytest.raises(ValueError, match="dpi"):
        plotting.show(plt.figure(), dpi=0)


def test_no_steering_label_in_the_old_convention():
    for path in PACKAGE.glob("*.py"):
        text = path.read_text(encoding="utf-8")
        for old in ("+1 left", "-1 right", "−1 right", "-1 = full right", "−1 = full right"):
            assert old not in text, f"{path.name} still says {old!r}"


# --------------------------------------------------------------------------- common
def test_common_figures_have_titles_and_labels():
    x = [1, 2, 4, 8]
    assert_labelled(
        common.plot_lines(
            x,
            {"a": [0.1, 0.2, 0.3, 0.4], "b": [0.4, 0.3, 0.2, 0.1]},
            xlabel="samples",
            ylabel="rate",
            title="t",
            logx=True,
            logy=True,
        )
    )
    assert_labelled(
        common.plot_lines(
            {"a": [1, 2], "b": [1, 3, 5]},
            {"a": [0, 1], "b": [1, 0, 1]},
            xlabel="x",
            ylabel="y",
            title="t",
        )
    )
    fig = common.plot_bars(
        ["cruise", "junction"],
        {"A": [0.5, 0.5], "B": [0.9, 0.1]},
        ylabel="share",
        title="t",
        points={"A": np.full((3, 2), 0.5)},
        reference={"data": [0.7, 0.3]},
    )
    assert [t.get_text() for t in fig.axes[0].get_xticklabels()] == ["cruise", "junction"]
    plt.close(fig)  # bars have no x label: the categories name them
    fig = common.plot_learning_curves(
        np.arange(5),
        {"IBC": np.random.default_rng(0).random((3, 5))},
        ylabel="NLL",
        title="t",
        references={"expert": 0.5},
    )
    assert "mean of 3 seeds" in fig.axes[0].get_legend().get_texts()[0].get_text()
    assert_labelled(fig)


def test_common_helpers():
    assert common.as_array(torch.ones(2, requires_grad=True), float).dtype == np.float64
    fig, ax = plt.subplots()
    assert common.figure_and_axes(ax, (1, 1)) == (fig, ax, False)
    assert common.plot_lines([0, 1], {"a": [0, 1]}, xlabel="x", ylabel="y", title="t", ax=ax) is fig
    plt.close(fig)
    with pytest.raises(ValueError, match="series"):
        common.plot_bars(["a"], {}, ylabel="y", title="t")


# --------------------------------------------------------------------------- Part I
def test_multimodality_figures():
    actions = torch.linspace(-1, 1, 21)
    energies = (actions[None, :] - torch.linspace(-0.5, 0.5, 6)[:, None]) ** 2  # (6, 21)
    fig = multimodality.plot_energy_landscape(
        torch.linspace(10, 0, 6), actions, energies, path=torch.zeros(6), expert=(np.ones(3), np.zeros(3))
    )
    assert fig.axes[0].get_ylabel() == common.STEER_LABEL == "steering (−1 left … +1 right)"
    assert_labelled(fig)
    fig = multimodality.plot_energy_curves(actions, {"near": energies[0], "far": energies[-1]}, title="t")
    assert fig.axes[0].get_xlabel() == common.STEER_LABEL
    assert_labelled(fig)
    assert_labelled(multimodality.plot_command_traces(0.1, {"a": np.zeros(10), "b": np.ones(10)}))
    fig = multimodality.plot_command_traces(
        0.1, {"a": np.zeros(10), "b": np.ones(10), "c": -np.ones(10)}, reference="a"
    )
    assert len(fig.axes) == 3  # one panel per trace, so that nearly equal traces do not overlap
    assert [len(ax.lines) for ax in fig.axes] == [
        2,
        3,
        3,
    ]  # zero line, trace, and the reference in the others
    assert_labelled(fig)
    with pytest.raises(ValueError, match="reference"):
        multimodality.plot_command_traces(0.1, {"a": np.zeros(10)}, reference="b")
    # the measured window, shaded in every panel
    fig = multimodality.plot_command_traces(0.1, {"a": np.zeros(10), "b": np.ones(10)}, shade=(0.0, 0.5))
    assert all(len(ax.patches) == 1 for ax in fig.axes)
    with pytest.raises(ValueError, match="shade"):
        multimodality.plot_command_traces(0.1, {"a": np.zeros(10)}, shade=(0.5, 0.1))
    assert_labelled(
        multimodality.plot_density_fits(
            torch.rand(30) * 2 - 1, actions, {"flat": torch.full((21,), 0.5)}, title="t"
        )
    )
    assert_labelled(multimodality.plot_beta_shapes([(2, 2)]))
    prev = torch.linspace(-1, 1, 5)
    fig = multimodality.plot_response_map(prev, {"copy": prev, "zero": torch.zeros(5)}, title="t")
    assert len(fig.axes[0].lines) == 3  # the diagonal and the two responses
    assert_labelled(fig)
    with pytest.raises(ValueError, match="shape"):
        multimodality.plot_response_map(prev, {"short": torch.zeros(3)}, title="t")
    # the range of previous actions the demonstrations hold, shaded and in the legend
    fig = multimodality.plot_response_map(prev, {"copy": prev}, title="t", seen=(-0.2, 0.2))
    assert len(fig.axes[0].patches) == 1
    assert "previous steering of the experts here" in [t.get_text() for t in fig.axes[0].get_legend().texts]
    with pytest.raises(ValueError, match="seen"):
        multimodality.plot_response_map(prev, {"copy": prev}, title="t", seen=(0.2, -0.2))


def test_rollout_figures_share_one_drawing():
    tree, road = TreeWorld(), SideRoadWorld()
    r_tree = tree.rollout(lambda obs: torch.zeros(len(obs), 1), 3, seed=0)
    r_road = road.rollout(lambda obs: torch.full((len(obs), 1), 0.5), 3, seed=0)
    fig = multimodality.plot_tree_closed_loop(tree, {"zero": r_tree})
    assert len(fig.axes[0].lines) >= 3 and fig.axes[0].get_title().startswith("zero:")
    assert_labelled(fig)
    fig = ingredients.plot_tree_rollouts(tree, {"zero": r_tree, "again": r_tree}, max_episodes=2)
    assert len(fig.axes[0].lines) == 2 and "collided or neither" in fig.axes[0].get_title()
    assert_labelled(fig)
    fig = multimodality.plot_rollout_grid(road, {"a": r_road}, title="grid", ncols=1)
    assert fig.axes[0].get_title().startswith("a: of 3: main 0")  # counts, not rounded shares
    assert_labelled(fig)
    assert multimodality.rollout_colors(tree, r_tree) == [
        multimodality.TREE_SIDE_COLORS[int(v)] for v in tree.pass_side(r_tree)
    ]
    # every closed-loop figure has a colour key of the outcomes
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert labels == [
        "ended on the main road",
        "ended on the side road",
        "left the road",
        "where it collided",
    ]
    fig = multimodality.plot_tree_closed_loop(tree, {"zero": r_tree})
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert labels[:3] == ["passed on the left", "passed on the right", "collided"]
    with pytest.raises(ValueError, match="rollouts"):
        multimodality.plot_side_road(road, {})


# --------------------------------------------------------------------------- Part II
def test_ingredients_figures():
    axis = torch.linspace(-1, 1, 9)
    e = axis[:, None] ** 2 + axis[None, :] ** 2  # (9, 9)
    fig = ingredients.plot_energy_2d(
        e, axis, title="t", unvisited=e > 1, modes=np.zeros((1, 2)), argmin=(0.0, 0.0)
    )
    assert fig.axes[0].get_xlabel() == common.STEER_LABEL
    assert_labelled(fig)
    # the hatching of unvisited cells has its legend entry
    assert any("never visited" in t.get_text() for t in fig.axes[0].get_legend().get_texts())
    acts = np.random.default_rng(0).uniform(-1, 1, (20, 2))
    assert_labelled(ingredients.plot_counter_examples(acts, np.arange(20) % 3, {"uniform": acts}))
    assert_labelled(
        ingredients.plot_sigma_sweep([0.1, 0.3], np.ones((2, 3)), uniform=np.ones(3), ylabel="NLL", title="t")
    )
    assert_labelled(ingredients.plot_kde_by_hand([0.0, 0.5], np.linspace(-1, 1, 11), 0.2, np.ones(11)))
    assert_labelled(ingredients.plot_kde_bandwidths({0.1: np.ones((9, 9)), 0.2: np.ones((9, 9))}, axis, acts))
    assert_labelled(ingredients.plot_populations_2d(e, axis, {"DFO": acts}, title="t"))


def test_paired_gains_and_weights_figures():
    gains = np.array([[0.1, -0.2], [0.3, 0.4], [0.0, 1.5]])  # (S=3, K=2)
    fig = ingredients.plot_paired_gains(
        ["a", "b"], gains, seeds=[0, 1, 2], xlabel="x", ylabel="gain", title="t"
    )
    ax = fig.axes[0]
    medians = sorted(float(seg[0][1]) for c in ax.collections for seg in getattr(c, "get_segments", list)())
    assert np.allclose([m for m in medians if m != 0.0], [0.1, 0.4])  # one median tick per column
    assert sorted(t.get_text() for t in ax.texts) == [
        "0",
        "0",
        "1",
        "1",
        "2",
        "2",
    ]  # every dot named by its seed
    assert_labelled(fig, ylabel=True)
    with pytest.raises(ValueError, match="gains"):
        ingredients.plot_paired_gains(["a"], gains, ylabel="gain", title="t")
    values = np.r_[np.full(10, -1.0), 0.5]  # ten samples in the first bin, one alone in another
    w = np.r_[np.ones(10), 20.0]
    fig = ingredients.plot_weights_by_value(
        values, {"w": w}, edges=np.linspace(-1, 1, 5), xlabel="x", title="t"
    )
    ax = fig.axes[0]
    assert ax.get_yscale() == "log"
    means = ax.lines[0].get_ydata()
    assert means[0] == 1.0 and np.isnan(means[3])  # the lone sample is a dot, not a bin's mean
    assert 20.0 in ax.collections[0].get_offsets()[:, 1]
    assert_labelled(fig)
    with pytest.raises(ValueError, match="weights"):
        ingredients.plot_weights_by_value(
            values, {"w": w[:3]}, edges=np.linspace(-1, 1, 5), xlabel="x", title="t"
        )


def test_dfo_iteration_figure():
    g = torch.Generator().manual_seed(0)
    samples = [torch.rand(50, 1, generator=g) * 2 - 1 for _ in range(3)]
    trace = SimpleNamespace(
        samples=samples,
        sigmas=[0.3, 0.1, float("nan")],
        action=torch.tensor([0.2]),
        config=DFOConfig(select="sample"),
    )
    grid = np.linspace(-1, 1, 21)
    fig = ingredients.plot_dfo_iterations(trace, grid, grid**2, bins=10)
    assert fig.axes[0].get_title().startswith("iteration 1") and "last" in fig.axes[2].get_title()
    assert "drawn" in fig.axes[2].get_title()
    plt.close(fig)
    argmax_trace = SimpleNamespace(**{**vars(trace), "config": DFOConfig(select="argmax")})
    fig = ingredients.plot_dfo_iterations(argmax_trace, grid, grid**2, bins=10)
    assert "argmax" in fig.axes[2].get_title()  # the title follows the final choice
    plt.close(fig)
    assert_labelled(fig)
    fig, ax = plt.subplots()
    energy_ax = ingredients.draw_dfo_iteration(ax, trace, 3, grid, grid**2, 10)
    assert energy_ax is not ax and ax.get_xlabel() == "action y"
    with pytest.raises(ValueError, match="it"):
        ingredients.draw_dfo_iteration(ax, trace, 4, grid, grid**2, 10)
    plt.close(fig)


# --------------------------------------------------------------------------- chapters 07-09
def test_town_figures():
    from ibc_tutorial.driving import get_town

    t = np.arange(20) * 0.1
    fig = town.plot_light_timeline(np.zeros((20, 3), dtype=int), labels=["a", "b", "c"])
    assert [t.get_text() for t in fig.axes[0].get_yticklabels()] == ["a", "b", "c"]
    assert_labelled(fig, ylabel=False)  # the heads' names label the y axis
    assert_labelled(
        town.plot_light_stop(
            t, 10 - t, np.ones(20), np.r_[np.zeros(10), 2 * np.ones(10)], gap_no_brake=10 - 2 * t
        )
    )
    fig = town.plot_action_histograms(np.zeros((10, 2)))
    assert fig.axes[0].get_xlabel() == common.STEER_LABEL
    assert_labelled(fig)
    assert_labelled(town.plot_step_and_turn(t, t, t, {"left": np.c_[t, t]}, radii={"left": (0, 1, 1)}))
    town02 = get_town("town02")
    assert_labelled(town.plot_routes(town02, [np.c_[t, t]]))
    path = np.c_[np.linspace(0, 200, 201), np.zeros(201)]  # 200 m eastwards
    fig = town.plot_routes(town02, [path], arrow_every_m=50.0)
    arrows = [c for c in fig.axes[0].texts if getattr(c, "arrow_patch", None) is not None]
    assert len(arrows) == 4 and all(a.xy[0] > a.xyann[0] for a in arrows)  # pointing east
    plt.close(fig)
    with pytest.raises(ValueError):
        town.plot_routes(town02, [path], arrow_every_m=0.0)
    fig = town.plot_bev_samples(np.zeros((2, 5, 64, 64)), np.zeros((2, 2)), np.ones((2, 3)))
    assert fig._suptitle is not None and fig.axes[0].get_title().startswith("v 1.0")
    plt.close(fig)


def test_free_driving_small_multiples():
    from ibc_tutorial.driving import get_town

    xy = np.array([[10.0, 10.0], [50.0, 10.0], [50.0, 60.0]])
    tracks = {"bc": [xy] * 3, "da-ibc": [xy] * 2}
    fig = replication.plot_free_driving(
        get_town("town02"), tracks, panel_titles={"bc": ["a", "b", "c"]}, columns=2
    )
    shown = [ax for ax in fig.axes if ax.get_visible()]
    assert len(shown) == 5 and [ax.get_title() for ax in shown[:3]] == ["a", "b", "c"]  # one episode per map
    assert all(ax.get_legend() is None for ax in fig.axes) and shown[3].get_title() == "episode 0"
    assert [f._suptitle.get_text() for f in fig.subfigs] == ["BC (Beta)", "DA-IBC"]
    assert_labelled(fig)
    with pytest.raises(ValueError, match="trajectories"):
        replication.plot_free_driving(get_town("town02"), {"bc": []})


def test_agents_figures():
    assert agents.plot_agent_architecture().axes[0].get_title()
    plt.close("all")
    curves = {
        "bc": {0: {"epoch": [1, 2], "score": [1.0, 2.0]}, 1: {"epoch": [1, 2], "score": [2.0, 3.0]}},
        "ibc": {},
    }
    assert_labelled(agents.plot_training_curves(curves))
    fig = agents.plot_training_curves(curves, reference=(250.0, "expert"))
    assert any(line.get_label() == "expert" and line.get_ydata()[0] == 250.0 for line in fig.axes[0].lines)
    plt.close(fig)
    fig = agents.plot_loss_curves({"bc": ([1, 2], [1.0, 0.5]), "da-ibc": ([1, 2], [2.0, 1.0])})
    assert [ax.get_title() for ax in fig.axes] == ["BC (Beta)", "DA-IBC"]
    assert_labelled(fig)
    steer, accel = np.linspace(-1, 1, 5), np.linspace(-1, 1, 4)
    fig = agents.plot_energy_landscapes(
        [("p", np.ones((4, 5)) + accel[:, None], np.array([[0.0, -1.0], [0.1, -1.0], [0.0, 0.0]]), None)],
        steer,
        accel,
    )
    assert common.STEER_LABEL in fig.axes[1].get_xlabel()
    assert not fig.axes[1].collections[-1].get_clip_on()  # draws at full braking (-1) are not cut
    assert_labelled(fig)
    counts = {
        "bc": {3: {"left": 1, "straight": 2, "right": 0}},
        "da-ibc": {3: {"left": 0, "straight": 1, "right": 1}, 5: {"left": 2, "straight": 0, "right": 0}},
    }
    fig = agents.plot_exit_counts(counts)
    assert [ax.get_title() for ax in fig.axes] == ["BC (Beta)", "DA-IBC"]
    assert [t.get_text() for t in fig.axes[1].get_xticklabels()] == ["3", "5"]
    assert fig.axes[1].patches[1].get_height() == 2  # da-ibc, approach 5, left
    assert_labelled(fig)
    with pytest.raises(ValueError):
        agents.plot_exit_counts({})
    fig = agents.plot_labels_at_rest(
        {"no held brakes": np.array([-1.0, -1.0, -1.0, 1.0]), "held brakes": [0.9, -1.0]}
    )
    assert "25% say go" in fig.axes[0].get_title() and "50% say go" in fig.axes[1].get_title()
    assert sum(p.get_height() for p in fig.axes[0].patches) == pytest.approx(
        1.0
    )  # shares of the states at rest
    assert_labelled(fig)
    with pytest.raises(ValueError):
        agents.plot_labels_at_rest({})
    fig = agents.plot_crossing_steering(
        {
            "IBC": {"left": [[-0.6, -0.1], [-0.5, -0.2]], "ended": [[-0.1, 0.2]]},
            "BC": {"right": np.zeros((0, 2))},
        }
    )
    texts = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert texts == ["left (2)", "ended (1)"] and fig.axes[0].get_title() == "IBC"
    assert_labelled(fig)
    for bad in ({}, {"IBC": {}}):
        with pytest.raises(ValueError):
            agents.plot_crossing_steering(bad)
    steer = np.linspace(-1, 1, 5)
    fig = agents.plot_crossing_energies(
        {"IBC seed 0": [[3, 1, 0, 2, 9], [2, 0, 1, 5, 20]], "B": np.zeros((1, 5))}, steer, clip=10
    )
    line = fig.axes[0].get_lines()[0]
    assert list(line.get_xdata()) == [0.0, -0.5] and fig.axes[0].get_title() == "IBC seed 0"
    assert fig.axes[0].get_images()[0].get_array().max() == 10  # clipped
    assert_labelled(fig)
    for bad in (
        dict(panels={}),
        dict(panels={"A": np.zeros((0, 5))}),
        dict(panels={"A": np.zeros((1, 5))}, clip=0),
    ):
        with pytest.raises(ValueError):
            agents.plot_crossing_energies(steer=steer, **bad)


def test_bev_channels_colour_bar_names_the_light_levels():
    bev = np.zeros((5, 24, 24), dtype=np.float32)
    bev[2:, 5, 5:10] = 0.6
    fig = town.plot_bev_channels(bev, light_levels=(0.3, 0.6, 1.0), level_names=("green", "yellow", "red"))
    bar = fig.axes[-1].child_axes[0]  # the colour bar beside the last light channel
    labels = [t.get_text() for t in bar.get_yticklabels()]
    assert labels == ["no line 0", "green 0.3", "yellow 0.6", "red 1"]
    plt.close(fig)
    fig = town.plot_bev_channels(bev)  # by default one level: a one-bit encoding
    bar = fig.axes[-1].child_axes[0]  # the colour bar beside the last light channel
    assert [t.get_text() for t in bar.get_yticklabels()] == ["no line 0", "light 1"]
    plt.close(fig)
    with pytest.raises(ValueError, match="level_names"):
        town.plot_bev_channels(bev, light_levels=(0.3, 0.6, 1.0))


def test_stem_figures():
    fig = agents.plot_stem_exit_shares(
        {"bc (v1)": (0.02, 0.0, 0.1), "da-ibc": (0.4, 0.3, 0.5), "expert": (0.5, 0.3, 0.7)}
    )
    assert_labelled(fig)
    assert len(fig.axes[0].patches) == 3
    assert fig.axes[0].get_legend().get_texts()[0].get_text() == "0.5: both exits alike"
    plt.close(fig)
    fig = agents.plot_stem_exit_shares({"ibc": (0.2, 0.1, 0.3)}, reference=0.3, reference_label="the target")
    assert fig.axes[0].get_legend().get_texts()[0].get_text() == "0.3: the target"
    plt.close(fig)
    pos = np.arange(-5, 6)
    fig = agents.plot_left_mass_by_position(
        {"turned left": (pos, np.linspace(0.5, 1, 11)), "turned right": (pos, np.linspace(0.5, 0, 11))}
    )
    assert_labelled(fig)
    assert len(fig.axes[0].lines) >= 2
    plt.close(fig)
    steer = np.linspace(-1, 1, 41)
    fig = agents.plot_steering_profiles({"stem": (steer - 0.3) ** 2 * 20, "red light": steer**2 * 40}, steer)
    assert_labelled(fig)
    assert len(fig.axes) == 2
    plt.close(fig)
    with pytest.raises(ValueError, match="one length"):
        agents.plot_left_mass_by_position({"x": (pos, pos[:3])})
    with pytest.raises(ValueError, match="one energy per steering value"):
        agents.plot_steering_profiles({"x": steer[:5]}, steer)
    with pytest.raises(ValueError, match="shares"):
        agents.plot_stem_exit_shares({})


def test_figure_explorer_redraws_on_each_control():
    import ipywidgets as w
    import matplotlib.pyplot as plt

    from ibc_tutorial.widgets import figure_explorer

    calls = []

    def draw(route, distance):
        calls.append((route, distance))
        fig, ax = plt.subplots()
        ax.set_title(f"{route} {distance}")
        return fig

    route = w.Dropdown(options=["r1", "r2"], value="r1")
    distance = w.SelectionSlider(options=[10, 5, 0], value=10)
    box = figure_explorer(draw, {"route": route, "distance": distance})
    image = box.children[-1]
    first = image.value
    route.value = "r2"
    distance.value = 0
    assert calls == [("r1", 10), ("r2", 10), ("r2", 0)] and image.value != first
    with pytest.raises(ValueError, match="controls must hold"):
        figure_explorer(draw, {})


def test_route_figures_draw_and_check_their_input():
    from ibc_tutorial.driving.route_following import route_path
    from ibc_tutorial.driving.towns import get_town
    from ibc_tutorial.plotting import routes
    from ibc_tutorial.stats import Interval

    xy, cmds = route_path("r4")
    fig = routes.plot_route_commands(get_town("town02"), xy, cmds, marks={"stem": xy[10]})
    assert fig.axes[0].get_title() == "A route and its commands"
    with pytest.raises(ValueError, match="xy must be"):
        routes.plot_route_commands(get_town("town02"), xy, cmds[:-1])
    with pytest.raises(ValueError, match="commands must be indices"):
        routes.plot_route_commands(get_town("town02"), xy, cmds + 4)
    rows = {"a": Interval(0.5, 0.4, 0.6), "b": Interval(0.9, 0.8, 1.0)}
    fig = routes.plot_intervals(rows, xlabel="x", title="t", reference=1.0)
    assert list(fig.axes[0].get_yticks()) == [1, 0]  # "a" drawn on top
    fig = routes.plot_success_by_command({"BC": {"left": Interval(0.5, 0.4, 0.6), "straight": None}})
    assert fig.axes[0].get_ylim() == (0, 1.05)
    steer = np.linspace(-1, 1, 5)
    fig = routes.plot_command_curves(
        {"2 m": {"left": steer**2, "no command": steer}}, steer, ylabel="E", title="T"
    )
    assert len(fig.axes) == 1 and len(fig.axes[0].lines) == 3  # two curves and the zero line
    assert fig.axes[0].get_legend() is None and len(fig.legends) == 1  # one legend, off the curves
    four = {f"{d} m": {"left": steer**2, "right": steer**3} for d in (1, 2, 3, 4)}
    fig = routes.plot_command_curves(four, steer, ylabel="E", title="T")
    assert len(fig.axes) == 4 and len({ax.get_position().y0 for ax in fig.axes}) == 2  # two rows of two
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["left", "right"]
    assert_labelled(fig)
    with pytest.raises(ValueError, match="one value per steering value"):
        routes.plot_command_curves({"2 m": {"left": steer[:3]}}, steer, ylabel="E", title="T")


def test_share_by_start():
    from ibc_tutorial.stats import Interval

    shares = {"bc": [0.5, 1.0, 0.7], "da-ibc": [1.1, 0.9, 1.2]}
    iv = {m: {"agents only": Interval(1.0, 0.9, 1.1), "crossed": Interval(1.0, 0.8, 1.2)} for m in shares}
    fig = replication.plot_share_by_start(shares, [1000, 1001, 1002], iv, title="T")
    left, right = fig.axes
    assert [t.get_text() for t in left.get_xticklabels()] == ["1000", "1001", "1002"]
    assert [t.get_text() for t in right.get_yticklabels()] == ["BC (Beta)", "DA-IBC"]
    assert [t.get_text() for t in right.get_legend().get_texts()] == ["agents only", "crossed"]
    assert_labelled(fig)
    with pytest.raises(ValueError, match="one share per start"):
        replication.plot_share_by_start({"bc": [0.5]}, [1000, 1001], iv, title="T")
