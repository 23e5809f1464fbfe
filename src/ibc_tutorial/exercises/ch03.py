"""Checkers for ``exercises/03_energy_models.ipynb``.

- ``check_info_nce(fn)``: InfoNCE, eqs. 2-3 of the DA-IBC paper (eq. 5 with weights),
  ``fn(pos_energy (B,), neg_energy (B, N), weights=None) -> scalar``.
- ``check_soft_targets(fn)``: the soft targets of eq. 5 of the steering-EBM paper (intended sign),
  ``fn(candidates (K, D), actions (B, D), temperature) -> (B, K)``.
- ``check_whiteness(fn)``: the whiteness of eq. 2 of the steering-EBM paper,
  ``fn(commands (T,), dt) -> float``.
- ``check_decision_prediction(fn)``: the chapter's finding, predicted (``fn() -> dict``): what an MSE and
  an MAE regression, the argmin and the draw of an energy model command where the tree experts
  decide, when 70 % of them pass on the right (checked against the demonstrations' statistics).

Each compares the reader's function with an independent reference (``torch.nn.functional``,
numpy) and, when they differ, tries the usual mistakes one by one to name the one made.
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F

from ibc_tutorial.exercises.core import Feedback, close, correct, hint, mistake_hint, run_check, scalar_answer
from ibc_tutorial.toy import TreeConfig, TreeWorld


def _as_scalar(out, name: str) -> torch.Tensor | Feedback:
    if isinstance(out, (float, int)) and not isinstance(out, bool):
        return hint(
            f"{name} returned a Python number: return a torch.Tensor (a scalar) so that training can "
            "back-propagate through it."
        )
    return scalar_answer(out, name, "average the per-sample terms over the batch.")


# --------------------------------------------------------------------------- InfoNCE (eqs. 2-3, 5)
def _nce_inputs(seed: int, b: int = 16, n: int = 9, scale: float = 2.0):
    g = torch.Generator().manual_seed(seed)
    return (
        scale * torch.randn(b, generator=g),
        scale * torch.randn(b, n, generator=g),
        0.2 + 2 * torch.rand(b, generator=g),
    )


def _nce_terms(pos, neg) -> torch.Tensor:
    """(B,) -log p̃_i by torch's cross-entropy (the reference): logits -E, the expert is class 0."""
    logits = torch.cat([-pos[:, None], -neg], dim=1).double()
    return F.cross_entropy(logits, torch.zeros(len(pos), dtype=torch.long), reduction="none")


def check_info_nce(fn) -> Feedback:
    """Check ``fn(pos_energy, neg_energy, weights=None)`` against eqs. 2-3 (and 5) of the DA-IBC paper."""

    def check() -> Feedback:
        pos, neg, w = _nce_inputs(0)
        out = _as_scalar(fn(pos.clone(), neg.clone()), "info_nce")
        if isinstance(out, Feedback):
            return out
        terms = _nce_terms(pos, neg)
        ref = terms.mean()
        if not close(out, ref):
            flipped = _nce_terms(-pos, -neg)
            logits = torch.cat([-pos[:, None], -neg], 1).double()
            mistakes = [
                (
                    flipped.mean(),
                    "the sign of the energies: low energy means a *likely* action, so p̃ is a softmax of −E.",
                ),
                (
                    (torch.logsumexp(-neg.double(), 1) + pos.double()).mean(),
                    "the denominator of eq. 3: it sums over the expert's action *and* its counter-examples.",
                ),
                (
                    terms.sum(),
                    "the reduction: average the per-sample terms over the batch (the mean, so the learning "
                    "rate does not depend on the batch size).",
                ),
                (-terms.mean(), "the overall sign: the loss is −log p̃, which training minimises."),
                (
                    -torch.log_softmax(logits, 1)[:, 1:].mean(),
                    "which candidate is the expert's: p̃ is read at the expert's action (the positive), "
                    "not at the counter-examples.",
                ),
            ]
            if (mistake := mistake_hint(out, mistakes)) is not None:
                return mistake
            return hint(
                f"your loss is {float(out):.4g} on a test batch where eqs. 2-3 give {float(ref):.4g}; write "
                "−log p̃ for one sample by hand and compare."
            )
        # weights (eq. 5)
        out_w = _as_scalar(fn(pos.clone(), neg.clone(), w.clone()), "info_nce with weights")
        if isinstance(out_w, Feedback):
            return out_w
        ref_w = (w.double() * terms).mean()
        if not close(out_w, ref_w):
            if close(out_w, ref):
                return hint(
                    "your loss ignores `weights`: eq. 5 multiplies each sample's −log p̃ by its weight w_i."
                )
            if close(out_w, (w.double() * terms).sum() / w.double().sum()):
                return hint(
                    "with weights, eq. 5 multiplies each term by w_i and then averages over the batch as "
                    "before; it does not divide by the sum of the weights."
                )
            return hint(
                f"with weights your loss is {float(out_w):.4g} where eq. 5 (mean over the batch of w_i · "
                f"(−log p̃_i)) gives {float(ref_w):.4g}."
            )
        # other shapes
        pos2, neg2, _ = _nce_inputs(1, b=5, n=3)
        out2 = _as_scalar(fn(pos2, neg2), "info_nce")
        if isinstance(out2, Feedback):
            return out2
        if not close(out2, _nce_terms(pos2, neg2).mean()):
            return hint(
                "correct on a (16, 9) batch but not on a (5, 3) one: avoid hard-coding the batch size or "
                "the number of counter-examples."
            )
        # large energies
        big_pos, big_neg = 1000.0 + pos * 20, 1000.0 + neg * 20
        out3 = fn(big_pos, big_neg)
        if not isinstance(out3, torch.Tensor) or not torch.isfinite(out3).all():
            return hint(
                "your loss is NaN or infinite when the energies are around 1000: e^(−1000) underflows to "
                "0. Compute log p̃ with a log-sum-exp (torch.logsumexp or log_softmax)."
            )
        if not close(out3, _nce_terms(big_pos, big_neg).mean(), rtol=1e-3, atol=1e-2):
            return hint(
                "your loss is finite but wrong when the energies are around 1000: compute log p̃ with a "
                "log-sum-exp instead of exponentiating."
            )
        p = pos.clone().requires_grad_(True)
        out4 = fn(p, neg.clone())
        if not isinstance(out4, torch.Tensor) or not out4.requires_grad:
            return hint(
                "your loss does not depend on the energies through autograd (did you use .item(), numpy or "
                "detach?): training needs its gradients."
            )
        return correct("Your InfoNCE matches eqs. 2-3 and 5, and stays exact for energies in the thousands.")

    return run_check(check, "`info_nce`")


