#!/usr/bin/env python
"""Decisions per second of three ways to act, on the same encoder and the same observations (issue 37).

    python benchmarks/bench_inference.py                     # the laptop preset's network, one observation
    python benchmarks/bench_inference.py --batch 8 --decisions 10
    python benchmarks/bench_inference.py --preset tiny --dfo-samples 64 --dfo-iters 2 ...   # a smoke run

The rows, all timed in one process on one batch of observations:

- DFO (Algorithm 1 of the DA-IBC paper) on the energy model of ``build_network("da-ibc", preset)`` (the
  paper's Fig. 2: ``BEVStateEncoder`` + a factorised energy head), at the paper's settings (16,384
  samples x 5 iterations, ``DFOConfig``'s defaults) and at the preset's own (``preset.dfo_config``; the
  laptop preset: 512 x 3);
- Langevin (the IBC reference's gradient-based inference, ``LangevinConfig``'s defaults: 1,024 chains x
  25 steps, each a forward and a backward pass of the head) on the same energy model;
- the flow-matching policy (``policies.flow.FlowPolicy``) on a copy of the same encoder with a velocity
  head of the same width and depth, K Euler steps (1, 4 and 10) on N samples per decision;
- the town's flow agent at the preset's own K and N (``preset.flow_steps``, ``preset.flow_samples``: the
  two-answers and laptop presets, 4 x 16), as ``experiments.agents.agent.Agent`` acts: its N samples and
  the one whose steering is nearest the previous steering.

Printed per row: decisions/s (median over the timed decisions; one decision = one action for each of
the B observations of the batch), the network evaluations per observation and decision (encoder passes
and head passes: candidates x iterations for DFO, chains x (steps + 1) forward and chains x steps
backward for Langevin, N x K for the flow), and the speed as a ratio to each DFO row. The networks are
untrained: the cost of a decision does not depend on the weights. Timings depend on what else the
machine runs: the load average is printed beside them.
"""

from __future__ import annotations

import argparse
import copy
import os
import platform
import statistics
import time

import torch

from ibc_tutorial.experiments.agents.agent import Agent, build_network
from ibc_tutorial.experiments.agents.presets import get_preset
from ibc_tutorial.kde import inverse_density_weights
from ibc_tutorial.optimizers import embedded_energy
from ibc_tutorial.optimizers.dfo import DFOConfig, act_with_dfo
from ibc_tutorial.optimizers.langevin import LangevinConfig, langevin
from ibc_tutorial.policies.flow import FlowConfig, FlowPolicy, network_evaluations


def ints(text: str) -> list[int]:
    return [int(v) for v in text.split(",") if v]


