"""One BLAS thread for the fitting code.

The fits multiply many small matrices (a few thousand rows by 21 or 63 columns). OpenBLAS
spreads each product over every core, and on a busy 2-core machine the threads' hand-offs made
single products 10-45× slower than one thread (measured: a 0.25 ms product took 11.5 ms, whole
fits 0.5-4.9 s instead of 0.14-0.3 s). :func:`single_threaded` runs a function with BLAS limited
to one thread (threadpoolctl), and restores the previous limits afterwards.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import ParamSpec, TypeVar

from threadpoolctl import threadpool_limits

__all__ = ["single_threaded"]

P = ParamSpec("P")
R = TypeVar("R")


def single_threaded(fn: Callable[P, R]) -> Callable[P, R]:
    """``fn`` with BLAS limited to one thread while it runs."""

    @functools.wraps(fn)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with threadpool_limits(limits=1, user_api="blas"):
            return fn(*args, **kwargs)

    return wrapper
