"""The tree world: dynamics, collision geometry, the experts' two modes, rollouts, bad policies."""

import math

import pytest
import torch

from ibc_tutorial.toy import Rollouts, TreeConfig, TreeWorld, car, check_policy_actions


def zero_policy(obs):
    return torch.zeros(len(obs), 1)


# --------------------------------------------------------------------------- the car
def test_step_straight_full_right_and_full_left():
    s = torch.tensor([[0.0, 0.0, 0.0], [1.0, -2.0, 0.3], [1.0, -2.0, 0.3]])
    out = car.step(s, torch.tensor([[0.0], [1.0], [-1.0]]), speed=5.0, heading_max=0.7, dt=0.1)
    assert torch.allclose(out[0], torch.tensor([0.5, 0.0, 0.0]))
    # steer +1 = full right: the heading becomes -heading_max whatever it was, and y decreases
    expected = torch.tensor([1.0 + 0.5 * math.cos(0.7), -2.0 - 0.5 * math.sin(0.7), -0.7])
    assert torch.allclose(out[1], expected, atol=1e-6)
    # steer -1 = full left: +heading_max, y increases (y points to the left)
    expected = torch.tensor([1.0 + 0.5 * math.cos(0.7), -2.0 + 0.5 * math.sin(0.7), 0.7])
    assert torch.allclose(out[2], expected, atol=1e-6)


def test_step_is_mirror_symmetric():
    """Reflecting the state in y and negating the steering reflects the next state in y, exactly."""
    g = torch.Generator().manual_seed(0)
    s = torch.randn(64, 3, generator=g)
    a = 2 * torch.rand(64, 1, generator=g) - 1
    flip = torch.tensor([1.0, -1.0, -1.0])
    kw = dict(speed=5.0, heading_max=0.6, dt=0.1)
    assert torch.equal(car.step(s * flip, -a, **kw), car.step(s, a, **kw) * flip)


def test_step_checks_its_arguments():
    with pytest.raises(ValueError, match="states"):
        car.step(torch.zeros(2, 2), torch.zeros(2, 1), speed=1.0, heading_max=0.5, dt=0.1)
    with pytest.raises(ValueError, match="steer"):
        car.step(torch.zeros(2, 3), torch.zeros(3, 1), speed=1.0, heading_max=0.5, dt=0.1)
    with pytest.raises(ValueError, match="speed"):
        car.step(torch.zeros(2, 3), torch.zeros(2, 1), speed=0.0, heading_max=0.5, dt=0.1)


def test_segment_circle_contact_analytic_cases():
    centre = torch.tensor([0.0, 0.0])
    p0 = torch.tensor([[-5.0, 0.0], [-5.0, 3.0], [-5.0, 2.0], [0.5, 0.0], [-5.0, 0.0], [-1.0, -5.0]])
    p1 = torch.tensor([[5.0, 0.0], [5.0, 3.0], [5.0, 2.0], [5.0, 0.0], [-3.0, 0.0], [-1.0, 5.0]])
    s = car.segment_circle_contact(p0, p1, centre, 2.0)
    assert s[0] == pytest.approx(0.3)  # head-on: touches at x = -2, 3 m of 10
    assert math.isinf(s[1])  # passes 3 m away from a 2 m circle
    assert math.isinf(s[2])  # tangent at x = 0: it only touches, which is no contact
    assert s[3] == 0.0  # starts inside
    assert math.isinf(s[4])  # stops before reaching it
    # crossing line x = -1: enters where y = -sqrt(3)
    assert s[5] == pytest.approx((5 - math.sqrt(3)) / 10, abs=1e-6)


def test_collides_matches_distance():
    w = TreeWorld()
    r = w.clearance
    pts = torch.tensor([[20.0, r - 0.01], [20.0, r + 0.01], [20.0 - r + 0.01, 0.0], [0.0, 0.0]])
    assert w.collides(pts).tolist() == [True, False, True, False]


