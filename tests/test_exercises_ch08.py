"""Checkers of exercises/08_training_agents.ipynb: solution -> correct, stub -> not attempted,
typical mistakes -> a hint naming the mistake, code that raises -> a hint (never an exception)."""

import math

import numpy as np
import pytest
import torch

from ibc_tutorial.exercises import ch08, solutions

CHECKS = [
    (ch08.check_episode_score, solutions.ch08_episode_score),
    (ch08.check_unseen_share, solutions.ch08_unseen_share),
    (ch08.check_recipe, solutions.ch08_recipe),
]


@pytest.mark.parametrize("check, solution", CHECKS)
def test_solution_stub_and_crash(check, solution, stub_and_crash):
    assert check(solution).status == "correct"
    stub_and_crash(check)


# ----------------------------------------------------------------------- the solutions agree with the library
def test_episode_score_solution_is_the_simulators():
    # drive the real simulator and score its log with the solution
    from ibc_tutorial.driving.sim import DrivingSim

    sim = DrivingSim("town02")
    sim.reset(np.random.default_rng(3))
    xy, crossed = [sim.car.pose[:2]], []
    for t in range(150):
        sim.step(0.1 * math.sin(t / 10), 0.6)
        xy.append(sim.car.pose[:2])
        crossed.append(2 if sim.ran_lights else -1)
    assert sim.distance > 50
    assert solutions.ch08_episode_score(np.array(xy), np.array(crossed)) == pytest.approx(sim.score, rel=1e-9)


def test_unseen_share_solution_is_the_training_draws():
    # one epoch of the training loop's draws (training.draw_minibatch, ceil(M / B) minibatches)
    from ibc_tutorial.experiments.agents.train import steps_per_epoch
    from ibc_tutorial.training import draw_minibatch

    probs = torch.tensor(ch08._probs())
    m, b = len(probs), 96
    gen = torch.Generator().manual_seed(0)
    unseen = []
    for _ in range(300):
        drawn = torch.cat([draw_minibatch(probs, m, b, gen) for _ in range(steps_per_epoch(m, b))])
        unseen.append(1 - len(torch.unique(drawn)) / m)
    assert np.mean(unseen) == pytest.approx(solutions.ch08_unseen_share(probs.numpy(), b), abs=0.003)


def test_recipes_are_the_librarys_agents():
    from ibc_tutorial.experiments.agents.agent import dfo_config
    from ibc_tutorial.experiments.agents.presets import TINY
    from ibc_tutorial.experiments.agents.train import objective_for

    class Recorder(torch.nn.Module):  # an energy model that records the candidates it is asked about
        def __init__(self):
            super().__init__()
            self.w = torch.nn.Parameter(torch.zeros(()))

        def energy(self, obs, candidates):
            self.candidates = candidates.detach()  # (B, 1 + N, D)
            return self.w * candidates.sum(-1)

    expert = torch.full((16, 2), 0.9)
    for method, recipe in ch08.RECIPES.items():
        cfg = dfo_config(method, TINY)
        assert (recipe["dfo_init"], recipe["dfo_select"]) == (
            (None, None) if cfg is None else (cfg.init, cfg.select)
        )
        if method == "bc":
            assert recipe["negatives"] is None
            continue
        net = Recorder()
        objective_for(method, net, TINY)({"obs": None, "actions": expert}, torch.Generator().manual_seed(0))
        negatives = net.candidates[:, 1:]  # (B, N, 2)
        near_expert = bool(((negatives - 0.9).abs() < 5 * TINY.neg_sigma).all())
        assert recipe["negatives"] == ("expert + noise" if near_expert else "uniform")
        assert (
            near_expert or float(negatives.min()) < -0.5
        )  # uniform over the box reaches far from the expert


# --------------------------------------------------------------------------- typical mistakes
def _score(path=True, counts=(2,), penalty="power"):
    return lambda xy, crossed: ch08._score_ref(xy, crossed, path=path, counts=counts, penalty=penalty)


SCORE_MISTAKES = {
    "displacement": (_score(path=False), "length of the path"),
    "no penalty": (_score(penalty="none"), "red lights cost"),
    "yellow counts": (_score(counts=(1, 2)), "at yellow is legal"),
    "any crossing counts": (_score(counts=(0, 1, 2)), "green or yellow"),
    "linear penalty": (_score(penalty="linear"), "compounds"),
    "0.7 times n": (_score(penalty="times n"), "not 0.7 times n"),
    "metres off": (_score(penalty="subtract"), "not metres taken off"),
    "other factor": (lambda xy, c: solutions.ch08_episode_score(xy, c) * 0.5, "sum over steps"),
    "returns a string": (lambda xy, c: "far", "number"),
    "returns a bool": (lambda xy, c: True, "number"),
}


@pytest.mark.parametrize("name", list(SCORE_MISTAKES))
def test_episode_score_mistakes(name):
    fn, words = SCORE_MISTAKES[name]
    fb = ch08.check_episode_score(fn)
    assert fb.status == "hint" and words in fb.message, fb.message


def _unseen(**kwargs):
    return lambda p, b: ch08._unseen_ref(p, b, **kwargs)


