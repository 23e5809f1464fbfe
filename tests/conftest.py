"""Fixtures shared by the tests."""

import pytest
from hypothesis import settings

# Hypothesis draws the same examples on every run, so that CI's verdict does not depend on chance; a
# case that once failed is pinned in its test with @example.
settings.register_profile("book", derandomize=True)
settings.load_profile("book")


def _stub(*args, **kwargs):
    """A reader who has not started: the exercise's stub."""
    raise NotImplementedError


def _crashes(*args, **kwargs):
    """A reader whose code fails with an error of its own."""
    raise KeyError("oops")


@pytest.fixture
def stub_and_crash():
    """``stub_and_crash(checker)`` asserts what every exercise checker does with the two readers
    who give no answer: the stub is "not attempted", and code that raises gets a hint naming its
    exception, never an exception of the checker's own."""

    def check(checker):
        assert checker(_stub).status == "not attempted"
        fb = checker(_crashes)
        assert fb.status == "hint" and "KeyError" in fb.message, fb.message

    return check
