"""Many photographs fitted at once, one worker process per core (:func:`fit_photos`).

:func:`leafview.fit.photo.fit_image` runs on one core (its BLAS is held to one thread); a folder
of photos is fitted by ``jobs`` worker processes of a ``forkserver`` pool (the parent may hold an
OpenGL context, which a forked child must not inherit), each importing the fit once. Results come
back in the order of the paths, so progress bars, reports and contact sheets keep that order. A
photo that fails gives its one-line error instead of a fit, and the others go on.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from leafview.errors import LeafviewError
from leafview.fit.photo import ImageFit, fit_image

__all__ = ["fit_photos", "default_jobs", "MAX_JOBS"]

MAX_JOBS = 16


def default_jobs() -> int:
    """One worker per core this process may run on, at most :data:`MAX_JOBS`."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:   # not on Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, MAX_JOBS))


def _fit_one(task: tuple[str, str, dict[str, Any]]) -> ImageFit | str:
    """One photo's fit, or its error as one line naming the file (errors are returned, not
    raised, so that every kind crosses the process boundary the same way)."""
    path, name, options = task
    try:
        return fit_image(path, name=name, **options)
    except Exception as exc:   # reported per photo; the batch goes on
        what = str(exc) if isinstance(exc, LeafviewError) else f"{type(exc).__name__}: {exc}"
        what = " ".join(what.split())
        return what if path in what else f"{path}: {what}"


def fit_photos(paths: Sequence[str | os.PathLike[str]], names: Sequence[str], *, jobs: int = 1,
               **options: Any) -> Iterator[ImageFit | str]:
    """:func:`~leafview.fit.photo.fit_image` of every path (with its name and ``options``), in
    order, each an :class:`ImageFit` or the error line of that photo; ``jobs`` worker processes
    (1: in this process)."""
    if len(paths) != len(names):
        raise ValueError(f"{len(paths)} paths but {len(names)} names")
    tasks = [(str(Path(p)), str(n), dict(options)) for p, n in zip(paths, names)]
    if jobs <= 1 or len(tasks) <= 1:
        for task in tasks:
            yield _fit_one(task)
        return
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(["leafview.fit.photo"])
    with ProcessPoolExecutor(max_workers=min(jobs, len(tasks)), mp_context=context) as pool:
        yield from pool.map(_fit_one, tasks)
