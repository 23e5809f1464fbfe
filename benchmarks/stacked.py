"""Several networks of one architecture trained and run as one batched model (the replication's agents).

A replication trains k agents of one method that differ only in their seed: the same Fig. 2
network (``policies.BEVStateEncoder`` with a ``policies.EnergyModel`` or ``policies.BetaPolicy``
head), the same data, the same settings. Trained one after the other, each step of each agent
is a chain of small convolutions and matrix products; stacked, the k agents' weights become one
leading dimension (``torch.func.stack_module_state``) and one step of all k agents is one call of
``torch.func.vmap`` over that dimension: a grouped convolution instead of k convolutions, a
batched matrix product instead of k.

**Measured, and not used by the replication.** On one CPU thread (``benchmarks/bench_replicate.py
--prototypes``, prototype (a)), a stacked step of k >= 2 laptop-preset agents costs *more* per agent than
k separate steps (about 0.7x the throughput at k = 2, 0.5x at k = 5): the convolutions' work is already
large per call (a 128-sample minibatch of 64 px views), so batching saves no overhead, and the grouped
convolution's kernels are slower than the plain ones. The module stays as the measured prototype (and
for a GPU, where k small models do not fill the device).

What stays exactly as in k separate runs (``training.Trainer``, ``objectives.info_nce_objective``):

- each agent keeps its own generator, seeded with its own seed, and draws from it in the same
  order as its own ``Trainer`` would: its minibatch indices (``training.draw_minibatch``), then
  its counter-examples (the sampler);
- each agent's loss is the same formula on its own minibatch (InfoNCE, eqs. 2-3 of the DA-IBC
  paper, or the Beta NLL of eq. 1); the stacked loss is their sum, so each agent's weights get
  exactly their own agent's gradient (the agents share no weight);
- Adam is elementwise, so one Adam over the stacked weights is k Adams, with the same step size
  schedule (``Trainer.learning_rate``).

What may differ: the floating-point rounding of the batched kernels (a grouped convolution and a
batched matrix product may sum in another order than the k separate calls), so the weights agree
with k separate runs to about 1e-6 after a step, not bit for bit (``tests/test_stacked.py`` checks
the agreement, and ``bench_replicate.py --prototypes`` prints the largest difference it sees).

- ``StackedNetworks``: k networks as one set of stacked weights; ``embed``, ``energy_from_embedding``
  (for DFO over k agents' episodes at once), ``losses`` and ``unstack`` (back to k modules).
- ``StackedTrainer``: ``training.Trainer`` for k seeds at once; ``agent_state_dict(i)`` is agent i's
  ``Trainer.state_dict()`` (what a run's ``last.pt`` stores), so checkpoints keep their format.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence

import torch
from torch import nn
from torch.func import functional_call, stack_module_state, vmap

from ibc_tutorial.losses import BETA_EPS
from ibc_tutorial.policies.encoders import SPEED_SCALE, BEVStateEncoder
from ibc_tutorial.policies.energy import EnergyModel
from ibc_tutorial.policies.explicit import BetaPolicy
from ibc_tutorial.training import Minibatches, TrainConfig, as_minibatches, draw_minibatch
from ibc_tutorial.utils import check_int, check_tensor

KINDS = ("info_nce", "beta_nll")
"""The losses a ``StackedNetworks`` computes: InfoNCE of an ``EnergyModel`` (IBC, DA-IBC) or the
Beta NLL of a ``BetaPolicy`` (BC)."""


def _encode(encoder: BEVStateEncoder, bev: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
    """``BEVStateEncoder.forward`` without its input checks (made once, outside ``vmap``): z (B, 2 E)."""
    scale = torch.tensor([1.0 / SPEED_SCALE, 1.0, 1.0], device=state.device)  # (3,)
    return torch.cat([encoder.cnn(bev.float()), encoder.state_mlp(state.float() * scale)], dim=1)


class _Loss(nn.Module):
    """One agent's loss on one minibatch, the formula of ``objectives`` / ``losses`` without the checks."""

    def __init__(self, net: nn.Module, kind: str):
        super().__init__()
        self.net, self.kind = net, kind

    def forward(self, bev, state, actions, negatives=None):
        net = self.net
        z = _encode(net.encoder, bev, state)  # (B, 2 E)
        if self.kind == "beta_nll":  # BetaPolicy.forward, then losses.beta_nll (eq. 1)
            u = net.head(z).view(-1, 2, net.action_dim)  # (B, 2, D)
            conc = net.min_concentration + nn.functional.softplus(u) + net.eps
            alpha, beta = conc[:, 0], conc[:, 1]  # (B, D) each
            y = ((actions + 1.0) / 2.0).clamp(BETA_EPS, 1.0 - BETA_EPS)  # (B, D)
            log_b = torch.lgamma(alpha) + torch.lgamma(beta) - torch.lgamma(alpha + beta)
            log_f = (alpha - 1.0) * torch.log(y) + (beta - 1.0) * torch.log1p(-y) - log_b
            return -log_f.sum(dim=1).mean()
        # objectives.info_nce_objective with EnergyModel.energy's training form, then losses.info_nce
        candidates = torch.cat([actions[:, None, :], negatives], dim=1)  # (B, 1 + N, D), expert first
        h_obs = net.obs_proj(z)  # (B, H)
        h = torch.relu(h_obs[:, None, :] + candidates @ net.act_proj.weight.T)  # (B, 1 + N, H)
        e = net.head(h).squeeze(-1)  # (B, 1 + N)
        logits = torch.cat([-e[:, :1], -e[:, 1:]], dim=1)  # (B, 1 + N), as losses.info_nce builds them
        return (torch.logsumexp(logits, dim=1) + e[:, 0]).mean()  # eq. 2 (divided by B)