# ------------------------------------------------------------- soft targets (eq. 5 of the steering-EBM paper)
def _soft_ref(candidates, actions, t) -> torch.Tensor:
    sq = ((candidates[None, :, :].double() - actions[:, None, :].double()) ** 2).sum(-1)  # (B, K)
    return torch.softmax(-sq / t, dim=1)


def check_soft_targets(fn) -> Feedback:
    """Check ``fn(candidates (K, D), actions (B, D), temperature) -> (B, K)`` against the intended eq. 5."""

    def check() -> Feedback:
        cand = torch.linspace(-1, 1, 21)[:, None]  # (21, 1)
        gt = torch.tensor([[0.1], [-0.63], [0.95]])
        t = 0.02
        out = fn(cand.clone(), gt.clone(), t)
        if not isinstance(out, torch.Tensor):
            return hint(f"soft_targets must return a torch.Tensor of shape (B, K), got {type(out).__name__}.")
        if tuple(out.shape) != (3, 21):
            return hint(
                "soft_targets must return one row of K target probabilities per sample, shape (3, 21) "
                f"here; got {tuple(out.shape)}."
            )
        ref = _soft_ref(cand, gt, t)
        if not close(out, ref, rtol=1e-4, atol=1e-6):
            sq = ((cand[None, :, :] - gt[:, None, :]) ** 2).sum(-1).double()
            if close(out, torch.softmax(sq / t, 1), atol=1e-6):
                return hint(
                    "your targets put the most weight on the candidate *farthest* from the ground truth: "
                    "that is the sign as printed in the transcription. The weight should fall with "
                    "distance."
                )
            if close(out, torch.softmax(-sq.sqrt() / t, 1), atol=1e-6):
                return hint("eq. 5 uses the *squared* distance (a − a_GT)², not the distance.")
            if close(out, torch.softmax(-sq * t, 1), atol=1e-6):
                return hint(
                    "check how the temperature enters: divide by T (a smaller T gives sharper targets)."
                )
            if not torch.allclose(out.double().sum(1), torch.ones(3, dtype=torch.float64), atol=1e-4):
                return hint(
                    "each row of targets must sum to 1 over the K candidates: take the softmax over the "
                    "candidate dimension."
                )
            return hint("your targets differ from p* = softmax(−(a − a_GT)² / T); compare one row by hand.")
        cand2 = torch.tensor([[0.0, 0.0], [0.5, 0.5], [-0.5, 0.2], [1.0, -1.0]])
        gt2 = torch.tensor([[0.4, 0.4], [0.0, 0.1]])
        out2 = fn(cand2, gt2, 0.5)
        if not isinstance(out2, torch.Tensor) or not close(out2, _soft_ref(cand2, gt2, 0.5), atol=1e-6):
            return hint(
                "correct for 1-D actions but not for 2-D ones: for D > 1, (a − a_GT)² is the squared "
                "Euclidean distance, summed over the action dimensions."
            )
        return correct(
            "Your soft targets fall with the distance from the ground truth, as the steering-EBM paper "
            "intends."
        )

    return run_check(check, "`soft_targets`")


