"""Independent refits of the chain on the machine's cores: :func:`parallel_map`.

Cross-validation refits the chain tens of times (model choice: 4 models × 8 folds; leave-one-out:
one fold per sample), each refit a few milliseconds of small dense algebra that holds the GIL, so
threads do not help. On Linux, :func:`parallel_map` forks workers that inherit the problem already
set up (no pickling of the session, the robot or the modules going in; only the results come back,
pickled through a pipe). The work is cut into items that do not depend on one another, and each
item's result is what the same call gives in this process: the answer is the same whatever the
number of cores, including one (where it simply runs in turn).

A worker's exception (e.g. :class:`~brachycal.errors.DegenerateDataError`) is raised here, the
lowest item's first, as running the items in turn would; its warnings are re-issued here. If a
worker dies without an answer, its items are computed here. Ctrl-C or SIGTERM in this process ends
the workers at once.

Forking is opt-in: a library call runs its items in turn unless it asks for workers, or the
command line, which owns its process, allows them (:func:`forking_workers`). A process the
library does not own (a Jupyter kernel with its threads, a thread pool, a Dask worker) is not
forked behind its back. Forking also needs CPython 3.11 exactly on Linux: from 3.12 CPython warns
(and may deadlock) when a process with threads forks, and OpenBLAS's threads count.
"""

from __future__ import annotations

import contextlib
import gc
import os
import pickle
import signal
import sys
import threading
import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import TypeVar

T = TypeVar("T")
R = TypeVar("R")


#: True in a worker of :func:`parallel_map`: a nested call runs its items in turn there (the cores
#: are already shared out).
_in_worker = False
#: Processes :func:`parallel_map` may use when its caller does not say: 1 (in turn) unless the
#: command line allows more (:func:`forking_workers`).
_allowed_workers = 1


def can_fork() -> bool:
    """Whether :func:`parallel_map` may fork here: CPython 3.11 on Linux, in the main thread of a
    process with no other Python thread, outside the workers of a process pool (e.g. ``brachycal
    study``'s, which already fill the cores) and of :func:`parallel_map` itself."""
    if _in_worker or not sys.platform.startswith("linux") or not hasattr(os, "fork"):
        return False
    if sys.version_info[:2] != (3, 11):  # 3.12+: fork() with threads (OpenBLAS's) is deprecated
        return False
    if threading.current_thread() is not threading.main_thread() or threading.active_count() > 1:
        return False
    import multiprocessing  # lazy: start-up (multiprocessing)

    return multiprocessing.parent_process() is None


def available_workers() -> int:
    """Processes :func:`parallel_map` uses by default: 1, or this process's cores (at most the
    number :func:`forking_workers` allows) where it forks (:func:`can_fork`)."""
    if _allowed_workers <= 1 or not can_fork():
        return 1
    return max(1, min(_allowed_workers, len(os.sched_getaffinity(0))))


@contextmanager
def forking_workers(count: int | None = None) -> Iterator[None]:
    """Within: calls that do not say how many workers use up to ``count`` (default: the cores).

    For the command line, which owns its process; library code never calls it.
    """
    global _allowed_workers
    previous = _allowed_workers
    _allowed_workers = (
        len(os.sched_getaffinity(0)) if count is None and hasattr(os, "sched_getaffinity") else count or 1
    )
    try:
        yield
    finally:
        _allowed_workers = previous