class _Embed(nn.Module):
    def __init__(self, net: nn.Module):
        super().__init__()
        self.net = net

    def forward(self, bev, state):
        return _encode(self.net.encoder, bev, state)


class _Energy(nn.Module):
    def __init__(self, net: nn.Module):
        super().__init__()
        self.net = net

    def forward(self, z, actions):
        return self.net.energy_from_embedding(z, actions)


class StackedNetworks:
    """k networks of one architecture as one set of weights with a leading agent dimension.

    Args:
        networks: k >= 1 modules of the same class and shapes, each a ``BEVStateEncoder`` under an
            ``EnergyModel`` or a ``BetaPolicy`` (``experiments.agents.build_network``); their weights are
            copied (the modules are left untouched).

    ``params`` holds the stacked weights (leaf tensors (k, ...), named as in ``named_parameters``).
    """

    def __init__(self, networks: Sequence[nn.Module]):
        networks = list(networks)
        if not networks:
            raise ValueError("networks must hold at least one network")
        first = networks[0]
        if not isinstance(first, (EnergyModel, BetaPolicy)) or not isinstance(first.encoder, BEVStateEncoder):
            raise ValueError(
                "networks must be EnergyModel or BetaPolicy modules on a BEVStateEncoder, got "
                f"{type(first).__name__}"
            )
        shapes = [[(n, tuple(p.shape)) for n, p in net.named_parameters()] for net in networks]
        if any(
            type(net) is not type(first) or s != shapes[0] for net, s in zip(networks, shapes, strict=True)
        ):
            raise ValueError("networks must share one class and the same parameter shapes")
        self.k = len(networks)
        self.kind = "info_nce" if isinstance(first, EnergyModel) else "beta_nll"
        params, buffers = stack_module_state(networks)  # {name: (k, ...)}, leaves requiring grad
        self.params = {n: p.detach().clone().requires_grad_(True) for n, p in params.items()}
        self.buffers = buffers
        self.template = copy.deepcopy(first)  # the architecture; its own weights are never used

    def _call(self, module: nn.Module, *args, in_dims=0):
        prefixed = {"net." + n: p for n, p in self.params.items()}
        prefixed.update({"net." + n: b for n, b in self.buffers.items()})

        def one(weights, *a):
            return functional_call(module, weights, a)

        return vmap(one, in_dims=(0,) + (in_dims if isinstance(in_dims, tuple) else (0,) * len(args)))(
            prefixed, *args
        )

    def parameters(self) -> list[torch.Tensor]:
        """The stacked weights, in ``named_parameters`` order of one network."""
        return list(self.params.values())

    def embed(self, bev: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
        """bev (k, B, C, S, S), state (k, B, 3) -> z (k, B, E): each agent encodes its own observations."""
        return self._call(_Embed(self.template), bev, state)

    def energy_from_embedding(self, z: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """z (k, B, E), actions (k, B, N, D) -> energies (k, B, N): each agent's
        ``EnergyModel.energy_from_embedding`` (its no-gradient form under ``torch.no_grad``)."""
        if self.kind != "info_nce":
            raise ValueError("energy_from_embedding needs energy models, got BetaPolicy networks")
        return self._call(_Energy(self.template), z, actions)

    def losses(self, bev, state, actions, negatives=None) -> torch.Tensor:
        """Each agent's loss on its own minibatch: bev (k, B, C, S, S), state (k, B, 3), actions (k, B, D),
        negatives (k, B, N, D) (energy models) -> (k,)."""
        args = (bev, state, actions) if self.kind == "beta_nll" else (bev, state, actions, negatives)
        return self._call(_Loss(self.template, self.kind), *args)

    @torch.no_grad()
    def unstack(self) -> list[nn.Module]:
        """k independent modules holding the current weights (the shape ``build_network`` returns)."""
        out = []
        for i in range(self.k):
            net = copy.deepcopy(self.template)
            net.load_state_dict(
                {
                    **{n: p[i].clone() for n, p in self.params.items()},
                    **{n: b[i] for n, b in self.buffers.items()},
                }
            )
            out.append(net)
        return out


class StackedTrainer:
    """``training.Trainer`` for k agents of one method at once: one batched step trains all k.

    Args:
        networks: the k freshly built (or resumed) networks, as ``StackedNetworks`` takes them.
        data: the shared training data (``training.Minibatches``, e.g. ``experiments.agents.DemoBatches``),
            whose ``batch`` returns ``{"obs": {"bev", "state"}, "actions"}``.
        config: the settings every agent shares (``TrainConfig``; its ``seed`` is ignored).
        seeds: k seeds: agent i's generator is ``torch.Generator().manual_seed(seeds[i])``, as its own
            ``Trainer`` would seed it.
        sampler: ``sampler(actions (B, D), n_neg, generator) -> (B, N, D)`` (energy models; None for BC).
        n_neg: counter-examples per sample (energy models).
        sample_probs: optional (M,) minibatch probabilities (``kde.inverse_density_weights``).
    """

    def __init__(
        self,
        networks: Sequence[nn.Module],
        data,
        config: TrainConfig,
        seeds: Sequence[int],
        *,
        sampler: Callable | None = None,
        n_neg: int = 0,
        sample_probs: torch.Tensor | None = None,
    ):
        self.stack = StackedNetworks(networks)
        if len(seeds) != self.stack.k:
            raise ValueError(f"seeds must give one seed per network ({self.stack.k}), got {len(seeds)}")
        check_int("config.steps", config.steps, minimum=1)
        check_int("config.batch_size", config.batch_size, minimum=1)
        if self.stack.kind == "info_nce":
            if sampler is None:
                raise ValueError("sampler must be given for energy models (the counter-examples)")
            check_int("n_neg", n_neg, minimum=1)
        self.data: Minibatches = as_minibatches(data)
        if sample_probs is not None:
            check_tensor("sample_probs", sample_probs, shape=(len(self.data),))
        self.config, self.sampler, self.n_neg, self.sample_probs = config, sampler, n_neg, sample_probs
        self.seeds = [check_int("seeds[i]", s, minimum=0) for s in seeds]
        self.generators = [torch.Generator().manual_seed(s) for s in self.seeds]
        self.optimizer = torch.optim.Adam(
            self.stack.parameters(), lr=config.lr, weight_decay=config.weight_decay
        )
        self.step = 0

    def learning_rate(self, step: int) -> float:
        """``Trainer.learning_rate``: the same schedule for every agent."""
        import math

        c = self.config
        if c.lr_schedule == "cosine":
            return c.lr * 0.5 * (1.0 + math.cos(math.pi * step / c.steps))
        return c.lr

    def draw(self) -> dict:
        """One minibatch per agent, drawn from each agent's generator in its own ``Trainer``'s order:
        ``{"bev": (k, B, C, S, S), "state": (k, B, 3), "actions": (k, B, D), "negatives": (k, B, N, D)}``
        (negatives None for BC)."""
        c, m = self.config, len(self.data)
        idx = [draw_minibatch(self.sample_probs, m, c.batch_size, g) for g in self.generators]  # k x (B,)
        batch = self.data.batch(torch.cat(idx))  # one assembly of k B samples
        k, b = self.stack.k, c.batch_size
        bev = batch["obs"]["bev"].reshape(k, b, *batch["obs"]["bev"].shape[1:])
        state = batch["obs"]["state"].reshape(k, b, -1)
        actions = batch["actions"].reshape(k, b, -1)
        negatives = None
        if self.stack.kind == "info_nce":
            negatives = torch.stack(
                [self.sampler(actions[i], self.n_neg, g) for i, g in enumerate(self.generators)]
            )  # (k, B, N, D)
        return {"bev": bev, "state": state, "actions": actions, "negatives": negatives}

    def train_step(self) -> torch.Tensor:
        """One Adam step of every agent; returns the k losses (k,)."""
        mb = self.draw()
        losses = self.stack.losses(mb["bev"], mb["state"], mb["actions"], mb["negatives"])  # (k,)
        if not torch.isfinite(losses).all():
            raise ValueError(
                f"the losses must be finite, got {losses.detach().tolist()} at step {self.step + 1}"
            )
        self.optimizer.zero_grad(set_to_none=True)
        losses.sum().backward()  # agents share no weight: each gets its own gradient
        for group in self.optimizer.param_groups:
            group["lr"] = self.learning_rate(self.step)
        self.optimizer.step()
        self.step += 1
        return losses.detach()

    def run(self, steps: int | None = None) -> list[torch.Tensor]:
        """Train up to ``config.steps`` (or ``steps`` more steps); the per-step losses (k,) each."""
        stop = self.config.steps if steps is None else min(self.config.steps, self.step + steps)
        return [self.train_step() for _ in range(self.step, stop)]

    def agent_state_dict(self, i: int) -> dict:
        """Agent i's ``Trainer.state_dict()``: its model, its Adam state (as a one-model Adam stores it),
        its generator, the step. A run's ``last.pt`` can be written from it unchanged."""
        check_int("i", i, minimum=0)
        if i >= self.stack.k:
            raise ValueError(f"i must be < {self.stack.k}, got {i}")
        opt = self.optimizer.state_dict()
        state = {
            j: {key: (v[i].clone() if torch.is_tensor(v) and v.ndim > 0 else v) for key, v in s.items()}
            for j, s in opt["state"].items()
        }
        return {
            "model": {n: p[i].detach().clone() for n, p in self.stack.params.items()}
            | {n: b[i].clone() for n, b in self.stack.buffers.items()},
            "optimizer": {"state": state, "param_groups": opt["param_groups"]},
            "generator": self.generators[i].get_state(),
            "step": self.step,
        }