# --------------------------------------------------------------------------- observations
def test_observation_is_the_scaled_distance_to_the_tree():
    w = TreeWorld()
    assert w.obs_dim == 1 and w.action_dim == 1
    states = torch.tensor([[0.0, 0.3, 0.1], [25.0, -1.0, 0.0]])
    assert torch.allclose(w.observe(states), torch.tensor([[2.0], [-0.5]]))
    assert torch.allclose(w.obs_at([10.0, 4.0]), torch.tensor([[1.0], [0.4]]))
    assert torch.allclose(w.physical(w.obs_at([7.0])), torch.tensor([[7.0]]))
    mask = w.in_window(w.obs_at([3.0, 7.0, 12.0]), (5.0, 10.0))
    assert mask.tolist() == [False, True, False]


def test_lateral_observation_variant():
    w = TreeWorld(TreeConfig(obs_lateral=True))
    assert w.obs_dim == 2
    obs = w.obs_at([10.0, 10.0], lateral=[0.0, 1.0])
    assert torch.allclose(obs, torch.tensor([[1.0, 0.0], [1.0, 0.5]]))
    # the lateral offset is measured to the right of the centre line (-y), signed like the steering
    assert w.states_at(10.0, lateral=1.0)[0, 1] == -1.0
    assert torch.allclose(w.observe(torch.tensor([[10.0, 1.0, 0.0]])), torch.tensor([[1.0, -0.5]]))
    assert torch.allclose(w.physical(obs)[:, 1], torch.tensor([0.0, 1.0]))
    assert w.in_window(obs, (9.0, 11.0), max_abs_lateral=0.5).tolist() == [True, False]
    assert w.expert_demonstrations(2, 0).obs.shape == (2 * w.config.horizon, 2)


def test_previous_action_observation_variant():
    w = TreeWorld(TreeConfig(obs_prev_action=True))
    assert w.obs_dim == 2
    obs = w.obs_at([10.0, 10.0], prev_action=[0.0, 0.5])
    assert torch.allclose(obs, torch.tensor([[1.0, 0.0], [1.0, 0.5]]))
    assert torch.allclose(w.physical(obs), torch.tensor([[10.0, 0.0], [10.0, 0.5]]))
    with pytest.raises(ValueError, match="prev_action"):
        w.obs_at(10.0, prev_action=1.5)
    # with the offset too, the previous action comes last
    both = TreeWorld(TreeConfig(obs_lateral=True, obs_prev_action=True))
    assert both.obs_dim == 3
    assert torch.allclose(both.obs_at(10.0, lateral=1.0, prev_action=-0.2), torch.tensor([[1.0, 0.5, -0.2]]))
    # demonstrations record the action applied at the step before (0 at the start)
    demos = w.expert_demonstrations(3, 0)
    assert demos.obs.shape == (3 * w.config.horizon, 2)
    first = demos.step == 0
    assert (demos.obs[first, 1] == 0).all()
    same = demos.episode[1:] == demos.episode[:-1]
    assert torch.allclose(demos.obs[1:, 1][same], demos.actions[:-1, 0][same])
    # and so do closed-loop rollouts: a policy that steers 0.3 sees 0.3 from the second step on
    r = w.rollout(lambda o: torch.full((len(o), 1), 0.3), 2, seed=0)
    assert (r.obs[:, 0, 1] == 0).all() and torch.allclose(r.obs[:, 1:, 1], torch.tensor(0.3))


def test_bad_config_and_arguments_raise():
    with pytest.raises(ValueError, match="tree_radius"):
        TreeWorld(TreeConfig(tree_radius=0.0))
    with pytest.raises(ValueError, match="swerve_start_min"):
        TreeWorld(TreeConfig(swerve_start_min=12.0, swerve_start_max=8.0))
    with pytest.raises(ValueError, match="right_prob"):
        TreeWorld(TreeConfig(right_prob=1.5))
    w = TreeWorld()
    with pytest.raises(ValueError, match="n_episodes"):
        w.rollout(zero_policy, 0, seed=0)
    with pytest.raises(ValueError, match="seed"):
        w.expert_demonstrations(3, seed=-1)
    with pytest.raises(ValueError, match="distance"):
        w.in_window(w.obs_at([1.0]), (5.0, 2.0))


