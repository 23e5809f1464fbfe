"""The flow-matching policy (policies.flow), its loss and its objective."""

import pytest
import torch

from ibc_tutorial.losses import flow_matching_loss
from ibc_tutorial.objectives import flow_matching_objective
from ibc_tutorial.policies import FlowConfig, FlowPolicy
from ibc_tutorial.policies.flow import network_evaluations
from ibc_tutorial.toy.tree import TreeWorld
from ibc_tutorial.training import TrainConfig, train


def _two_gaussians(m: int, seed: int) -> dict[str, torch.Tensor]:
    """One observation; actions at −0.5 (mass 0.3) and +0.5 (mass 0.7), standard deviation 0.05."""
    g = torch.Generator().manual_seed(seed)
    left = torch.rand(m, generator=g) < 0.3
    y = torch.where(left, -0.5, 0.5) + 0.05 * torch.randn(m, generator=g)
    return {"obs": torch.zeros(m, 1), "actions": y[:, None]}


def test_the_flow_policy_reproduces_the_masses_of_two_modes():
    torch.manual_seed(0)
    policy = FlowPolicy.for_vectors(1, 1, hidden=32, config=FlowConfig(n_steps=10, n_samples=4000))
    config = TrainConfig(steps=500, batch_size=64, lr=3e-3, seed=0, progress=False)
    train(policy, flow_matching_objective(policy), _two_gaussians(2000, 0), config)
    y = policy.sample(torch.zeros(1, 1), generator=torch.Generator().manual_seed(0))[0, :, 0]  # (N,)
    left = float((y < 0).float().mean())
    assert left == pytest.approx(0.3, abs=0.05)
    near = float(((y.abs() - 0.5).abs() < 0.2).float().mean())
    assert near > 0.8  # the samples sit at the modes, not between them as a regression's mean would


def _policy(noise: str = "gaussian", **kwargs) -> FlowPolicy:
    torch.manual_seed(0)
    return FlowPolicy.for_vectors(3, 2, hidden=8, config=FlowConfig(noise=noise, **kwargs))


def test_sample_is_k_euler_steps_from_the_noise_clipped_only_at_the_end():
    policy = _policy(n_steps=3, n_samples=5)
    with torch.no_grad():  # a head that pushes hard, so that the unclipped path leaves the box
        policy.head[-1].bias.fill_(2.0)
    obs = torch.randn(4, 3, generator=torch.Generator().manual_seed(1))
    y = policy.sample(obs, generator=torch.Generator().manual_seed(2))  # (B, N, D)
    assert y.shape == (4, 5, 2)
    g = torch.Generator().manual_seed(2)
    with torch.no_grad():
        z = policy.embed(obs)
        ref = policy.draw_noise(4, 5, g, z)
        for k in range(3):
            ref = ref + policy.velocity_from_embedding(z, ref, k / 3) / 3
    assert (ref.abs() > 1).any()  # the unclipped end leaves the box ...
    assert torch.allclose(y, ref.clamp(-1, 1))  # ... and only the end is clipped
    act = policy.act(obs, generator=torch.Generator().manual_seed(2))
    assert torch.equal(act, y[:, 0])  # act: the first of the N samples


def test_a_decision_embeds_once_and_runs_the_head_k_times_on_all_samples():
    policy = _policy(n_steps=4, n_samples=6)
    calls = {"encoder": 0, "head": 0, "rows": []}
    policy.encoder.register_forward_hook(lambda m, i, o: calls.__setitem__("encoder", calls["encoder"] + 1))

    def head_hook(module, inputs, output):
        calls["head"] += 1
        calls["rows"].append(output.shape[:-1].numel())

    policy.head.register_forward_hook(head_hook)
    policy.act(torch.zeros(2, 3), generator=torch.Generator().manual_seed(0))
    assert calls["encoder"] == 1 and calls["head"] == 4 and calls["rows"] == [2 * 6] * 4
    assert network_evaluations(6, 4) == {"encoder": 1, "head": 24}


def test_sampling_is_reproducible_and_keeps_the_training_mode():
    policy = _policy(n_samples=3).train()
    obs = torch.zeros(2, 3)
    a = policy.sample(obs, generator=torch.Generator().manual_seed(5))
    b = policy.sample(obs, generator=torch.Generator().manual_seed(5))
    assert torch.equal(a, b) and policy.training


def test_uniform_noise_lies_in_the_box_and_trains():
    policy = _policy("uniform", low=(-1.0, -0.5), high=(1.0, 0.5))
    y0 = policy.draw_noise(50, 40, torch.Generator().manual_seed(0), torch.zeros(1))
    assert (y0[..., 0].abs() <= 1).all() and (y0[..., 1].abs() <= 0.5).all()
    data = {"obs": torch.randn(64, 3), "actions": torch.rand(64, 2) - 0.5}
    res = train(policy, flow_matching_objective(policy), data, TrainConfig(steps=5, progress=False))
    assert len(res.losses) == 1


def test_the_controller_drives_a_toy_world_rollout():
    world = TreeWorld()
    torch.manual_seed(0)
    policy = FlowPolicy.for_vectors(world.obs_dim, 1, hidden=8, config=FlowConfig(n_steps=2, n_samples=1))
    ro = world.rollout(policy.controller(torch.Generator().manual_seed(0)), 3, seed=0)
    assert ro.actions.abs().max() <= 1


def test_flow_matching_loss_is_the_squared_error_to_the_straight_velocity():
    y0, y1 = torch.zeros(2, 3, 2), torch.ones(2, 3, 2)
    assert float(flow_matching_loss(torch.ones(2, 3, 2), y0, y1)) == 0.0
    assert float(flow_matching_loss(torch.zeros(2, 3, 2), y0, y1)) == pytest.approx(2.0)  # summed over D


def test_bad_inputs_name_the_argument():
    for field, value in (("n_steps", 0), ("n_samples", 0), ("noise", "cauchy"), ("train_draws", 0)):
        with pytest.raises(ValueError, match=field):
            FlowConfig(**{field: value})
    with pytest.raises(ValueError, match="low"):
        FlowConfig(low=1.0, high=-1.0)
    policy = _policy()
    with pytest.raises(ValueError, match="n_samples"):
        policy.sample(torch.zeros(1, 3), n_samples=0)
    with pytest.raises(ValueError, match="n_steps"):
        policy.act(torch.zeros(1, 3), n_steps=0)
    with pytest.raises(ValueError, match="y_t"):
        policy.velocity(torch.zeros(2, 3), torch.zeros(2, 4, 3), 0.5)
    with pytest.raises(ValueError, match="actions"):
        policy.loss(torch.zeros(2, 3), torch.zeros(3, 2))
    with pytest.raises(ValueError, match="y0"):
        flow_matching_loss(torch.zeros(2, 3, 2), torch.zeros(2, 3, 1), torch.zeros(2, 3, 2))
    with pytest.raises(ValueError, match="policy"):
        flow_matching_objective(torch.nn.Linear(2, 2))
    with pytest.raises(ValueError, match="encoder"):
        FlowPolicy(torch.nn.Linear(2, 2), 2)
    with pytest.raises(ValueError, match="config"):
        FlowPolicy.for_vectors(3, 2, config={"n_steps": 3})
