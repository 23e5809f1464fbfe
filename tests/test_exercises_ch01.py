"""Checkers of exercises/01_the_tree.ipynb: solution -> correct, stub -> not attempted,
typical mistakes -> a hint naming the mistake, code that raises -> a hint (never an exception)."""

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from ibc_tutorial.exercises import ch01, solutions
from ibc_tutorial.toy import TreeWorld


def stub(*args):
    raise NotImplementedError


CHECKERS = {
    "best_constant_mse": (ch01.check_best_constant_mse, solutions.ch01_best_constant_mse),
    "hits_tree": (ch01.check_hits_tree, solutions.ch01_hits_tree),
    "swerve": (ch01.check_swerve, solutions.ch01_swerve),
}


@pytest.mark.parametrize("name", list(CHECKERS))
def test_solution_is_correct_and_stub_not_attempted(name):
    check, solution = CHECKERS[name]
    assert check(solution).status == "correct"
    assert check(stub).status == "not attempted"


@pytest.mark.parametrize("name", list(CHECKERS))
def test_code_that_raises_gets_a_hint(name):
    check, _ = CHECKERS[name]

    def broken(*args):
        return args[0].nonexistent_method()

    fb = check(broken)
    assert fb.status == "hint" and "AttributeError" in fb.message


def test_library_agrees_with_the_solutions():
    """The chapter's world uses the same definitions the exercises teach."""
    w = TreeWorld()
    pts = torch.tensor([[20.0, 2.4], [20.0, 2.6], [0.0, 0.0], [18.0, -1.0]])
    tree = torch.tensor([w.config.tree_x, 0.0])
    assert torch.equal(
        w.collides(pts), solutions.ch01_hits_tree(pts, tree, w.config.car_radius, w.config.tree_radius)
    )


# --------------------------------------------------------------------------- best constant
@pytest.mark.parametrize(
    "wrong, words",
    [
        (lambda a: float(a.median()), "absolute"),
        (lambda a: float(a.sum()), "number of actions"),
        (lambda a: 0.0, "does not depend"),
        (lambda a: float(a[0]), "one of the actions"),
        (
            lambda a: float(
                torch.linspace(-1, 1, 101)[
                    ((a[None, :] - torch.linspace(-1, 1, 101)[:, None]) ** 2).mean(1).argmin()
                ]
            ),
            "grid",
        ),
        (lambda a: a, "one number"),
        (lambda a: float(a.mean()) + 0.3, "better constant"),
    ],
)
def test_best_constant_mistakes(wrong, words):
    fb = ch01.check_best_constant_mse(wrong)
    assert fb.status == "hint" and words in fb.message, fb.message
    assert "mean" not in fb.message.lower().replace("mean squared", "").replace(
        "mean *absolute*", ""
    )  # the answer is not given


def test_best_constant_accepts_a_tensor():
    assert ch01.check_best_constant_mse(lambda a: a.mean()).status == "correct"


# --------------------------------------------------------------------------- collision check
@pytest.mark.parametrize(
    "wrong, words",
    [
        (lambda xy, t, rc, rt: (xy - t).norm(dim=1) < rt, "the car has a size"),
        (lambda xy, t, rc, rt: (xy - t).norm(dim=1) < rc, "tree has a size"),
        (lambda xy, t, rc, rt: (xy - t).norm(dim=1) < 2 * (rc + rt), "diameters"),
        (lambda xy, t, rc, rt: ((xy - t) ** 2).sum(1) < rc + rt, "like with like"),
        (lambda xy, t, rc, rt: (xy[:, 0] - t[0]).abs() < rc + rt, "both coordinates"),
        (lambda xy, t, rc, rt: (xy - t).norm(dim=1) >= rc + rt, "opposite"),
        (lambda xy, t, rc, rt: (xy - t).norm(dim=1) <= rc + rt, "only touch"),
        (lambda xy, t, rc, rt: ((xy - t) ** 2).sum(1) <= (rc + rt) ** 2, "only touch"),
        (lambda xy, t, rc, rt: bool(((xy - t).norm(dim=1) < rc + rt).any()), "Tensor"),
        (lambda xy, t, rc, rt: ((xy - t).norm(dim=1) < rc + rt)[:, None], "one answer per car position"),
    ],
)
def test_hits_tree_mistakes(wrong, words):
    fb = ch01.check_hits_tree(wrong)
    assert fb.status == "hint" and words in fb.message, fb.message
    assert "sum of" not in fb.message