def test_observation_noise_is_what_the_policy_sees_not_the_state():
    clean = TreeWorld(TreeConfig(obs_lateral=True))
    noisy = TreeWorld(TreeConfig(obs_lateral=True, obs_noise_std=0.1))
    d0, d1 = clean.expert_demonstrations(20, seed=0), noisy.expert_demonstrations(20, seed=0)
    # the expert steers from the true state, with its own noise: the same episodes
    assert torch.equal(d0.states, d1.states) and torch.equal(d0.actions, d1.actions)
    jitter = d1.obs - d0.obs  # (M, 2)
    assert 0.09 < float(jitter.std()) < 0.11 and abs(float(jitter.mean())) < 0.01
    seen = []

    def policy(obs):
        seen.append(obs.clone())
        return torch.zeros(len(obs), 1)

    r0, r1 = noisy.rollout(policy, 10, seed=3), noisy.rollout(policy, 10, seed=3)
    assert torch.equal(r0.obs, r1.obs)  # reproducible from the seed
    assert torch.equal(seen[0], r0.obs[:, 0])  # the policy saw the noisy observation recorded
    straight = clean.rollout(zero_policy, 10, seed=3)
    assert torch.equal(r0.states, straight.states)  # same starts; the car moves on its true state
    assert not torch.equal(r0.obs, straight.obs)
    assert not torch.equal(noisy.rollout(policy, 10, seed=4).obs[:, 1:], r0.obs[:, 1:])
    with pytest.raises(ValueError, match="obs_noise_std"):
        TreeWorld(TreeConfig(obs_noise_std=-0.1))


# --------------------------------------------------------------------------- experts
@pytest.fixture(scope="module")
def expert():
    w = TreeWorld()
    ro, modes = w.expert_rollouts(1000, seed=3)
    return w, ro, modes


def test_experts_never_hit_the_tree(expert):
    w, ro, _ = expert
    assert w.collision_rate(ro) == 0.0
    centre = torch.tensor([w.config.tree_x, 0.0])
    closest = (ro.states[:, :, :2] - centre).norm(dim=-1).min()
    assert closest > w.clearance + 0.3  # with a margin, not by luck


def test_both_modes_half_and_half(expert):
    w, ro, modes = expert
    # Binomial(1000, 1/2): 4 standard deviations is about +-63
    assert abs(int((modes == 0).sum()) - 500) < 63
    side = w.pass_side(ro)
    assert torch.equal(side, torch.where(modes == 0, 1, -1))  # mode 0 passes on the right (+1)
    assert w.mode_names == ("passes right", "passes left")


def test_experts_end_past_the_tree(expert):
    w, ro, _ = expert
    assert (ro.states[:, -1, 0] > w.config.tree_x + 10.0).all()


def test_same_observation_two_modes_of_action():
    """Near the swerve, the demonstrations' actions for the same observations split in two."""
    w = TreeWorld()
    demos = w.expert_demonstrations(400, seed=0)
    window = w.in_window(demos.obs, (7.0, 9.0))
    a, m = demos.actions[window, 0], demos.mode[window]
    assert window.sum() > 500
    assert (m == 0).any() and (m == 1).any()
    assert a[m == 0].mean() > 0.5 and a[m == 1].mean() < -0.5  # right steers right (+), left steers left (-)
    # two clusters, nothing in between: almost no action near the mean of all of them
    assert (a.abs() < 0.3).float().mean() < 0.02
    assert abs(float(a.mean())) < 0.15  # the average action is about straight ahead


def test_demonstrations_fields_and_shapes():
    w = TreeWorld()
    d = w.expert_demonstrations(5, seed=1)
    t = w.config.horizon
    assert d.obs.shape == (5 * t, 1) and d.obs.dtype == torch.float32
    assert d.actions.shape == (5 * t, 1) and d.actions.dtype == torch.float32
    assert d.episode.dtype == torch.int64 and d.mode.dtype == torch.int64
    assert d.states.shape == (5, t + 1, 3)
    assert torch.equal(d.mode, d.episode_mode[d.episode])
    assert d.actions.abs().max() <= 1.0
    assert set(d.training_data()) == {"obs", "actions"}
    # the observations are those of the stored states
    assert torch.allclose(d.obs.view(5, t, 1), w.observe(d.states[:, :-1]))


