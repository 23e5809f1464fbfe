"""Ranking NCE (losses.ranking_nce, info_nce_objective(ranking=True)) and the samplers' log_prob."""

import math

import pytest
import torch

from ibc_tutorial.losses import info_nce, ranking_nce
from ibc_tutorial.negatives import ExpertSampler, UniformSampler
from ibc_tutorial.objectives import info_nce_objective
from ibc_tutorial.policies import EnergyModel, MLPEncoder
from ibc_tutorial.toy.junction import JunctionWorld
from ibc_tutorial.training import TrainConfig, train


def test_ranking_nce_with_a_constant_log_q_equals_info_nce():
    g = torch.Generator().manual_seed(0)
    pos, neg = torch.randn(6, generator=g), torch.randn(6, 9, generator=g)
    const = torch.full((6,), -math.log(4.0))
    r = ranking_nce(pos, neg, const, const[:, None].expand(6, 9))
    assert torch.allclose(r, info_nce(pos, neg), atol=1e-6)


def test_ranking_objective_equals_info_nce_objective_for_uniform_counter_examples():
    torch.manual_seed(0)
    model = EnergyModel(MLPEncoder(3, embed_dim=8, hidden=8), action_dim=2, hidden=8)
    g = torch.Generator().manual_seed(1)
    batch = {"obs": torch.randn(5, 3, generator=g), "actions": torch.rand(5, 2, generator=g) * 2 - 1}
    sampler = UniformSampler(-1.0, 1.0)
    plain = info_nce_objective(model, sampler, 7)(batch, torch.Generator().manual_seed(2))
    ranked = info_nce_objective(model, sampler, 7, ranking=True)(batch, torch.Generator().manual_seed(2))
    assert torch.allclose(plain, ranked, atol=1e-6)


P = torch.tensor([0.05, 0.10, 0.20, 0.30, 0.35])
Q = torch.tensor([0.40, 0.30, 0.15, 0.10, 0.05])


def _fit_discrete(ranking: bool, n_sets: int = 10000, n_neg: int = 4) -> torch.Tensor:
    """Free per-action energies (5,) fitted by Adam on fixed draws (expert ~ p, N counter-examples ~ q)."""
    g = torch.Generator().manual_seed(0)
    pos = torch.multinomial(P, n_sets, replacement=True, generator=g)  # (S,)
    neg = torch.multinomial(Q, n_sets * n_neg, replacement=True, generator=g).reshape(n_sets, n_neg)
    energy = torch.zeros(5, requires_grad=True)
    opt = torch.optim.Adam([energy], lr=0.05)
    log_q = Q.log()
    for _ in range(300):
        opt.zero_grad()
        if ranking:
            loss = ranking_nce(energy[pos], energy[neg], log_q[pos], log_q[neg])
        else:
            loss = info_nce(energy[pos], energy[neg])
        loss.backward()
        opt.step()
    return torch.softmax(-energy.detach(), dim=0)  # exp(−E), normalised


def test_on_a_discrete_toy_info_nce_learns_p_over_q_and_ranking_nce_learns_p():
    ratio = P / Q / (P / Q).sum()
    info, ranked = _fit_discrete(False), _fit_discrete(True)
    assert (info - ratio).abs().max() < 0.03, (info, ratio)
    assert (ranked - P).abs().max() < 0.03, (ranked, P)
    assert (info - P).abs().max() > 0.2  # the two optima differ: InfoNCE's is tilted by 1/q


def test_uniform_log_prob_is_minus_log_volume_inside_and_minus_inf_outside():
    s = UniformSampler(-1.0, 1.0)
    cand = torch.tensor([[[0.0, 0.5], [1.0, -1.0], [1.5, 0.0]]])  # (1, 3, 2)
    lp = s.log_prob(cand, torch.zeros(1, 2))
    assert torch.allclose(lp[0, :2], torch.full((2,), -math.log(4.0)))
    assert lp[0, 2] == -math.inf


def _grid_integral(sampler, actions, lo, hi, n=321):
    x = torch.linspace(lo, hi, n, dtype=torch.float64)
    dx = float(x[1] - x[0])
    xx, yy = torch.meshgrid(x, x, indexing="ij")
    cand = torch.stack([xx.reshape(-1), yy.reshape(-1)], dim=1)[None].expand(len(actions), -1, -1)
    p = sampler.log_prob(cand, actions).exp()[0]  # (G,) row 0: every row holds the same mixture
    return float(p.sum() * dx * dx)


def test_expert_log_prob_integrates_to_one():
    actions = torch.tensor([[0.0, 0.3], [-0.7, 0.1], [0.7, 0.1], [0.2, -0.5]], dtype=torch.float64)
    assert _grid_integral(ExpertSampler(0.1), actions, -1.6, 1.6) == pytest.approx(1.0, abs=2e-3)


