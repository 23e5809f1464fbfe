"""Independent runs side by side in worker processes: ``parallel_map``, ``parallel_calls``,
``imap_unordered``.

The toy chapters train the same small network from several seeds. Networks this small gain
little from torch's threads (each step is a few small matrix products): on two cores, two
processes with one thread each finish a set of such runs about 1.5 to 1.7 times sooner than one
process with two threads, where a pool of Python threads would be held back by the GIL.
``parallel_map(job, calls)`` runs ``job`` on each call in a pool of worker processes, one thread
each, and returns the results in the order of ``calls``; ``parallel_calls`` does the same for
calls of different functions. ``imap_unordered(calls, workers=..., threads=...)`` is the pool of the
command line's long studies (``ibc-tutorial replicate``, ``replicate-steering``): each result as soon as
its call finishes, the caller's errors unchanged, and as many torch threads per worker as asked.

**Same results with any number of workers.** Each call runs with the caller's default dtype and
deterministic-algorithms setting, and a call's result must depend only on its arguments: a job
draws every random number from its own seeds (``torch.manual_seed(seed)`` before building a
network, a ``torch.Generator`` for the rest), never from state an earlier call left behind, since
a worker runs several calls in an order that timing decides. ``workers=1`` runs the calls here,
one after another, and leaves this process's random generators as it found them, as worker
processes do; ``tests/test_parallel.py`` checks that 1 and 2 workers give identical results.

**Spawned, not forked.** Workers start as fresh interpreters (``spawn``): forking a process
after torch has started its thread pool is not safe (and Python 3.12+ warns about it). A
spawned worker imports ``job`` by name, so it must be a function of an importable module (the
library's, not one defined in a notebook or script's ``__main__``), and the arguments and results
travel by pickle. In a script, call ``parallel_map`` under ``if __name__ == "__main__":`` (a
spawned worker imports the script); a notebook needs nothing of the kind.

**Started once.** Starting a worker costs a second or more (it imports torch), so the first call
starts the pool and later calls with the same number of workers reuse it; the workers wait idle
in between and end with this process, or at ``shutdown()`` (after editing the library, so that
the next call's workers import the new code). A call that fails, or is interrupted, stops the
pool; the next call starts a fresh one.
"""

from __future__ import annotations

import atexit
import functools
import multiprocessing
import os
import pickle
import random
import signal
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from typing import Any, TypeVar

import numpy as np
import torch

from ibc_tutorial.utils import QUIET_ENV, WORKER_SLOT_ENV, check_int

T = TypeVar("T")

MAX_WORKERS = 2
"""Most worker processes ``parallel_map`` starts by default: the book's budget is 2 CPU cores."""

WORKERS_ENV = "IBC_TUTORIAL_WORKERS"
"""Environment variable that sets the default number of workers (1: every call in this process),
e.g. for a machine that runs other work beside the notebooks."""


def default_workers() -> int:
    """``$IBC_TUTORIAL_WORKERS`` if set, else ``min(MAX_WORKERS, CPU cores this process may use)``,
    at least 1."""
    value = os.environ.get(WORKERS_ENV, "").strip()
    if value:
        try:
            return check_int(WORKERS_ENV, int(value), minimum=1)
        except ValueError:
            raise ValueError(f"{WORKERS_ENV} must be an integer >= 1, got {value!r}") from None
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not on Linux
        cores = os.cpu_count() or 1
    return max(1, min(MAX_WORKERS, cores))


def _settings() -> dict[str, Any]:
    """What a worker must share with the caller for the same call to give the same result."""
    return {
        "dtype": torch.get_default_dtype(),
        "deterministic": torch.are_deterministic_algorithms_enabled(),
        "warn_only": torch.is_deterministic_algorithms_warn_only_enabled(),
    }


def _init_worker(threads: int = 1, slots=None) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the caller's to handle (it stops the workers)
    os.environ[QUIET_ENV] = "1"  # no progress bars unless a call asks for one (``utils.progress``)
    if slots is not None:  # the next free slot: this worker's line for a bar a call asks for
        with slots.get_lock():
            os.environ[WORKER_SLOT_ENV] = str(slots.value)
            slots.value += 1
    torch.set_num_threads(max(1, int(threads)))


def _run_in_worker(payload: bytes) -> bytes:
    task, settings = pickle.loads(payload)
    torch.set_default_dtype(settings["dtype"])
    torch.use_deterministic_algorithms(settings["deterministic"], warn_only=settings["warn_only"])
    return pickle.dumps(task(), protocol=pickle.HIGHEST_PROTOCOL)