# --------------------------------------------------------------------------- rollouts
def test_straight_policy_hits_the_tree_where_the_discs_touch():
    w = TreeWorld()
    ro = w.rollout(zero_policy, 50, seed=0)
    assert isinstance(ro, Rollouts)
    assert ro.collided.all() and w.collision_rate(ro) == 1.0
    assert (w.pass_side(ro) == 0).all()
    end = ro.states[:, -1, :2]
    dist = (end - torch.tensor([w.config.tree_x, 0.0])).norm(dim=-1)
    assert torch.allclose(dist, torch.full_like(dist, w.clearance), atol=1e-4)  # stopped at contact
    assert not ro.alive[:, -1].any() and ro.alive[:, 0].all()


@pytest.mark.parametrize("steer, side", [(1.0, 1), (-1.0, -1)])
def test_swerving_policy_passes_on_its_side(steer, side):
    w = TreeWorld()

    def swerve(obs):  # steer from 12 m before the tree until 2 m before it (+1 right, -1 left)
        d = w.physical(obs)[:, :1]
        return torch.where((d < 12.0) & (d > 2.0), torch.full_like(d, steer), torch.zeros_like(d))

    ro = w.rollout(swerve, 20, seed=0)
    assert not ro.collided.any()
    assert (w.pass_side(ro) == side).all()
    assert (ro.states[:, 40, 1] * side < -3.0).all()  # right: y < 0, left: y > 0


def test_rollouts_reproducible_from_seed():
    w = TreeWorld()

    def wobbly(obs):
        return torch.sin(3 * obs)

    a, b, c = (w.rollout(wobbly, 30, seed=s) for s in (7, 7, 8))
    assert torch.equal(a.states, b.states) and torch.equal(a.actions, b.actions)
    assert not torch.equal(a.states, c.states)
    d1, d2 = w.expert_demonstrations(10, seed=4), w.expert_demonstrations(10, seed=4)
    assert torch.equal(d1.actions, d2.actions) and torch.equal(d1.mode, d2.mode)
    # a rollout from the same seed starts where the experts start
    ro, _ = w.expert_rollouts(10, seed=4)
    assert torch.equal(ro.states[:, 0], w.rollout(wobbly, 10, seed=4).states[:, 0])


def test_rollout_of_200_episodes_is_batched():
    w = TreeWorld()
    calls = []

    def counting(obs):
        calls.append(obs.shape)
        return torch.zeros(len(obs), 1)

    ro = w.rollout(counting, 200, seed=0)
    assert len(calls) == w.config.horizon and calls[0] == (200, 1)
    assert ro.states.shape == (200, w.config.horizon + 1, 3) and ro.actions.shape == (
        200,
        w.config.horizon,
        1,
    )


@pytest.mark.parametrize(
    "bad, message",
    [
        (lambda obs: torch.full((len(obs), 1), float("nan")), "finite"),
        (lambda obs: torch.zeros(len(obs)), r"shape \(4, 1\)"),
        (lambda obs: torch.zeros(len(obs), 2), r"shape \(4, 1\)"),
        (lambda obs: torch.full((len(obs), 1), 1.5), r"\[-1, 1\]"),
        (lambda obs: [[0.0]] * len(obs), "torch.Tensor"),
        (lambda obs: torch.zeros(len(obs), 1, dtype=torch.long), "floating"),
    ],
)
def test_bad_policies_get_a_clear_value_error(bad, message):
    with pytest.raises(ValueError, match=message):
        TreeWorld().rollout(bad, 4, seed=0)


def test_check_policy_actions_accepts_the_bounds():
    a = torch.tensor([[-1.0], [1.0]], dtype=torch.float64)
    out = check_policy_actions(a, 2)
    assert out.dtype == torch.float32 and out.tolist() == [[-1.0], [1.0]]


