"""parallel_map: the same results, in the same order, with one worker (in this process) and with two
worker processes; clear errors for bad arguments and for a job that raises."""

import functools
import os
import threading

import pytest
import torch

from ibc_tutorial import parallel
from ibc_tutorial.negatives import UniformSampler
from ibc_tutorial.objectives import info_nce_objective
from ibc_tutorial.policies import EnergyModel, MLPEncoder
from ibc_tutorial.training import TrainConfig, train


# Jobs: functions of an importable module (this one), as worker processes need them.
def train_tiny(seed, steps=20):
    """A tiny energy model trained from ``seed``: its weights and loss curve."""
    torch.manual_seed(seed)
    model = EnergyModel(MLPEncoder(1, embed_dim=8, hidden=8), 1, hidden=8)
    g = torch.Generator().manual_seed(100)
    data = {"obs": torch.rand(64, 1, generator=g), "actions": torch.rand(64, 1, generator=g) * 2 - 1}
    curve = train(
        model,
        info_nce_objective(model, UniformSampler(-1.0, 1.0), 8),
        data,
        TrainConfig(steps=steps, batch_size=16, lr=1e-2, seed=seed, log_every=5, progress=False),
    )
    return model.state_dict(), curve.losses


def where_am_i(x):
    return x, os.getpid(), torch.get_num_threads(), torch.get_default_dtype()


def combine(a, b, *, c):
    return (a, b, c)


def fail_on_two(x):
    if x == 2:
        raise ValueError("two is not allowed")
    return x


def draw(seed):
    torch.manual_seed(seed)
    return float(torch.rand(()))


@pytest.fixture(scope="module", autouse=True)
def stop_workers():
    yield
    parallel.shutdown()


@pytest.fixture
def float64():
    before = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    yield
    torch.set_default_dtype(before)


def test_same_results_with_one_and_two_workers(float64):
    seeds = [3, 0, 1, 2]
    one = parallel.parallel_map(train_tiny, seeds, workers=1)
    two = parallel.parallel_map(train_tiny, seeds, workers=2)
    assert len(one) == len(two) == len(seeds)
    for (w1, l1), (w2, l2) in zip(one, two, strict=True):
        assert l1 == l2
        assert all(torch.equal(w1[k], w2[k]) for k in w1)
        assert all(v.dtype == torch.float64 for v in w2.values())
    # different seeds, different models: the results are not one run repeated
    assert not torch.equal(one[0][0]["head.0.weight"], one[1][0]["head.0.weight"])


def test_order_threads_and_dtype_in_workers(float64):
    out = parallel.parallel_map(where_am_i, range(7), workers=2)
    assert [x for x, *_ in out] == list(range(7))
    assert all(pid != os.getpid() for _, pid, _, _ in out)
    assert all(threads == 1 and dtype == torch.float64 for _, _, threads, dtype in out)
    here = parallel.parallel_map(where_am_i, range(3), workers=1)
    assert [x for x, *_ in here] == [0, 1, 2] and all(pid == os.getpid() for _, pid, _, _ in here)


@pytest.mark.parametrize("workers", [1, 2])
def test_tuples_are_unpacked_and_shared_keywords_passed(workers):
    out = parallel.parallel_map(combine, [(1, 2), (3, 4)], c="x", workers=workers)
    assert out == [(1, 2, "x"), (3, 4, "x")]
    assert parallel.parallel_map(combine, [], c=0, workers=workers) == []


def test_one_worker_leaves_the_callers_generators_alone():
    torch.manual_seed(7)
    before = torch.get_rng_state()
    assert parallel.parallel_map(draw, [1, 2], workers=1) == parallel.parallel_map(draw, [1, 2], workers=2)
    assert torch.equal(torch.get_rng_state(), before)


@pytest.mark.parametrize("workers", [0, -1, 1.5, True, "2"])
def test_bad_workers(workers):
    with pytest.raises(ValueError, match="workers"):
        parallel.parallel_map(where_am_i, [1, 2], workers=workers)


def test_bad_jobs():
    with pytest.raises(ValueError, match="job must be callable"):
        parallel.parallel_map(3, [1, 2])
    with pytest.raises(ValueError, match="importable module"):
        parallel.parallel_map(lambda x: x, [1, 2], workers=2)
    assert parallel.parallel_map(lambda x: x + 1, [1, 2], workers=1) == [2, 3]  # in this process: fine
    with pytest.raises(ValueError, match="picklable"):
        parallel.parallel_map(combine, [(1, 2), (3, 4)], c=threading.Lock(), workers=2)


