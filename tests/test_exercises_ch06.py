"""Checkers of exercises/06_dfo_inference.ipynb: solution -> correct, stub -> not attempted,
typical mistakes -> a hint naming the mistake, code that raises -> a hint (never an exception)."""

import pytest
import torch

from ibc_tutorial.exercises import ch06, solutions


def stub(*args, **kwargs):
    raise NotImplementedError


def raises(*args, **kwargs):
    raise ZeroDivisionError("division by zero")


def test_dfo_step_solution_is_correct():
    assert ch06.check_dfo_step(solutions.ch06_dfo_step).status == "correct"


def test_dfo_step_stub_and_crash():
    assert ch06.check_dfo_step(stub).status == "not attempted"
    fb = ch06.check_dfo_step(raises)
    assert fb.status == "hint" and "ZeroDivisionError" in fb.message


def _step(sign=-1.0, resample=True, noise="sigma", clip="clamp", use_gen=True):
    def fn(samples, energies, sigma, low, high, generator):
        gen = generator if use_gen else None
        p = torch.softmax(sign * energies, dim=0)
        idx = torch.multinomial(p, len(samples), replacement=True, generator=gen) if resample else torch.arange(len(samples))
        scale = {"sigma": sigma, "sigma2": sigma**2, "none": 0.0}[noise]
        new = samples[idx] + scale * torch.randn(samples.shape, generator=gen)
        if clip == "clamp":
            return new.clamp(low, high)
        if clip == "redraw":  # reflect out-of-bounds samples back inside
            new = torch.where(new > high, 2 * high - new, new)
            return torch.where(new < low, 2 * low - new, new)
        return new

    return fn


STEP_MISTAKES = {
    "softmax of +E": (_step(sign=1.0), "softmax of −E"),
    "no resampling": (_step(resample=False), "resample with replacement"),
    "sigma squared": (_step(noise="sigma2"), "σ²"),
    "no noise": (_step(noise="none"), "add Gaussian noise"),
    "no clip": (_step(clip="none"), "clip them"),
    "reflect instead of clamp": (_step(clip="redraw"), "clamped onto it"),
    "global generator": (_step(use_gen=False), "generator"),
    "wrong shape": (lambda s, e, sg, lo, hi, g: solutions.ch06_dfo_step(s, e, sg, lo, hi, g)[:, 0], "shape"),
}


@pytest.mark.parametrize("name", list(STEP_MISTAKES))
def test_dfo_step_mistakes_get_a_hint_naming_them(name):
    fn, words = STEP_MISTAKES[name]
    fb = ch06.check_dfo_step(fn)
    assert fb.status == "hint", (name, fb)
    assert words in fb.message, (name, fb.message)


def test_select_action_solution_is_correct():
    assert ch06.check_select_action(solutions.ch06_select_action).status == "correct"


def test_select_action_stub_and_crash():
    assert ch06.check_select_action(stub).status == "not attempted"
    assert ch06.check_select_action(raises).status == "hint"


def _select(sign=-1.0, argmax_max=False, always_best=False, uniform=False):
    def fn(samples, energies, select, generator):
        p = torch.softmax(sign * energies, dim=0)
        if select == "argmax":
            return samples[int(energies.argmax())] if argmax_max else samples[int(energies.argmin())]
        if always_best:
            return samples[int(p.argmax())]
        if uniform:
            return samples[int(torch.randint(len(samples), (1,), generator=generator))]
        return samples[int(torch.multinomial(p, 1, generator=generator))]

    return fn


SELECT_MISTAKES = {
    "argmax of energy": (_select(argmax_max=True), "lowest* energy"),
    "sample from softmax(+E)": (_select(sign=1.0), "p̃ is the softmax of −E"),
    "always the best": (_select(always_best=True), "*drawn*"),
    "uniform draw": (_select(uniform=True), "equally often"),
    "returns an index": (lambda s, e, sel, g: int(e.argmin()), "torch.Tensor"),
}


@pytest.mark.parametrize("name", list(SELECT_MISTAKES))
def test_select_action_mistakes_get_a_hint_naming_them(name):
    fn, words = SELECT_MISTAKES[name]
    fb = ch06.check_select_action(fn)
    assert fb.status == "hint", (name, fb)
    assert words in fb.message, (name, fb.message)
