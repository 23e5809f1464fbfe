"""Checkers for ``exercises/06_dfo_inference.ipynb``.

- ``check_dfo_step(fn)``: one iteration of Algorithm 1 of the DA-IBC paper after the energies
  (lines 5 and 7-10), ``fn(samples (N, D), energies (N,), sigma, low, high, generator) -> (N, D)``.
- ``check_select_action(fn)``: the final choice (line 14, or the original IBC's argmax),
  ``fn(samples (N, D), energies (N,), select, generator) -> (D,)``.
- ``check_shallow_share(fn)``: understanding the chapter's finding, ``fn(delta, k, r) -> float``:
  the share of calls DFO ends in the shallower of two valleys after k rounds (p(y|x)^k).

The step is random, so the checks are statistical: with many samples, the share of each resampled
value, the spread the noise adds and the clamping at the bounds must match what the algorithm
prescribes; the reader's function must draw its randomness from the generator it is given.
"""

from __future__ import annotations

import math

import torch

from ibc_tutorial.exercises.core import Feedback, correct, hint, run_check, tensor_answer
from ibc_tutorial.optimizers.dfo import DFOConfig, dfo


def _out(out, shape: tuple, name: str = "dfo_step") -> torch.Tensor | Feedback:
    """The answer, or a hint (``core.tensor_answer``)."""
    return tensor_answer(out, name, shape, ": keep N samples of D dimensions")