def _simulated(p, b):  # a Monte Carlo estimate: near, not exact
    rng = np.random.default_rng(0)
    n = math.ceil(len(p) / b) * b
    return float(np.mean([1 - len(np.unique(rng.choice(len(p), n, p=p))) / len(p) for _ in range(20)]))


UNSEEN_MISTAKES = {
    "uniform": (_unseen(uniform=True), "weighted"),
    "M draws": (_unseen(draws="m"), "a few more than M"),
    "floor": (_unseen(draws="floor"), "rounded up"),
    "one minibatch": (_unseen(draws="batch"), "one minibatch"),
    "linear": (_unseen(linear=True), "(1 - p_i) ** n"),
    "without replacement": (
        lambda p, b: max(0.0, 1 - math.ceil(len(p) / b) * b / len(p)),
        "with replacement",
    ),
    "count": (_unseen(count=True), "*number*"),
    "simulation": (_simulated, "expectation exactly"),
    "seen share": (lambda p, b: 1 - solutions.ch08_unseen_share(p, b), "none of the epoch's draws"),
}


@pytest.mark.parametrize("name", list(UNSEEN_MISTAKES))
def test_unseen_share_mistakes(name):
    fn, words = UNSEEN_MISTAKES[name]
    fb = ch08.check_unseen_share(fn)
    assert fb.status == "hint" and words in fb.message, fb.message


def _recipe(**changes):
    def fn(method):
        out = dict(solutions.ch08_recipe(method))
        out.update(changes.get(method, {}))
        return out

    return fn


RECIPE_MISTAKES = {
    "da-ibc argmax": (_recipe(**{"da-ibc": {"dfo_select": "argmax"}}), "draws the action"),
    "ibc from the expert": (_recipe(ibc={"dfo_init": "inverse-kde"}), "without looking at the expert"),
    "da-ibc uniform negatives": (
        _recipe(**{"da-ibc": {"negatives": "uniform"}}),
        "minibatch's own expert actions",
    ),
    "bc with DFO": (_recipe(bc={"dfo_init": "uniform"}), "never runs DFO"),
    "bc infonce": (_recipe(bc={"loss": "infonce"}), "Beta head"),
    "unknown word": (_recipe(ibc={"negatives": "random"}), "must be one of"),
    "missing key": (lambda m: {"loss": "infonce"}, "exactly the keys"),
}


@pytest.mark.parametrize("name", list(RECIPE_MISTAKES))
def test_recipe_mistakes(name):
    fn, words = RECIPE_MISTAKES[name]
    fb = ch08.check_recipe(fn)
    assert fb.status == "hint" and words in fb.message, fb.message


def test_recipe_accepts_other_capitals():
    def shout(method):
        return {k: v.upper() if isinstance(v, str) else v for k, v in solutions.ch08_recipe(method).items()}

    assert ch08.check_recipe(shout).status == "correct"


# --------------------------------------------------------------------------- issue 26: the paper's conclusion
def test_recipe_accepts_ibc_ending_with_a_draw():
    """The paper's conclusion names the counter-examples and the DFO's initialisation; an IBC that ends
    with Algorithm 1's draw is a defensible reading, accepted and told apart from the book's."""
    fb = ch08.check_recipe(_recipe(ibc={"dfo_select": "sample"}))
    assert fb.status == "correct" and "does not say" in fb.message, fb.message
    fb = ch08.check_recipe(solutions.ch08_recipe)
    assert fb.status == "correct" and "book's reading" in fb.message, fb.message
    for message in (fb.message, ch08.check_recipe(_recipe(ibc={"dfo_select": "sample"})).message):
        assert "as the paper's conclusion says" not in message
        assert "initialis" in message


def test_recipe_other_readings_do_not_open_other_holes():
    """Only IBC's ending has a second reading: DA-IBC's argmax and IBC without DFO stay wrong."""
    assert ch08.check_recipe(_recipe(**{"da-ibc": {"dfo_select": "argmax"}})).status == "hint"
    fb = ch08.check_recipe(_recipe(ibc={"dfo_select": None}))
    assert fb.status == "hint" and "runs DFO too" in fb.message, fb.message
    fb = ch08.check_recipe(_recipe(ibc={"dfo_init": None, "dfo_select": None}))
    assert fb.status == "hint"


def test_exercise_1_says_the_score_is_the_papers_own():
    import json
    from pathlib import Path

    nb = json.loads(Path(__file__).parents[1].joinpath("exercises/08_training_agents.ipynb").read_text())
    text = next("".join(c["source"]) for c in nb["cells"] if "".join(c["source"]).startswith("## Exercise 1"))
    assert "as CARLA's leaderboard does" not in text
    assert "its own score" in text and "route completion" in text


def test_a_numpy_boolean_is_not_a_number():
    """np.True_ converts to 1.0 like True; numpy 2 names its type "bool", which the check used to miss."""
    fb = ch08.check_unseen_share(lambda probs, batch_size: np.bool_(True))
    assert fb.status == "hint" and "must return a number" in fb.message, fb.message
