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


def _uses_generator(draw, seeds, name: str, same: str, other: str) -> Feedback | None:
    """``draw(generator)`` three times, the global generator reseeded with ``seeds[i][0]`` before each
    and the passed one seeded with ``seeds[i][1]``: the first two seeds give equally seeded generators
    and must agree (else the hint ``same``), the third a differently seeded one and must not (else
    ``other``). The reader's global random state is restored afterwards."""
    state = torch.random.get_rng_state()
    try:
        outs = []
        for global_seed, seed in seeds:
            torch.manual_seed(global_seed)
            out = draw(torch.Generator().manual_seed(seed))
            outs.append(out.detach() if isinstance(out, torch.Tensor) else out)
    finally:
        torch.random.set_rng_state(state)
    if not all(isinstance(o, torch.Tensor) for o in outs):
        return hint(f"{name} must return a torch.Tensor every time it is called.")
    if not torch.equal(outs[0], outs[1]):
        return hint(same)
    if torch.equal(outs[0], outs[2]):
        return hint(other)
    return None


def _generator_check(fn, samples, energies) -> Feedback | None:
    """Two calls with equally seeded generators, σ > 0, the global generator reseeded differently
    before each, must agree; calls with differently seeded generators must not."""
    return _uses_generator(
        lambda g: fn(samples.clone(), energies.clone(), 0.1, -1.0, 1.0, g),
        ((11, 0), (12, 0), (11, 1)),
        "dfo_step",
        "two calls with equally seeded generators gave different results (with σ > 0): draw every random "
        "number, the resampling's and the noise's, from the `generator` argument.",
        "calls with differently seeded generators gave the same result: draw the random numbers from the "
        "`generator` argument (not from a generator of your own seeded inside the function).",
    )


def _gaussian_check(z: torch.Tensor) -> Feedback | None:
    """The noise divided by its standard deviation (about 40,000 draws) must look like N(0, 1): the
    largest distance between its empirical CDF and the normal one (Kolmogorov-Smirnov) below 0.015 (a
    normal sample of this size exceeds 0.01 about once in a hundred thousand); uniform and Laplace
    noise are near 0.06 and 0.05."""
    z = torch.sort(z.double()).values
    n = len(z)
    cdf = 0.5 * (1 + torch.erf(z / math.sqrt(2)))
    ks = float(torch.maximum(torch.arange(1, n + 1) / n - cdf, cdf - torch.arange(n) / n).max())
    if ks <= 0.015:
        return None
    within = float((z.abs() <= 1).double().mean())
    return hint(
        f"your noise has the right spread but not the shape of a Gaussian: {within:.0%} of it lies within "
        "one σ of the resampled value, where N(0, σ) puts 68 % (line 9 draws normal noise, e.g. torch.randn)."
    )


def _clip_check(fn, n: int) -> Feedback | None:
    """Samples near both bounds of the box [-0.5, 0.75] with σ = 0.5: every output inside the box,
    and the ones pushed out clamped onto the bound they crossed (about 23 % of all at each)."""
    low, high = -0.5, 0.75
    start = torch.where(
        torch.arange(n)[:, None] % 2 == 0, torch.tensor(high - 0.05), torch.tensor(low + 0.05)
    )
    out = _out(fn(start.clone(), torch.zeros(n), 0.5, low, high, torch.Generator().manual_seed(2)), (n, 1))
    if isinstance(out, Feedback):
        return out
    above = float((out > high).double().mean())  # shares of the samples outside the box
    below = float((out < low).double().mean())
    if above + below > 0:
        if float(out.max()) <= 1.0 and float(out.min()) >= -1.0 and above + below > 0.1:
            return hint(
                "with low = -0.5 and high = 0.75 some of your samples leave [low, high]: clip to the bounds "
                "given as arguments, not to [-1, 1]."
            )
        if min(above, below) == 0 and max(above, below) > 0.1:
            side = "upper" if above > 0 else "lower"
            return hint(
                f"your samples stay inside one bound but cross the {side} one: clip at both ends, "
                "[low, high] (line 10)."
            )
        if above + below > 0.1:
            return hint(
                "some samples leave [low, high]: clip them to the bounds after adding the noise (line 10)."
            )
    at_high = float((out == high).double().mean())
    at_low = float((out == low).double().mean())
    if min(at_high, at_low) < 0.15:
        return hint(
            "samples the noise pushes past a bound should be clamped onto it (Algorithm 1 line 10: clip), "
            "not "
            "redrawn, reflected or dropped."
        )
    return None