def test_hits_tree_accepts_float_flags():
    assert (
        ch01.check_hits_tree(lambda xy, t, rc, rt: ((xy - t).norm(dim=1) < rc + rt).float()).status
        == "correct"
    )


def test_hits_tree_accepts_squared_distances():
    assert (
        ch01.check_hits_tree(lambda xy, t, rc, rt: ((xy - t) ** 2).sum(1) < (rc + rt) ** 2).status
        == "correct"
    )


def test_touching_is_no_collision_in_the_checker_nor_the_library():
    """The checker tests positions exactly r_car + r_tree from the tree, where the discs only touch."""
    xy, tree, rc, rt = ch01._hits_cases()
    touching = (xy - tree).norm(dim=1) == rc + rt
    assert touching.sum() >= 4
    w = TreeWorld()
    assert not w.collides(xy[touching]).any()
    assert not solutions.ch01_hits_tree(xy[touching], tree, rc, rt).any()


# --------------------------------------------------------------------------- swerve
@pytest.mark.parametrize(
    "wrong, words",
    [
        (lambda y: y[:, 0] - y.max(dim=1).values, "negative"),
        (lambda y: y.max(dim=1).values - y[:, 0], "to the right"),  # towards +y: the left
        (lambda y: y.min(dim=1).values - y[:, 0], "sign"),
        (lambda y: (-y.min(dim=1).values).clamp_min(0.0), "from where each car was"),
        (lambda y: (y - y[:, :1]).abs().max(dim=1).values, "towards the side road"),
        (lambda y: (y[:, 0] - y[:, -1]).clamp_min(0.0), "largest"),
        (lambda y: (y[0] - y.min(dim=0).values).clamp_min(0.0), "which dimension"),
        (lambda y: 0.5, "torch.Tensor"),
    ],
)
def test_swerve_mistakes(wrong, words):
    fb = ch01.check_swerve(wrong)
    assert fb.status == "hint" and words in fb.message, fb.message


def test_swerve_matches_the_library_measure():
    """The exercise's swerve is the side-road world's, on the part of each episode it looks at."""
    from ibc_tutorial.toy import SideRoadWorld

    w = SideRoadWorld()
    ro = w.rollout(lambda obs: 0.1 * torch.ones(len(obs), 1) * (obs < 0.5), 5, seed=0)
    near = ro.states[0, :, 0] >= w.config.branch_x - w.config.swerve_from
    first = int(near.float().argmax())
    y = ro.states[
        :, first:, 1
    ]  # every episode reaches the section at the same step here (straight until then)
    assert torch.allclose(w.swerve(ro), solutions.ch01_swerve(y))


def test_predict_mae_side():
    check = ch01.check_predict_mae_side
    assert check(solutions.ch01_predict_mae_side).status == "correct"
    assert check(stub).status == "not attempted"
    mistakes = {
        "the mean": (lambda r, n: "anywhere in the gap", "like the mean"),
        "smaller mode": (
            lambda r, n: "right" if r < n else ("left" if n < r else "anywhere in the gap"),
            "smaller mode",
        ),
        "no tie": (lambda r, n: "right" if r >= n else "left", "samples above and below"),
        "tie too wide": (
            lambda r, n: "right" if r - n > 5 else ("left" if n - r > 5 else "anywhere in the gap"),
            "breaks the tie",
        ),
        "not an answer": (lambda r, n: "straight", "answer with one of"),
    }
    for fn, words in mistakes.values():
        fb = check(fn)
        assert fb.status == "hint" and words in fb.message, fb.message


# -------------------------------------------------------- holes closed (issue 26): answers that were accepted
@settings(max_examples=30, deadline=None)
@given(
    tx=st.floats(-30, 30, allow_nan=False),
    ty=st.floats(-30, 30, allow_nan=False),
    r=st.floats(0.5, 5.0, allow_nan=False),
)
def test_hits_tree_that_ignores_its_arguments_is_not_correct(tx, ty, r):
    """Any tree position and radius sum hard-coded into the function, instead of read from the
    arguments, gets a hint: the checker asks about trees and radii other than the chapter's."""
    tree = torch.tensor([tx, ty])

    def hard_coded(xy, t, rc, rt):
        return (xy - tree).norm(dim=1) < r

    assert ch01.check_hits_tree(hard_coded).status == "hint"


