"""Checkers for ``exercises/01_the_tree.ipynb``.

- ``check_best_constant_mse(fn)``: ``fn(actions (N,)) -> float``, the constant c minimising
  the mean squared error (1/N) Σ (a_i - c)^2 over a set of actions.
- ``check_hits_tree(fn)``: ``fn(car_xy (B, 2), tree_xy (2,), car_radius, tree_radius) -> (B,) bool``,
  whether the car's disc overlaps the tree's (discs that only touch do not).
- ``check_swerve(fn)``: ``fn(y (E, T)) -> (E,)``, how far each episode moved towards the side
  road, which branches off to the right (-y, as y points to the left), from its first lateral
  offset: max_t (y_0 - y_t), at least 0.
- ``check_predict_mae_side(fn)``: ``fn(n_right, n_left) -> "right" | "left" | "anywhere in the gap"``,
  a prediction of where the constant of least mean absolute error lies for two modes of actions
  (a question about the chapter's finding, checked against the minimum on a grid).

Steering, as everywhere in the book: +1 turns right, -1 left.

Each compares the reader's function with an independent reference on inputs it draws itself,
then, when they differ, recognises the usual mistakes and names them without the answer.
"""

from __future__ import annotations

import torch

from ibc_tutorial.exercises.core import Feedback, correct, hint, run_check


def _as_float(out) -> float | None:
    """The reader's scalar as a float, or None when it is not one number."""
    if isinstance(out, torch.Tensor):
        if out.numel() != 1:
            return None
        out = out.detach().reshape(())
    try:
        return float(out)
    except (TypeError, ValueError):
        return None


def _bimodal_actions(seed: int, n_right: int, n_left: int) -> torch.Tensor:
    """Steering of experts passing on the right (about +0.75) and on the left (about -0.7), shuffled."""
    gen = torch.Generator().manual_seed(seed)
    right = 0.75 + 0.08 * torch.randn(n_right, generator=gen)
    left = -0.7 + 0.1 * torch.randn(n_left, generator=gen)
    return torch.cat([right, left])[torch.randperm(n_right + n_left, generator=gen)].clamp(-1, 1)


# --------------------------------------------------------------------------- 1. best constant (MSE)
def check_best_constant_mse(fn) -> Feedback:
    """Check ``fn(actions) -> c``, the constant prediction with the smallest mean squared error."""

    def check() -> Feedback:
        cases = [_bimodal_actions(0, 60, 40), _bimodal_actions(1, 25, 75), torch.tensor([0.2, 0.4, 0.9])]
        for actions in cases:
            out = fn(actions.clone())
            c = _as_float(out)
            if c is None:
                shape = tuple(out.shape) if isinstance(out, torch.Tensor) else type(out).__name__
                return hint(
                    f"return one number (a float or a 0-d tensor) for the whole set of actions, got {shape}."
                )
            ref = float(actions.mean())
            if abs(c - ref) < 1e-4:
                continue
            loss = lambda v, actions=actions: float(((actions - v) ** 2).mean())  # noqa: E731
            if abs(c - float(actions.median())) < 1e-6 or abs(c - float(torch.quantile(actions, 0.5))) < 1e-6:
                return hint(
                    "your constant is a median: it minimises the mean *absolute* error. Which value makes "
                    "the derivative of the *squared* error zero?"
                )
            if abs(c - float(actions.sum())) < 1e-4:
                return hint(
                    "your value grows with the number of actions: the best constant should not change if "
                    "every action were repeated twice."
                )
            if abs(c) < 1e-9 and abs(ref) > 1e-3:
                return hint(
                    "your constant does not depend on the actions (it is 0): the loss here is not "
                    "symmetric around 0."
                )
            if any(abs(c - float(a)) < 1e-6 for a in actions):
                return hint(
                    "your constant is one of the actions an expert took, but the loss there "
                    f"({loss(c):.4f}) is not the smallest: "
                    "try c a little to either side. The optimum need not be an action anyone took."
                )
            n = len(actions)
            total = float(actions.sum())
            off_by_one = [total / (n - 1)] + [(total - float(a)) / (n - 1) for a in (actions[0], actions[-1])]
            if any(abs(c - v) < 1e-6 for v in off_by_one):
                return hint(
                    "close, but your constant leaves one action out or divides by N - 1: the loss averages "
                    "over all N actions, each counted once."
                )
            pos, neg = actions[actions > 0], actions[actions <= 0]
            if len(pos) and len(neg) and abs(c - (float(pos.mean()) + float(neg.mean())) / 2) < 1e-6:
                return hint(
                    "your constant weighs the two groups of actions equally, whatever their sizes: in the "
                    "loss every action counts once, so the bigger group pulls harder."
                )
            if abs(c - ref) < 2e-2:
                return hint(
                    "close, but not exact: set the derivative of the loss with respect to c to zero and "
                    "solve it exactly (a search over a grid of constants only lands near the optimum)."
                )
            return hint(
                f"for one of the test sets your constant gives a mean squared error of {loss(c):.4f}; a "
                "better constant exists. Differentiate the loss with respect to c."
            )
        return correct("The mean: it lies between the two modes, where no expert steered.")

    return run_check(check, "best_constant_mse")