# --------------------------------------------------------------------------- one DFO iteration
def check_dfo_step(fn) -> Feedback:
    """Check ``fn(samples, energies, sigma, low, high, generator)``: softmax of −E, resample, add noise,
    clip."""

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
                "with sigma = 0 every new sample must be a copy of an old one (resampling with "
                "replacement, then zero noise); yours are not."
            )
        share = float((out == 0.0).float().mean())  # expected 0.75
        if abs(share - 0.25) < 0.03:
            return hint(
                "your resampling favours the *high*-energy samples: the probabilities are a softmax of −E "
                "(line 5), low energy = likely."
            )
        if abs(share - 0.5) < 0.03:
            return hint(
                "your new population has the old proportions: resample with replacement in proportion to "
                "the softmax probabilities p̃_i (lines 7-8)."
            )
        if abs(share - 0.75) > 0.03:
            return hint(
                f"after resampling, {share:.0%} of the samples should be copies of the low-energy value "
                "where p̃ gives 75 %: check lines 5 and 7-8."
            )
        # 2. reproducible with the generator, whatever the global generator does, and with noise
        fb = _generator_check(fn, samples, energies)
        if fb is not None:
            return fb
        # 3. the noise, on a multi-valued 2-D population: three values, p̃ ∝ 4 : 2 : 1, in a box of
        # half-width 1.5 that the noise never reaches (so a σ read relative to the box is told apart)
        values = torch.tensor([[-0.4, -0.4], [0.0, 0.0], [0.4, 0.4]])
        which = torch.arange(n) % 3  # (n,)
        e3 = torch.tensor([0.0, math.log(2.0), math.log(4.0)])[which]  # (n,)
        low, high = -1.5, 1.5
        out = _out(
            fn(values[which].clone(), e3.clone(), 0.1, low, high, torch.Generator().manual_seed(1)), (n, 2)
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
                "the coordinates of a sample move together: draw an independent N(0, σ) for each "
                "coordinate (line 9)."
            )
        std = float(resid.std())
        if abs(std - 0.01) < 0.003:
            return hint(
                "your noise has standard deviation σ², not σ: the paper's N(0, σ) takes σ as the standard "
                "deviation."
            )
        if any(abs(std - 0.1 * width) < 0.01 for width in ((high - low) / 2, high - low)):
            return hint(
                f"with σ = 0.1 in the box [{low}, {high}] your noise spreads with standard deviation "
                f"{std:.3g}: σ is the standard deviation in the action's own units, not a share of the "
                "box's width."
            )
        if abs(std - 0.1) > 0.003:  # 40,000 draws: the standard deviation's own error is about 0.35 %
            return hint(
                f"with σ = 0.1 the new samples spread with standard deviation {std:.3g}; line 9 adds N(0, "
                "σ) to each coordinate."
            )
        # the shares after the spread: noise far wider than σ blurs which value a sample came from
        share = torch.bincount(nearest, minlength=3).float() / n
        if (share - torch.tensor([4.0, 2.0, 1.0]) / 7).abs().max() > 0.03:
            return hint(
                "with σ = 0.1 the new samples sit around the three old values in shares "
                f"{[round(float(x), 2) for x in share]}, "
                "where p̃ gives 0.57, 0.29, 0.14: resample by p̃ first (lines 5, 7-8), then add the noise."
            )
        fb = _gaussian_check(resid.reshape(-1) / std)  # the shape, whatever the spread
        if fb is not None:
            return fb
        # 4. clipping: samples near both bounds of an asymmetric box, large noise
        fb = _clip_check(fn, n)
        if fb is not None:
            return fb
        return correct(
            "Your step resamples by softmax(−E), adds N(0, σ) and clips, exactly lines 5 and 7-10 of "
            "Algorithm 1."
        )

    return run_check(check, "`dfo_step`")