# --------------------------------------------------------------------------- one DFO iteration
def check_dfo_step(fn) -> Feedback:
    """Check ``fn(samples, energies, sigma, low, high, generator)``: softmax of −E, resample, add noise, clip."""

    def check() -> Feedback:
        n = 20000
        # 1. resampling proportions (sigma = 0): two values, energies 0 and log 3 -> p ∝ 1 and 1/3
        samples = torch.zeros(n, 1)
        samples[n // 2 :] = 0.5
        energies = torch.zeros(n)
        energies[n // 2 :] = math.log(3.0)
        out = _out(
            fn(samples.clone(), energies.clone(), 0.0, -1.0, 1.0, torch.Generator().manual_seed(0)), (n, 1)
        )
        if isinstance(out, Feedback):
            return out
        values = set(torch.unique(out).tolist())
        if not values <= {0.0, 0.5}:
            return hint(
                "with sigma = 0 every new sample must be a copy of an old one (resampling with replacement, then zero noise); yours are not."
            )
        share = float((out == 0.0).float().mean())  # expected 0.75
        if abs(share - 0.25) < 0.03:
            return hint(
                "your resampling favours the *high*-energy samples: the probabilities are a softmax of −E (line 5), low energy = likely."
            )
        if abs(share - 0.5) < 0.03:
            return hint(
                "your new population has the old proportions: resample with replacement in proportion to the softmax probabilities p̃_i (lines 7-8)."
            )
        if abs(share - 0.75) > 0.03:
            return hint(
                f"after resampling, {share:.0%} of the samples should be copies of the low-energy value where p̃ gives 75 %: check lines 5 and 7-8."
            )
        # 2. reproducible with the generator
        again = fn(samples.clone(), energies.clone(), 0.0, -1.0, 1.0, torch.Generator().manual_seed(0))
        if not isinstance(again, torch.Tensor) or not torch.equal(again.detach(), out):
            return hint(
                "two calls with equally seeded generators gave different results: draw every random number from the `generator` argument."
            )
        # 3. the noise, on a multi-valued 2-D population: three values, p̃ ∝ 4 : 2 : 1
        values = torch.tensor([[-0.4, -0.4], [0.0, 0.0], [0.4, 0.4]])
        which = torch.arange(n) % 3  # (n,)
        e3 = torch.tensor([0.0, math.log(2.0), math.log(4.0)])[which]  # (n,)
        out = _out(
            fn(values[which].clone(), e3.clone(), 0.1, -1.0, 1.0, torch.Generator().manual_seed(1)), (n, 2)
        )
        if isinstance(out, Feedback):
            return out
        nearest = (out[:, None, :] - values[None]).norm(dim=-1).argmin(dim=1)  # (n,) the value each came from
        resid = out - values[nearest]  # (n, 2) the noise added
        if float(resid.abs().max()) < 1e-9:
            return hint(
                "your samples do not move: add Gaussian noise N(0, σ) to every resampled sample (line 9)."
            )
        if len(torch.unique(out, dim=0)) < 0.99 * n:
            return hint(
                "your new population holds exact copies of one another: add the noise *after* resampling "
                "(line 9 follows lines 7-8), a fresh draw for every resampled sample."
            )
        if float((resid[:, 0] - resid[:, 1]).abs().max()) < 1e-9:  # the same draw in both coordinates
            return hint(
                "the coordinates of a sample move together: draw an independent N(0, σ) for each coordinate (line 9)."
            )
        share = torch.bincount(nearest, minlength=3).float() / n
        if (share - torch.tensor([4.0, 2.0, 1.0]) / 7).abs().max() > 0.03:
            return hint(
                f"with σ = 0.1 the new samples sit around the three old values in shares {[round(float(x), 2) for x in share]}, "
                "where p̃ gives 0.57, 0.29, 0.14: resample by p̃ first (lines 5, 7-8), then add the noise."
            )
        std = float(resid.std())
        if abs(std - 0.01) < 0.003:
            return hint(
                "your noise has standard deviation σ², not σ: the paper's N(0, σ) takes σ as the standard deviation."
            )
        if abs(std - 0.1) > 0.01:
            return hint(
                f"with σ = 0.1 the new samples spread with standard deviation {std:.3g}; line 9 adds N(0, σ) to each coordinate."
            )
        # 4. clipping: samples near the upper bound, large noise
        near = torch.full((n, 1), 0.95)
        out = _out(fn(near.clone(), torch.zeros(n), 0.5, -1.0, 1.0, torch.Generator().manual_seed(2)), (n, 1))
        if isinstance(out, Feedback):
            return out
        if float(out.max()) > 1.0 or float(out.min()) < -1.0:
            return hint(
                "some samples leave [low, high]: clip them to the bounds after adding the noise (line 10)."
            )
        at_bound = float((out == 1.0).float().mean())
        if at_bound < 0.3:
            return hint(
                "samples the noise pushes past a bound should be clamped onto it (Algorithm 1 line 10: clip), not redrawn or dropped."
            )
        return correct(
            "Your step resamples by softmax(−E), adds N(0, σ) and clips, exactly lines 5 and 7-10 of Algorithm 1."
        )

    return run_check(check, "`dfo_step`")


# --------------------------------------------------------------------------- the final choice
def check_select_action(fn) -> Feedback:
    """Check ``fn(samples, energies, select, generator) -> (D,)`` for "argmax" and "sample"."""

    def check() -> Feedback:
        samples = torch.tensor([[0.1, 0.2], [-0.5, 0.0], [0.9, -0.3]])
        energies = torch.tensor([0.0, math.log(2.0), math.log(4.0)])  # p̃ ∝ 4 : 2 : 1
        a = _out(
            fn(samples.clone(), energies.clone(), "argmax", torch.Generator().manual_seed(0)),
            (2,),
            "select_action",
        )
        if isinstance(a, Feedback):
            return a
        if torch.equal(a, samples[2]):
            return hint(
                'with select = "argmax" return the sample of highest probability p̃, i.e. of *lowest* energy.'
            )
        if not torch.equal(a, samples[0]):
            return hint(
                'with select = "argmax" return the sample with the highest probability p̃ (one of the samples, unchanged).'
            )
        g = torch.Generator().manual_seed(1)
        counts = torch.zeros(3)
        for _ in range(3000):
            s = _out(fn(samples.clone(), energies.clone(), "sample", g), (2,), "select_action")
            if isinstance(s, Feedback):
                return s
            match = (samples == s).all(dim=1)
            if not match.any():
                return hint(
                    'with select = "sample" return one of the samples, drawn from Categorical({ỹ_i}, {p̃_i}) (line 14).'
                )
            counts[int(match.float().argmax())] += 1
        share = counts / counts.sum()
        expected = torch.tensor([4.0, 2.0, 1.0]) / 7
        if (share - expected).abs().max() < 0.04:
            return correct(
                "Line 14 of Algorithm 1: you draw ŷ with probabilities p̃ (and the argmax picks the lowest energy)."
            )
        if (share - expected.flip(0)).abs().max() < 0.04:
            return hint("your draws favour the high-energy samples: p̃ is the softmax of −E.")
        if (share - 1 / 3).abs().max() < 0.04:
            return hint("your draws pick every sample equally often: draw with the softmax probabilities p̃.")
        if share[0] > 0.97:
            return hint(
                'with select = "sample" the action must be *drawn* from p̃, not always the most probable one.'
            )
        return hint(
            f"your draws give the three samples shares {[round(float(x), 2) for x in share]} where p̃ is {[round(float(x), 2) for x in expected]}."
        )

    return run_check(check, "`select_action`")


# --------------------------------------------------------------------------- understanding: p(y|x)^k
def _measured_shallow_share(delta: float, k: int, n_calls: int = 2000) -> float:
    """What the library's DFO does: share of ``n_calls`` calls (uniform start, 256 samples, k rounds)
    ending in the shallower of two equal-shaped valleys ``delta`` nats apart."""

    def energy(y):  # (B, N, 1) -> (B, N): floors at −0.5 (0) and +0.5 (delta), width 0.02
        y = y[..., 0]
        return torch.minimum((y + 0.5) ** 2 / 0.02, (y - 0.5) ** 2 / 0.02 + delta)

    a = dfo(
        energy,
        torch.zeros(1, 1),
        DFOConfig(n_samples=256, n_iters=k, init="uniform"),
        n_obs=n_calls,
        generator=torch.Generator().manual_seed(0),
    )  # (n_calls, 1)
    return float((a[:, 0] > 0).float().mean())


def check_shallow_share(fn) -> Feedback:
    """Check ``fn(delta, k, r)``: the share of DFO calls ending in the shallower valley after k rounds.

    Two valleys of the same shape whose floors differ by ``delta`` nats; ``r`` is the shallow
    valley's share of the initial samples over the deep one's. Chapter 06's argument: each round
    multiplies the population by p(y|x), so the share is r e^{−kΔ} / (1 + r e^{−kΔ}). The checker
    compares the reader's prediction with that and, for r = 1, with what ``dfo`` measures.
    """

    def expected(delta, k, r):
        x = r * math.exp(-k * delta)
        return x / (1 + x)

    def check() -> Feedback:
        cases = [(0.5, 1, 1.0), (0.5, 5, 1.0), (1.0, 3, 1.0), (0.5, 2, 3.0), (0.2, 4, 0.5), (2.0, 1, 1.0)]
        got = []
        for delta, k, r in cases:
            v = fn(delta, k, r)
            if isinstance(v, torch.Tensor) and v.numel() == 1:
                v = float(v)
            if not isinstance(v, (int, float)) or not math.isfinite(v):
                return hint(f"shallow_share must return one number (a share between 0 and 1), got {v!r}.")
            got.append(float(v))
        if any(not 0.0 <= v <= 1.0 for v in got):
            return hint(
                "a share lies between 0 and 1: normalise over the two valleys (shallow / (shallow + deep))."
            )
        want = [expected(*c) for c in cases]
        if all(abs(g - w) < 1e-6 for g, w in zip(got, want)):
            m = _measured_shallow_share(0.5, 5)
            return correct(
                f"Each round multiplies by p(y|x) once more. The library's DFO agrees: Δ = 0.5, k = 5 rounds, "
                f"2000 calls from a uniform start end in the shallow valley {m:.2f} of the time; you predicted {want[1]:.2f}."
            )
        if all(abs(g - (1 - w)) < 1e-6 for g, w in zip(got, want)):
            return hint(
                "that is the share of the *deeper* valley: the shallow one, with the higher floor, gets the smaller share."
            )
        if all(abs(g - expected(d, 1, r)) < 1e-6 for g, (d, k, r) in zip(got, cases)):
            return hint(
                "your share does not change with k: each of the k rounds multiplies the population by p(y|x) once more."
            )
        if all(abs(g - expected(d, k, 1.0)) < 1e-6 for g, (d, k, r) in zip(got, cases)):
            return hint(
                "your share ignores r: the initial samples' share multiplies in (the initialisation is a prior over the valleys)."
            )
        if all(abs(g - r * math.exp(-k * d)) < 1e-6 for g, (d, k, r) in zip(got, cases)):
            return hint(
                "normalise over the two valleys: the share is shallow / (shallow + deep), with the deep valley's weight 1."
            )
        if abs(got[0] - want[0]) > 1e-6:  # Δ = 0.5, k = 1, r = 1
            return hint(
                f"with Δ = 0.5 and one round from an even start, DFO is an importance sampler of p(y|x) itself: "
                f"the shallow valley gets 1 / (1 + e^0.5), not {got[0]:.3g}."
            )
        m = _measured_shallow_share(0.5, 5)
        return hint(
            f"with Δ = 0.5 and k = 5 you predict {got[1]:.3g}; the library's DFO measures {m:.2f} over 2000 calls. "
            "Follow the valleys' weights through one round (resampling multiplies by e^{−E}), then k of them."
        )

    return run_check(check, "`shallow_share`")
