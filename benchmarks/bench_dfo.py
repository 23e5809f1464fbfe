#!/usr/bin/env python
"""Decisions per second of DFO inference (Algorithm 1 of the DA-IBC paper) at the paper's settings.

    python benchmarks/bench_dfo.py                      # 16,384 samples x 5 iterations, paper-sized head
    python benchmarks/bench_dfo.py --samples 4096 --iters 3 --decisions 50
    python benchmarks/bench_dfo.py --bf16               # also time the energy head in bfloat16 (autocast)

The energy model is the paper's size (sec. 3.3 and Fig. 2): a 256-wide observation embedding
and an action head of two hidden layers of 256 units on a 2-D action (steering, acceleration).
One decision = one call of ``optimizers.dfo.dfo(..., n_obs=1)`` for one observation: the observation is
embedded once, then N_iters x N_samples candidates are scored by the head.

Two heads with the same weights, timed in the same run:
- factorised (``EnergyModel.energy_from_embedding``): the first layer's observation part W_z z + b
  once per observation, only W_a y per candidate (2 x D x H multiply-adds instead of 2 x (E + D) x H);
- plain: the observation embedding tiled N times and concatenated with each candidate, then the
  unsplit first layer, as a naive implementation would do;
- factorised, fused: a per-row reference of the memory-lean form (the first layer as one ``addmm``
  with W_z z + b as its bias, ReLUs in place). ``EnergyModel`` itself computes its first layer as
  one ``baddbmm`` with in-place ReLUs since this benchmark showed that form to be about twice as
  fast as a broadcast add of separate W_z z and W_a y tensors; this row keeps it honest.

Printed: decisions/s of each (median over the timed decisions), their ratio, the floating-point
operations (FLOPs) per decision (counted from the layer sizes: 2 per multiply-add), the achieved
GFLOP/s, and the share of a decision spent outside the energy head (sampling, noise, clipping).
The goal is the paper's control rate, 10 decisions/s, on 2 CPU cores with the factorised head.
Timings depend on what else the machine runs: the load average is printed beside them.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import torch

from ibc_tutorial.optimizers.dfo import DFOConfig, dfo, initial_weights
from ibc_tutorial.policies import EnergyModel, MLPEncoder


def plain_energy_fn(model: EnergyModel, z: torch.Tensor):
    """The unsplit head: [z; y] concatenated per candidate, then W [z; y] + b (the weights of ``model``)."""
    weight = torch.cat([model.obs_proj.weight, model.act_proj.weight], dim=1)  # (H, E + D): W = [W_z, W_a]
    bias = model.obs_proj.bias  # (H,)

    def energy(actions: torch.Tensor) -> torch.Tensor:  # (B, N, D) -> (B, N)
        b, n, _ = actions.shape
        zy = torch.cat([z[:, None, :].expand(b, n, z.shape[1]), actions], dim=-1)  # (B, N, E + D)
        h = torch.relu(torch.nn.functional.linear(zy, weight, bias))  # (B, N, H)
        return model.head(h).squeeze(-1)

    return energy


def factorised_energy_fn(model: EnergyModel, z: torch.Tensor):
    """``model.energy_from_embedding`` against the fixed embedding ``z`` (the library's own head)."""

    def energy(actions: torch.Tensor) -> torch.Tensor:  # (B, N, D) -> (B, N)
        return model.energy_from_embedding(z, actions)

    return energy


def fused_energy_fn(model: EnergyModel, z: torch.Tensor):
    """The factorised head with fewer passes over memory: the first layer as one ``addmm`` (the
    observation's part W_z z + b enters as the bias of W_a y), ReLUs in place, each hidden layer as
    one ``addmm``. Same weights and energies as ``model.energy_from_embedding`` (B = 1 per call here)."""
    linears = [m for m in model.head if isinstance(m, torch.nn.Linear)]

    def energy(actions: torch.Tensor) -> torch.Tensor:  # (B, N, D) -> (B, N)
        b, n, d = actions.shape
        h_obs = model.obs_proj(z)  # (B, H): W_z z + b, once per observation
        out = []
        for i in range(b):
            h = torch.addmm(h_obs[i : i + 1], actions[i], model.act_proj.weight.T).relu_()  # (N, H)
            for lin in linears[:-1]:
                h = torch.addmm(lin.bias, h, lin.weight.T).relu_()
            out.append(torch.addmm(linears[-1].bias, h, linears[-1].weight.T)[:, 0])  # (N,)
        return torch.stack(out)

    return energy


def head_flops(model: EnergyModel, factorised: bool) -> tuple[int, int]:
    """(FLOPs per candidate, FLOPs once per observation) of the energy head, 2 per multiply-add."""
    e, d, h = model.embed_dim, model.action_dim, model.hidden
    hidden_layers = [m for m in model.head if isinstance(m, torch.nn.Linear)]
    rest = sum(2 * m.in_features * m.out_features + m.out_features for m in hidden_layers)  # matmuls + biases
    if factorised:
        per_candidate = 2 * d * h + h + rest  # W_a y, + (W_z z + b), then the rest of the head
        once = 2 * e * h + h  # W_z z + b
    else:
        per_candidate = 2 * (e + d) * h + h + rest
        once = 0
    return per_candidate, once


def encoder_flops(encoder: MLPEncoder) -> int:
    return sum(
        2 * m.in_features * m.out_features + m.out_features
        for m in encoder.net
        if isinstance(m, torch.nn.Linear)
    )


def time_decisions(energy_fn, experts, weights, config: DFOConfig, n: int) -> list[float]:
    """Seconds per decision of ``n`` DFO decisions (one observation each)."""
    gen = torch.Generator().manual_seed(0)
    times = []
    with torch.no_grad():
        for _ in range(n):
            t0 = time.perf_counter()
            dfo(energy_fn(), experts, config, n_obs=1, init_weights=weights, generator=gen)
            times.append(time.perf_counter() - t0)
    return times


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--samples", type=int, default=16384, help="N_samples (the paper: 16,384)")
    p.add_argument("--iters", type=int, default=5, help="N_iters (the paper: 5)")
    p.add_argument("--embed", type=int, default=256, help="observation embedding width (the paper: 256)")
    p.add_argument(
        "--hidden", type=int, default=256, help="width of the head's hidden layers (the paper: 256)"
    )
    p.add_argument("--layers", type=int, default=2, help="hidden layers in the head (the paper: 2)")
    p.add_argument(
        "--obs-dim", type=int, default=8, help="size of the (vector) observation fed to the encoder"
    )
    p.add_argument("--experts", type=int, default=2000, help="expert actions the initialisation draws from")
    p.add_argument("--decisions", type=int, default=20, help="timed decisions per head")
    p.add_argument("--warmup", type=int, default=3, help="untimed decisions first")
    p.add_argument(
        "--bf16", action="store_true", help="also time the factorised head under bfloat16 autocast"
    )
    p.add_argument(
        "--threads", type=int, default=None, help="torch threads (default: torch's own choice, one per core)"
    )
    args = p.parse_args(argv)
    if args.threads is not None:
        torch.set_num_threads(args.threads)

    torch.manual_seed(0)
    encoder = MLPEncoder(args.obs_dim, embed_dim=args.embed, hidden=args.embed, layers=2)
    model = EnergyModel(encoder, action_dim=2, hidden=args.hidden, layers=args.layers).eval()
    gen = torch.Generator().manual_seed(1)
    obs = torch.randn(1, args.obs_dim, generator=gen)
    experts = (torch.randn(args.experts, 2, generator=gen) * 0.3).clamp(-1, 1)  # (M, 2)
    config = DFOConfig(n_samples=args.samples, n_iters=args.iters)  # the paper's init: inverse-kde
    weights = initial_weights(experts, config)  # once, as a closed loop would

    with torch.no_grad():
        z = model.embed(obs)  # (1, E)
        cand = torch.rand(1, 4096, 2, generator=gen) * 2 - 1
        e_fact = model.energy_from_embedding(z, cand)
        e_plain = plain_energy_fn(model, z)(cand)
        e_fused = fused_energy_fn(model, z)(cand)
        max_diff = float(max((e_fact - e_plain).abs().max(), (e_fact - e_fused).abs().max()))
    assert torch.allclose(e_fact, e_plain, rtol=1e-4, atol=1e-4) and torch.allclose(
        e_fact, e_fused, rtol=1e-4, atol=1e-4
    ), max_diff

    # Each decision embeds the observation once (as dfo_policy does), then runs Algorithm 1.
    heads = {
        "factorised": lambda: factorised_energy_fn(model, model.embed(obs)),
        "plain concatenated": lambda: plain_energy_fn(model, model.embed(obs)),
        "factorised, fused (addmm, in-place ReLU)": lambda: fused_energy_fn(model, model.embed(obs)),
    }
    if args.bf16:

        def bf16_head():
            z_ = model.embed(obs)

            def energy(a):
                with torch.autocast("cpu", dtype=torch.bfloat16):
                    return model.energy_from_embedding(z_, a).float()

            return energy

        heads["factorised, bf16 autocast"] = bf16_head
    heads["no head (DFO bookkeeping only)"] = lambda: lambda a: a.sum(-1)

    print(
        f"DFO benchmark: {args.samples} samples x {args.iters} iterations, 2-D actions, "
        f"embedding {args.embed}, head {args.layers} hidden layers of {args.hidden}"
    )
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"torch {torch.__version__}, {torch.get_num_threads()} threads, "
        f"load average before: {os.getloadavg()[0]:.2f}"
    )
    print(f"factorised, plain and fused heads agree: max |ΔE| = {max_diff:.1e}")
    enc = encoder_flops(encoder)
    results = {}
    for name, make in heads.items():
        time_decisions(make, experts, weights, config, args.warmup)
        times = time_decisions(make, experts, weights, config, args.decisions)
        med = statistics.median(times)
        results[name] = med
        line = (
            f"{name:>42}: {1 / med:7.2f} decisions/s  ({med * 1e3:7.1f} ms per decision, "
            f"best {min(times) * 1e3:.1f} ms)"
        )
        if not name.startswith("no head") and "bf16" not in name:
            per_cand, once = head_flops(model, factorised=name != "plain concatenated")
            flops = args.samples * args.iters * per_cand + once + enc
            line += f"  {flops / 1e9:6.2f} GFLOP per decision, {flops / med / 1e9:6.1f} GFLOP/s achieved"
        print(line)
    ratio = results["plain concatenated"] / results["factorised"]
    overhead = results["no head (DFO bookkeeping only)"] / results["factorised"]
    print(f"factorised / plain speed ratio: {ratio:.2f}x")
    print(f"share of a factorised decision outside the head (resampling, noise, clipping): {overhead:.0%}")
    fused = "factorised, fused (addmm, in-place ReLU)"
    print(f"fused / factorised speed ratio: {results['factorised'] / results[fused]:.2f}x")
    for name in ("factorised", fused):
        goal = 1 / results[name] >= 10
        print(f"goal of 10 decisions/s, {name} head: {'met' if goal else 'NOT met'}")
    print(f"load average after: {os.getloadavg()[0]:.2f} (the figures drop when other work shares the cores)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