# --------------------------------------------------------------------------- the final choice
SELECT_SAMPLES = torch.tensor([[0.1, 0.2], [-0.5, 0.0], [0.9, -0.3], [0.4, 0.7], [-0.8, -0.6]])
"""Five candidates; the lowest energy is the third's (not the first: "always the first" is wrong)."""
SELECT_ENERGIES = torch.tensor([1.0, 3.0, 0.0, 2.0, 4.0])
"""Energies a nat apart: p̃ ∝ e^{-E}, from 0.64 down to 0.012, so a softmax at another temperature
(e.g. 1.1) shifts the shares by several standard errors of the checker's 8,000 draws."""
SELECT_DRAWS = 8000


def _draw_shares(fn, generator) -> torch.Tensor | Feedback:
    """The shares of the candidates among ``SELECT_DRAWS`` calls with ``select="sample"``."""
    index = {tuple(row): i for i, row in enumerate(SELECT_SAMPLES.tolist())}
    counts = [0] * len(SELECT_SAMPLES)
    for _ in range(SELECT_DRAWS):
        s = fn(SELECT_SAMPLES.clone(), SELECT_ENERGIES.clone(), "sample", generator)
        if not isinstance(s, torch.Tensor) or tuple(s.shape) != (2,):
            return _out(s, (2,), "select_action")
        i = index.get(tuple(s.tolist()))
        if i is None:
            return hint(
                'with select = "sample" return one of the samples, drawn from Categorical({ỹ_i}, {p̃_i}) '
                "(line 14)."
            )
        counts[i] += 1
    return torch.tensor(counts, dtype=torch.float32) / SELECT_DRAWS


def _select_generator_check(fn) -> Feedback | None:
    """Equally seeded generators give the same draws whatever the global generator does; differently
    seeded ones give other draws."""
    return _uses_generator(
        lambda g: torch.stack(
            [fn(SELECT_SAMPLES.clone(), SELECT_ENERGIES.clone(), "sample", g) for _ in range(40)]
        ),
        ((21, 5), (22, 5), (21, 6)),
        "select_action",
        "two runs with equally seeded generators drew different actions: draw from the `generator` "
        "argument (torch.multinomial(..., generator=generator)), so that the choice is reproducible.",
        "runs with differently seeded generators drew the same actions: draw from the `generator` "
        "argument, not from a generator of your own.",
    )