@pytest.mark.parametrize(
    "wrong, words",
    [
        (lambda xy, t, rc, rt: (xy - torch.tensor([20.0, 0.0])).norm(dim=1) < rc + rt, "`tree_xy`"),
        (lambda xy, t, rc, rt: (xy - torch.tensor([20.0, 0.0])).norm(dim=1) < 2.5, "`tree_xy`"),
        (lambda xy, t, rc, rt: (xy - t).norm(dim=1) < 2.5, "`car_radius`"),
        (lambda xy, t, rc, rt: xy.norm(dim=1) < rc + rt, "from the tree's centre"),
    ],
)
def test_hits_tree_hard_coded_numbers_are_named(wrong, words):
    fb = ch01.check_hits_tree(wrong)
    assert fb.status == "hint" and words in fb.message, fb.message


def test_hits_tree_scenes_touch_exactly():
    """Every scene has positions exactly r_car + r_tree from its tree: strictness is tested in each."""
    for xy, tree, rc, rt in ch01._hits_scenes():
        assert int(((xy - tree).norm(dim=1) == rc + rt).sum()) >= 4


@pytest.mark.parametrize(
    "wrong, words",
    [
        (lambda y: y[:, 0] - y[:, 1:].min(dim=1).values, "t = 0"),  # skips t = 0
        (lambda y: (y[:, :1] - y[:, 1:]).max(dim=1).values, "t = 0"),  # the same, written otherwise
        (lambda y: (y[:, 0] - y.min(dim=1).values) - 0.01 * (y[:, -1] > y[:, 0]), "negative"),
    ],
)
def test_swerve_that_skips_t0_or_goes_negative_is_not_correct(wrong, words):
    fb = ch01.check_swerve(wrong)
    assert fb.status == "hint" and words in fb.message, fb.message


@settings(max_examples=20, deadline=None)
@given(k=st.integers(1, 10))
def test_swerve_from_a_later_step_is_not_correct(k):
    """Starting the max at any t = k >= 1 (an off-by-one in a loop) gets a hint."""
    assert ch01.check_swerve(lambda y: y[:, 0] - y[:, k:].min(dim=1).values).status == "hint"


def test_swerve_cases_include_episodes_without_a_swerve():
    y = ch01._swerve_cases()
    assert int((solutions.ch01_swerve(y) == 0).sum()) >= 2
    assert bool((y[:, 1:] > y[:, :1]).all(dim=1).any())  # one episode only ever moves left


@settings(max_examples=20, deadline=None)
@given(margin=st.integers(1, 30))
def test_predict_mae_side_tie_with_a_margin_is_not_correct(margin):
    """ "A tie when the counts differ by at most `margin`" gets a hint for every margin >= 1."""

    def fn(r, n):
        if abs(r - n) <= margin:
            return "anywhere in the gap"
        return "right" if r > n else "left"

    fb = ch01.check_predict_mae_side(fn)
    assert fb.status == "hint" and "breaks the tie" in fb.message, fb.message


@settings(max_examples=20, deadline=None)
@given(share=st.floats(0.505, 0.9))
def test_predict_mae_side_by_a_share_above_half_is_not_correct(share):
    """ "Right only if more than `share` of the samples are right", for any share above 50.5 %."""

    def fn(r, n):
        if r > share * (r + n):
            return "right"
        if n > share * (r + n):
            return "left"
        return "anywhere in the gap"

    assert ch01.check_predict_mae_side(fn).status == "hint"


@pytest.mark.parametrize(
    "wrong, words",
    [
        (lambda a: float(a[1:].mean()), "leaves one action out"),
        (lambda a: float(a[:-1].mean()), "leaves one action out"),
        (lambda a: float(a.sum() / (len(a) - 1)), "N - 1"),
        (lambda a: float((a[a > 0].mean() + a[a <= 0].mean()) / 2), "two groups"),
    ],
)
def test_best_constant_near_misses_are_named(wrong, words):
    """Off by one action, or the two groups weighed alike: the hint says which, not "a grid search"."""
    fb = ch01.check_best_constant_mse(wrong)
    assert fb.status == "hint" and words in fb.message, fb.message
    assert "mean" not in fb.message.lower().replace("mean squared", "")  # the answer is not given
