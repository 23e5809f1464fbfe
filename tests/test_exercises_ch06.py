"""Checkers of exercises/06_dfo_inference.ipynb: solution -> correct, stub -> not attempted,
typical mistakes -> a hint naming the mistake, code that raises -> a hint (never an exception)."""

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from ibc_tutorial.exercises import ch06, solutions


@pytest.mark.parametrize("checker", [ch06.check_dfo_step, ch06.check_select_action, ch06.check_shallow_share])
def test_stub_is_not_attempted_and_a_crash_is_a_hint(checker, stub_and_crash):
    stub_and_crash(checker)


def test_dfo_step_solution_is_correct():
    assert ch06.check_dfo_step(solutions.ch06_dfo_step).status == "correct"


def _step(
    sign=-1.0,
    resample=True,
    noise="sigma",
    clip="clamp",
    use_gen=True,
    order="after",
    shape="full",
    law="normal",
):
    def fn(samples, energies, sigma, low, high, generator):
        gen = generator if use_gen else None
        p = torch.softmax(sign * energies, dim=0)
        idx = (
            torch.multinomial(p, len(samples), replacement=True, generator=gen)
            if resample
            else torch.arange(len(samples))
        )
        scale = {"sigma": sigma, "sigma2": sigma**2, "none": 0.0}[noise]
        n_shape = {"full": samples.shape, "per_sample": (len(samples), 1), "one": (1, 1)}[shape]
        if law == "normal":
            z = torch.randn(n_shape, generator=gen)
        elif law == "uniform":  # the same standard deviation as N(0, 1)
            z = (2 * torch.rand(n_shape, generator=gen) - 1) * math.sqrt(3.0)
        else:  # Laplace with standard deviation 1
            u = torch.rand(n_shape, generator=gen) - 0.5
            z = -torch.sign(u) * torch.log1p(-2 * u.abs()) / math.sqrt(2.0)
        if order == "before":  # noise first, then resampling: copies of noisy samples
            new = (samples + scale * z)[idx]
        else:
            new = samples[idx] + scale * z
        if clip == "clamp":
            return new.clamp(low, high)
        if clip == "upper":
            return new.clamp(max=high)
        if clip == "lower":
            return new.clamp(min=low)
        if clip == "unit box":
            return new.clamp(-1.0, 1.0)
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
    "noise before resampling": (_step(order="before"), "*after* resampling"),
    "one noise value per sample, shared by its coordinates": (
        _step(shape="per_sample"),
        "independent N(0, σ) for each coordinate",
    ),
    "one noise value for the whole population": (_step(shape="one"), "exact copies"),
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


# --------------------------------------------------------------------------- understanding: p(y|x)^k
def test_shallow_share_solution_is_correct_and_quotes_the_library():
    fb = ch06.check_shallow_share(solutions.ch06_shallow_share)
    assert fb.status == "correct" and "library" in fb.message


def test_the_library_measures_what_the_solution_predicts():
    measured = ch06._measured_shallow_share(0.5, 5)
    assert abs(measured - solutions.ch06_shallow_share(0.5, 5, 1.0)) < 0.03


SHARE_MISTAKES = {
    "the deeper valley's share": (lambda d, k, r: 1 - solutions.ch06_shallow_share(d, k, r), "*deeper*"),
    "no k": (lambda d, k, r: solutions.ch06_shallow_share(d, 1, r), "each of the k rounds"),
    "no r": (lambda d, k, r: solutions.ch06_shallow_share(d, k, 1.0), "ignores r"),
    "not normalised": (lambda d, k, r: r * math.exp(-k * d), "normalise"),
    "p(y|x)^(1/k)": (lambda d, k, r: solutions.ch06_shallow_share(d / k, 1, r), "measures"),
    "exponent k·Δ but linear": (lambda d, k, r: max(0.0, 0.5 - 0.1 * k * d), "one round"),
    "a string": (lambda d, k, r: "0.3", "one number"),
    "above 1": (lambda d, k, r: 2.0, "between 0 and 1"),
}


@pytest.mark.parametrize("name", list(SHARE_MISTAKES))
def test_shallow_share_mistakes_get_a_hint_naming_them(name):
    fn, words = SHARE_MISTAKES[name]
    fb = ch06.check_shallow_share(fn)
    assert fb.status == "hint", (name, fb)
    assert words in fb.message, (name, fb.message)


def test_shallow_share_wrong_only_for_many_rounds_quotes_the_measurement():
    def fn(d, k, r):  # right for one round, wrong beyond
        return solutions.ch06_shallow_share(d, 1 if k > 1 and d < 1 else k, r) if k == 1 else 0.3

    fb = ch06.check_shallow_share(fn)
    assert fb.status == "hint" and "measures" in fb.message


# --------------------------------------------------------------------------- holes closed (issue 26)
HOLES_STEP = {
    "uniform noise": (_step(law="uniform"), "shape of a Gaussian"),
    "Laplace noise": (_step(law="Laplace"), "shape of a Gaussian"),
    "clip the upper bound only": (_step(clip="upper"), "both ends"),
    "clip the lower bound only": (_step(clip="lower"), "both ends"),
    "clip to [-1, 1] whatever the bounds": (_step(clip="unit box"), "arguments"),
}