def check_select_action(fn) -> Feedback:
    """Check ``fn(samples, energies, select, generator) -> (D,)`` for "argmax" and "sample"."""

    def check() -> Feedback:
        p = torch.softmax(-SELECT_ENERGIES.double(), dim=0)  # (5,) p̃
        a = _out(
            fn(SELECT_SAMPLES.clone(), SELECT_ENERGIES.clone(), "argmax", torch.Generator().manual_seed(0)),
            (2,),
            "select_action",
        )
        if isinstance(a, Feedback):
            return a
        if torch.equal(a, SELECT_SAMPLES[int(SELECT_ENERGIES.argmax())]):
            return hint(
                'with select = "argmax" return the sample of highest probability p̃, i.e. of *lowest* energy.'
            )
        if not torch.equal(a, SELECT_SAMPLES[int(SELECT_ENERGIES.argmin())]):
            return hint(
                'with select = "argmax" return the sample with the highest probability p̃ (one of the '
                "samples, "
                "unchanged)."
            )
        share = _draw_shares(fn, torch.Generator().manual_seed(1))
        if isinstance(share, Feedback):
            return share
        expected = p.float()
        # Pearson's chi-square over the five candidates (4 degrees of freedom): above 30 happens for a
        # correct draw about once in 200,000 checks; a softmax at temperature 1.1 gives about 60, at 0.9
        # about 75
        chi2 = float((SELECT_DRAWS * (share - expected) ** 2 / expected).sum())
        if chi2 > 30:
            shown = ", ".join(f"{float(x):.3f}" for x in share)
            want = ", ".join(f"{float(x):.3f}" for x in expected)
            if (share - torch.softmax(SELECT_ENERGIES, 0)).abs().max() < 0.02:
                return hint("your draws favour the high-energy samples: p̃ is the softmax of −E.")
            if (share - 0.2).abs().max() < 0.02:
                return hint(
                    "your draws pick every sample equally often: draw with the softmax probabilities p̃."
                )
            if float(share.max()) > 0.97:
                return hint(
                    'with select = "sample" the action must be *drawn* from p̃, not always the most '
                    "probable one."
                )
            return hint(
                f"over {SELECT_DRAWS} draws your shares of the five samples are ({shown}) where p̃ is "
                f"({want}): "
                "more than chance explains. p̃ is exactly softmax(−E), with no temperature or other change."
            )
        fb = _select_generator_check(fn)
        if fb is not None:
            return fb
        return correct(
            "Line 14 of Algorithm 1: you draw ŷ with probabilities p̃ (and the argmax picks the lowest "
            "energy)."
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
        if all(abs(g - w) < 1e-6 for g, w in zip(got, want, strict=False)):
            m = _measured_shallow_share(0.5, 5)
            return correct(
                "Each round multiplies by p(y|x) once more. The library's DFO agrees: Δ = 0.5, k = 5 "
                "rounds, "
                f"2000 calls from a uniform start end in the shallow valley {m:.2f} of the time; you "
                f"predicted {want[1]:.2f}."
            )
        if all(abs(g - (1 - w)) < 1e-6 for g, w in zip(got, want, strict=False)):
            return hint(
                "that is the share of the *deeper* valley: the shallow one, with the higher floor, gets "
                "the smaller share."
            )
        if all(abs(g - expected(d, 1, r)) < 1e-6 for g, (d, k, r) in zip(got, cases, strict=False)):
            return hint(
                "your share does not change with k: each of the k rounds multiplies the population by "
                "p(y|x) once more."
            )
        if all(abs(g - expected(d, k, 1.0)) < 1e-6 for g, (d, k, r) in zip(got, cases, strict=False)):
            return hint(
                "your share ignores r: the initial samples' share multiplies in (the initialisation is a "
                "prior over the valleys)."
            )
        if all(abs(g - r * math.exp(-k * d)) < 1e-6 for g, (d, k, r) in zip(got, cases, strict=False)):
            return hint(
                "normalise over the two valleys: the share is shallow / (shallow + deep), with the deep "
                "valley's weight 1."
            )
        if all(abs(g - expected(d, k, 1.0 / r)) < 1e-6 for g, (d, k, r) in zip(got, cases, strict=True)):
            return hint(
                "r is the *shallow* valley's share of the initial samples over the deep one's: it "
                "multiplies the "
                "shallow valley's weight, not the deep one's."
            )
        # the first case the prediction gets wrong (never one it got right)
        i = next(i for i, (g, w) in enumerate(zip(got, want, strict=True)) if abs(g - w) > 1e-6)
        delta, k, r = cases[i]
        start = (
            "an even start (r = 1)"
            if r == 1.0
            else f"r = {r} (the shallow valley {r} times as full at the start)"
        )
        if k == 1:
            return hint(
                f"with Δ = {delta}, one round and {start} you predict {got[i]:.3g}: one round of resampling "
                "multiplies each valley's weight by its e^{−E}; normalise over the two valleys."
            )
        measured = ""
        if r == 1.0 and (delta, k) == (0.5, 5):
            measured = f"; the library's DFO measures {_measured_shallow_share(0.5, 5):.2f} over 2000 calls"
        return hint(
            f"with Δ = {delta}, k = {k} rounds and {start} you predict {got[i]:.3g}{measured}. Follow the "
            "valleys' weights through one round (resampling multiplies by e^{−E}), then k of them."
        )

    return run_check(check, "`shallow_share`")
