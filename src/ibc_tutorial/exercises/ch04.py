"""Checkers for ``exercises/04_da_ibc_negatives.ipynb``.

- ``check_expert_negatives(fn)``: the DA-IBC counter-example sampler (sec. 2.4 of the DA-IBC
  paper), ``fn(expert_actions (M, D), batch_size, n_neg, sigma, generator) -> (B, N, D)``.
- ``check_grid_nll(fn)``: the held-out NLL of chapter 04, with Z(x) summed over a grid,
  ``fn(pos_energy (B,), grid_energy (B, G), cell_volume) -> (B,)``.
- ``check_predicted_shares(fn)``: the chapter's finding, the tilt of a DA-IBC landscape:
  ``fn(valid_actions (K, 2), expert_actions (M, 2), sigma) -> (K,)`` shares ∝ 1/q.

The sampler is random, so its checker tests properties: the shape, draws from the given actions
(with replacement, independently per sample), the noise's scale (mean and variance of the
counter-examples against the expert set's plus σ²), its Gaussian shape and independence per
coordinate, no clipping to the box, and the use of the generator.
"""

from __future__ import annotations

import math

import torch

from ibc_tutorial.exercises.core import (
    Feedback,
    close,
    correct,
    hint,
    mistake_hint,
    run_check,
    unnormalised_hint,
)

_EXPERT = torch.tensor([[0.0, 0.4], [0.1, 0.5], [-0.5, 0.3], [0.4, -0.6], [0.0, 0.45]])


