"""How far each stage of ``replicate`` is from what one CPU thread can do; what candidate speed-ups buy.

Imported by ``bench_replicate.py`` (``--limits``, ``--prototypes``); not a script of its own.

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

**Prototypes.** Each candidate runs against the current path in the same process, the two timed in
alternation, and the ratio (current time / candidate time; > 1 = the candidate is faster) is the
median of the per-round ratios: a shared machine slows both alike within a round.
"""

from __future__ import annotations

import cProfile
import io
import math
import pstats
import statistics
import time
from collections.abc import Callable

import numpy as np
import torch
from stacked import StackedNetworks, StackedTrainer
from torch.nn import functional as F
from torch.utils.flop_counter import FlopCounterMode

from ibc_tutorial.driving.bev import UNPACK_TABLE
from ibc_tutorial.driving.pooling import pool_packed
from ibc_tutorial.driving.sim import DrivingSim
from ibc_tutorial.experiments.agents.agent import Agent, build_network
from ibc_tutorial.experiments.agents.train import DemoBatches, objective_for
from ibc_tutorial.negatives import ExpertSampler, UniformSampler
from ibc_tutorial.optimizers.dfo import dfo
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


def ratio(current: Callable[[], object], candidate: Callable[[], object], rounds: int = 5, number: int = 1):
    """(median of current/candidate per round, best current s, best candidate s), timed in alternation."""
    current(), candidate()
    rs, a_s, b_s = [], [], []
    for _ in range(rounds):
        t = time.perf_counter()
        for _ in range(number):
            current()
        a = (time.perf_counter() - t) / number
        t = time.perf_counter()
        for _ in range(number):
            candidate()
        b = (time.perf_counter() - t) / number
        rs.append(a / b)
        a_s.append(a)
        b_s.append(b)
    return statistics.median(rs), min(a_s), min(b_s)


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


# --------------------------------------------------------------------------- prototypes
def proto_stacked(p, ds, probs, ks=(1, 2, 5, 10), method="ibc", rounds=3) -> list[tuple]:
    """(a) k agents of one method trained as one vmapped model vs k separate Trainers: per-agent ratio."""
    out = []
    batches = DemoBatches(ds)
    cfg = TrainConfig(steps=10**6, batch_size=p.batch_size, lr=p.lr, progress=False)
    sampler = (
        None
        if method == "bc"
        else UniformSampler(-1.0, 1.0)
        if method == "ibc"
        else ExpertSampler(p.neg_sigma)
    )
    for k in ks:
        nets = []
        for s in range(k):
            torch.manual_seed(s)
            nets.append(build_network(method, p))
        st = StackedTrainer(
            nets, batches, cfg, list(range(k)), sampler=sampler, n_neg=p.n_neg, sample_probs=probs
        )
        trs = [Trainer(n, objective_for(method, n, p), batches, cfg, sample_probs=probs) for n in nets]

        def separate(trs=trs):
            for tr in trs:
                tr.config.steps = tr.step + 1
                tr.run()

        r, a, b_ = ratio(separate, st.train_step, rounds)
        out.append((k, r, a / k, b_ / k))
        print(
            f"  (a) stacked {method}, k = {k:>2}: separate {a / k * 1e3:7.1f} ms/agent-step, stacked "
            f"{b_ / k * 1e3:7.1f} ms/agent-step, ratio {r:.2f}x"
        )
    return out


def stacked_gradient_agreement(p, ds, method="ibc", k=3) -> float:
    """Largest ||g_stacked - g_separate|| / ||g_separate|| over the weights of k agents after one minibatch
    (the energy head's output bias excluded: InfoNCE does not depend on it, its gradient is rounding
    noise)."""
    from ibc_tutorial.training import draw_minibatch

    batches = DemoBatches(ds)
    nets = []
    for s in range(k):
        torch.manual_seed(s)
        nets.append(build_network(method, p))
    sampler = (
        None
        if method == "bc"
        else UniformSampler(-1.0, 1.0)
        if method == "ibc"
        else ExpertSampler(p.neg_sigma)
    )
    st = StackedTrainer(
        nets,
        batches,
        TrainConfig(steps=1, batch_size=p.batch_size),
        list(range(k)),
        sampler=sampler,
        n_neg=p.n_neg,
    )
    mb = st.draw()
    losses = st.stack.losses(mb["bev"], mb["state"], mb["actions"], mb["negatives"])
    losses.sum().backward()
    worst, same_loss = 0.0, True
    for i in range(k):
        g = torch.Generator().manual_seed(i)
        idx = draw_minibatch(None, len(batches), p.batch_size, g)
        loss = objective_for(method, nets[i], p)(batches.batch(idx), g)
        loss.backward()
        same_loss &= bool(loss.detach() == losses[i].detach())
        for n, prm in nets[i].named_parameters():
            if n == "head.2.bias" and method != "bc":
                continue
            d = float((st.stack.params[n].grad[i] - prm.grad).norm() / prm.grad.norm().clamp_min(1e-30))
            worst = max(worst, d)
    print(
        f"  (a) one minibatch, {k} agents: losses bit-identical: {same_loss}; largest relative gradient "
        f"difference {worst:.1e} (grouped convolution / batched products sum in another order)"
    )
    return worst


