"""Checkers for ``exercises/04_da_ibc_negatives.ipynb``.

- ``check_expert_negatives(fn)``: the DA-IBC counter-example sampler (sec. 2.4 of the DA-IBC
  paper), ``fn(expert_actions (M, D), batch_size, n_neg, sigma, generator) -> (B, N, D)``.
- ``check_grid_nll(fn)``: the held-out NLL of chapter 04, with Z(x) summed over a grid,
  ``fn(pos_energy (B,), grid_energy (B, G), cell_volume) -> (B,)``.

The sampler is random, so its checker tests properties: the shape, draws from the given actions
(with replacement, independently per sample), the noise's scale (mean and variance of the
counter-examples against the expert set's plus σ²) and the use of the generator.
"""

from __future__ import annotations

import math

import torch

from ibc_tutorial.exercises.core import Feedback, correct, hint, run_check

_EXPERT = torch.tensor([[0.0, 0.4], [0.1, 0.5], [-0.5, 0.3], [0.4, -0.6], [0.0, 0.45]])


def _gen(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def _shape_feedback(out, want: tuple) -> Feedback | None:
    if not isinstance(out, torch.Tensor):
        return hint(f"expert_negatives must return a torch.Tensor of shape (batch_size, n_neg, D), got {type(out).__name__}.")
    if tuple(out.shape) != want:
        return hint(f"expert_negatives must return shape (batch_size, n_neg, D) = {want}, got {tuple(out.shape)}.")
    if not torch.isfinite(out).all():
        return hint("expert_negatives returned NaN or infinite values.")
    return None


def check_expert_negatives(fn) -> Feedback:
    """Check the DA-IBC sampler ``fn(expert_actions, batch_size, n_neg, sigma, generator)``."""

    def check() -> Feedback:
        out = fn(_EXPERT.clone(), 4, 3, 0.1, _gen(0))
        bad = _shape_feedback(out, (4, 3, 2))
        if bad:
            return bad
        # more counter-examples than expert actions: with replacement
        try:
            many = fn(_EXPERT[:3].clone(), 2, 50, 0.0, _gen(2))
        except Exception as exc:  # e.g. randperm / sampling without replacement
            return hint(f"drawing 50 counter-examples from 3 expert actions failed ({type(exc).__name__}): the paper samples *with replacement*.")
        bad = _shape_feedback(many, (2, 50, 2))
        if bad:
            return bad
        # sigma = 0: copies of the given expert actions
        copies = fn(_EXPERT.clone(), 16, 40, 0.0, _gen(1))
        bad = _shape_feedback(copies, (16, 40, 2))
        if bad:
            return bad
        match = (copies.reshape(-1, 1, 2) == _EXPERT[None]).all(-1).any(-1)  # (B*N,)
        if not match.all():
            return hint("with sigma = 0 every counter-example should be exactly one of the expert actions you were given: draw rows of `expert_actions` (then add the noise).")
        # uniform over the set, independently per sample
        pool = torch.linspace(-1, 1, 4)[:, None]  # (4, 1)
        draws = fn(pool.clone(), 200, 100, 0.0, _gen(3))
        bad = _shape_feedback(draws, (200, 100, 1))
        if bad:
            return bad
        if all(torch.equal(draws[0], draws[i]) for i in range(1, 5)):
            return hint("every sample of the batch gets the same counter-examples: draw a fresh set for each sample.")
        freq = torch.stack([(draws == v).float().mean() for v in pool[:, 0]])
        if (freq - 0.25).abs().max() > 0.03:
            return hint("some expert actions are drawn far more often than others: draw each one with equal probability (uniformly over the M rows).")
        # the noise: mean and variance = expert set's + sigma^2
        sigma = 0.1
        big = fn(_EXPERT.clone(), 400, 250, sigma, _gen(4)).reshape(-1, 2).double()
        mu = _EXPERT.double().mean(0)
        var0 = _EXPERT.double().var(0, unbiased=False)
        var = big.var(0)
        if ((big.mean(0) - mu).abs() > 0.01).any():
            return hint("the counter-examples are not centred on the expert actions: the noise should have mean 0.")
        if ((var - (var0 + sigma**2)).abs() / (var0 + sigma**2) > 0.05).any():
            if (big.reshape(-1, 1, 2) == _EXPERT.double()[None]).all(-1).any(-1).all():
                return hint("no noise was added: each counter-example is an expert action plus N(0, σ²I).")
            if ((var - (var0 + sigma**4)).abs() / (var0 + sigma**4) < 0.05).all() or ((var - (var0 + sigma)).abs() / (var0 + sigma) < 0.05).all():
                return hint("the noise has the wrong scale: σ is the standard deviation of N(0, σ²I), so multiply standard-normal draws by σ.")
            return hint(f"the counter-examples' variance per dimension is {var.tolist()} but should be the expert set's plus σ² = {(var0 + sigma**2).tolist()}.")
        # reproducible with the generator
        a = fn(_EXPERT.clone(), 3, 5, 0.2, _gen(7))
        b = fn(_EXPERT.clone(), 3, 5, 0.2, _gen(7))
        if not torch.equal(a, b):
            return hint("two calls with equally seeded generators gave different counter-examples: pass `generator=generator` to every random draw.")
        return correct("Your sampler draws expert actions with replacement, per sample, and adds N(0, σ²I): DA-IBC's counter-examples.")

    return run_check(check, "`expert_negatives`")


# --------------------------------------------------------------------------- held-out grid NLL
def _nll_ref(pos, grid_e, cell) -> torch.Tensor:
    return pos.double() + torch.logsumexp(-grid_e.double(), dim=1) + math.log(cell)


def check_grid_nll(fn) -> Feedback:
    """Check ``fn(pos_energy (B,), grid_energy (B, G), cell_volume) -> (B,)`` against the chapter's formula."""

    def check() -> Feedback:
        g = _gen(0)
        pos, grid_e, cell = 3 * torch.randn(6, generator=g), 3 * torch.randn(6, 121, generator=g), (2 / 10) ** 2
        out = fn(pos.clone(), grid_e.clone(), cell)
        if not isinstance(out, torch.Tensor):
            return hint(f"grid_nll must return a torch.Tensor of shape (B,), got {type(out).__name__}.")
        if out.ndim == 0:
            return hint("grid_nll must return one NLL per sample, shape (B,): leave the averaging to the caller.")
        if tuple(out.shape) != (6,):
            return hint(f"grid_nll must return shape (B,) = (6,), got {tuple(out.shape)}.")
        ref = _nll_ref(pos, grid_e, cell)
        if not _close(out, ref):
            lse = torch.logsumexp(-grid_e.double(), 1)
            mistakes = [
                (pos.double() + lse, "the cell area: Z(x) is an integral over the box, so each grid point stands for its cell's area ΔA."),
                (pos.double() + lse - math.log(cell), "the cell area's sign: Z(x) ≈ Σ e^(−E) · ΔA, so log Z gains + log ΔA."),
                (pos.double() + lse - math.log(121) + math.log(cell), "Z(x): it *sums* e^(−E) over the grid points (times ΔA), it does not average them."),
                (-pos.double() + torch.logsumexp(grid_e.double(), 1) + math.log(cell), "the sign of the energies: p(y|x) = e^(−E(x, y)) / Z(x)."),
                (-(pos.double() + lse + math.log(cell)), "the overall sign: this is the *negative* log-likelihood."),
            ]
            for value, what in mistakes:
                if _close(out, value):
                    return hint(f"close, but check {what}")
            return hint(f"your NLL of the first sample is {float(out[0]):.4g} where −log p = E + log Σ e^(−E_g) + log ΔA gives {float(ref[0]):.4g}.")
        out2 = fn(pos + 1000, grid_e + 1000, cell)
        if not isinstance(out2, torch.Tensor) or not _close(out2, ref, rtol=1e-3, atol=1e-2):
            return hint("your NLL breaks down when the energies are around 1000 (e^(−1000) underflows): use torch.logsumexp.")
        return correct("Your grid NLL is the model's normalised density at the expert's action, Z computed on the grid.")

    return run_check(check, "`grid_nll`")


def _close(a, b, rtol: float = 1e-4, atol: float = 1e-4) -> bool:
    a = torch.as_tensor(a, dtype=torch.float64)
    b = torch.as_tensor(b, dtype=torch.float64)
    return a.shape == b.shape and bool(torch.isfinite(a).all()) and bool(torch.allclose(a, b, rtol=rtol, atol=atol))
