"""EnergyModel (late fusion with a factorised first layer) and grid argmin inference."""

import pytest
import torch
from torch import nn

from ibc_tutorial.optimizers.grid import action_grid, grid_argmin, grid_energies
from ibc_tutorial.policies import EnergyModel, GridArgminPolicy, MLPEncoder
from ibc_tutorial.policies.encoders import ObservationEncoder


def make_model(obs_dim=3, action_dim=2, hidden=16, layers=2, seed=0):
    torch.manual_seed(seed)
    return EnergyModel(MLPEncoder(obs_dim, embed_dim=8, hidden=16), action_dim, hidden=hidden, layers=layers)


def concat_reference(model: EnergyModel, obs, actions):
    """The same energies through the plain, unsplit first layer on [z; y]."""
    z = model.encoder(obs)  # (B, E)
    b, n, _ = actions.shape
    first = nn.Linear(model.embed_dim + model.action_dim, model.hidden)
    with torch.no_grad():
        first.weight.copy_(torch.cat([model.obs_proj.weight, model.act_proj.weight], dim=1))
        first.bias.copy_(model.obs_proj.bias)
    zy = torch.cat([z[:, None, :].expand(b, n, -1), actions], dim=-1)  # (B, N, E + D)
    return model.head(torch.relu(first(zy))).squeeze(-1)


@pytest.mark.parametrize("layers", [1, 2, 3])
def test_factorised_head_equals_concatenation(layers):
    model = make_model(layers=layers)
    obs = torch.randn(5, 3)
    actions = torch.rand(5, 7, 2) * 2 - 1
    e = model.energy(obs, actions)
    assert e.shape == (5, 7)
    torch.testing.assert_close(e, concat_reference(model, obs, actions), rtol=1e-5, atol=1e-5)


def test_shared_candidates_and_embedding_path():
    model = make_model()
    obs = torch.randn(4, 3)
    grid = action_grid(5, 2)  # (25, 2)
    shared = model.energy(obs, grid)
    per_obs = model.energy(obs, grid.expand(4, -1, -1))
    torch.testing.assert_close(shared, per_obs)
    z = model.embed(obs)
    assert z.shape == (4, 8)
    torch.testing.assert_close(model.energy_from_embedding(z, grid), shared)
    torch.testing.assert_close(model(obs, grid), shared)


def test_each_observation_scored_independently():
    model = make_model()
    obs = torch.randn(6, 3)
    actions = torch.randn(6, 4, 2)
    full = model.energy(obs, actions)
    one = model.energy(obs[2:3], actions[2:3])
    torch.testing.assert_close(full[2:3], one)


def test_first_layer_initialised_like_unsplit_linear():
    torch.manual_seed(1)
    model = EnergyModel(MLPEncoder(3, embed_dim=30), 2, hidden=50)
    bound = 1 / (30 + 2) ** 0.5  # nn.Linear's bound for fan_in = E + D
    assert model.obs_proj.weight.abs().max() <= bound and model.act_proj.weight.abs().max() <= bound
    assert model.act_proj.weight.abs().max() > 0.5 * bound  # drawn over the whole joint range


def test_gradients_reach_encoder_and_action_projection():
    model = make_model()
    e = model.energy(torch.randn(3, 3), torch.randn(3, 4, 2))
    e.sum().backward()
    assert model.act_proj.weight.grad.abs().sum() > 0
    assert model.encoder.net[0].weight.grad.abs().sum() > 0


class DictEncoder(ObservationEncoder):
    def __init__(self):
        super().__init__()
        self.embed_dim = 4
        self.a = nn.Linear(2, 4)
        self.b = nn.Linear(1, 4)

    def forward(self, obs):
        return torch.relu(self.a(obs["x"]) + self.b(obs["speed"]))


def test_dict_observations():
    torch.manual_seed(0)
    model = EnergyModel(DictEncoder(), 1, hidden=8)
    obs = {"x": torch.randn(3, 2), "speed": torch.randn(3, 1)}
    assert model.energy(obs, torch.randn(3, 5, 1)).shape == (3, 5)


def test_bad_input_raises_value_error():
    model = make_model()
    with pytest.raises(ValueError, match="actions"):
        model.energy(torch.randn(3, 3), torch.randn(3, 5, 1))  # wrong D
    with pytest.raises(ValueError, match="actions"):
        model.energy(torch.randn(3, 3), torch.randn(4, 5, 2))  # wrong B
    with pytest.raises(ValueError, match="z must"):
        model.energy_from_embedding(torch.randn(3, 5), torch.randn(3, 5, 2))
    with pytest.raises(ValueError, match="action_dim"):
        EnergyModel(MLPEncoder(3), 0)
    with pytest.raises(ValueError, match="encoder"):
        EnergyModel(nn.Linear(3, 3), 1)


