"""What every benchmark table measures with: the median-time helper, step progress on stderr,
the GL renderer of a result, and the context a table runs on.

Every timing is the median of several repeats, with ``ctx.finish()`` (``finish``) before the
clock stops; the GL renderer (``GL_RENDERER``) is part of each result because numbers from
llvmpipe (software) and a real GPU are not comparable.
"""

from __future__ import annotations

import statistics
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import moderngl

from leafview.gpu.context import create_headless_context

__all__ = ["median_time", "interleaved", "Progress", "gl_info", "log_gl_renderer", "bench_context"]


def median_time(fn: Callable[[], Any], repeats: int, finish: Callable[[], None] | None = None) -> float:
    """Median wall time of ``fn`` over ``repeats`` runs (``finish`` before the clock stops)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        if finish is not None:
            finish()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def interleaved(base: Callable[[], Any], other: Callable[[], Any], rounds: int,
                finish: Callable[[], None] | None = None, *, warm: bool = True) -> dict[str, Any]:
    """``base`` and ``other`` timed in alternation, ``rounds`` pairs (each run once first unless
    ``warm`` is off, so that compilation and allocation stay out of the clock): ms of each
    (median), the median of the per-pair ratios other ÷ base, and their range. Side by side on a
    noisy machine, the pairs share its load."""
    if warm:
        base()
        other()
        if finish is not None:
            finish()
    ta, tb, ratios = [], [], []
    for _ in range(rounds):
        a = median_time(base, 1, finish)
        b = median_time(other, 1, finish)
        ta.append(a)
        tb.append(b)
        ratios.append(b / a)
    return {"ratio": statistics.median(ratios), "base_ms": 1e3 * statistics.median(ta),
            "other_ms": 1e3 * statistics.median(tb), "range": [min(ratios), max(ratios)]}


class Progress:
    """Step names on stderr, only when stderr is a terminal; ``with Progress(n) as progress:``
    clears the line at the end."""

    def __init__(self, total: int) -> None:
        self.enabled = sys.stderr.isatty()
        self.total, self.done = total, 0

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def step(self, what: str) -> None:
        self.done += 1
        if self.enabled:
            sys.stderr.write(f"\r\033[K[{self.done}/{self.total}] {what}")
            sys.stderr.flush()

    def close(self) -> None:
        if self.enabled:
            sys.stderr.write("\r\033[K")
            sys.stderr.flush()


def gl_info(ctx: moderngl.Context) -> dict[str, str]:
    """``gl_renderer`` and ``gl_version`` of ``ctx``: the part of a result that says what ran it."""
    return {"gl_renderer": str(ctx.info["GL_RENDERER"]), "gl_version": str(ctx.info["GL_VERSION"])}


def log_gl_renderer(table: str, renderer: str) -> None:
    """Say on stderr which GL renderer the ``table`` benchmark measures, before it starts."""
    print(f"{table} bench: GL_RENDERER = {renderer}", file=sys.stderr, flush=True)


@contextmanager
def bench_context(ctx: moderngl.Context | None) -> Iterator[moderngl.Context]:
    """``ctx`` as it is (kept open), or when None a new headless context, released at the end.

    Pass the context already in use when the process has one: creating a second standalone
    context makes it current behind the first one's back."""
    if ctx is not None:
        yield ctx
        return
    own = create_headless_context()
    try:
        yield own
    finally:
        own.release()