def proto_batched_eval(p, ds, probs, k=5, episodes=10, rounds=5) -> float:
    """(b) the DFO decision of k agents x E episodes in one call vs k calls of E."""
    torch.manual_seed(0)
    nets = [build_network("ibc", p).eval() for _ in range(k)]
    agents = [Agent("ibc", n, p, ds.actions) for n in nets]
    stack = StackedNetworks(nets)
    idx = torch.arange(episodes) * (len(ds) // episodes)
    obs, _ = ds.batch(idx)
    gen = torch.Generator().manual_seed(0)
    cfg = agents[0].dfo_config
    bev_k = obs["bev"].expand(k, *obs["bev"].shape)
    st_k = obs["state"].expand(k, *obs["state"].shape)

    def separate():
        for a in agents:
            a.act(obs, gen)

    @torch.no_grad()
    def batched():
        z = stack.embed(bev_k, st_k)  # (k, E, 512)

        def energy(y):  # (k E, N, D) -> (k E, N)
            return stack.energy_from_embedding(z, y.view(k, episodes, *y.shape[1:])).reshape(k * episodes, -1)

        return dfo(energy, ds.actions, cfg, n_obs=k * episodes, generator=gen)

    r, a, b_ = ratio(separate, batched, rounds)
    print(
        f"  (b) DFO of {k} agents x {episodes} episodes: {k} calls {a * 1e3:.1f} ms, one vmapped call "
        f"{b_ * 1e3:.1f} ms, ratio {r:.2f}x"
    )
    return r


def proto_channels_last(p, ds, probs, rounds=5) -> dict:
    """(c) channels-last convolutions: the CNN forward+backward at the training batch, forward at B=10."""
    out = {}
    torch.manual_seed(0)
    enc = build_network("ibc", p).encoder
    enc_cl = build_network("ibc", p).encoder
    enc_cl.load_state_dict(enc.state_dict())
    enc_cl.to(memory_format=torch.channels_last)
    x = (torch.rand(p.batch_size, 5, p.bev_size, p.bev_size) > 0.7).float()
    x_cl = x.contiguous(memory_format=torch.channels_last)
    cnn, cnn_cl = enc.cnn, enc_cl.cnn
    with torch.no_grad():
        diff = float((cnn(x) - cnn_cl(x_cl)).abs().max())
    out["train_cnn"] = ratio(lambda: cnn(x).sum().backward(), lambda: cnn_cl(x_cl).sum().backward(), rounds)[
        0
    ]
    x10, x10_cl = x[:10], x_cl[:10]
    with torch.no_grad():
        out["infer_cnn"] = ratio(lambda: cnn(x10), lambda: cnn_cl(x10_cl), rounds, 5)[0]
    for method in ("bc", "ibc"):
        out[method] = _channels_last_step(p, ds, probs, method, rounds)
    print(
        f"  (c) channels-last CNN: forward+backward at B={p.batch_size} {out['train_cnn']:.2f}x, forward at "
        f"B=10 {out['infer_cnn']:.2f}x; largest output difference {diff:.1e}"
    )
    return out


def _channels_last_step(p, ds, probs, method, rounds) -> float:
    """The whole training step of ``method`` with the network and the minibatch's BEVs channels-last."""

    class ChannelsLast(DemoBatches):
        def batch(self, indices):
            b = super().batch(indices)
            b["obs"]["bev"] = b["obs"]["bev"].contiguous(memory_format=torch.channels_last)
            return b

    cfg = TrainConfig(steps=10**6, batch_size=p.batch_size, lr=p.lr, progress=False)
    trainers = []
    for fmt, data in ((torch.contiguous_format, DemoBatches(ds)), (torch.channels_last, ChannelsLast(ds))):
        torch.manual_seed(0)
        net = build_network(method, p).to(memory_format=fmt)
        trainers.append(Trainer(net, objective_for(method, net, p), data, cfg, sample_probs=probs))

    def step(tr):
        def one():
            tr.config.steps = tr.step + 1
            tr.run()

        return one

    r = ratio(step(trainers[0]), step(trainers[1]), rounds)[0]
    print(f"  (c) channels-last, the whole {method} training step: {r:.2f}x")
    return r


def proto_unpack(p, ds, rounds=7) -> float:
    """(d) minibatch assembly: the packed cache unpacked by numpy per channel (today) vs one torch gather."""
    table = torch.from_numpy(np.ascontiguousarray(UNPACK_TABLE.T))  # (256, 5)
    packed = ds._packed  # (M, S, S) uint8, the cache
    idx = torch.randint(0, len(ds), (p.batch_size,))

    def current():
        return ds.batch(idx)[0]["bev"]

    def gathered():
        codes = torch.from_numpy(packed[idx.numpy()]).long()  # (B, S, S)
        return table[codes].permute(0, 3, 1, 2)  # (B, 5, S, S) view of (B, S, S, 5): channels-last memory

    same = torch.equal(current(), gathered())
    r = ratio(current, gathered, rounds, 3)[0]
    print(
        f"  (d) minibatch of {p.batch_size}: torch gather (channels-last layout) vs numpy per-channel take: "
        f"{r:.2f}x; bit-identical: {same}"
    )
    return r


def proto_pool(ds, rounds=7) -> float:
    """(f) BEV pooling (192 -> S): numpy reductions over short axes (today) vs ``driving.pooling.pool_packed``
    (strided slices); bit-identical on random bytes and on real views; a whole render; a whole rollout."""
    r = ds.renderer
    rng = np.random.default_rng(0)
    codes = rng.integers(0, 256, size=(4, 192, 192), dtype=np.uint8)
    same = np.array_equal(r._pool(codes), pool_packed(codes, r.pool))
    pose, lights = ds.log.pose[0], r.check_lights(ds.log.light_history(np.array([0]))[0])
    view = r._lut(lights).take(r.raster.code.ravel().take(r._indices(*pose)))  # (192, 192) before pooling
    same &= np.array_equal(r._pool(view), pool_packed(view, r.pool))
    rr = ratio(lambda: r._pool(view), lambda: pool_packed(view, r.pool), rounds, 20)[0]

    def render_strided():
        return r.unpack(
            pool_packed(r._lut(lights).take(r.raster.code.ravel().take(r._indices(*pose))), r.pool)
        )

    assert np.array_equal(render_strided(), r.render(*pose, lights))
    rv = ratio(lambda: r.render(*pose, lights), render_strided, rounds, 20)[0]
    print(
        f"  (f) BEV pooling 192 -> {r.size}: strided slices vs numpy reductions {rr:.2f}x (a whole render "
        f"{rv:.2f}x); bit-identical: {same}"
    )
    return rv


def proto_rollout(p, ds, probs, steps: int = 60, rounds: int = 2) -> dict:
    """(f) in the closed loop: evaluation episodes (``p.final_episodes`` batched, ``steps`` steps) of a BC
    and a DA-IBC agent with the renderer's pooling as today and as ``pool_packed``, alternately; the time per
    episode-step, the policy's share of it, and whether the episodes end identically."""
    from ibc_tutorial.driving import bev
    from ibc_tutorial.driving.env import EnvConfig
    from ibc_tutorial.driving.rollout import RolloutRecording, rollout

    today = bev.BEVRenderer._pool

    def strided(self, codes):
        return pool_packed(codes, self.pool)

    out = {}
    for method in ("bc", "da-ibc"):
        torch.manual_seed(0)
        agent = Agent(method, build_network(method, p).eval(), p, ds.actions, init_weights=probs)
        runs = {"today": [], "strided": []}
        for _ in range(rounds):
            for name, pool in (("today", today), ("strided", strided)):
                bev.BEVRenderer._pool = pool
                policy, spent = agent.policy(0), [0.0]

                def timed(obs, policy=policy, spent=spent):
                    t = time.perf_counter()
                    a = policy(obs)
                    spent[0] += time.perf_counter() - t
                    return a

                t = time.perf_counter()
                env = EnvConfig("town02", p.bev_size, True, steps, light_encoding=p.light_encoding)
                res = rollout(
                    timed, env, p.final_episodes, 1000, record=RolloutRecording(xy=False), show_progress=False
                )
                total = time.perf_counter() - t
                n = sum(r.steps for r in res)
                runs[name].append((total / n, spent[0] / total, [(r.steps, r.distance_m) for r in res]))
        bev.BEVRenderer._pool = today
        same = all(a[2] == b[2] for a, b in zip(runs["today"], runs["strided"], strict=True))
        r = statistics.median(a[0] / b[0] for a, b in zip(runs["today"], runs["strided"], strict=True))
        share_today = statistics.median(a[1] for a in runs["today"])
        share_new = statistics.median(b[1] for b in runs["strided"])
        out[method] = (r, share_today, share_new, same)
        print(
            f"  (f) {method} evaluation, {p.final_episodes} episodes x {steps} steps: strided pooling "
            f"{r:.2f}x per episode-step; the policy's share {share_today:.0%} -> {share_new:.0%}; "
            f"episodes identical: {same}"
        )
    return out


def proto_sim_profile(steps=3000, top=10) -> None:
    """(e) cProfile of environment steps (simulator + BEV + observation), the top costs by own time."""
    from ibc_tutorial.driving.env import make_env

    env = make_env("town02", bev_size=64, routeless=True, max_steps=10**6, light_encoding="flag")
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    acts = rng.uniform([-0.2, 0.2], [0.2, 0.6], size=(steps, 2))
    prof = cProfile.Profile()
    prof.enable()
    for a in acts:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset(seed=int(rng.integers(1000)))
    prof.disable()
    s = io.StringIO()
    st = pstats.Stats(prof, stream=s).sort_stats("tottime")
    total = st.total_tt
    print(f"  (e) {steps} env steps, {total / steps * 1e3:.3f} ms/step under cProfile; top own-time costs:")
    for (file, line, fn), (_cc, nc, tt, _ct, _callers) in sorted(st.stats.items(), key=lambda kv: -kv[1][2])[
        :top
    ]:
        where = file.split("/src/")[-1] if "/src/" in file else file.split("/")[-1]
        print(f"      {tt / total:6.1%}  {nc / steps:5.1f} calls/step  {fn} ({where}:{line})")


def _fused_energy_from_embedding(self, z: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """``EnergyModel.energy_from_embedding`` with the first layer always in its inference form: one batched
    multiply-add ``baddbmm(W_z z + b, y, W_a^T)`` and ReLU, under autograd too (the training form adds a
    broadcast ``y W_a^T`` to ``W_z z + b``: two (B, N, H) temporaries more, and a K = 2 matrix product)."""
    h_obs = self.obs_proj(z)  # (B, H)
    if actions.ndim == 2:
        actions = actions.expand(len(z), -1, -1)  # (B, N, D)
    w_a = self.act_proj.weight.T.expand(len(z), -1, -1)  # (B, D, H)
    h = torch.baddbmm(h_obs[:, None, :], actions, w_a).relu()  # (B, N, H)
    return self.head(h).squeeze(-1)  # (B, N)


def proto_fused_first_layer(p, ds, probs, rounds=5, steps=20) -> dict:
    """(g) the energy head's first layer in training as one batched multiply-add (the form DFO already uses)
    against today's broadcast form: the whole IBC and DA-IBC training step, and how far the two runs are
    apart after ``steps`` steps (not bit for bit: the sums are ordered otherwise)."""
    import types

    out = {}
    cfg = TrainConfig(steps=10**6, batch_size=p.batch_size, lr=p.lr, progress=False)
    for method in ("ibc", "da-ibc"):
        trainers = []
        for fused in (False, True):
            torch.manual_seed(0)
            net = build_network(method, p)
            if fused:
                net.energy_from_embedding = types.MethodType(_fused_energy_from_embedding, net)
            trainers.append(
                Trainer(net, objective_for(method, net, p), DemoBatches(ds), cfg, sample_probs=probs)
            )
        for (
            tr
        ) in trainers:  # the same minibatches and counter-examples: each trainer has its own seeded draws
            tr.config.steps = steps
            tr.run()
        drift = max(
            float((a - b).detach().abs().max())
            for a, b in zip(trainers[0].model.parameters(), trainers[1].model.parameters(), strict=True)
        )

        def step(tr):
            def one():
                tr.config.steps = tr.step + 1
                tr.run()

            return one

        out[method] = ratio(step(trainers[0]), step(trainers[1]), rounds)[0]
        print(
            f"  (g) fused first layer, the whole {method} training step: {out[method]:.2f}x; largest weight "
            f"difference after {steps} steps {drift:.1e}"
        )
    return out