def test_grid_argmin_picks_lowest_energy():
    model = make_model(action_dim=1)
    obs = torch.randn(10, 3)
    grid = action_grid(33)
    actions, energies = grid_argmin(model, obs, grid, return_energies=True)
    assert actions.shape == (10, 1) and energies.shape == (10, 33)
    with torch.no_grad():
        brute = model.energy(obs, grid)  # independent path: no cached embedding
    torch.testing.assert_close(energies, brute)
    for i in range(10):
        assert actions[i, 0] == grid[int(torch.argmin(brute[i])), 0]


def test_grid_argmin_finds_minimum_of_known_energy():
    class Quadratic(nn.Module):
        """E(x, y) = (y - x)²: the argmin is the grid point nearest x."""

        def embed(self, obs):
            return obs

        def energy_from_embedding(self, z, actions):
            return ((actions.expand(len(z), -1, -1) - z[:, None, :]) ** 2).sum(-1)

    obs = torch.tensor([[-0.73], [0.0], [0.41]])
    grid = action_grid(201)
    got = grid_argmin(Quadratic(), obs, grid)
    torch.testing.assert_close(got, torch.tensor([[-0.73], [0.0], [0.41]]), atol=0.0051, rtol=0)


def test_grid_argmin_policy_has_no_grad_and_restores_mode():
    model = make_model(action_dim=1)
    model.train()
    policy = GridArgminPolicy(model, action_grid(21))
    a = policy(torch.randn(4, 3))
    assert a.shape == (4, 1) and not a.requires_grad and model.training
    with pytest.raises(ValueError, match="grid"):
        GridArgminPolicy(model, action_grid(5, 2))


def test_grid_energies_in_blocks_equal_one_pass():
    model = make_model(action_dim=2)
    z = model.embed(torch.randn(37, 3))
    grid = action_grid(9, 2)
    with torch.no_grad():
        whole = model.energy_from_embedding(z, grid)
        torch.testing.assert_close(
            grid_energies(model, z, grid, chunk_elements=500), whole
        )  # blocks of 3 rows
        torch.testing.assert_close(
            grid_energies(model, z, grid, chunk_elements=1), whole
        )  # one row at a time


def test_energy_explorer_widget_builds_and_redraws():
    from ibc_tutorial.widgets import energy_explorer

    model = make_model(obs_dim=1, action_dim=1)
    widget = energy_explorer(
        model, lambda d: torch.tensor([[d / 10.0]]), action_grid(41), values=(0.0, 20.0, 1.0), value=5.0
    )
    slider = widget.children[0]
    slider.value = 12.0  # triggers a redraw without error
    assert slider.value == 12.0


def test_grid_sample_policy_draws_from_softmax_of_minus_energy():
    from scipy import stats

    from ibc_tutorial.policies import GridSamplePolicy

    class Fixed(nn.Module):
        """E = 0, log 2, log 4 on a 3-point grid: p = 4/7, 2/7, 1/7 whatever the observation."""

        action_dim = 1
        hidden = 1

        def embed(self, obs):
            return obs

        def energy_from_embedding(self, z, actions):
            return torch.log(torch.tensor([1.0, 2.0, 4.0])).expand(len(z), 3)

    grid = torch.tensor([[-0.5], [0.0], [0.5]])
    policy = GridSamplePolicy(Fixed(), grid, generator=torch.Generator().manual_seed(0))
    a = policy(torch.zeros(7000, 1))
    assert a.shape == (7000, 1)
    counts = torch.stack([(a[:, 0] == v).sum() for v in grid[:, 0]]).numpy()
    assert stats.chisquare(counts, [4000.0, 2000.0, 1000.0]).pvalue > 1e-3


def test_inference_form_matches_training_form():
    """Under no_grad the first layer runs fused (baddbmm, in-place ReLU); energies must agree."""
    import torch

    from ibc_tutorial.policies import EnergyModel, MLPEncoder

    torch.manual_seed(0)
    model = EnergyModel(MLPEncoder(3, embed_dim=16, hidden=16), action_dim=2, hidden=32, layers=3)
    obs, per_obs, shared = torch.randn(4, 3), torch.rand(4, 50, 2) * 2 - 1, torch.rand(50, 2) * 2 - 1
    for actions in (per_obs, shared):
        with_grad = model.energy(obs, actions)
        with torch.no_grad():
            fused = model.energy(obs, actions)
        assert with_grad.requires_grad and not fused.requires_grad
        torch.testing.assert_close(fused, with_grad.detach(), rtol=1e-5, atol=1e-5)