# --------------------------------------------------------------------------- 2. collision check
def _hits_cases():
    """The chapter's scene: the tree at (20, 0), radii 1 (car) and 1.5 (tree)."""
    gen = torch.Generator().manual_seed(3)
    tree = torch.tensor([20.0, 0.0])
    # random points around the tree, plus hand-picked ones near the boundary (distance 2.5)
    pts = tree + torch.empty(200, 2).uniform_(-5.0, 5.0, generator=gen)
    special = torch.tensor(
        [
            [20.0, 2.4],
            [20.0, 2.6],
            [17.6, 0.0],
            [22.6, 0.0],
            [20.0 + 1.7, 1.7],
            [20.0 + 1.8, -1.8],
            [20.0, 0.0],
            [10.0, 0.0],
            [21.55, 0.0],
            [20.0, -1.05],
        ]
    )
    # exactly 2.5 m from the tree (exact in float32): the discs only touch, which is no collision
    touching = tree + torch.tensor([[2.5, 0.0], [0.0, -2.5], [-1.5, 2.0], [2.0, -1.5]])
    return torch.cat([pts, special, touching]), tree, 1.0, 1.5


def _hits_scenes():
    """The chapter's scene, then two others (another tree, other radii), so that an answer which
    hard-codes the chapter's numbers instead of using its arguments is told apart. Every scene has
    points exactly r_car + r_tree from the tree (dyadic numbers: exact in float32)."""
    scenes = [_hits_cases()]
    gen = torch.Generator().manual_seed(4)
    for tree, rc, rt in ((torch.tensor([-3.5, 7.25]), 0.75, 2.0), (torch.tensor([6.0, -12.5]), 1.25, 0.5)):
        r = rc + rt
        pts = tree + torch.empty(150, 2).uniform_(-2.2 * r, 2.2 * r, generator=gen)
        touching = tree + torch.tensor([[r, 0.0], [-r, 0.0], [0.0, r], [0.0, -r]])
        scenes.append((torch.cat([pts, touching]), tree, rc, rt))
    return scenes


def _hits_diagnose(got, xy, tree, rc, rt, ref) -> Feedback:
    """The hint for an answer ``got`` that differs from ``ref`` on one scene."""
    dist = (xy - tree).norm(dim=1)
    if torch.equal(got, dist <= rc + rt) or torch.equal(got, ((xy - tree) ** 2).sum(1) <= (rc + rt) ** 2):
        return hint(
            "right everywhere except where the two discs only touch (centres exactly r_car + r_tree "
            "apart): touching is not overlapping, so that comparison must be strict."
        )
    if torch.equal(got, dist < rt) or torch.equal(got, dist <= rt):
        return hint(
            "a car whose centre stays outside the tree's disc can still touch it: the car has a size too."
        )
    if torch.equal(got, dist < rc) or torch.equal(got, dist <= rc):
        return hint("the tree has a size too, not only the car.")
    if torch.equal(got, dist < 2 * (rc + rt)):
        return hint("you flag collisions too far from the tree: are you using diameters where radii belong?")
    if torch.equal(got, dist**2 < rc + rt) or torch.equal(got, dist < (rc + rt) ** 2):
        return hint(
            "compare like with like: a squared distance with a squared length, or a distance with a length."
        )
    if torch.equal(got, (xy[:, 0] - tree[0]).abs() < rc + rt) or torch.equal(
        got, (xy[:, 1] - tree[1]).abs() < rc + rt
    ):
        return hint("the distance between the centres depends on both coordinates, x and y.")
    if torch.equal(got, ~(dist < rc + rt)):
        return hint("your answer is the opposite: True should mean the discs overlap.")
    if torch.equal(got, xy.norm(dim=1) < rc + rt):
        return hint("measure the distance from the tree's centre, `tree_xy`, not from the origin.")
    _, tree0, rc0, rt0 = _hits_cases()
    if not torch.equal(tree, tree0) and (
        torch.equal(got, (xy - tree0).norm(dim=1) < rc + rt)
        or torch.equal(got, (xy - tree0).norm(dim=1) < rc0 + rt0)
    ):
        return hint(
            f"right for the chapter's tree at {tree0.tolist()}, wrong for a tree at {tree.tolist()}: use the "
            "argument `tree_xy`, not the chapter's numbers."
        )
    if (rc, rt) != (rc0, rt0) and torch.equal(got, dist < rc0 + rt0):
        return hint(
            f"right for the chapter's radii ({rc0} and {rt0} m), wrong for radii {rc} and {rt} m: use the "
            "arguments `car_radius` and `tree_radius`, not the chapter's numbers."
        )
    wrong = int((got != ref).sum())
    first = xy[(got != ref).nonzero()[0, 0]].tolist()
    return hint(
        f"{wrong} of {len(xy)} positions get the wrong answer; for instance a car at {first} (tree at "
        f"{tree.tolist()}, radii {rc} and {rt})."
    )