def test_expert_log_prob_matches_a_histogram_of_its_draws():
    actions = torch.tensor([[-0.5], [0.1], [0.2], [0.85]])  # (M, 1): one dimension, an edge near 0.85
    sampler = ExpertSampler(0.1)
    draws = sampler(actions, 50000, torch.Generator().manual_seed(0)).reshape(-1)  # (M * N,)
    edges = torch.linspace(-1.0, 1.0, 21)
    hist = torch.histc(draws, bins=20, min=-1.0, max=1.0) / len(draws)  # share per bin
    fine = torch.linspace(-1.0, 1.0, 4001)[:-1] + 0.00025  # midpoints of 4000 cells
    dens = sampler.log_prob(fine[None, :, None].expand(4, -1, -1), actions)[0].exp()  # (4000,)
    per_bin = (dens * 0.0005).reshape(20, 200).sum(dim=1)
    assert (per_bin - hist).abs().max() < 0.005, (per_bin, hist, edges)


def test_clipped_expert_log_prob_interior_density_plus_face_masses_is_one():
    actions = torch.tensor([[0.9], [-0.95], [0.0]], dtype=torch.float64)  # near both faces
    sampler = ExpertSampler(0.1, -1.0, 1.0)
    cand = torch.tensor([[[-1.0], [1.0]]], dtype=torch.float64).expand(3, -1, -1)
    atoms = sampler.log_prob(cand, actions)[0].exp()  # (2,) the clip's masses on the two faces
    x = torch.linspace(-1.0, 1.0, 20001, dtype=torch.float64)[1:-1]  # strictly inside
    inside = sampler.log_prob(x[None, :, None].expand(3, -1, -1), actions)[0].exp().sum() * 1e-4
    assert float(inside + atoms.sum()) == pytest.approx(1.0, abs=1e-3)
    draws = sampler(actions, 40000, torch.Generator().manual_seed(0)).reshape(-1)
    on_faces = float(((draws == -1.0) | (draws == 1.0)).double().mean())
    assert on_faces == pytest.approx(float(atoms.sum()), abs=0.005)
    assert sampler.boundary_mass(actions) == pytest.approx(float(atoms.sum()), abs=1e-9)


def test_the_clip_touches_half_a_percent_of_da_ibc_counter_examples_on_the_junction_world():
    data = JunctionWorld().sample(4000, torch.Generator().manual_seed(12345))
    share = ExpertSampler(0.1, -1.0, 1.0).boundary_mass(data["actions"])
    assert 0.001 < share < 0.01  # the size of the face approximation (negatives' module docstring)


def test_ranking_nce_trains_an_energy_model_with_da_ibc_counter_examples():
    torch.manual_seed(0)
    world = JunctionWorld()
    data = world.sample(256, torch.Generator().manual_seed(0))
    model = EnergyModel(MLPEncoder(4, embed_dim=16, hidden=16), action_dim=2, hidden=16)
    objective = info_nce_objective(model, ExpertSampler(0.1), 8, ranking=True)
    res = train(model, objective, {"obs": data["obs"], "actions": data["actions"]}, TrainConfig(steps=20))
    assert all(math.isfinite(v) for v in res.losses)


def test_bad_inputs_name_the_argument():
    pos, neg = torch.zeros(3), torch.zeros(3, 4)
    with pytest.raises(ValueError, match="pos_log_q"):
        ranking_nce(pos, neg, torch.zeros(2), torch.zeros(3, 4))
    with pytest.raises(ValueError, match="neg_log_q"):
        ranking_nce(pos, neg, torch.zeros(3), torch.zeros(3, 5))
    with pytest.raises(ValueError, match="neg_log_q"):
        ranking_nce(pos, neg, torch.zeros(3), torch.full((3, 4), -math.inf))  # q = 0 at a counter-example
    model = EnergyModel(MLPEncoder(3, embed_dim=4, hidden=4), action_dim=2, hidden=4)
    with pytest.raises(ValueError, match="sampler"):
        info_nce_objective(model, lambda a, n, g=None: a[:, None].expand(-1, n, -1), 4, ranking=True)
    with pytest.raises(ValueError, match="ranking"):
        info_nce_objective(model, UniformSampler(), 4, ranking="yes")
    with pytest.raises(ValueError, match="sigma"):
        ExpertSampler(0.0).log_prob(torch.zeros(2, 3, 2), torch.zeros(2, 2))
    with pytest.raises(ValueError, match="candidates"):
        ExpertSampler(0.1).log_prob(torch.zeros(2, 3, 1), torch.zeros(2, 2))
    with pytest.raises(ValueError, match="candidates"):
        UniformSampler().log_prob(torch.zeros(3, 3, 2), torch.zeros(2, 2))
