"""The side-road world: road geometry, the experts' choice, leaving the road, the swerve measure."""

import math

import pytest
import torch

from ibc_tutorial.toy import SideRoadConfig, SideRoadWorld


def constant(value):
    return lambda obs: torch.full((len(obs), 1), value)


def test_road_geometry():
    """The side road branches off to the right: towards -y (y points to the left)."""
    w = SideRoadWorld()
    c = w.config
    k = math.tan(math.radians(c.side_angle_deg))
    pts = torch.tensor(
        [
            [5.0, -1.9],  # on the main road
            [5.0, -2.1],  # off it, and before the branch
            [c.branch_x + 10.0, -10.0 * k],  # on the side road's centre line
            [
                c.branch_x + 10.0,
                -10.0 * k - 2.0 / math.cos(math.radians(c.side_angle_deg)) - 0.1,
            ],  # just beyond its edge
            [c.branch_x - 3.0, -3.0],  # beside the main road before the branch
            [c.branch_x + 10.0, 10.0 * k],  # where a side road to the left would be: off the road
        ]
    )
    assert w.on_main_road(pts).tolist() == [True, False, False, False, False, False]
    assert w.on_side_road(pts).tolist() == [False, False, True, False, False, False]
    assert w.on_road(pts).tolist() == [True, False, True, False, False, False]
    assert torch.allclose(
        w.side_road_lateral(torch.tensor([0.0, c.branch_x + 4.0])), torch.tensor([0.0, -4.0 * k])
    )
    u = w.side_direction
    assert u[0] > 0 and u[1] < 0 and torch.isclose(u.norm(), torch.tensor(1.0))


def test_observation_is_the_distance_to_the_branch():
    w = SideRoadWorld()
    assert w.obs_dim == 1
    assert torch.allclose(
        w.observe(torch.tensor([[0.0, 0.5, 0.0]])), torch.tensor([[w.config.branch_x / 10.0]])
    )


@pytest.fixture(scope="module")
def expert():
    w = SideRoadWorld()
    ro, modes = w.expert_rollouts(1000, seed=2)
    return w, ro, modes


def test_experts_stay_on_the_road(expert):
    w, ro, _ = expert
    assert not ro.collided.any()
    assert w.on_road(ro.states[:, :, :2]).all()


def test_experts_take_the_side_road_about_one_time_in_five(expert):
    w, ro, modes = expert
    # Binomial(1000, 0.2): sd about 12.6, allow 4 sd
    assert abs(int((modes == 1).sum()) - 200) < 51
    assert torch.equal(w.took_side_road(ro), modes == 1)
    assert torch.equal(w.stayed_on_main_road(ro), modes == 0)
    assert w.mode_names == ("keeps straight", "takes the side road")
    side = modes == 1
    assert (ro.actions[side].amax(dim=(1, 2)) > 0.5).all()  # taking the side road steers right (+)
    assert (ro.states[side, -1, 1] < -3.0).all()  # and ends to the right (y < 0)


def test_swerve_of_straight_experts_is_small_and_nan_for_the_others(expert):
    w, ro, modes = expert
    sw = w.swerve(ro)
    assert torch.isnan(sw[modes == 1]).all()
    straight = sw[modes == 0]
    assert not torch.isnan(straight).any() and (straight >= 0).all()
    assert straight.mean() < 0.15 and straight.max() < 0.5


def test_swerve_measures_the_largest_deviation_towards_the_side_road():
    w = SideRoadWorld()

    def nudge(obs):  # steer 0.2 right for the 5 m after the branch point, then straight
        d = w.physical(obs)[:, :1]
        return torch.where((d <= 0.0) & (d > -5.0), torch.full_like(d, 0.2), torch.zeros_like(d))

    start = torch.zeros(3, 3)
    ro = w.rollout(nudge, 3, seed=0, initial_states=start)
    assert w.stayed_on_main_road(ro).all()
    # the same drive, step by step in plain Python
    x = y = 0.0
    for _ in range(w.config.horizon):
        d = w.config.branch_x - x
        heading = -0.2 * w.config.heading_max if -5.0 < d <= 0.0 else 0.0  # steer +0.2: to the right
        x, y = x + 0.5 * math.cos(heading), y + 0.5 * math.sin(heading)
    assert y < -0.5
    assert torch.allclose(w.swerve(ro), torch.full((3,), -y), atol=1e-4)
    # a deviation to the other side is not a swerve towards the side road
    away = w.rollout(lambda obs: -nudge(obs), 3, seed=0, initial_states=start)
    assert torch.allclose(w.swerve(away), torch.zeros(3))


def test_leaving_the_road_is_a_collision():
    w = SideRoadWorld()
    ro = w.rollout(constant(0.5), 20, seed=0)  # drifts right before the branch: off the road
    assert ro.collided.all()
    assert not w.on_road(ro.states[:, -1, :2]).any()
    assert torch.isnan(w.swerve(ro)).all()
    straight = w.rollout(constant(0.0), 20, seed=0)
    assert not straight.collided.any() and w.stayed_on_main_road(straight).all()


def test_reproducible_and_checked():
    w = SideRoadWorld()
    a, b = w.expert_demonstrations(20, seed=5), w.expert_demonstrations(20, seed=5)
    assert torch.equal(a.obs, b.obs) and torch.equal(a.actions, b.actions) and torch.equal(a.mode, b.mode)
    assert set(a.mode.tolist()) <= {0, 1}
    with pytest.raises(ValueError, match="finite"):
        w.rollout(constant(float("nan")), 3, seed=0)
    with pytest.raises(ValueError, match="side_angle_deg"):
        SideRoadWorld(SideRoadConfig(side_angle_deg=95.0))
    with pytest.raises(ValueError, match="straight_prob"):
        SideRoadWorld(SideRoadConfig(straight_prob=-0.1))


def test_side_road_figure_has_titles_and_labels():
    import matplotlib.pyplot as plt

    from ibc_tutorial.plotting import multimodality

    w = SideRoadWorld()
    ro, _ = w.expert_rollouts(5, seed=0)
    fig = multimodality.plot_side_road(w, {"experts": ro, "off road": w.rollout(constant(0.5), 3, seed=0)})
    assert fig._suptitle is not None and all(ax.get_title() and ax.get_ylabel() for ax in fig.axes)
    assert "swerve" in fig.axes[0].get_title()
    plt.close(fig)
