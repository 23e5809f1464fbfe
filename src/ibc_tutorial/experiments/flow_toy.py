"""Chapter 13's live example: a flow policy learns a 1-D target with two answers, and acts by K Euler steps.

The target is the tree's choice in one dimension: one observation (a constant 0), and the expert's action
drawn half the time near minus ``centre`` and half the time near ``centre``, with Gaussian noise of
standard deviation ``spread`` (``two_gaussians``). A ``FlowPolicy`` is trained on it by conditional flow
matching (``train_flow``) and draws samples with K Euler steps (``samples_by_k``). With K = 1 the single
step from t = 0 lands every sample on y_0 + v(y_0, 0) = E[y_1]: the velocity at t = 0 is E[y_1] − y_0
whatever y_0 is, so one step is the regression's average, the answer between the two modes. More steps
follow the curved field and split the samples between the two modes.
"""

from __future__ import annotations

import torch

from ibc_tutorial.objectives import flow_matching_objective
from ibc_tutorial.policies import FlowConfig, FlowPolicy
from ibc_tutorial.training import TrainConfig, train
from ibc_tutorial.utils import check_int, check_positive


def two_gaussians(
    n: int, generator: torch.Generator, centre: float = 0.6, spread: float = 0.08
) -> dict[str, torch.Tensor]:
    """``n`` demonstrations {"obs": (n, 1) zeros, "actions": (n, 1)}: ``centre`` or minus ``centre`` (half
    each, at random) plus N(0, ``spread`` squared) noise."""
    n = check_int("n", n, minimum=1)
    check_positive("centre", centre)
    check_positive("spread", spread)
    side = torch.randint(0, 2, (n, 1), generator=generator).to(torch.get_default_dtype()) * 2 - 1
    actions = side * centre + spread * torch.randn(n, 1, generator=generator)
    return {"obs": torch.zeros(n, 1), "actions": actions.clamp(-1.0, 1.0)}


def train_flow(seed: int = 0, *, n: int = 2000, steps: int = 600, width: int = 64) -> FlowPolicy:
    """A ``FlowPolicy`` (two layers of ``width``) trained from ``seed`` on ``two_gaussians(n)`` by ``steps``
    Adam steps at learning rate 3e-3 on minibatches of 128."""
    seed = check_int("seed", seed, minimum=0)
    data = two_gaussians(n, torch.Generator().manual_seed(seed))
    torch.manual_seed(seed)  # the initial weights
    policy = FlowPolicy.for_vectors(1, 1, hidden=width, layers=3, config=FlowConfig(n_steps=10))
    config = TrainConfig(
        steps=check_int("steps", steps, minimum=1), batch_size=128, lr=3e-3, seed=seed, progress=False
    )
    train(policy, flow_matching_objective(policy), data, config)
    return policy


def samples_by_k(policy: FlowPolicy, ks, n: int = 2000, seed: int = 0) -> dict[int, torch.Tensor]:
    """{K: (n,) samples drawn with K Euler steps from the same noise (seeded by ``seed``)} for each K of
    ``ks``."""
    obs = torch.zeros(1, 1)
    out = {}
    for k in ks:
        g = torch.Generator().manual_seed(check_int("seed", seed, minimum=0))
        out[int(k)] = policy.sample(obs, check_int("n", n, minimum=1), int(k), generator=g)[0, :, 0]
    return out