def check_hits_tree(fn) -> Feedback:
    """Check ``fn(car_xy, tree_xy, car_radius, tree_radius) -> (B,) bool`` (discs overlap) on three
    scenes: the chapter's tree and radii, and two others."""

    def check() -> Feedback:
        for xy, tree, rc, rt in _hits_scenes():
            out = fn(xy.clone(), tree.clone(), rc, rt)
            if not isinstance(out, torch.Tensor):
                return hint(
                    f"return a torch.Tensor of booleans, one per car position, got {type(out).__name__}."
                )
            if out.shape != (len(xy),):
                return hint(
                    f"return one answer per car position: shape ({len(xy)},) for {len(xy)} positions, "
                    f"got {tuple(out.shape)}."
                )
            got = out.detach().bool() if out.dtype == torch.bool else out.detach() != 0
            ref = (xy - tree).norm(dim=1) < rc + rt
            if not torch.equal(got, ref):
                return _hits_diagnose(got, xy, tree, rc, rt, ref)
        return correct("Two discs overlap when their centres are closer than the sum of their radii.")

    return run_check(check, "hits_tree")


# --------------------------------------------------------------------------- 3. swerve
def _swerve_cases() -> torch.Tensor:
    """(E=8, T=30) lateral offsets: most bumps to the right (-y); the last two episodes never move
    right of where they started (one drifts steadily left, one holds its line), so their swerve is 0."""
    gen = torch.Generator().manual_seed(5)
    t = torch.linspace(0, 1, 30)
    start = torch.empty(6, 1).uniform_(-0.3, 0.3, generator=gen)
    bump = torch.tensor([[0.8], [0.0], [-0.5], [0.3], [1.2], [0.05]]) * torch.sin(torch.pi * t)[None, :]
    drift = torch.tensor([[0.0], [0.2], [0.0], [-0.4], [0.0], [0.0]]) * t[None, :]
    moving = -(start + bump + drift + 0.01 * torch.randn(6, 30, generator=gen))
    away = 0.2 + 0.5 * t[None, :]  # only ever moves left (y increasing): no swerve
    steady = torch.full((1, 30), -0.15)  # holds its line: no swerve
    return torch.cat([moving, away, steady])


def check_swerve(fn) -> Feedback:
    """Check ``fn(y) -> (E,)``: max over t of (y_0 - y_t) for each episode (row), t = 0 included."""

    def check() -> Feedback:
        y = _swerve_cases()
        out = fn(y.clone())
        if not isinstance(out, torch.Tensor):
            return hint(f"return a torch.Tensor with one swerve per episode, got {type(out).__name__}.")
        ref = y[:, 0] - y.min(dim=1).values  # >= 0: t = 0 is one of the t
        if out.shape != ref.shape:
            if out.shape == (y.shape[1],):
                return hint(
                    f"return one number per episode (rows, {y.shape[0]} of them), not one per time step: "
                    "which dimension do you reduce over?"
                )
            return hint(f"return one number per episode: shape ({y.shape[0]},), got {tuple(out.shape)}.")
        out = out.detach().to(ref.dtype)
        if torch.allclose(out, ref, atol=1e-5):
            return correct("The largest move towards the side road, measured from where the car was.")
        low = y.min(dim=1).values
        if torch.allclose(out, (-low).clamp_min(0.0), atol=1e-5) or torch.allclose(out, -low, atol=1e-5):
            return hint(
                "measure from where each car was at the start (its first offset), not from the centre "
                "line: a car driving a little off-centre all along has not swerved."
            )
        if torch.allclose(out, y.max(dim=1).values - y[:, 0], atol=1e-5):
            return hint(
                "that is the largest move to the left (y increasing); the side road branches off to the "
                "right, where y decreases."
            )
        if torch.allclose(out, (y - y[:, :1]).abs().max(dim=1).values, atol=1e-5):
            return hint(
                "only moves towards the side road (to the right, y decreasing) count as a swerve towards it."
            )
        if torch.allclose(out, (y[:, 0] - y[:, -1]).clamp_min(0.0), atol=1e-5):
            return hint(
                "the swerve is the *largest* deviation during the episode, not where the car ends up."
            )
        if torch.allclose(out, low - y[:, 0], atol=1e-5):
            return hint(
                "check the sign: a swerve is a distance moved, at least 0, so count the moves towards -y."
            )
        later = y[:, 0] - y[:, 1:].min(dim=1).values  # the largest move over t >= 1 only
        if torch.allclose(out, later, atol=1e-5):
            return hint(
                "a car that never moves right of where it started (it drifts left, or holds its line) has "
                "swerved 0, not a negative amount: t = 0 is one of the t in the max."
            )
        if (out < -1e-6).any():
            return hint(
                "a swerve is a distance moved towards the side road, at least 0: some of yours are negative."
            )
        return hint(
            "for some episodes your value differs from the largest move towards the side road (y "
            "decreasing) since the first time step."
        )

    return run_check(check, "swerve")