def _name(task: Callable) -> str:
    fn = task.func if isinstance(task, functools.partial) else task
    return getattr(fn, "__qualname__", None) or type(fn).__name__


def _check_importable(what: str, task: Callable) -> None:
    """ValueError unless a spawned worker can import the function ``task`` calls by name."""
    fn = task.func if isinstance(task, functools.partial) else task
    module = getattr(fn, "__module__", None)
    qualname = getattr(fn, "__qualname__", "")
    if module in (None, "__main__", "__mp_main__") or "<" in qualname:  # <lambda>, <locals>
        where = "a lambda or nested function" if "<" in qualname else f"defined in module {module!r}"
        raise ValueError(
            f"{what} must be a function of an importable module for worker processes to import it, got "
            f"{_name(task)!r}, {where}: move it into the library (ibc_tutorial), or pass workers=1"
        )


class _Restored:
    """Leave the global random generators (torch, NumPy, Python) as they were: a call run in this
    process then changes the caller's state no more than one run in a worker process does."""

    def __enter__(self):
        self.state = (torch.get_rng_state(), np.random.get_state(), random.getstate())

    def __exit__(self, *exc):
        torch.set_rng_state(self.state[0])
        np.random.set_state(self.state[1])
        random.setstate(self.state[2])
        return False


def _failed(task: Callable, index: int, n: int, exc: BaseException) -> RuntimeError:
    return RuntimeError(f"{_name(task)} raised {type(exc).__name__} on call {index} (of {n}): {exc}")


def parallel_map(job: Callable[..., T], calls: Iterable, *, workers: int | None = None, **shared) -> list[T]:
    """``[job(*call, **shared) for call in calls]``, computed in up to ``workers`` processes.

    Args:
        job: a function of an importable module (see the module docstring), for example
            ``ibc_tutorial.experiments.counter_examples.run``.
        calls: one item per call: a tuple of positional arguments, or any other value as the
            single argument (so a list of seeds maps ``job`` over the seeds).
        workers: processes to use; None = ``default_workers()`` (at most 2). With 1, or with a
            single call, the calls run in this process, one after another.
        **shared: keyword arguments passed to every call (data, settings).

    Returns:
        The results, in the order of ``calls``, identical whatever ``workers`` is.

    Raises:
        ValueError: ``workers`` is not an integer >= 1, ``job`` is not callable, or (with more than
            one worker) ``job`` cannot be imported by a worker or its arguments cannot be pickled.
        RuntimeError: a call raised (the message names the job, the call and the error; the
            original exception, with its traceback from the worker, is chained as the cause), or a
            worker process died.
    """
    if not callable(job):
        raise ValueError(f"job must be callable, got {type(job).__name__}")
    tasks = [functools.partial(job, *(c if isinstance(c, tuple) else (c,)), **shared) for c in calls]
    return _execute("job", tasks, workers)


def parallel_calls(calls: Iterable[Callable[[], T]], *, workers: int | None = None) -> list[T]:
    """``[call() for call in calls]``, computed in up to ``workers`` processes: ``parallel_map`` for
    calls of different functions, e.g. ``[functools.partial(fit_regression, demos, 0),
    functools.partial(fit_ebm, data, 1, objective, 0)]``.

    Each call is a function of an importable module, or a ``functools.partial`` of one; the rest
    (arguments, results, errors) is as for ``parallel_map``.
    """
    tasks = list(calls)
    for i, task in enumerate(tasks):
        if not callable(task):
            raise ValueError(
                f"calls[{i}] must be callable (a function or a functools.partial), got {type(task).__name__}"
            )
    return _execute("each call", tasks, workers)