@pytest.mark.parametrize("workers", [1, 2])
def test_a_job_that_raises(workers):
    with pytest.raises(
        RuntimeError, match=r"fail_on_two raised ValueError on call 2 \(of 4\): two is not allowed"
    ) as info:
        parallel.parallel_map(fail_on_two, [0, 1, 2, 3], workers=workers)
    assert isinstance(info.value.__cause__, ValueError)
    # the next call works (with workers, on a fresh pool)
    assert parallel.parallel_map(fail_on_two, [0, 1, 3], workers=workers) == [0, 1, 3]


@pytest.mark.parametrize("workers", [1, 2])
def test_calls_of_different_functions(workers, float64):
    calls = [
        functools.partial(combine, 1, 2, c=3),
        functools.partial(train_tiny, 1, steps=10),
        functools.partial(where_am_i, "x"),
    ]
    out = parallel.parallel_calls(calls, workers=workers)
    assert out[0] == (1, 2, 3) and out[2][0] == "x" and out[2][3] == torch.float64
    weights, losses = train_tiny(1, steps=10)
    assert out[1][1] == losses and all(torch.equal(out[1][0][k], weights[k]) for k in weights)
    with pytest.raises(ValueError, match=r"calls\[1\] must be callable"):
        parallel.parallel_calls([calls[0], 3], workers=workers)


def test_calls_must_be_importable():
    with pytest.raises(ValueError, match="each call must be a function of an importable module"):
        parallel.parallel_calls([functools.partial(combine, 1, 2, c=3), lambda: 1], workers=2)


def test_default_workers(monkeypatch):
    monkeypatch.delenv(parallel.WORKERS_ENV, raising=False)
    assert 1 <= parallel.default_workers() <= parallel.MAX_WORKERS
    monkeypatch.setenv(parallel.WORKERS_ENV, "1")
    assert parallel.default_workers() == 1
    assert parallel.parallel_map(where_am_i, [1, 2])[1][1] == os.getpid()  # in this process
    for bad in ("0", "two", "1.5"):
        monkeypatch.setenv(parallel.WORKERS_ENV, bad)
        with pytest.raises(ValueError, match=parallel.WORKERS_ENV):
            parallel.default_workers()


# ----------------------------------------------------------------- imap_unordered (the studies' pool)
def test_imap_unordered_gives_every_result_with_the_threads_asked_for():
    calls = [functools.partial(where_am_i, x) for x in range(5)]
    out = list(parallel.imap_unordered(calls, workers=2, threads=2))
    assert sorted(x for x, *_ in out) == list(range(5))
    assert all(pid != os.getpid() and threads == 2 for _, pid, threads, _ in out)
    lazy = parallel.imap_unordered([functools.partial(where_am_i, x) for x in range(3)], workers=1)
    assert [x for x, *_ in lazy] == [0, 1, 2]  # in this process, in order


@pytest.mark.parametrize("workers", [1, 2])
def test_imap_unordered_raises_a_calls_error_as_it_is(workers):
    calls = [functools.partial(fail_on_two, x) for x in (0, 2)]
    with pytest.raises(ValueError, match="two is not allowed"):
        list(parallel.imap_unordered(calls, workers=workers))
    assert sorted(parallel.imap_unordered([functools.partial(fail_on_two, 1)], workers=workers)) == [1]


def _bar_line() -> tuple[str | None, bool]:
    """In a worker: its slot and whether a bar asked for is shown (``utils.progress``)."""
    import os

    from ibc_tutorial.utils import WORKER_SLOT_ENV, progress

    bar = progress(range(3), enabled=True)
    shown = not bar.disable
    bar.close()
    return os.environ.get(WORKER_SLOT_ENV), shown and not progress(range(3)).disable


def test_each_worker_has_its_own_line_for_a_bar_a_call_asks_for():
    """Two workers number themselves 0 and 1 (the lines their bars take); a bar shows in a worker only if the
    call asks for it (``enabled=True``), never by default."""
    import functools

    from ibc_tutorial.parallel import parallel_calls, shutdown

    shutdown()  # a fresh pool: its workers numbered from 0
    try:
        out = parallel_calls([functools.partial(_bar_line) for _ in range(8)], workers=2)
    finally:
        shutdown()
    assert {slot for slot, _ in out} <= {"0", "1"} and all(slot is not None for slot, _ in out)
    assert not any(default_shown for _, default_shown in out)


def test_replicate_run_options_show_worker_bars_only_when_asked_or_on_a_terminal(monkeypatch):
    from ibc_tutorial.experiments.agents.replicate import run_options

    assert run_options(1, print, None) == {"log": print, "show_progress": None}
    assert run_options(2, print, True) == {"show_progress": True}
    assert run_options(2, print, False) == {"show_progress": False}
    monkeypatch.setenv("TQDM_DISABLE", "1")  # the tests: no bars
    assert run_options(2, print, None) == {"show_progress": False}
