"""How far each stage of ``replicate`` is from what one CPU thread can do.

Imported by ``bench_replicate.py`` (``--limits``); not a script of its own.

**Limits.** For each stage, the floating-point work of one unit is counted from the network's shapes
(``torch.utils.flop_counter.FlopCounterMode`` on one real call, checked against a hand count of the
Fig. 2 encoder's convolutions and linear layers), the unit is timed, and the time a machine running
at its peak would need is measured in the same process: a matrix product (GEMM) and a convolution of
the stage's own shapes, alone, best of several runs. The stage's share of the peak is

    share = (GEMM FLOPs / GEMM peak + convolution FLOPs / convolution peak) / measured time,

so 100 % would mean the stage does nothing but its arithmetic at the speed of its largest GEMM and
convolution. Stages without arithmetic are compared with their own floor: minibatch assembly with a
plain copy of the bytes it writes (memory bandwidth), the BEV render with its pixel gathers alone (no
pooling), the simulator step with its two pymunk physics substeps alone.

The speed-ups tried against these limits and not adopted (several seeds as one stacked model, the DFO of
several agents batched, channels-last convolutions, and others) have left the code: their last measured
ratios are in ``RESULTS.md`` beside this file.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
import torch
from torch.nn import functional as F
from torch.utils.flop_counter import FlopCounterMode

from ibc_tutorial.driving.sim import DrivingSim
from ibc_tutorial.experiments.agents.agent import Agent, build_network
from ibc_tutorial.experiments.agents.train import DemoBatches, objective_for
from ibc_tutorial.policies.encoders import BEVStateEncoder
from ibc_tutorial.training import TrainConfig, Trainer

CONV_OPS = ("convolution", "convolution_backward")
GEMM_OPS = ("mm", "addmm", "bmm", "baddbmm")


# --------------------------------------------------------------------------- timing
def interleaved_best(fns: dict, reps: int = 5) -> dict:
    """{name: seconds per call}: each ``(fn, number)`` timed once per round, the rounds interleaved, the
    minimum over rounds kept, so that a stage and the peaks it is compared with see the same load."""
    for fn, _ in fns.values():
        fn()
    best = {name: math.inf for name in fns}
    for _ in range(reps):
        for name, (fn, number) in fns.items():
            t = time.perf_counter()
            for _ in range(number):
                fn()
            best[name] = min(best[name], (time.perf_counter() - t) / number)
    return best


# --------------------------------------------------------------------------- FLOPs
def count_flops(fn: Callable[[], object]) -> dict[str, int]:
    """FLOPs of one call of ``fn`` (2 per multiply-add), by kind: {"conv", "gemm", "other"}."""
    with FlopCounterMode(display=False) as fc:
        fn()
    out = {"conv": 0, "gemm": 0, "other": 0}
    for op, n in fc.get_flop_counts().get("Global", {}).items():
        name = str(op).split(".")[-1] if "." in str(op) else str(op)
        name = name.replace("aten::", "")
        kind = "conv" if name in CONV_OPS else "gemm" if name in GEMM_OPS else "other"
        out[kind] += int(n)
    return out


def encoder_flops_by_hand(enc: BEVStateEncoder) -> int:
    """Forward FLOPs of one observation through the Fig. 2 encoder, from its layer shapes (2 per mult-add)."""
    total, side, c_in = 0, enc.bev_size, enc.in_channels
    for m in enc.cnn:
        if isinstance(m, torch.nn.Conv2d):
            side = (side + 2 - 3) // 2 + 1
            total += 2 * m.out_channels * c_in * 9 * side * side
            c_in = m.out_channels
        elif isinstance(m, torch.nn.Linear):
            total += 2 * m.in_features * m.out_features
    for m in enc.state_mlp:
        if isinstance(m, torch.nn.Linear):
            total += 2 * m.in_features * m.out_features
    return total


# --------------------------------------------------------------------------- peaks
def gemm_call(m: int, k: int, n: int) -> tuple[Callable[[], object], int]:
    """(one (m, k) @ (k, n) float32 product, its FLOPs): the GEMM peak of a shape."""
    a, b = torch.randn(m, k), torch.randn(k, n)
    out = torch.empty(m, n)
    return (lambda: torch.mm(a, b, out=out)), 2 * m * k * n


def conv_call(batch: int, c_in: int, c_out: int, side: int) -> tuple[Callable[[], object], int]:
    """(one 3x3 stride-2 convolution (batch, c_in, side, side) -> c_out, its FLOPs): the convolution peak."""
    x, w = torch.randn(batch, c_in, side, side), torch.randn(c_out, c_in, 3, 3)
    out_side = (side + 2 - 3) // 2 + 1
    return (lambda: F.conv2d(x, w, stride=2, padding=1)), 2 * batch * c_out * c_in * 9 * out_side * out_side


def largest_conv(enc: BEVStateEncoder) -> tuple[int, int, int]:
    """(c_in, c_out, input side) of the encoder's convolution with the most FLOPs."""
    best, side, c_in, out = 0, enc.bev_size, enc.in_channels, None
    for m in enc.cnn:
        if isinstance(m, torch.nn.Conv2d):
            o = (side + 2 - 3) // 2 + 1
            f = m.out_channels * c_in * o * o
            if f > best:
                best, out = f, (c_in, m.out_channels, side)
            side, c_in = o, m.out_channels
    return out