def time_decisions(decide, n: int) -> list[float]:
    """Seconds per call of ``decide()`` over ``n`` calls."""
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        decide()
        times.append(time.perf_counter() - t0)
    return times


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--preset", default="laptop", help="whose network (BEV size, CNN, head) and DFO settings")
    p.add_argument("--batch", type=int, default=1, help="observations per decision (B)")
    p.add_argument("--dfo-samples", type=int, default=DFOConfig.n_samples, help="the paper row's N_samples")
    p.add_argument("--dfo-iters", type=int, default=DFOConfig.n_iters, help="the paper row's N_iters")
    p.add_argument("--langevin-samples", type=int, default=LangevinConfig.n_samples, help="Langevin chains")
    p.add_argument("--langevin-iters", type=int, default=LangevinConfig.n_iters, help="Langevin steps")
    p.add_argument("--flow-steps", type=ints, default=[1, 4, 10], help="K, Euler steps (comma-separated)")
    p.add_argument("--flow-samples", type=ints, default=[1, 64], help="N, flow samples per decision")
    p.add_argument("--experts", type=int, default=2000, help="expert actions DFO's initialisation draws from")
    p.add_argument("--decisions", type=int, default=5, help="timed decisions per row")
    p.add_argument("--warmup", type=int, default=1, help="untimed decisions first")
    p.add_argument("--threads", type=int, default=None, help="torch threads (default: torch's choice)")
    args = p.parse_args(argv)
    if args.threads is not None:
        torch.set_num_threads(args.threads)

    preset = get_preset(args.preset)
    torch.manual_seed(0)
    energy_model = build_network("da-ibc", preset).eval()  # BEVStateEncoder + factorised energy head
    flow_policy = FlowPolicy(
        copy.deepcopy(energy_model.encoder),  # the same encoder (architecture and weights)
        action_dim=2,
        hidden=preset.head_hidden,
        layers=preset.head_layers,
        config=FlowConfig(),
    ).eval()
    gen = torch.Generator().manual_seed(1)
    s, b = preset.bev_size, args.batch
    obs = {
        "bev": (torch.rand(b, 5, s, s, generator=gen) < 0.2).float(),  # (B, 5, S, S) of 0./1.
        "state": torch.rand(b, 3, generator=gen) * torch.tensor([8.0, 2.0, 2.0]) - torch.tensor([0, 1, 1]),
    }
    experts = (torch.randn(args.experts, 2, generator=gen) * 0.3).clamp(-1, 1)  # (M, 2)
    weights = inverse_density_weights(experts, preset.kde_bandwidth)  # (M,) once, as an agent does

    paper = DFOConfig(n_samples=args.dfo_samples, n_iters=args.dfo_iters)  # init inverse-kde, select sample
    own = preset.dfo_config("da-ibc")
    lang = LangevinConfig(n_samples=args.langevin_samples, n_iters=args.langevin_iters)

    def dfo_row(config: DFOConfig):
        g = torch.Generator().manual_seed(0)

        def decide():
            with torch.no_grad():
                return act_with_dfo(energy_model, obs, experts, config, init_weights=weights, generator=g)

        return decide, {"encoder": 1, "head": config.n_samples * config.n_iters}

    def langevin_decide():
        g = torch.Generator().manual_seed(0)

        def decide():
            with torch.no_grad():
                energy_fn, n_obs = embedded_energy(energy_model, obs)  # the embedding once
            return langevin(energy_fn, experts, lang, n_obs=n_obs, generator=g)  # gradients inside

        return decide

    def flow_row(k: int, n: int):
        g = torch.Generator().manual_seed(0)
        return (lambda: flow_policy.sample(obs, n, k, generator=g)), network_evaluations(n, k)

    rows = {
        f"DFO, paper ({paper.n_samples} x {paper.n_iters})": dfo_row(paper),
        f"DFO, {preset.name} ({own.n_samples} x {own.n_iters})": dfo_row(own),
        f"Langevin ({lang.n_samples} chains x {lang.n_iters} steps)": (
            langevin_decide(),
            {
                "encoder": 1,
                "head": lang.n_samples * (lang.n_iters + 1),
                "backward": lang.n_samples * lang.n_iters,
            },
        ),
    }
    for n in args.flow_samples:
        for k in args.flow_steps:
            rows[f"flow, K = {k}, N = {n}"] = flow_row(k, n)
    agent = Agent("flow", build_network("flow", preset).eval(), preset, experts)
    agent.network.encoder.load_state_dict(energy_model.encoder.state_dict())  # the same encoder again

    def flow_agent_decide():
        g = torch.Generator().manual_seed(0)
        return lambda: agent.act(obs, g)

    rows[f"flow agent, {preset.name} (K = {preset.flow_steps}, N = {preset.flow_samples})"] = (
        flow_agent_decide(),
        agent.network_evaluations(),
    )

    print(
        f"inference benchmark: the {preset.name} preset's network (BEVStateEncoder {s}x{s}, CNN "
        f"{tuple(preset.cnn_channels)}, embedding {2 * preset.embed_dim}, head {preset.head_layers} x "
        f"{preset.head_hidden}), 2-D actions, a batch of {b} observation(s) per decision"
    )
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"torch {torch.__version__}, {torch.get_num_threads()} threads, "
        f"load average before: {os.getloadavg()[0]:.2f}"
    )
    speed = {}
    for name, (decide, _) in rows.items():
        time_decisions(decide, args.warmup)
        speed[name] = 1.0 / statistics.median(time_decisions(decide, args.decisions))
    dfo_names = list(rows)[:2]
    print(
        f"{'':>40}  {'decisions/s':>11}  {'encoder':>7}  {'head evals':>10}  {'backward':>8}  "
        + "  ".join(f"{'x ' + n.split(' (')[0]:>14}" for n in dfo_names)
    )
    for name, (_, evals) in rows.items():
        ratios = "  ".join(f"{speed[name] / speed[d]:14.2f}" for d in dfo_names)
        print(
            f"{name:>40}  {speed[name]:11.2f}  {evals['encoder']:7d}  {evals['head']:10d}  "
            f"{evals.get('backward', 0):8d}  {ratios}"
        )
    print("network evaluations are per observation and decision; ratios: decisions/s over the DFO row's")
    print(f"load average after: {os.getloadavg()[0]:.2f} (the figures drop when other work shares the cores)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
