"""Checkers for ``exercises/06_dfo_inference.ipynb``.

- ``check_dfo_step(fn)``: one iteration of Algorithm 1 of the DA-IBC paper after the energies
  (lines 5 and 7-10), ``fn(samples (N, D), energies (N,), sigma, low, high, generator) -> (N, D)``.
- ``check_select_action(fn)``: the final choice (line 14, or the original IBC's argmax),
  ``fn(samples (N, D), energies (N,), select, generator) -> (D,)``.

The step is random, so the checks are statistical: with many samples, the share of each resampled
value, the spread the noise adds and the clamping at the bounds must match what the algorithm
prescribes; the reader's function must draw its randomness from the generator it is given.
"""

from __future__ import annotations

import math

import torch

from ibc_tutorial.exercises.core import Feedback, correct, hint, run_check


def _out(out, shape: tuple, name: str = "dfo_step") -> torch.Tensor | Feedback:
    if not isinstance(out, torch.Tensor):
        return hint(f"{name} must return a torch.Tensor of shape {shape}, got {type(out).__name__}.")
    if tuple(out.shape) != shape:
        return hint(f"{name} must return a tensor of shape {shape}, got {tuple(out.shape)}: keep N samples of D dimensions.")
    if not torch.isfinite(out).all():
        return hint(f"{name} returned NaN or inf values.")
    return out.detach()


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
        out = _out(fn(samples.clone(), energies.clone(), 0.0, -1.0, 1.0, torch.Generator().manual_seed(0)), (n, 1))
        if isinstance(out, Feedback):
            return out
        values = set(torch.unique(out).tolist())
        if not values <= {0.0, 0.5}:
            return hint("with sigma = 0 every new sample must be a copy of an old one (resampling with replacement, then zero noise); yours are not.")
        share = float((out == 0.0).float().mean())  # expected 0.75
        if abs(share - 0.25) < 0.03:
            return hint("your resampling favours the *high*-energy samples: the probabilities are a softmax of −E (line 5), low energy = likely.")
        if abs(share - 0.5) < 0.03:
            return hint("your new population has the old proportions: resample with replacement in proportion to the softmax probabilities p̃_i (lines 7-8).")
        if abs(share - 0.75) > 0.03:
            return hint(f"after resampling, {share:.0%} of the samples should be copies of the low-energy value where p̃ gives 75 %: check lines 5 and 7-8.")
        # 2. reproducible with the generator
        again = fn(samples.clone(), energies.clone(), 0.0, -1.0, 1.0, torch.Generator().manual_seed(0))
        if not isinstance(again, torch.Tensor) or not torch.equal(again.detach(), out):
            return hint("two calls with equally seeded generators gave different results: draw every random number from the `generator` argument.")
        # 3. the noise: one value, sigma = 0.1 -> spread 0.1
        one = torch.zeros(n, 2)
        out = _out(fn(one.clone(), torch.zeros(n), 0.1, -1.0, 1.0, torch.Generator().manual_seed(1)), (n, 2))
        if isinstance(out, Feedback):
            return out
        std = float(out.std())
        if std < 1e-6:
            return hint("your samples do not move: add Gaussian noise N(0, σ) to every resampled sample (line 9).")
        if abs(std - 0.01) < 0.003:
            return hint("your noise has standard deviation σ², not σ: the paper's N(0, σ) takes σ as the standard deviation.")
        if abs(std - 0.1) > 0.01:
            return hint(f"with σ = 0.1 the new samples spread with standard deviation {std:.3g}; line 9 adds N(0, σ) to each coordinate.")
        # 4. clipping: samples near the upper bound, large noise
        near = torch.full((n, 1), 0.95)
        out = _out(fn(near.clone(), torch.zeros(n), 0.5, -1.0, 1.0, torch.Generator().manual_seed(2)), (n, 1))
        if isinstance(out, Feedback):
            return out
        if float(out.max()) > 1.0 or float(out.min()) < -1.0:
            return hint("some samples leave [low, high]: clip them to the bounds after adding the noise (line 10).")
        at_bound = float((out == 1.0).float().mean())
        if at_bound < 0.3:
            return hint("samples the noise pushes past a bound should be clamped onto it (Algorithm 1 line 10: clip), not redrawn or dropped.")
        return correct("Your step resamples by softmax(−E), adds N(0, σ) and clips, exactly lines 5 and 7-10 of Algorithm 1.")

    return run_check(check, "`dfo_step`")


# --------------------------------------------------------------------------- the final choice
def check_select_action(fn) -> Feedback:
    """Check ``fn(samples, energies, select, generator) -> (D,)`` for "argmax" and "sample"."""

    def check() -> Feedback:
        samples = torch.tensor([[0.1, 0.2], [-0.5, 0.0], [0.9, -0.3]])
        energies = torch.tensor([0.0, math.log(2.0), math.log(4.0)])  # p̃ ∝ 4 : 2 : 1
        a = _out(fn(samples.clone(), energies.clone(), "argmax", torch.Generator().manual_seed(0)), (2,), "select_action")
        if isinstance(a, Feedback):
            return a
        if torch.equal(a, samples[2]):
            return hint('with select = "argmax" return the sample of highest probability p̃, i.e. of *lowest* energy.')
        if not torch.equal(a, samples[0]):
            return hint('with select = "argmax" return the sample with the highest probability p̃ (one of the samples, unchanged).')
        g = torch.Generator().manual_seed(1)
        counts = torch.zeros(3)
        for _ in range(3000):
            s = _out(fn(samples.clone(), energies.clone(), "sample", g), (2,), "select_action")
            if isinstance(s, Feedback):
                return s
            match = (samples == s).all(dim=1)
            if not match.any():
                return hint('with select = "sample" return one of the samples, drawn from Categorical({ỹ_i}, {p̃_i}) (line 14).')
            counts[int(match.float().argmax())] += 1
        share = counts / counts.sum()
        expected = torch.tensor([4.0, 2.0, 1.0]) / 7
        if (share - expected).abs().max() < 0.04:
            return correct("Line 14 of Algorithm 1: you draw ŷ with probabilities p̃ (and the argmax picks the lowest energy).")
        if (share - expected.flip(0)).abs().max() < 0.04:
            return hint("your draws favour the high-energy samples: p̃ is the softmax of −E.")
        if (share - 1 / 3).abs().max() < 0.04:
            return hint("your draws pick every sample equally often: draw with the softmax probabilities p̃.")
        if share[0] > 0.97:
            return hint('with select = "sample" the action must be *drawn* from p̃, not always the most probable one.')
        return hint(f"your draws give the three samples shares {[round(float(x), 2) for x in share]} where p̃ is {[round(float(x), 2) for x in expected]}.")

    return run_check(check, "`select_action`")