def test_initial_states_argument():
    w = TreeWorld()
    start = torch.tensor([[0.0, 3.0, 0.0], [0.0, -3.0, 0.0]])  # beside the tree: a straight car passes
    ro = w.rollout(zero_policy, 2, seed=0, initial_states=start)
    assert not ro.collided.any() and w.pass_side(ro).tolist() == [-1, 1]
    with pytest.raises(ValueError, match="initial_states"):
        w.rollout(zero_policy, 3, seed=0, initial_states=start)


# --------------------------------------------------------------------------- chapter 01's figures
def test_chapter_01_figures_have_titles_and_labels():
    import matplotlib.pyplot as plt

    from ibc_tutorial.plotting import multimodality

    w = TreeWorld()
    demos = w.expert_demonstrations(6, seed=0)
    ro = w.rollout(zero_policy, 4, seed=0)
    a = demos.actions[:, 0]
    grid = torch.linspace(-1, 1, 11)
    figs = [
        multimodality.plot_tree_scene(w, demos.states, demos.episode_mode),
        multimodality.plot_actions_by_distance(
            w, demos, window=(7.0, 9.0), predictions={"zero": (torch.tensor([0.0, 10.0]), torch.zeros(2))}
        ),
        multimodality.plot_action_histogram(a, demos.mode, title="actions"),
        multimodality.plot_constant_losses(
            grid, {"MSE": grid**2, "MAE": grid.abs()}, minimisers={"MSE": 0.0}, flat={"MAE": (-0.1, 0.1)}
        ),
        multimodality.plot_tree_closed_loop(w, {"zero": ro, "again": ro}),
    ]
    for fig in figs:
        axes = [ax for ax in fig.axes if ax.get_visible()]
        assert fig._suptitle is not None or all(ax.get_title() for ax in axes)
        assert all(ax.get_ylabel() for ax in axes) and any(ax.get_xlabel() for ax in axes)
        plt.close(fig)


# --------------------------------------------------------------------------- mirror symmetry
def test_the_tree_world_is_mirror_symmetric():
    """The tree stands on the centre line: reflecting a drive in y (states (x, -y, -heading),
    steering negated) gives a drive of the same world, with the other pass side."""
    w = TreeWorld(TreeConfig(obs_lateral=True))
    flip = torch.tensor([1.0, -1.0, -1.0])

    def policy(obs):  # any policy that uses the lateral offset
        return torch.tanh(2.0 * obs[:, 1:] + torch.sin(3.0 * obs[:, :1]))

    def mirrored(obs):
        return -policy(obs * torch.tensor([1.0, -1.0]))

    start = w.initial_states(40, torch.Generator().manual_seed(0))
    a = w.rollout(policy, 40, seed=0, initial_states=start)
    b = w.rollout(mirrored, 40, seed=0, initial_states=start * flip)
    assert torch.equal(b.states, a.states * flip) and torch.equal(b.actions, -a.actions)
    assert torch.equal(b.collided, a.collided) and torch.equal(w.pass_side(b), -w.pass_side(a))


def test_right_and_left_experts_are_mirror_images():
    """Without steering noise and from the centre line, an expert who passes on the right (mode 0,
    steering > 0) drives the mirror image of one who passes on the left (mode 1)."""
    cfg = dict(expert_noise_std=0.0, start_lateral_range=0.0)
    right = TreeWorld(TreeConfig(right_prob=1.0, **cfg)).expert_demonstrations(5, seed=1)
    left = TreeWorld(TreeConfig(right_prob=0.0, **cfg)).expert_demonstrations(5, seed=1)
    assert (right.episode_mode == 0).all() and (left.episode_mode == 1).all()
    assert torch.equal(left.states, right.states * torch.tensor([1.0, -1.0, -1.0]))
    assert torch.equal(left.actions, -right.actions)
    assert right.actions.max() > 0.5 and (right.states[:, :, 1] <= 0).all()  # right: steering +, y <= 0
