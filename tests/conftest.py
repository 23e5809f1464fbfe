"""Fixtures shared by the tests."""

import hashlib
from pathlib import Path

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


def _digest(folder: Path) -> dict[str, str]:
    """Every file under ``folder``: its SHA-256."""
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


@pytest.fixture(scope="session")
def tiny_replication(tmp_path_factory):
    """One finished ``ibc-tutorial replicate --preset tiny`` folder, built once for the whole session and
    shared by the tests that read one (``test_replicate``, ``test_claims``) or its demonstrations
    (``tiny_demonstrations``). A test that changes a folder copies it first (``shutil.copytree``); the
    session checks at its end that no test changed this one."""
    from ibc_tutorial import cli

    out = tmp_path_factory.mktemp("tiny-replication") / "rep"
    assert cli.main(["replicate", "--preset", "tiny", "--out", str(out)]) == 0
    before = _digest(out)
    yield out
    changed = sorted(set(before.items()) ^ set(_digest(out).items()))
    assert not changed, f"a test changed the shared tiny replication (copy it first): {changed}"


@pytest.fixture(scope="session")
def tiny_demonstrations(tiny_replication):
    """The tiny preset's demonstrations (``TINY.collect_config()``, about 100 samples): the file the
    shared replication collected. Read it; write a changed copy elsewhere."""
    return tiny_replication / "data" / "town01.npz"
