"""Two threads for the leaf-by-leaf arithmetic of large scenes.

numpy releases the interpreter lock inside its array loops, so two Python threads that each run
numpy over half of the leaves keep two cores busy. The scene build (:mod:`leafview.scene.plants`,
:mod:`leafview.scene.stems`) and the packing of a scene's rows (:mod:`leafview.gpu.scene`) hand
such work to :func:`in_two_threads`, and one long task beside the caller's to :func:`background`.
The work must treat its items one by one, so that its numbers do not depend on the split, and
must draw its random numbers before, in order.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, TypeVar

__all__ = ["PARALLEL_MIN", "background", "two_threads", "in_two_threads"]

PARALLEL_MIN = 100_000   # items from which in_two_threads uses a second thread
_T = TypeVar("_T")
_POOL: ThreadPoolExecutor | None = None
_WORKERS: set[threading.Thread] = set()
_POOL_LOCK = threading.Lock()


def _forget_pool() -> None:
    """In a forked child: the parent's worker thread is not there; the next task starts a new one."""
    global _POOL, _POOL_LOCK
    _POOL, _POOL_LOCK = None, threading.Lock()
    _WORKERS.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool)


def background(fn: Callable[..., _T], *args: Any) -> Future[_T]:
    """``fn(*args)`` on the build's worker thread (one, started on first use; numpy releases the
    interpreter lock in its array loops, so the two run on two cores)."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is None:
            _POOL = ThreadPoolExecutor(max_workers=1, thread_name_prefix="leafview-build",
                                       initializer=lambda: _WORKERS.add(threading.current_thread()))
        return _POOL.submit(fn, *args)


def two_threads(n: int) -> bool:
    """Whether work on ``n`` items goes to two threads: from :data:`PARALLEL_MIN` items, with more
    than one CPU, and not already on the worker (which would wait for itself)."""
    return n >= PARALLEL_MIN and (os.cpu_count() or 1) > 1 and threading.current_thread() not in _WORKERS


def in_two_threads(n: int, work: Callable[[int, int], object], pieces: int = 4) -> None:
    """``work(a, b)`` over ``0:n`` in ``pieces`` runs, taken in turn by the calling thread and the
    worker thread where :func:`two_threads` (so that a thread slowed by other processes on its
    core takes fewer), else ``work(0, n)``. ``work`` must treat items one by one (elementwise
    numpy, gathers, reductions within an item, results written to disjoint rows), so that the
    numbers do not depend on the split, and must draw no random numbers (they are drawn before,
    in order)."""
    if not two_threads(n):
        work(0, n)
        return
    edges = [n * k // pieces for k in range(pieces + 1)]
    runs = iter(range(pieces))
    lock = threading.Lock()

    def take() -> None:
        while True:
            with lock:
                k = next(runs, None)
            if k is None:
                return
            work(edges[k], edges[k + 1])

    other = background(take)
    try:
        take()
    finally:
        other.result()