def _gen(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def _shape_feedback(out, want: tuple) -> Feedback | None:
    if not isinstance(out, torch.Tensor):
        return hint(
            "expert_negatives must return a torch.Tensor of shape (batch_size, n_neg, D), got "
            f"{type(out).__name__}."
        )
    if tuple(out.shape) != want:
        return hint(
            f"expert_negatives must return shape (batch_size, n_neg, D) = {want}, got {tuple(out.shape)}."
        )
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
            return hint(
                f"drawing 50 counter-examples from 3 expert actions failed ({type(exc).__name__}): the "
                "paper samples *with replacement*."
            )
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
            return hint(
                "with sigma = 0 every counter-example should be exactly one of the expert actions you were "
                "given: draw rows of `expert_actions` (then add the noise)."
            )
        # uniform over the set, independently per sample
        pool = torch.linspace(-1, 1, 4)[:, None]  # (4, 1)
        draws = fn(pool.clone(), 200, 100, 0.0, _gen(3))
        bad = _shape_feedback(draws, (200, 100, 1))
        if bad:
            return bad
        if all(torch.equal(draws[0], draws[i]) for i in range(1, 5)):
            return hint(
                "every sample of the batch gets the same counter-examples: draw a fresh set for each sample."
            )
        freq = torch.stack([(draws == v).float().mean() for v in pool[:, 0]])
        if (freq - 0.25).abs().max() > 0.03:
            return hint(
                "some expert actions are drawn far more often than others: draw each one with equal "
                "probability (uniformly over the M rows)."
            )
        # every row counts, a repeated action as often as it stands in the set, beyond the first B rows
        repeated = torch.tensor([[-1.0], [-1.0], [-1.0], [1.0]])  # (4, 1): full brake three times of four
        draws = fn(repeated.clone(), 200, 100, 0.0, _gen(5))
        bad = _shape_feedback(draws, (200, 100, 1))
        if bad:
            return bad
        if abs(float((draws == -1.0).float().mean()) - 0.75) > 0.03:
            return hint(
                "an action that stands in `expert_actions` three times of four must be drawn three times "
                "of four: draw rows of the set with equal probability, repeated actions included (as the "
                "minibatch holds them), not its distinct values."
            )
        many_rows = torch.linspace(-1, 1, 40)[:, None]  # (40, 1): more expert actions than samples
        draws = fn(many_rows.clone(), 2, 500, 0.0, _gen(6))
        bad = _shape_feedback(draws, (2, 500, 1))
        if bad:
            return bad
        if len(torch.unique(draws)) < len(many_rows):
            return hint(
                f"from {len(many_rows)} expert actions and a batch of 2, your counter-examples use "
                f"{len(torch.unique(draws))} of them: draw from all M rows of `expert_actions`, whatever "
                "batch_size is."
            )
        # the noise: mean and variance = expert set's + sigma^2
        sigma = 0.1
        big = fn(_EXPERT.clone(), 400, 250, sigma, _gen(4)).reshape(-1, 2).double()
        mu = _EXPERT.double().mean(0)
        var0 = _EXPERT.double().var(0, unbiased=False)
        var = big.var(0)
        if ((big.mean(0) - mu).abs() > 0.01).any():
            return hint(
                "the counter-examples are not centred on the expert actions: the noise should have mean 0."
            )
        if ((var - (var0 + sigma**2)).abs() / (var0 + sigma**2) > 0.05).any():
            if (big.reshape(-1, 1, 2) == _EXPERT.double()[None]).all(-1).any(-1).all():
                return hint("no noise was added: each counter-example is an expert action plus N(0, σ²I).")
            if ((var - (var0 + sigma**4)).abs() / (var0 + sigma**4) < 0.05).all() or (
                (var - (var0 + sigma)).abs() / (var0 + sigma) < 0.05
            ).all():
                return hint(
                    "the noise has the wrong scale: σ is the standard deviation of N(0, σ²I), so multiply "
                    "standard-normal draws by σ."
                )
            return hint(
                f"the counter-examples' variance per dimension is {var.tolist()} but should be the expert "
                f"set's plus σ² = {(var0 + sigma**2).tolist()}."
            )
        # the noise's shape: Gaussian and independent per coordinate (one action, many draws)
        one = torch.tensor([[0.2, -0.3]])
        noise = (
            fn(one.clone(), 500, 200, sigma, _gen(5)).reshape(-1, 2).double() - one.double()
        ) / sigma  # (100000, 2) in units of σ
        within1 = float((noise.abs() <= 1).double().mean())  # N(0, 1): 0.683
        within2 = float((noise.abs() <= 2).double().mean())  # N(0, 1): 0.954
        kurtosis = float((noise**4).mean() / (noise**2).mean() ** 2)  # N(0, 1): 3
        if abs(within1 - 0.6827) > 0.01 or abs(within2 - 0.9545) > 0.01 or abs(kurtosis - 3) > 0.15:
            return hint(
                f"the noise has the right variance but not the Gaussian shape: {within1:.0%} of it lies "
                "within one σ, "
                f"where N(0, σ²) puts 68 % (its kurtosis is {kurtosis:.2f}, a Gaussian's 3). Draw it with "
                "torch.randn, times σ."
            )
        if abs(float(torch.corrcoef(noise.T)[0, 1])) > 0.02:
            return hint(
                "the noise of the two coordinates is correlated: N(0, σ²I) draws every coordinate "
                "independently."
            )
        # no clipping: near the edge of the box, some counter-examples must fall outside it
        edge = torch.tensor([[0.95, -0.95], [1.0, -1.0]])
        near = fn(edge.clone(), 100, 50, 0.3, _gen(6)).double()  # (100, 50, 2)
        if not (near.abs() > 1).any() or (near.abs() == 1).double().mean() > 0.01:
            return hint(
                "your counter-examples stay inside [-1, 1] (or pile up on its edges): do not clip them. "
                "The chapter explains why: "
                "clipping stacks counter-examples exactly on the bounds, where the expert itself often acts."
            )
        # reproducible with the generator
        a = fn(_EXPERT.clone(), 3, 5, 0.2, _gen(7))
        b = fn(_EXPERT.clone(), 3, 5, 0.2, _gen(7))
        if not torch.equal(a, b):
            return hint(
                "two calls with equally seeded generators gave different counter-examples: pass "
                "`generator=generator` to every random draw."
            )
        return correct(
            "Your sampler draws expert actions with replacement, per sample, and adds N(0, σ²I): DA-IBC's "
            "counter-examples."
        )

    return run_check(check, "`expert_negatives`")


# --------------------------------------------------------------------------- held-out grid NLL
def _nll_ref(pos, grid_e, cell) -> torch.Tensor:
    return pos.double() + torch.logsumexp(-grid_e.double(), dim=1) + math.log(cell)


def check_grid_nll(fn) -> Feedback:
    """Check ``fn(pos_energy (B,), grid_energy (B, G), cell_volume) -> (B,)`` against the chapter's
    formula."""

    def check() -> Feedback:
        g = _gen(0)
        pos, grid_e, cell = (
            3 * torch.randn(6, generator=g),
            3 * torch.randn(6, 121, generator=g),
            (2 / 10) ** 2,
        )
        out = fn(pos.clone(), grid_e.clone(), cell)
        if not isinstance(out, torch.Tensor):
            return hint(f"grid_nll must return a torch.Tensor of shape (B,), got {type(out).__name__}.")
        if out.ndim == 0:
            return hint(
                "grid_nll must return one NLL per sample, shape (B,): leave the averaging to the caller."
            )
        if tuple(out.shape) != (6,):
            return hint(f"grid_nll must return shape (B,) = (6,), got {tuple(out.shape)}.")
        ref = _nll_ref(pos, grid_e, cell)
        if not close(out, ref):
            lse = torch.logsumexp(-grid_e.double(), 1)
            mistakes = [
                (
                    pos.double() + lse,
                    "the cell area: Z(x) is an integral over the box, so each grid point stands for its "
                    "cell's area ΔA.",
                ),
                (
                    pos.double() + lse - math.log(cell),
                    "the cell area's sign: Z(x) ≈ Σ e^(−E) · ΔA, so log Z gains + log ΔA.",
                ),
                (
                    pos.double() + lse - math.log(121) + math.log(cell),
                    "Z(x): it *sums* e^(−E) over the grid points (times ΔA), it does not average them.",
                ),
                (
                    -pos.double() + torch.logsumexp(grid_e.double(), 1) + math.log(cell),
                    "the sign of the energies: p(y|x) = e^(−E(x, y)) / Z(x).",
                ),
                (
                    -(pos.double() + lse + math.log(cell)),
                    "the overall sign: this is the *negative* log-likelihood.",
                ),
                (
                    pos.double()
                    + torch.logsumexp(torch.cat([-pos.double()[:, None], -grid_e.double()], 1), 1)
                    + math.log(cell),
                    "what Z(x) sums over: the grid points alone, not the expert's action as well (the grid "
                    "already covers the box).",
                ),
            ]
            if (mistake := mistake_hint(out, mistakes)) is not None:
                return mistake
            worst = int((out.double() - ref).abs().argmax())  # the sample the reader's NLL misses most
            return hint(
                f"your NLL of sample {worst} is {float(out[worst]):.4g} where −log p = E + log Σ e^(−E_g) + "
                f"log ΔA gives {float(ref[worst]):.4g}."
            )
        other_cell = (2 / 40) ** 2  # a finer grid: the cell area is an argument, not the chapter's number
        out_cell = fn(pos.clone(), grid_e.clone(), other_cell)
        if not isinstance(out_cell, torch.Tensor) or not close(out_cell, _nll_ref(pos, grid_e, other_cell)):
            return hint(
                f"right for a cell area of {cell:g}, wrong for {other_cell:g}: use the `cell_volume` you are "
                "given."
            )
        out2 = fn(pos + 1000, grid_e + 1000, cell)
        if not isinstance(out2, torch.Tensor) or not close(out2, ref, rtol=1e-3, atol=1e-2):
            return hint(
                "your NLL breaks down when the energies are around 1000 (e^(−1000) underflows): use "
                "torch.logsumexp."
            )
        return correct(
            "Your grid NLL is the model's normalised density at the expert's action, Z computed on the grid."
        )

    return run_check(check, "`grid_nll`")


# --------------------------------------------------------------------------- the tilt of a DA-IBC landscape
def _junction_like() -> torch.Tensor:
    """(M, 2) expert actions shaped like the chapter's: a crowded cruise cloud and two rare turns."""
    g = _gen(11)
    cruise = torch.tensor([0.0, 0.35]) + 0.05 * torch.randn(300, 2, generator=g, dtype=torch.float64)
    left = torch.tensor([-0.7, 0.1]) + 0.02 * torch.randn(30, 2, generator=g, dtype=torch.float64)
    right = torch.tensor([0.7, 0.1]) + 0.02 * torch.randn(15, 2, generator=g, dtype=torch.float64)
    return torch.cat([cruise, left, right])


def _q(points: torch.Tensor, actions: torch.Tensor, bandwidth: float) -> torch.Tensor:
    """Density of expert actions blurred by N(0, bandwidth² I) at points (K, 2) -> (K,), float64."""
    sq = ((points.double()[:, None, :] - actions.double()[None, :, :]) ** 2).sum(-1)  # (K, M)
    return torch.exp(-sq / (2 * bandwidth**2)).mean(1) / (2 * math.pi * bandwidth**2)


def _normalise(v: torch.Tensor) -> torch.Tensor:
    return v / v.sum()


def check_predicted_shares(fn) -> Feedback:
    """Check ``fn(valid_actions (K, 2), expert_actions (M, 2), sigma) -> (K,)``: the share of p_θ's mass
    a DA-IBC model puts near each of K valid actions the expert takes equally often, as the
    density-ratio argument predicts: e^(−E) ∝ p(y|x) / q(y), q the expert actions blurred by σ."""

    def check() -> Feedback:
        actions = _junction_like()
        modes = torch.tensor([[-0.7, 0.1], [0.0, 0.35], [0.7, 0.1]], dtype=torch.float64)
        out = fn(modes.clone(), actions.clone(), 0.1)
        if not isinstance(out, torch.Tensor) or tuple(out.shape) != (3,):
            return hint(
                "predicted_shares must return a torch.Tensor of shape (K,) = (3,), one share per valid "
                f"action, got {getattr(out, 'shape', type(out).__name__)}."
            )
        out = out.detach().double()
        if not torch.isfinite(out).all():
            return hint("predicted_shares returned NaN or infinite values.")
        ref = _normalise(1 / _q(modes, actions, 0.1))
        if not close(out, ref, rtol=1e-3, atol=1e-4):
            if close(out, torch.full((3,), 1 / 3, dtype=torch.float64)):
                return hint(
                    "one third each is what the expert does, p(y|x). But the model does not learn p(y|x): "
                    "with counter-examples drawn from q, InfoNCE is best served by e^(−E) ∝ p(y|x) / q(y)."
                )
            if close(out, _normalise(_q(modes, actions, 0.1)), rtol=1e-3, atol=1e-4):
                return hint(
                    "your shares grow with q: the wrong way round. A counter-example pushes the energy "
                    "*up* where it lands, so where counter-examples are common the model puts *less* mass."
                )
            if close(out, _normalise(1 / _q(modes, actions, 0.2)), rtol=1e-3, atol=1e-4):
                return hint(
                    "q is the density of the counter-examples: expert actions plus N(0, σ²I), a KDE with "
                    "bandwidth σ, not chapter 05's 0.2."
                )
            if (
                fb := unnormalised_hint(out, ref, "they are shares of the mass near the K actions")
            ) is not None:
                return fb
            return hint(
                f"your shares are {[round(v, 3) for v in out.tolist()]}: compute q at each valid action "
                "(the expert actions blurred by σ), then share ∝ 1/q."
            )
        out2 = fn(modes.clone(), actions.clone(), 0.3)
        if not isinstance(out2, torch.Tensor) or not close(
            out2.detach().double(), _normalise(1 / _q(modes, actions, 0.3)), rtol=1e-3, atol=1e-4
        ):
            return hint("right for σ = 0.1 but not for σ = 0.3: use the σ you are given.")
        straight = float(ref[1])
        return correct(
            f"Right: with these actions a DA-IBC model should put only {straight:.0%} of the mass near "
            "'straight' on it, "
            "against the expert's 1/3, because straight on looks like cruising, where the counter-examples "
            "crowd."
        )

    return run_check(check, "`predicted_shares`")