def imap_unordered(
    calls: Iterable[Callable[[], T]], *, workers: int | None = None, threads: int = 1
) -> Iterator[T]:
    """``call()`` for each of ``calls``, in up to ``workers`` processes of ``threads`` torch threads each:
    yields each result as soon as its call finishes (not in the order of ``calls``).

    The calls are submitted at once (the caller can do other work before it asks for the first result);
    with one worker they run here, one after another, as the results are asked for. An error of a call
    is raised as it is (so a ``ValueError`` of the library stays one), and an error or Ctrl-C stops the
    workers at once. Each call is a function of an importable module, or a ``functools.partial`` of one,
    whose arguments and result can be pickled (see ``parallel_calls``).
    """
    workers = default_workers() if workers is None else check_int("workers", workers, minimum=1)
    threads = check_int("threads", threads, minimum=1)
    tasks = list(calls)
    if min(workers, len(tasks)) <= 1:
        return (task() for task in tasks)
    for task in tasks:
        _check_importable("each call", task)
    settings = _settings()
    payloads = [pickle.dumps((task, settings), protocol=pickle.HIGHEST_PROTOCOL) for task in tasks]
    pool = _pool(workers, threads)
    futures = [pool.submit(_run_in_worker, payload) for payload in payloads]

    def results() -> Iterator:
        try:
            for future in as_completed(futures):
                yield pickle.loads(future.result())
        except BaseException:  # an error or Ctrl-C: stop the workers now (the studies' files are atomic)
            shutdown(terminate=True)
            raise

    return results()


def _execute(what: str, tasks: list[Callable], workers: int | None) -> list:
    """Run the zero-argument ``tasks``: here (one worker or one task) or in the kept pool."""
    workers = default_workers() if workers is None else check_int("workers", workers, minimum=1)
    n = len(tasks)
    if min(workers, n) <= 1:
        results = []
        with _Restored():
            for i, task in enumerate(tasks):
                try:
                    results.append(task())
                except Exception as exc:
                    raise _failed(task, i, n, exc) from exc
        return results

    for task in tasks:
        _check_importable(what, task)
    # Plain pickle, to bytes: multiprocessing's own pickler, as torch sets it up, would move every tensor
    # it sends to shared memory, this process's own tensors included; while the workers lived, this
    # process then computed up to twice as slowly with two threads (chapter 02's training, measured).
    settings = _settings()
    try:
        payloads = [pickle.dumps((task, settings), protocol=pickle.HIGHEST_PROTOCOL) for task in tasks]
    except Exception as exc:  # pickle raises several types: PicklingError, TypeError, AttributeError
        raise ValueError(
            f"the calls and their arguments must be picklable to reach a worker process: "
            f"{type(exc).__name__}: {exc}"
        ) from exc
    pool = _pool(workers)  # started on demand: no more processes than tasks
    try:
        futures = [pool.submit(_run_in_worker, payload) for payload in payloads]
        results = []
        for i, future in enumerate(futures):
            try:
                results.append(pickle.loads(future.result()))
            except BrokenProcessPool as exc:
                raise RuntimeError(
                    f"a worker process died during call {i} (of {n}), {_name(tasks[i])} "
                    f"(killed, or out of memory?)"
                ) from exc
            except Exception as exc:
                raise _failed(tasks[i], i, n, exc) from exc
    except BaseException:  # an error or Ctrl-C: stop the workers now rather than finish the other calls
        shutdown(terminate=True)
        raise
    return results


_POOL: ProcessPoolExecutor | None = None
"""The worker processes of the last call, kept for the next one (the package's one pool)."""
_POOL_SHAPE: tuple[int, int] = (0, 0)
"""(workers, torch threads per worker) of ``_POOL``."""


def _pool(workers: int, threads: int = 1) -> ProcessPoolExecutor:
    """The kept pool if it has ``workers`` processes of ``threads`` threads, else a new one (the old one
    shut down)."""
    global _POOL, _POOL_SHAPE
    if _POOL is not None and (_POOL_SHAPE != (workers, threads) or getattr(_POOL, "_broken", False)):
        shutdown()
    if _POOL is None:
        ctx = multiprocessing.get_context("spawn")  # never fork: see the module docstring
        slots = ctx.Value("i", 0)  # numbers the workers: each one's line for a progress bar
        _POOL = ProcessPoolExecutor(
            workers, mp_context=ctx, initializer=_init_worker, initargs=(threads, slots)
        )
        _POOL_SHAPE = (workers, threads)
    return _POOL


def shutdown(*, terminate: bool = False) -> None:
    """End the worker processes ``parallel_map``, ``parallel_calls`` and ``imap_unordered`` keep
    (``terminate``: at once,
    without letting a running call finish). The next call starts new ones."""
    global _POOL
    pool, _POOL = _POOL, None
    if pool is None:
        return
    if terminate:
        for process in list((getattr(pool, "_processes", None) or {}).values()):
            process.terminate()
    pool.shutdown(wait=True, cancel_futures=True)


atexit.register(shutdown)