# ---------------------------------------------------------------- whiteness (eq. 2 of the steering-EBM paper)
def check_whiteness(fn) -> Feedback:
    """Check ``fn(commands (T,), dt) -> float`` against eq. 2 of the steering-EBM paper."""

    def check() -> Feedback:
        x = np.random.default_rng(0).normal(size=12)
        dt = 0.1
        try:
            out = float(fn(torch.tensor(x, dtype=torch.float32), dt))
        except (TypeError, ValueError) as exc:
            return hint(f"whiteness must return a number (a float or a 0-dimensional tensor): {exc}.")
        d = np.diff(x)
        ref = math.sqrt(np.mean((d / dt) ** 2))
        if not math.isclose(out, ref, rel_tol=1e-4):
            mistakes = [
                (
                    math.sqrt(np.mean(d**2)),
                    "the time step: eq. 2 divides each change δP_i by δt, the time between decisions.",
                ),
                (
                    np.mean((d / dt) ** 2),
                    "the square root: whiteness is the *root* mean square of the rate of change.",
                ),
                (
                    math.sqrt(np.sum((d / dt) ** 2) / len(x)),
                    "the count D: it is the number of changes, one fewer than the number of commands.",
                ),
                (
                    np.std(x) / dt,
                    "what is squared: eq. 2 uses the *changes* between consecutive commands, not the "
                    "commands themselves.",
                ),
                (
                    math.sqrt(np.mean(x**2)) / dt,
                    "what is squared: eq. 2 uses the *changes* between consecutive commands, not the "
                    "commands themselves.",
                ),
                (
                    float(np.std(d / dt, ddof=1)),
                    "the mean: eq. 2 is the root mean square of the rates, not their spread around their "
                    "mean "
                    "(a steady ramp has a rate, and a whiteness, of its own).",
                ),
                (
                    float(np.std(d / dt)),
                    "the mean: eq. 2 is the root mean square of the rates, not their spread around their "
                    "mean "
                    "(a steady ramp has a rate, and a whiteness, of its own).",
                ),
                (
                    np.mean(np.abs(d / dt)),
                    "the mean: eq. 2 averages the *squared* rates and then takes the square root.",
                ),
            ]
            for value, what in mistakes:
                if math.isclose(out, value, rel_tol=1e-4):
                    return hint(f"close, but check {what}")
            return hint(f"your whiteness is {out:.4g} on a test sequence where eq. 2 gives {ref:.4g}.")
        if not math.isclose(float(fn(torch.full((30,), 0.4), 0.05)), 0.0, abs_tol=1e-9):
            return hint("a constant command has no changes: its whiteness must be 0.")
        # a steady ramp, then a ramp with a wiggle: the rates' mean is not 0 here, so their spread
        # (a standard deviation) is not their root mean square
        for seq, step in (
            (np.linspace(-0.5, 0.7, 25), 0.1),
            (np.linspace(0.0, 0.9, 16) + 0.05 * (-1.0) ** np.arange(16), 0.05),
        ):
            got = float(fn(torch.tensor(seq, dtype=torch.float32), step))
            rates = np.diff(seq) / step
            want = math.sqrt(np.mean(rates**2))
            if not math.isclose(got, want, rel_tol=1e-4):
                if math.isclose(got, float(np.std(rates)), rel_tol=1e-3, abs_tol=1e-6):
                    return hint(
                        "a steady ramp changes at a constant, non-zero rate, yet your whiteness of it is "
                        f"{got:.3g}: eq. 2 is the root mean square of the rates, not their spread around "
                        "their "
                        "mean."
                    )
                return hint(
                    f"right on a random sequence, but on a ramp of {len(seq)} commands your whiteness is "
                    f"{got:.4g} where eq. 2 gives {want:.4g}."
                )
        return correct("Your whiteness matches eq. 2: the RMS rate of change of the command.")

    return run_check(check, "`whiteness`")