@contextmanager
def frozen_heap() -> Iterator[None]:
    """Within: the objects alive on entry (modules, the robot, the session: long-lived) are left out of
    the cyclic garbage collector's passes (:func:`gc.freeze`); put back on exit (:func:`gc.unfreeze`).

    For the command line, with :func:`forking_workers`: a forked worker shares this process's memory
    page by page until either process writes to a page, and a collection writes to every object it
    scans (its bookkeeping), so each worker's full collections (and this process's) would copy the
    pages of every module loaded; they also spare scanning those objects again. Library code never
    calls it (the collector's state is the process's).
    """
    if gc.get_freeze_count():  # the caller froze its own: unfreezing would release theirs too
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def parallel_map(fn: Callable[[T], R], items: Sequence[T], workers: int | None = None) -> list[R]:
    """``[fn(item) for item in items]``, the items shared round-robin between up to ``workers``
    processes (default :func:`available_workers`; one where it does not fork, :func:`can_fork`); this
    process is one of them.

    ``fn`` must be deterministic and must not depend on the other items' results (they run apart);
    it may close over anything (the workers are forked). Results must pickle.

    Raises:
        Whatever ``fn`` raised for the lowest item that raised.
    """
    items = list(items)
    count = min(len(items), available_workers() if workers is None else workers if can_fork() else 1)
    if count <= 1:
        return [fn(item) for item in items]
    children: list[tuple[int, int, int]] = []  # (pid, read end or -1 once handed over, worker index)
    try:
        for w in range(1, count):
            read, write = os.pipe()
            pid = os.fork()
            if pid == 0:  # the worker: compute, answer, leave without unwinding the parent's stack
                try:
                    global _in_worker
                    _in_worker = True
                    os.close(read)
                    signal.signal(signal.SIGINT, signal.SIG_DFL)
                    signal.signal(signal.SIGTERM, signal.SIG_DFL)
                    answer = pickle.dumps(_run(fn, items, w, count, capture=True))
                    with os.fdopen(write, "wb") as pipe:
                        pipe.write(answer)
                finally:
                    os._exit(0)
            children.append((pid, read, w))  # first: from here on the cleanup below knows it
            os.close(write)
        outcomes: dict[int, tuple[bool, object, list]] = dict(_run(fn, items, 0, count, capture=False))
        while children:
            pid, read, w = children[0]
            children[0] = (pid, -1, w)  # the file object below closes it, also when interrupted
            with os.fdopen(read, "rb") as pipe:
                answer = pipe.read()
            os.waitpid(pid, 0)
            children.pop(0)  # reaped: its pid may be reused, never signal it again
            try:
                outcomes.update(pickle.loads(answer))
            except Exception:  # it died without an answer: its items are computed here
                outcomes.update(_run(fn, items, w, count, capture=False))
    finally:
        for pid, read, _ in children:  # interrupted or failed here: end the workers not yet reaped
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
            with contextlib.suppress(OSError):
                os.waitpid(pid, 0)
            if read >= 0:
                with contextlib.suppress(OSError):
                    os.close(read)
    results: list[R] = []
    for k in range(len(items)):
        if k not in outcomes:  # an earlier item of its worker raised: running in turn stops before it
            continue
        ok, value, caught = outcomes[k]
        for message, category in caught:
            warnings.warn(message, category, stacklevel=2)
        if not ok:
            assert isinstance(value, BaseException)
            raise value
        results.append(value)  # type: ignore[arg-type]
    return results


def balanced_groups(costs: Sequence[float], groups: int) -> list[list[int]]:
    """Indices of ``costs`` in at most ``groups`` groups of about equal total cost: the costliest
    placed first, each into the cheapest group so far (longest processing time first, within 4/3 of
    the best split); each group's indices ascending. Empty groups are left out."""
    out: list[list[int]] = [[] for _ in range(max(1, min(groups, len(costs))))]
    totals = [0.0] * len(out)
    for k in sorted(range(len(costs)), key=lambda k: (-costs[k], k)):
        g = totals.index(min(totals))
        out[g].append(k)
        totals[g] += costs[k]
    return [sorted(group) for group in out if group]


def parallel_calls(calls: Sequence[Callable[[], R]], costs: Sequence[float], workers: int | None = None) -> list[R]:
    """``[call() for call in calls]``, the calls shared between up to ``workers`` processes (default
    :func:`available_workers`) in groups of about equal total ``costs`` (:func:`balanced_groups`).

    For work of different kinds and sizes that does not depend on each other (a stage's refits and
    another stage's): one fork for all of them, and the cores kept busy until the end. ``costs`` are
    relative (any unit, e.g. measured seconds): they decide which process runs which call, never a
    result. Each call is what it gives in this process (:func:`parallel_map`'s rules).

    Raises:
        Whatever the lowest call that raised raised, as running the calls in turn would (within a
        group the calls run in index order and stop at the first that raises, so every call below
        it has run).
    """
    if len(costs) != len(calls):
        raise ValueError(f"{len(calls)} calls but {len(costs)} costs")
    count = available_workers() if workers is None else workers

    def run(group: list[int]) -> list[tuple[int, bool, object]]:
        out: list[tuple[int, bool, object]] = []
        for k in group:
            try:
                out.append((k, True, calls[k]()))
            except Exception as exc:
                out.append((k, False, exc))
                break
        return out

    done = {
        k: (ok, value) for part in parallel_map(run, balanced_groups(costs, count), workers) for k, ok, value in part
    }
    for k in sorted(done):
        ok, value = done[k]
        if not ok:
            assert isinstance(value, BaseException)
            raise value
    return [done[k][1] for k in range(len(calls))]  # type: ignore[misc]


def _run(
    fn: Callable[[T], R], items: list[T], first: int, step: int, *, capture: bool
) -> list[tuple[int, tuple[bool, object, list]]]:
    """Items ``first, first + step, …``: ``(index, (ok, result or exception, [(message, category)]))``,
    stopping at the first that raises. ``capture``: record the warnings (a worker, whose warnings
    filters are its own) instead of letting them through (this process: its filters stay as they are)."""
    out: list[tuple[int, tuple[bool, object, list]]] = []
    for k in range(first, len(items), step):
        caught: list[warnings.WarningMessage] = []
        with warnings.catch_warnings(record=True) if capture else contextlib.nullcontext() as recorded:
            if capture:
                warnings.simplefilter("always")
            try:
                value: object = fn(items[k])
                ok = True
            except Exception as exc:
                value, ok = exc, False
            caught = list(recorded or [])
        out.append((k, (ok, value, [(str(w.message), w.category) for w in caught])))
        if not ok:
            break
    return out