# --------------------------------------------------------------------------- the limits table
def limits(p, ds, probs, episodes: int = 10, reps: int = 5) -> list[dict]:
    """One row per stage: unit, FLOPs per unit, seconds per unit, GFLOP/s, ideal seconds, share of peak."""
    rows = []
    enc = build_network("ibc", p).encoder
    hand = encoder_flops_by_hand(enc)
    obs1 = {"bev": torch.zeros(1, 5, p.bev_size, p.bev_size), "state": torch.zeros(1, 3)}
    counted = count_flops(lambda: enc(obs1))
    assert counted["conv"] + counted["gemm"] == hand, (
        counted,
        hand,
    )  # the counter agrees with the hand count
    print(
        f"FLOP counter checked against a hand count: the encoder's forward pass of one observation is "
        f"{hand / 1e6:.2f} MFLOP both ways"
    )
    c_in, c_out, side = largest_conv(enc)
    b, n_neg, h = p.batch_size, p.n_neg, p.head_hidden

    def timed_with_peaks(stage, number, g_shape, c_shape):
        """(stage s, GEMM peak FLOP/s, conv peak FLOP/s), timed in interleaved rounds."""
        (g, g_flops), (c, c_flops) = gemm_call(*g_shape), conv_call(*c_shape)
        t = interleaved_best({"stage": (stage, number), "gemm": (g, 5), "conv": (c, 5)}, reps)
        return t["stage"], g_flops / t["gemm"], c_flops / t["conv"]

    batches = DemoBatches(ds)
    for method in ("bc", "ibc", "da-ibc"):
        torch.manual_seed(0)
        net = build_network(method, p)
        cfg = TrainConfig(steps=10**6, batch_size=b, lr=p.lr, progress=False)
        tr = Trainer(net, objective_for(method, net, p), batches, cfg, sample_probs=probs)
        tr.config.steps = 2
        tr.run()

        def one_step(tr=tr):
            tr.config.steps = tr.step + 1
            tr.run()

        flops = count_flops(one_step)
        g_shape = (
            (b, net.encoder.cnn[-2].in_features, p.embed_dim) if method == "bc" else (b * (1 + n_neg), h, h)
        )
        t, gp, cp = timed_with_peaks(one_step, 2, g_shape, (b, c_in, c_out, side))
        rows.append(
            _row(
                f"train {method}",
                "minibatch",
                flops,
                t,
                gp,
                cp,
                f"GEMM {g_shape[0]}x{g_shape[1]}x{g_shape[2]}, conv B={b} {c_in}->{c_out} @{side}",
            )
        )
    idx = torch.arange(episodes) * (len(ds) // episodes)
    obs, _ = ds.batch(idx)
    for method in ("ibc", "da-ibc"):
        torch.manual_seed(0)
        agent = Agent(
            method,
            build_network(method, p).eval(),
            p,
            ds.actions,
            init_weights=probs if method == "da-ibc" else None,
        )
        gen = torch.Generator().manual_seed(0)

        def decide(agent=agent, gen=gen):
            return agent.act(obs, gen)

        flops = count_flops(decide)
        g_shape = (episodes * p.dfo_samples, h, h)
        t, gp, cp = timed_with_peaks(decide, 3, g_shape, (episodes, c_in, c_out, side))
        rows.append(
            _row(
                f"DFO decision {method}",
                f"{episodes} episodes",
                flops,
                t,
                gp,
                cp,
                f"GEMM {g_shape[0]}x{h}x{h}, conv B={episodes}",
            )
        )
    # no arithmetic: compared with a copy of the bytes they write
    ib = torch.randint(0, len(ds), (b,))
    x = torch.empty(b, 5, p.bev_size, p.bev_size)
    y = torch.empty_like(x)
    tt = interleaved_best({"stage": (lambda: ds.batch(ib), 3), "copy": (lambda: y.copy_(x), 3)}, reps)
    t, t_copy = tt["stage"], tt["copy"]
    rows.append(_mem_row("minibatch assembly", f"{b} samples", x.numel() * 4, t, t_copy))
    renderer = ds.renderer
    pose, lights = ds.log.pose[0], ds.log.light_history(np.array([0]))[0]
    lights = renderer.check_lights(lights)
    raster = renderer.raster.code.ravel()

    def gathers():  # what a render cannot skip: the view's raster indices and its two lookups, no pooling
        return renderer._lut(lights).take(raster.take(renderer._indices(*pose)))

    tt = interleaved_best(
        {"stage": (lambda: renderer.render(*pose, lights), 50), "floor": (gathers, 50)}, reps
    )
    rows.append(
        {
            "stage": "BEV render (env obs)",
            "unit": "view",
            "seconds": tt["stage"],
            "ideal": tt["floor"],
            "share": tt["floor"] / tt["stage"],
            "note": "floor: its 192x192 gathers without the pooling",
        }
    )
    sim = DrivingSim("town02")
    sim.reset(np.random.default_rng(0))
    rng = np.random.default_rng(1)
    acts = rng.uniform(-0.3, 0.6, size=(4000, 2))
    k = [0]

    def sim_step():
        sim.step(*acts[k[0] % 4000])
        k[0] += 1
        if sim.terminated:
            sim.reset(np.random.default_rng(k[0]))

    dt, space, sub = sim.dt, sim.space, sim.car.config.substeps

    def physics():
        for _ in range(sub):
            space.step(dt)

    tt = interleaved_best({"stage": (sim_step, 200), "floor": (physics, 200)}, reps)
    t, t_floor = tt["stage"], tt["floor"]
    rows.append(
        {
            "stage": "simulator step",
            "unit": "step",
            "seconds": t,
            "ideal": t_floor,
            "share": t_floor / t,
            "note": f"floor: {sub} pymunk substeps alone",
        }
    )
    return rows


def _row(stage, unit, flops, t, gemm_peak_, conv_peak_, note):
    total = sum(flops.values())
    ideal = (flops["gemm"] + flops["other"]) / gemm_peak_ + flops["conv"] / conv_peak_
    return {
        "stage": stage,
        "unit": unit,
        "flops": total,
        "conv_share": flops["conv"] / max(total, 1),
        "seconds": t,
        "rate": total / t,
        "gemm_peak": gemm_peak_,
        "conv_peak": conv_peak_,
        "ideal": ideal,
        "share": ideal / t,
        "note": note,
    }


def _mem_row(stage, unit, nbytes, t, t_copy):
    return {
        "stage": stage,
        "unit": unit,
        "bytes": nbytes,
        "seconds": t,
        "ideal": t_copy,
        "share": t_copy / t,
        "note": f"floor: copying its {nbytes / 1e6:.2f} MB",
    }


def print_limits(rows: list[dict]) -> None:
    print(
        f"\n{'stage':<22}{'unit':>14}{'GFLOP':>8}{'conv':>6}{'ms':>9}{'GFLOP/s':>9}"
        f"{'GEMM pk':>9}{'conv pk':>9}{'share':>7}  peak measured on"
    )
    for r in rows:
        if "flops" in r:
            print(
                f"{r['stage']:<22}{r['unit']:>14}{r['flops'] / 1e9:>8.3f}{r['conv_share']:>6.0%}"
                f"{r['seconds'] * 1e3:>9.2f}{r['rate'] / 1e9:>9.1f}{r['gemm_peak'] / 1e9:>9.1f}"
                f"{r['conv_peak'] / 1e9:>9.1f}{r['share']:>7.0%}  {r['note']}"
            )
        else:
            print(
                f"{r['stage']:<22}{r['unit']:>14}{'-':>8}{'-':>6}{r['seconds'] * 1e3:>9.3f}{'-':>9}{'-':>9}"
                f"{'-':>9}{r['share']:>7.0%}  {r['note']}"
            )
    print(
        "share = time at the measured peaks (GEMM FLOPs / GEMM peak + conv FLOPs / conv peak, or the "
        "floor) / measured time; 'conv' = the convolutions' part of the FLOPs"
    )