# --------------------------------------------------------------------------- the finding, predicted
DECISION_RIGHT_PROB = 0.7
"""Share of the experts of the exercise's tree world that pass on the right."""
DECISION_WINDOW = (8.0, 10.0)
"""The observations (m before the tree) where the experts have just decided."""
DECISION_KEYS = ("mse", "mae", "argmin", "sample_right")


def decision_reference() -> dict:
    """What the four policies command in ``DECISION_WINDOW`` of a tree world whose experts pass on
    the right with ``DECISION_RIGHT_PROB``, computed from its demonstrations (200 episodes, seed 0):
    the mean of the actions there (MSE's minimiser), their median (MAE's), the side of the deeper
    valley of p(y | x) (the more frequent side), and the share of draws to the right."""

    dtype = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)  # the same reference whatever the reader's default
    try:
        world = TreeWorld(TreeConfig(right_prob=DECISION_RIGHT_PROB))
        demos = world.expert_demonstrations(200, seed=0)
        a = demos.actions[world.in_window(demos.obs, DECISION_WINDOW), 0]  # (N,)
    finally:
        torch.set_default_dtype(dtype)
    right = float((a > 0).double().mean())
    return {
        "mse": float(a.mean()),
        "mae": float(a.median()),
        "argmin": "right" if right > 0.5 else "left",
        "sample_right": right,
    }


def check_decision_prediction(fn) -> Feedback:
    """Check the reader's prediction ``fn()`` = {"mse": command, "mae": command, "argmin": "right" |
    "left", "sample_right": share} against ``decision_reference()``: commands within 0.15, the
    share within 0.1. A stub raises NotImplementedError ("not attempted")."""

    def check() -> Feedback:
        prediction = fn()
        if not isinstance(prediction, dict) or set(prediction) != set(DECISION_KEYS):
            got = sorted(prediction) if isinstance(prediction, dict) else type(prediction).__name__
            return hint(f"prediction must be a dict with the keys {list(DECISION_KEYS)}, got {got}.")
        ref = decision_reference()
        side = str(prediction["argmin"]).strip().lower()
        if side not in ("right", "left"):
            return hint('"argmin" is a side of the tree: "right" or "left".')
        try:
            mse, mae, share = (float(prediction[k]) for k in ("mse", "mae", "sample_right"))
        except (TypeError, ValueError):
            return hint(
                '"mse" and "mae" are steering commands in [-1, 1] and "sample_right" a share in [0, 1]: '
                "give numbers."
            )
        if abs(mse - ref["mse"]) > 0.15:
            if abs(mse) < 0.1:
                return hint(
                    "MSE regression averages the two modes, but weighted by how often each occurs: 70 % of "
                    "the experts steer right, so the average is not 0."
                )
            if abs(mse - ref["mae"]) <= 0.15 or abs(mse) > 0.7:
                return hint(
                    "the minimiser of the squared error is the *mean* of the actions: a mixture of +0.9 "
                    "(70 %) and −0.9 (30 %) averages to a command between the modes, on neither of them."
                )
            return hint(
                "MSE regression commands the mean of the experts' actions there; weigh the two modes "
                "(about ±0.9 in this window) by their shares."
            )
        if abs(mae - ref["mae"]) > 0.15:
            if abs(mae - ref["mse"]) <= 0.15:
                return hint(
                    "the minimiser of the absolute error is not the mean but the *median*: with 70 % of "
                    "the actions in the right mode, where does the middle one lie?"
                )
            if mae < 0:
                return hint(
                    "the median lies in the mode that holds more than half of the actions: here the right "
                    "one (+)."
                )
            return hint(
                "MAE regression commands the median of the experts' actions: the middle one of a set where "
                "70 % sit near +0.9."
            )
        if side != ref["argmin"]:
            return hint(
                "the energy is −log p(y | x) up to a constant, so the deepest valley is the *most "
                "probable* action: on the side most experts take."
            )
        if abs(share - ref["sample_right"]) > 0.1:
            if share > 0.95:
                return hint(
                    "a draw from p(y | x) does not always take the deeper valley: it takes each side as "
                    "often as the experts did."
                )
            return hint(
                "drawing from p(y | x) reproduces the experts' shares: how often do they pass on the right?"
            )
        return correct(
            f"Right: MSE averages ({ref['mse']:.2f}, between the modes), MAE takes the median "
            f"({ref['mae']:.2f}, inside the majority mode), the argmin the deeper valley ({ref['argmin']}), "
            f"and drawing reproduces the shares ({ref['sample_right']:.2f} to the right). At 50/50 the "
            "mean is 0: straight into the tree, and a memory of the previous action does not help it."
        )

    return run_check(check, "`predict_decision`")