@pytest.mark.parametrize("name", list(HOLES_STEP))
def test_dfo_step_holes_are_closed(name):
    fn, words = HOLES_STEP[name]
    fb = ch06.check_dfo_step(fn)
    assert fb.status == "hint" and words in fb.message, (name, fb.message)


def test_dfo_step_noise_from_the_global_generator_gets_a_hint():
    """The resampling from `generator`, the noise from torch's global generator: caught only with σ > 0."""

    def fn(samples, energies, sigma, low, high, generator):
        idx = torch.multinomial(
            torch.softmax(-energies, 0), len(samples), replacement=True, generator=generator
        )
        return (samples[idx] + sigma * torch.randn(samples.shape)).clamp(low, high)

    fb = ch06.check_dfo_step(fn)
    assert fb.status == "hint" and "generator" in fb.message, fb.message


def test_dfo_step_own_generator_gets_a_hint_and_the_global_state_is_kept():
    def fn(samples, energies, sigma, low, high, generator):
        return solutions.ch06_dfo_step(samples, energies, sigma, low, high, torch.Generator().manual_seed(0))

    torch.manual_seed(123)
    before = torch.random.get_rng_state()
    fb = ch06.check_dfo_step(fn)
    assert fb.status == "hint" and "generator" in fb.message, fb.message
    assert torch.equal(torch.random.get_rng_state(), before)


@settings(max_examples=6, deadline=None)
@given(temperature=st.one_of(st.floats(0.5, 0.9), st.floats(1.1, 2.0)))
def test_select_action_at_another_temperature_gets_a_hint(temperature):
    """A softmax of −E / T for T away from 1 by 10 % or more (1.1 used to pass)."""

    def fn(samples, energies, select, generator):
        p = torch.softmax(-energies / temperature, dim=0)
        if select == "argmax":
            return samples[int(p.argmax())]
        return samples[int(torch.multinomial(p, 1, generator=generator))]

    assert ch06.check_select_action(fn).status == "hint"


def test_select_action_ignoring_the_generator_gets_a_hint():
    def fn(samples, energies, select, generator):
        p = torch.softmax(-energies, dim=0)
        if select == "argmax":
            return samples[int(p.argmax())]
        return samples[int(torch.multinomial(p, 1))]  # torch's global generator

    fb = ch06.check_select_action(fn)
    assert fb.status == "hint" and "generator" in fb.message, fb.message


def test_select_action_always_the_first_sample_for_argmax_gets_a_hint():
    fb = ch06.check_select_action(lambda s, e, sel, g: s[0])
    assert fb.status == "hint"


@settings(max_examples=25, deadline=None)
@given(i=st.integers(0, 5), factor=st.floats(0.3, 3.0).filter(lambda f: abs(f - 1) > 0.01))
def test_shallow_share_hint_names_a_case_the_prediction_gets_wrong(i, factor):
    """Wrong in one case only (any of the six): the hint names that case, never one it got right."""
    cases = [(0.5, 1, 1.0), (0.5, 5, 1.0), (1.0, 3, 1.0), (0.5, 2, 3.0), (0.2, 4, 0.5), (2.0, 1, 1.0)]
    wrong_case = cases[i]

    def fn(d, k, r):
        v = solutions.ch06_shallow_share(d, k, r)
        return min(1.0, v * factor) if (d, k, r) == wrong_case else v

    fb = ch06.check_shallow_share(fn)
    assert fb.status == "hint"
    d, k, r = wrong_case
    assert f"Δ = {d}" in fb.message, fb.message
    for other in cases:
        if other != wrong_case and other[:2] != wrong_case[:2]:
            assert f"Δ = {other[0]}, k = {other[1]} rounds" not in fb.message


@pytest.mark.parametrize("scale", [0.96, 1.05, 1.1])
def test_dfo_step_noise_a_few_percent_off_gets_a_hint_about_the_spread(scale):
    """σ off by 4 % or more is named as the spread, not as the shape."""

    def fn(samples, energies, sigma, low, high, generator):
        return solutions.ch06_dfo_step(samples, energies, scale * sigma, low, high, generator)

    fb = ch06.check_dfo_step(fn)
    assert fb.status == "hint" and "standard deviation" in fb.message, fb.message


@pytest.mark.parametrize("width", ["half", "whole"])
def test_dfo_step_sigma_relative_to_the_box_gets_a_hint(width):
    """σ read as a share of the box (times its half-width, or its width) passed while the noise was only
    tested in [-1, 1], whose half-width is 1."""

    def fn(samples, energies, sigma, low, high, generator):
        scale = (high - low) / 2 if width == "half" else high - low
        return solutions.ch06_dfo_step(samples, energies, sigma * scale, low, high, generator)

    fb = ch06.check_dfo_step(fn)
    assert fb.status == "hint" and "standard deviation" in fb.message, fb.message
