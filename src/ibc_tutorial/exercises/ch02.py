"""Checkers for ``exercises/02_explicit_policies.ipynb``.

- ``check_beta_nll(fn)``: the Beta negative log-likelihood of eq. 1 of the DA-IBC paper,
  ``fn(alpha (B, D), beta (B, D), actions (B, D)) -> scalar``.
- ``check_mdn_nll(fn)``: the mixture-density NLL of the steering-EBM paper's MDN baseline,
  ``fn(logits (B, K), means (B, K, D), stds (B, K, D), actions (B, D)) -> scalar``.
- ``check_beta_can_represent(fn)``: ``fn(shape) -> bool`` for each shape of ``BETA_SHAPES``, a
  prediction of what a Beta density can look like (a question about the chapter's finding,
  checked against a search over (alpha, beta)).

Each compares the reader's function with an independent reference (``torch.distributions``)
on random inputs and, when they differ, tests the usual mistakes one by one to name the
one that was made, without giving the answer away.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ibc_tutorial.exercises.core import Feedback, close, correct, hint, mistake_hint, run_check, scalar_answer


def _scalar(out, name: str) -> torch.Tensor | Feedback:
    return scalar_answer(
        out, name, "reduce over the action dimensions and over the batch as the equation does."
    )


# --------------------------------------------------------------------------- Beta NLL (eq. 1)
def _beta_inputs(seed: int, b: int = 32, d: int = 2):
    gen = torch.Generator().manual_seed(seed)
    alpha = torch.exp(torch.empty(b, d).uniform_(-1.5, 2.0, generator=gen))
    beta = torch.exp(torch.empty(b, d).uniform_(-1.5, 2.0, generator=gen))
    actions = torch.empty(b, d).uniform_(
        -0.98, 0.98, generator=gen
    )  # y' in [0.01, 0.99]: any clamp up to 0.01 is fine
    return alpha, beta, actions


def _near_bound_inputs():
    """(8, 2) actions, two of them at ±0.97 (y' = 0.015 or 0.985, inside the bounds), with
    concentrations in [1.5, 2.5]. A clamp of y' wider than about 0.015 changes the loss by more than
    the check's 4e-3; a shift log(y' + 1e-4) changes it by less."""
    gen = torch.Generator().manual_seed(4)
    alpha = torch.empty(8, 2).uniform_(1.5, 2.5, generator=gen)
    beta = torch.empty(8, 2).uniform_(1.5, 2.5, generator=gen)
    actions = torch.empty(8, 2).uniform_(-0.8, 0.8, generator=gen)
    actions[:2, 0] = torch.tensor([-0.97, 0.97])
    return alpha, beta, actions


def _bound_inputs():
    """(8, 2) actions, half of the rows with both dimensions at exactly -1 or +1, concentrations in
    [1.5, 3] (> 1: every term at a bound grows as y' nears it, so the loss rises as the margin shrinks)."""
    gen = torch.Generator().manual_seed(3)
    alpha = torch.empty(8, 2).uniform_(1.5, 3.0, generator=gen)
    beta = torch.empty(8, 2).uniform_(1.5, 3.0, generator=gen)
    actions = torch.empty(8, 2).uniform_(-0.8, 0.8, generator=gen)
    actions[:4] = torch.tensor([[-1.0, 1.0], [1.0, -1.0], [-1.0, -1.0], [1.0, 1.0]])
    return alpha, beta, actions


def _bound_range(alpha, beta, actions) -> tuple[float, float]:
    """The range of eq. 1's loss over clamps of y' to [eps, 1 - eps], eps from 1e-12 to 0.01 (float64)."""
    y = (actions.double() + 1) / 2
    dist = torch.distributions.Beta(alpha.double(), beta.double())
    values = [
        float(-dist.log_prob(y.clamp(eps, 1 - eps)).sum(1).mean())
        for eps in torch.logspace(-12, -2, 101, dtype=torch.float64).tolist()
    ]
    return min(values), max(values)


TOO_WIDE = (
    "your loss is what eq. 1 gives when y' is clamped (or squeezed) by a margin of more than 0.01, which "
    "changes ordinary actions too: the margin must only keep y' off exactly 0 and 1."
)
"""The hint for a clamp of y' that also changes actions inside the bounds."""


def _clamped_too_wide(fn) -> bool:
    """Whether ``fn`` clamps y' by a margin wider than 0.0105: probed with one action at a time under
    Beta(2, 1), whose loss -log(2 y') gives back the y' the function scored. A clamp scores every y'
    below its margin as the margin itself and every y' above it unchanged."""
    probes = [0.003, 0.006, 0.0125, 0.025, 0.05, 0.1, 0.2]  # y'
    scored = []
    try:
        for z in probes:
            out = fn(torch.full((1, 1), 2.0), torch.full((1, 1), 1.0), torch.full((1, 1), 2 * z - 1))
            scored.append(math.exp(-float(torch.as_tensor(out).detach()) - math.log(2.0)))
    except Exception:  # a function that fails on a (1, 1) batch is judged on the other checks
        return False
    raised = [(z, e) for z, e in zip(probes, scored, strict=True) if e > z * 1.001]
    if not raised:
        return False
    margin = max(e for _, e in raised)
    same = all(abs(e - margin) <= 0.01 * margin for _, e in raised)
    below = all(e > z * 1.001 for z, e in zip(probes, scored, strict=True) if z < margin * 0.99)
    return same and below and margin > 0.0105


def _beta_log_f(alpha, beta, actions) -> torch.Tensor:
    """(B, D) log f(y'; α, β) of eq. 1, by torch.distributions (the reference)."""
    y = (actions.double() + 1) / 2
    return torch.distributions.Beta(alpha.double(), beta.double()).log_prob(y)


def check_beta_nll(fn) -> Feedback:
    """Check ``fn(alpha, beta, actions)`` against eq. 1 of the DA-IBC paper."""

    def check() -> Feedback:
        alpha, beta, actions = _beta_inputs(0)
        out = _scalar(fn(alpha.clone(), beta.clone(), actions.clone()), "beta_nll")
        if isinstance(out, Feedback):
            return out
        log_f = _beta_log_f(alpha, beta, actions)  # (B, D)
        b, d = actions.shape
        ref = -log_f.sum(1).mean()
        if not torch.isfinite(out):
            pos = actions.abs()  # (B, D) in [0, 0.98]: a loss that forgot to rescale is finite here
            out_pos = fn(alpha.clone(), beta.clone(), pos)
            unscaled = (
                -torch.distributions.Beta(alpha.double(), beta.double())
                .log_prob(pos.double().clamp_min(1e-6))
                .sum(1)
                .mean()
            )
            if (
                isinstance(out_pos, torch.Tensor)
                and out_pos.ndim == 0
                and close(out_pos, unscaled, rtol=1e-3, atol=1e-3)
            ):
                return hint(
                    "your loss is NaN or infinite for actions inside (-1, 1): the Beta density lives on "
                    "[0, 1], "
                    "and eq. 1 maps each action to y' = (y + 1)/2 before scoring it."
                )
            return hint(
                "your loss is NaN or infinite for actions inside (-1, 1): check every log, and that the "
                "actions are mapped into [0, 1]."
            )
        if not close(out, ref, rtol=1e-3, atol=1e-3):
            mistakes = [
                (
                    log_f.sum(1).mean(),
                    "the sign: eq. 1 is the *negative* log-likelihood, which training minimises.",
                ),
                (
                    -log_f.mean(),
                    "the reduction over action dimensions: eq. 1 *sums* log f over the action dimensions "
                    "(acceleration + steering) and averages over the samples.",
                ),
                (
                    -log_f.sum(),
                    "the reduction over the batch: eq. 1 *averages* over the N samples (the 1/N in front).",
                ),
                (
                    ref + d * math.log(2.0),
                    "the rescaling: eq. 1 scores the density of the rescaled action y' itself, with no "
                    "change-of-variables term.",
                ),
                (
                    ref - d * math.log(2.0),
                    "the rescaling: eq. 1 scores the density of the rescaled action y' itself, with no "
                    "change-of-variables term.",
                ),
            ]
            log_b = (
                torch.lgamma(alpha.double())
                + torch.lgamma(beta.double())
                - torch.lgamma(alpha.double() + beta.double())
            )
            mistakes.append(
                (
                    -(log_f + log_b).sum(1).mean(),
                    "the normalising constant B(α, β): without it f is not a density.",
                )
            )
            mistakes.append(
                (
                    -(log_f - log_b).sum(1).mean(),
                    "the normalising constant B(α, β): f divides by it, so log f subtracts log B.",
                )
            )
            y = actions.double().clamp(1e-6, 1 - 1e-6)
            wrong_y = torch.distributions.Beta(alpha.double(), beta.double()).log_prob(y)
            mistakes.append(
                (
                    -wrong_y.sum(1).mean(),
                    "the rescaling: actions live in [-1, 1]; eq. 1 maps them to y' = (y + 1)/2 before "
                    "scoring them.",
                )
            )
            swapped = torch.distributions.Beta(beta.double(), alpha.double()).log_prob(
                (actions.double() + 1) / 2
            )
            mistakes.append(
                (
                    -swapped.sum(1).mean(),
                    "which exponent goes with α and which with β: α belongs to y', β to (1 - y').",
                )
            )
            if _clamped_too_wide(fn):  # first: a wide clamp's loss can land near another mistake's by chance
                return hint(TOO_WIDE)
            if (mistake := mistake_hint(out, mistakes, rtol=1e-3, atol=1e-3)) is not None:
                return mistake
            return hint(
                f"your loss is {float(out):.4g} on a random test batch where eq. 1 gives {float(ref):.4g}; "
                "compare your formula with the Beta density term by term."
            )
        # other batch sizes and dimensions, and one dimension at a time
        for seed, (b2, d2) in [(1, (7, 1)), (2, (5, 3))]:
            a2, b2_, y2 = _beta_inputs(seed, b2, d2)
            out2 = _scalar(fn(a2, b2_, y2), "beta_nll")
            if isinstance(out2, Feedback):
                return out2
            if not close(out2, -_beta_log_f(a2, b2_, y2).sum(1).mean(), rtol=1e-3, atol=1e-3):
                if _clamped_too_wide(fn):
                    return hint(TOO_WIDE)
                return hint(
                    f"correct on a (32, 2) batch but not on a ({len(y2)}, {y2.shape[1]}) one: avoid "
                    "hard-coding the batch size or the number of action dimensions."
                )
        # close to the bounds but inside (y' = 0.015 and 0.985): a clamp wider than ~0.01 changes these
        alpha, beta, actions = _near_bound_inputs()
        out = _scalar(fn(alpha.clone(), beta.clone(), actions.clone()), "beta_nll")
        if isinstance(out, Feedback):
            return out
        if not close(out, -_beta_log_f(alpha, beta, actions).sum(1).mean(), rtol=1e-3, atol=4e-3):
            return hint(
                "right for actions well inside (-1, 1), wrong for actions close to the bounds but inside "
                "them "
                "(y = ±0.97, y' = 0.015 and 0.985): keeping y' inside (0, 1) must change nothing but the "
                "actions at exactly ±1, so the margin of your clamp (or shift) is too wide."
            )
        # the bounds: full lock and full brake, in a batch with ordinary actions
        alpha, beta, actions = _bound_inputs()
        alpha.requires_grad_(True)
        beta.requires_grad_(True)
        out = _scalar(fn(alpha, beta, actions), "beta_nll")
        if isinstance(out, Feedback):
            return out
        if not torch.isfinite(out):
            return hint(
                "your loss is infinite or NaN for actions exactly at -1 or +1 (full brake, full steering "
                "lock: "
                "expert data holds them). Keep y' a little inside (0, 1) before taking logs."
            )
        if not out.requires_grad:
            return hint(
                "your loss does not depend on alpha and beta through autograd (did you use .item(), numpy or "
                "detach?): training needs its gradients."
            )
        low, high = _bound_range(alpha.detach(), beta.detach(), actions)
        value = float(out.detach())
        if not low - 1e-3 * abs(low) - 1e-3 <= value <= high + 1e-3 * abs(high) + 1e-3:
            if _clamped_too_wide(fn):
                return hint(TOO_WIDE)
            return hint(
                f"on a batch with actions at exactly ±1 your loss is {value:.4g}, where eq. 1 with y' kept "
                "just "
                f"inside (0, 1) (a margin between 1e-12 and 0.01) gives between {low:.4g} and {high:.4g}: "
                "the "
                "samples at the bounds count like any other, with y' moved just inside (0, 1), not dropped "
                "or "
                "replaced."
            )
        out.backward()
        if not (torch.isfinite(alpha.grad).all() and torch.isfinite(beta.grad).all()):
            return hint(
                "the loss is finite at actions of exactly ±1 but its gradients are not: keep y' a little "
                "inside "
                "(0, 1) before taking logs."
            )
        return correct("Your Beta NLL matches eq. 1 and stays finite, with finite gradients, at the bounds.")

    return run_check(check, "`beta_nll`")


# --------------------------------------------------------------------------- MDN NLL
def _mdn_inputs(seed: int, b: int = 40, k: int = 3, d: int = 2):
    gen = torch.Generator().manual_seed(seed)
    logits = torch.randn(b, k, generator=gen)
    means = torch.randn(b, k, d, generator=gen) * 0.5
    stds = torch.exp(torch.randn(b, k, d, generator=gen) * 0.3 - 1.0)
    actions = torch.rand(b, d, generator=gen) * 2 - 1
    return logits, means, stds, actions


def _mixture(logits, means, stds):
    return torch.distributions.MixtureSameFamily(
        torch.distributions.Categorical(logits=logits.double()),
        torch.distributions.Independent(torch.distributions.Normal(means.double(), stds.double()), 1),
    )


def check_mdn_nll(fn) -> Feedback:
    """Check ``fn(logits, means, stds, actions)`` against ``torch.distributions.MixtureSameFamily``."""

    def check() -> Feedback:
        logits, means, stds, actions = _mdn_inputs(0)
        out = _scalar(fn(logits.clone(), means.clone(), stds.clone(), actions.clone()), "mdn_nll")
        if isinstance(out, Feedback):
            return out
        ref = -_mixture(logits, means, stds).log_prob(actions.double()).mean()
        if not close(out, ref, rtol=1e-3, atol=1e-3):
            if not torch.isfinite(out):
                return hint(
                    "your loss is NaN or infinite on an ordinary batch: check the logs (of the weights, of "
                    "the densities)."
                )
            normal = torch.distributions.Normal(means.double(), stds.double())
            log_comp = normal.log_prob(actions.double()[:, None]).sum(-1)  # (B, K)
            log_w = torch.log_softmax(logits.double(), 1)
            w_raw = logits.double().clamp_min(1e-12)
            mistakes = [
                (-ref, "the sign: the loss is the *negative* log-likelihood."),
                (
                    -_mixture(logits, means, stds).log_prob(actions.double()).sum(),
                    "the reduction: average over the batch, not sum.",
                ),
                (
                    -(log_w + log_comp).sum(1).mean(),
                    "how the components combine: the mixture density is a weighted *sum* of the component "
                    "densities, so take the log after summing (log-sum-exp), not a sum of logs.",
                ),
                (
                    -(log_w.exp() * log_comp).sum(1).mean(),
                    "how the components combine: the mixture density is a weighted *sum* of the component "
                    "densities; the log of that sum is not the weighted sum of logs.",
                ),
                (
                    -torch.logsumexp(logits.double() + log_comp, 1).mean(),
                    "the mixture weights: the logits are not normalised; a softmax over the K components "
                    "turns them into weights that sum to 1.",
                ),
                (
                    -torch.logsumexp(torch.log(w_raw) + log_comp, 1).mean(),
                    "the mixture weights: the logits are not probabilities; a softmax over the K "
                    "components turns them into weights that sum to 1.",
                ),
                (
                    -torch.logsumexp(log_w + normal.log_prob(actions.double()[:, None]).mean(-1), 1).mean(),
                    "the action dimensions: a diagonal Gaussian's log-density *sums* the per-dimension "
                    "log-densities.",
                ),
                (
                    -torch.logsumexp(
                        log_w
                        + (normal.log_prob(actions.double()[:, None]) + torch.log(stds.double())).sum(-1),
                        1,
                    ).mean(),
                    "the Gaussian's normalisation: its log-density has a -log σ term.",
                ),
                (
                    -torch.logsumexp(
                        log_w
                        + (normal.log_prob(actions.double()[:, None]) - torch.log(stds.double())).sum(-1),
                        1,
                    ).mean(),
                    "the Gaussian's normalisation: its log-density has -log σ, not -2 log σ (σ is a "
                    "standard deviation, not a variance).",
                ),
            ]
            var_normal = torch.distributions.Normal(means.double(), stds.double().sqrt())
            mistakes.append(
                (
                    -torch.logsumexp(
                        log_w + var_normal.log_prob(actions.double()[:, None]).sum(-1), 1
                    ).mean(),
                    "the Gaussian: stds are standard deviations, not variances.",
                )
            )
            if (mistake := mistake_hint(out, mistakes, rtol=1e-3, atol=1e-3)) is not None:
                return mistake
            return hint(
                f"your loss is {float(out):.4g} on a random test batch where the mixture gives "
                f"{float(ref):.4g}; compare your formula with log Σ_k π_k N(y; μ_k, σ_k²) term by term."
            )
        for seed, (b, k, d) in [(1, (6, 1, 1)), (2, (9, 5, 3))]:
            args = _mdn_inputs(seed, b, k, d)
            out2 = _scalar(fn(*args), "mdn_nll")
            if isinstance(out2, Feedback):
                return out2
            if not close(out2, -_mixture(*args[:3]).log_prob(args[3].double()).mean(), rtol=1e-3, atol=1e-3):
                return hint(
                    f"correct for K = 3 components and D = 2 action dimensions but not for K = {k}, D = "
                    f"{d}: avoid hard-coding the sizes."
                )
        # far from every component: a naive exp underflows to 0 and log(0) = -inf
        logits, means, stds, actions = _mdn_inputs(3, 8, 3, 1)
        far_means = means - 40.0
        out3 = _scalar(fn(logits, far_means, stds, actions), "mdn_nll")
        if isinstance(out3, Feedback):
            return out3
        ref3 = -_mixture(logits, far_means, stds).log_prob(actions.double()).mean()
        if not close(out3, ref3, rtol=1e-3, atol=1e-2):
            return hint(
                "right on ordinary inputs, but not when the action is far from every component (at the "
                "start of "
                "training it often is): the densities underflow to 0. Stay in log space (torch.logsumexp)."
            )
        return correct(
            "Your MDN loss matches torch.distributions.MixtureSameFamily, also far from every component."
        )

    return run_check(check, "`mdn_nll`")


# ------------------------------------------------------------------- 3. prediction: what a Beta can represent
BETA_SHAPES = ("flat", "one peak inside", "peaks at both ends", "two peaks inside")


def _beta_shape_exists(shape: str) -> bool:
    """Whether some Beta(alpha, beta) on a grid of 3600 pairs (0.05 ... 55) has ``shape``: the
    library's answer, computed from the densities as the chapter does."""
    conc = torch.exp(torch.linspace(-3.0, 4.0, 60, dtype=torch.float64))
    conc = torch.cat([conc, torch.ones(1, dtype=torch.float64)])  # include alpha = beta = 1
    a, b = torch.meshgrid(conc, conc, indexing="ij")
    z = torch.linspace(0.001, 0.999, 2001, dtype=torch.float64)
    logf = torch.distributions.Beta(a.reshape(-1, 1), b.reshape(-1, 1)).log_prob(z)  # (P, G)
    mid = logf[:, 1:-1]
    peaks = ((mid > logf[:, :-2]) & (mid > logf[:, 2:])).sum(dim=1)  # (P,) interior local maxima
    if shape == "flat":
        return bool(((logf.max(1).values - logf.min(1).values) < 1e-9).any())
    if shape == "one peak inside":
        return bool((peaks == 1).any())
    if shape == "two peaks inside":
        return bool((peaks >= 2).any())
    inner_max = logf[:, 100:-100].max(1).values
    return bool(((logf[:, 0] > inner_max) & (logf[:, -1] > inner_max)).any())  # peaks at both ends


def check_beta_can_represent(fn) -> Feedback:
    """Check ``fn(shape) -> bool`` for every shape in ``BETA_SHAPES``: the reader's prediction of
    whether some Beta density on (0, 1) has that shape, against a search over (alpha, beta)."""

    def check() -> Feedback:
        for shape in BETA_SHAPES:
            answer = fn(shape)
            if isinstance(answer, np.bool_):  # numpy's True and False are answers too
                answer = bool(answer)
            if not isinstance(answer, bool):
                return hint(f"answer True or False for each shape, got {answer!r} for {shape!r}.")
            truth = _beta_shape_exists(shape)
            if answer == truth:
                continue
            if shape == "two peaks inside":
                return hint(
                    "look at the second derivative of log f in the chapter: can log f be concave near one "
                    "point and "
                    "have a dip in between two peaks, with alpha and beta fixed?"
                )
            if shape == "peaks at both ends":
                return hint("try alpha and beta both below 1: what does the density do near z = 0 and z = 1?")
            if shape == "flat":
                return hint("evaluate the density for alpha = beta = 1.")
            return hint("try alpha = beta = 2: where is the density highest?")
        return correct(
            "A Beta has at most one peak inside the interval; its 'two modes' can only be the two walls of "
            "a U, "
            "at full lock. That is why the chapter's Beta policy is flat or U-shaped at the tree."
        )

    return run_check(check, "`beta_can_represent`")