# ------------------------------------------------------------------------- 4. prediction: where the MAE lands
MAE_ANSWERS = ("right", "left", "anywhere in the gap")


def _mae_optimal_side(n_right: int, n_left: int) -> str:
    """Where the constants of least mean absolute error lie for ``n_right`` actions near +0.75 and
    ``n_left`` near -0.7, computed on a grid of constants (the library's answer to the prediction)."""
    actions = _bimodal_actions(7, n_right, n_left).double()  # (N,)
    grid = torch.linspace(-1, 1, 4001, dtype=torch.float64)  # (G,)
    mae = (actions[None, :] - grid[:, None]).abs().mean(1)  # (G,)
    best = grid[mae <= mae.min() + 1e-9]  # every constant that attains the minimum (flat to ~1e-15)
    gap = (float(actions[actions < 0].max()), float(actions[actions > 0].min()))
    if float(best.min()) <= gap[0] + 1e-3 and float(best.max()) >= gap[1] - 1e-3:
        return "anywhere in the gap"
    return "right" if float(best.mean()) > 0 else "left"


def check_predict_mae_side(fn) -> Feedback:
    """Check ``fn(n_right, n_left) -> one of MAE_ANSWERS``: the reader's prediction of where the
    constant of least mean absolute error lies, for actions from two modes (right about +0.75,
    left about -0.7) with ``n_right`` and ``n_left`` samples, against the minimum on a grid."""

    def check() -> Feedback:
        # counts one apart (51 : 50, 40 : 41, 3 : 2): a tie "when the counts are close" is told apart
        cases = [
            (60, 40),
            (30, 70),
            (50, 50),
            (51, 49),
            (10, 90),
            (80, 80),
            (51, 50),
            (40, 41),
            (3, 2),
            (7, 7),
        ]
        wrong = []  # (n_right, n_left, answer, truth) for every case answered wrongly
        for n_right, n_left in cases:
            answer = fn(n_right, n_left)
            if answer not in MAE_ANSWERS:
                return hint(f"answer with one of {MAE_ANSWERS}, got {answer!r}.")
            truth = _mae_optimal_side(n_right, n_left)
            if answer != truth:
                wrong.append((n_right, n_left, answer, truth))
        if wrong:
            n_right, n_left, answer, truth = wrong[0]
            if truth == "anywhere in the gap":
                return hint(
                    f"with {n_right} actions on each side, count the samples above and below a constant in "
                    "the gap: does moving it within the gap change the mean absolute error?"
                )
            if answer == "anywhere in the gap":
                sided = [c for c in cases if _mae_optimal_side(*c) != "anywhere in the gap"]
                some_sided_right = any(fn(*c) == _mae_optimal_side(*c) for c in sided)
                if some_sided_right and all(w[2] == "anywhere in the gap" for w in wrong):
                    r, n = min(((w[0], w[1]) for w in wrong), key=lambda c: abs(c[0] - c[1]))
                    return hint(
                        f"for {r} right and {n} left: even one sample more on one side breaks the tie. "
                        "Where is the MAE's slope, (#below - #above)/N, zero?"
                    )
                return hint(
                    "you answer like the mean (the MSE's optimum) or as if the counts did not matter. "
                    f"For {n_right} right and {n_left} left, which value has half the samples on each side?"
                )
            return hint(
                f"for {n_right} right and {n_left} left you picked the smaller mode: the median lies in the "
                "mode that holds more than half of the samples."
            )
        return correct(
            "A median: in the bigger mode when the counts differ, anywhere in the gap when they are equal. "
            "So an MAE policy follows the majority at the side road (straight on), but at the tree's near "
            "tie it is arbitrary."
        )

    return run_check(check, "`predict_mae_side`")
