"""The junction world of chapters 04-06: situations, the expert's valid actions and density."""

import math

import pytest
import torch

from ibc_tutorial.toy import SITUATIONS, JunctionConfig, JunctionWorld


def test_density_matches_torch_distributions():
    world = JunctionWorld()
    data = world.sample(300, torch.Generator().manual_seed(0))
    assert data["obs"].shape == (300, 4) and data["actions"].shape == (300, 2)
    shares = torch.bincount(data["situation"], minlength=len(SITUATIONS)).float() / 300
    assert shares[0] > 0.5 and shares[1] > 0.05 and shares[2] > 0.05
    modes, valid = world.modes(data["obs"])
    s = world.config.expert_noise
    for i in range(0, 300, 37):
        m = modes[i][valid[i]]  # (K, 2)
        mix = torch.distributions.MixtureSameFamily(
            torch.distributions.Categorical(torch.ones(len(m))),
            torch.distributions.Independent(torch.distributions.Normal(m, s), 1),
        )
        torch.testing.assert_close(
            world.log_density(data["obs"][i : i + 1], data["actions"][i : i + 1])[0],
            mix.log_prob(data["actions"][i]),
            atol=1e-4,
            rtol=1e-5,
        )
    # junctions have three valid actions, the rest one
    assert (valid.sum(1) == torch.where(data["situation"] == 1, 3, 1)).all()


def test_junction_turns_follow_the_steering_convention():
    """Steer +1 turns right: at a junction the columns are turn left (-), go straight, turn right (+)."""
    world = JunctionWorld()
    modes, valid = world.modes(torch.tensor([[0.0, 1.0, 0.0, 0.5]]))
    assert valid.all() and world.mode_names == ("turn left", "go straight", "turn right")
    assert modes[0, :, 0].tolist() == pytest.approx([-0.7, 0.0, 0.7])
    # cruising on a road that bends right (κ > 0) steers right; a red light brakes
    cruise, _ = world.modes(torch.tensor([[0.3, 0.0, 0.0, 0.5], [0.0, 0.0, 1.0, 0.5]]))
    assert cruise[0, 0, 0] > 0 and cruise[1, 0, 1] < 0


def test_samples_are_reproducible_and_in_the_box():
    world = JunctionWorld()
    a, b = (world.sample(100, torch.Generator().manual_seed(3)) for _ in range(2))
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert a["actions"].abs().max() <= 1.0 and a["situation"].dtype == torch.int64


def test_bad_config_and_arguments_raise():
    with pytest.raises(ValueError, match="expert_noise"):
        JunctionWorld(JunctionConfig(expert_noise=0.0))
    with pytest.raises(ValueError, match="p_junction"):
        JunctionWorld(JunctionConfig(p_junction=0.6, p_red=0.5))
    with pytest.raises(ValueError, match="p_red"):
        JunctionWorld(JunctionConfig(p_red=-0.1))
    with pytest.raises(ValueError, match="obs"):
        JunctionWorld().modes(torch.zeros(3, 2))
    with pytest.raises(ValueError, match="n"):
        JunctionWorld().sample(0, torch.Generator())
    assert math.isfinite(
        float(
            JunctionWorld(JunctionConfig(curvature_std=0.0))
            .sample(5, torch.Generator().manual_seed(0))["actions"]
            .sum()
        )
    )


def test_expert_energy_is_minus_the_log_density_and_floored():
    world = JunctionWorld(JunctionConfig(expert_noise=0.05))
    y = torch.rand(1, 50, 2) * 2 - 1  # (1, N, 2)
    for x in ([0.1, 0.0, 0.0, 0.5], [0.0, 1.0, 0.0, 0.5], [0.0, 0.0, 1.0, 0.8]):
        obs = torch.tensor([x])
        exact = world.log_density(obs.expand(50, 4), y[0])  # (N,)
        assert torch.allclose(-world.expert_energy(obs)(y)[0], exact, atol=1e-3)
        floored = world.expert_energy(obs, 0.01)(y)[0]
        assert torch.allclose(floored, -torch.log(exact.exp() + 0.01), atol=1e-4)
        assert float(floored.max()) <= -math.log(0.01) + 1e-6  # the floor caps the energy
    with pytest.raises(ValueError, match="floor must be"):
        world.expert_energy(torch.tensor([[0.0, 1.0, 0.0, 0.5]]), -1.0)
    with pytest.raises(ValueError, match="floor must be"):
        world.expert_energy(torch.tensor([[0.0, 1.0, 0.0, 0.5]]), "a little")
    with pytest.raises(ValueError, match="obs must"):
        world.expert_energy(torch.zeros(2, 4))


def test_hits_counts_actions_near_each_valid_action():
    world = JunctionWorld()
    junction = torch.tensor([[0.0, 1.0, 0.0, 0.5]])
    modes, _ = world.modes(junction)  # (1, 3, 2): left, straight, right
    actions = torch.cat([modes[0, [0, 0, 2]], torch.tensor([[0.35, -0.9]])])  # 2 left, 1 right, 1 far
    share, per_mode = world.hits(actions, junction)
    assert share == 0.75 and per_mode.tolist() == [0.5, 0.0, 0.25]
    cruise = torch.tensor([[0.0, 0.0, 0.0, 0.5]])  # one valid action: turning is no hit there
    assert world.hits(modes[0, [0, 2]], cruise)[0] == 0.0
    with pytest.raises(ValueError, match="radius must be"):
        world.hits(actions, junction, radius=0)
    with pytest.raises(ValueError, match="actions must"):
        world.hits(torch.zeros(3), junction)
