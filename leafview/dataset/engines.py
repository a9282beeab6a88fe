"""Where a dataset's shards are rendered: local worker processes or Ray actors.

Work is cut into shards of ``shard_size`` images (:meth:`Recipe.shard_images
<leafview.dataset.recipe.Recipe.shard_images>`); a worker renders one shard at a time, writes each
image's files (one transaction per image) and then the shard's manifest, the marker that the shard
is done (:mod:`leafview.dataset.writer`). Every worker holds its own headless EGL context for its
whole life.

``local`` (:class:`LocalEngine`)
    ``workers`` processes started with multiprocessing's ``spawn`` method (no GL state is ever
    inherited through ``fork``). Each sets ``LP_NUM_THREADS`` (llvmpipe's rasteriser threads) to
    ``threads`` before it creates its context: by default the CPUs this process may use divided by
    the workers, at least 1, unless ``LP_NUM_THREADS`` is already set in the environment. The
    parent hands out shards over a pipe and hears of every image (the progress bar) and every
    finished shard.
``ray`` (:class:`RayEngine`)
    ``workers`` Ray actors (``num_cpus=1``, ``num_gpus=gpus_per_worker``), each with its own
    context, connected to ``address`` (``ray.init(address=...)``) or to a local Ray started for
    the run (``num_cpus=workers``, no dashboard, worker logs not forwarded) and shut down after.
    Ray is optional (``pip install "leafview[ray]"``) and imported only here, only for this engine.

A worker that dies (a crash, not a Python exception) while rendering a shard is replaced and the
shard is given to a worker again, once; a second death is reported (:class:`ShardFailed`, exit 1,
naming the shard) after the other shards are done. A Python exception in a worker (a full disk,
say) stops the run with that error.

Test hook: ``LEAFVIEW_DATASET_CRASH_SHARD=S`` makes a worker end its process abruptly
(``os._exit(70)``) when it starts shard ``S``; ``S@A`` only on attempt ``A`` (1 or 2). It is read
in one place, :func:`_crash_hook`, when a worker starts a shard, and does nothing when unset.
"""

from __future__ import annotations

import contextlib
import importlib
import logging
import multiprocessing
import os
import signal
import socket
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any

from leafview.atomic import signal_guard
from leafview.dataset.recipe import Recipe
from leafview.dataset.writer import ImageRenderer, render_shard
from leafview.errors import LeafviewError, ParamError, UsageError

__all__ = ["ENGINES", "DatasetError", "ShardFailed", "EngineResult", "LocalEngine", "RayEngine", "start_engine",
           "default_threads", "CRASH_ENV", "RAY_INSTALL"]

ENGINES = ("local", "ray")
CRASH_ENV = "LEAFVIEW_DATASET_CRASH_SHARD"
RAY_INSTALL = 'pip install "leafview[ray]"'
MAX_ATTEMPTS = 2
_CRASH_STATUS = 70


class DatasetError(LeafviewError, RuntimeError):
    """A dataset run failed because of its environment (a worker, the Ray cluster); ``leafview
    dataset`` exits 1. The shards finished before it stay on disk and a rerun skips them."""


class ShardFailed(DatasetError):
    """A shard whose worker died on every attempt; ``shards`` lists them."""

    def __init__(self, message: str, shards: Sequence[int]) -> None:
        super().__init__(message)
        self.shards = list(shards)


@dataclass
class EngineResult:
    """What an engine did: the shards it finished, the images it rendered, the shards that were
    retried after a worker died, and the GL renderer of its workers."""

    done: list[int] = field(default_factory=list)
    images: int = 0
    retried: list[int] = field(default_factory=list)
    gl_renderer: str = ""


def default_threads(workers: int) -> int:
    """llvmpipe threads per worker: the CPUs this process may use // workers, at least 1."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cpus = os.cpu_count() or 1
    return max(1, cpus // max(1, workers))


def _crash_hook(shard: int, attempt: int) -> None:
    """The test hook of the module docstring (``LEAFVIEW_DATASET_CRASH_SHARD``)."""
    text = os.environ.get(CRASH_ENV)
    if not text:
        return
    target, _, when = text.partition("@")
    if target.strip() == str(shard) and (not when or when.strip() == str(attempt)):
        os._exit(_CRASH_STATUS)


def _set_threads(threads: int | None) -> None:
    if threads is not None and "LP_NUM_THREADS" not in os.environ:
        os.environ["LP_NUM_THREADS"] = str(int(threads))


def _error_message(exc: BaseException) -> tuple[int, str]:
    """(exit code, one line) of an exception raised in a worker."""
    code = 2 if isinstance(exc, (UsageError, ParamError)) else 1
    text = " ".join(str(exc).split()) or type(exc).__name__
    if not isinstance(exc, LeafviewError):
        text = f"{type(exc).__name__}: {text}"
    return code, text


def _raise_worker_error(code: int, text: str, shard: int | None) -> None:
    where = f"shard {shard}: " if shard is not None else ""
    if code == 2:
        raise UsageError(f"{where}{text}")
    raise DatasetError(f"{where}{text}")


def _shard_text(recipe: Recipe, shard: int) -> str:
    images = recipe.shard_images(shard)
    return f"shard {shard} (images {images.start:06d}-{images.stop - 1:06d})"


def _failed(recipe: Recipe, failed: dict[int, str]) -> ShardFailed:
    shards = sorted(failed)
    first = shards[0]
    more = f" and {len(shards) - 1} more" if len(shards) > 1 else ""
    return ShardFailed(f"{_shard_text(recipe, first)}{more}: the worker died on each of {MAX_ATTEMPTS} attempts "
                       f"({failed[first]}); the other shards are done, rerun the command to try again", shards)


# -- local processes --------------------------------------------------------------------------------
def _local_worker(conn: Connection, out: str, recipe: Recipe, threads: int | None) -> None:
    """A worker process: one context, then shards from ``conn`` until None."""
    _set_threads(threads)
    try:
        renderer = ImageRenderer(recipe)
    except Exception as exc:
        conn.send(("error", None, *_error_message(exc)))
        return
    try:
        conn.send(("ready", renderer.gl_renderer))
        while True:
            try:
                task = conn.recv()
            except EOFError:        # the parent is gone
                return
            if task is None:
                return
            shard, attempt = task
            _crash_hook(shard, attempt)
            try:
                def sent(shard: int = shard) -> None:
                    conn.send(("image", shard))

                n = render_shard(renderer, Path(out), shard, on_image=sent)
            except Exception as exc:
                conn.send(("error", shard, *_error_message(exc)))
                return
            conn.send(("done", shard, n))
    except (BrokenPipeError, EOFError, KeyboardInterrupt):   # the parent is gone, or Ctrl-C reached us too
        return
    finally:
        renderer.release()


@dataclass
class _Slot:
    process: Any
    conn: Connection
    shard: int | None = None
    attempt: int = 0
    ready: bool = False


class LocalEngine:
    """Worker processes on this machine (see the module docstring)."""

    name = "local"

    def __init__(self, out: Path, recipe: Recipe, workers: int, threads: int | None = None) -> None:
        self.out, self.recipe, self.workers = out, recipe, workers
        self.threads = default_threads(workers) if threads is None else threads
        self._mp = multiprocessing.get_context("spawn")

    def _spawn(self) -> _Slot:
        parent, child = self._mp.Pipe()
        proc = self._mp.Process(target=_local_worker, args=(child, str(self.out), self.recipe, self.threads),
                                daemon=True, name="leafview-dataset-worker")
        proc.start()
        child.close()
        return _Slot(proc, parent)

    def run(self, shards: Sequence[int], on_image: Callable[[], None] | None = None) -> EngineResult:
        """Render ``shards``; ``on_image()`` after every image written."""
        result = EngineResult()
        queue = [(s, 1) for s in shards]
        if not queue:
            return result
        failed: dict[int, str] = {}
        slots: list[_Slot] = []
        startup_deaths = 0
        with signal_guard():   # SIGTERM/SIGHUP become exceptions here, so the finally below ends the workers
            try:
                slots = [self._spawn() for _ in range(min(self.workers, len(queue)))]
                while queue or any(s.shard is not None for s in slots):
                    for slot in slots:
                        if slot.ready and slot.shard is None and queue:
                            slot.shard, slot.attempt = queue.pop(0)
                            slot.conn.send((slot.shard, slot.attempt))
                    ready = wait([s.conn for s in slots] + [s.process.sentinel for s in slots])
                    for slot in list(slots):
                        if slot.conn in ready or slot.process.sentinel in ready:
                            self._drain(slot, result, on_image)
                        if slot.process.sentinel in ready:
                            slot.process.join()
                            code = slot.process.exitcode
                            slot.conn.close()
                            slots.remove(slot)
                            why = f"exit status {code}" if code is not None and code >= 0 else f"signal {-(code or 0)}"
                            if slot.shard is not None:
                                shard, attempt = slot.shard, slot.attempt
                                if attempt < MAX_ATTEMPTS:
                                    result.retried.append(shard)
                                    queue.insert(0, (shard, attempt + 1))
                                else:
                                    failed[shard] = why
                            elif not slot.ready:
                                startup_deaths += 1
                                if startup_deaths > 2 * self.workers:
                                    raise DatasetError(f"the worker processes die while starting ({why})")
                            if queue and len(slots) < self.workers:
                                slots.append(self._spawn())
            finally:
                for slot in slots:
                    if slot.process.is_alive():
                        try:
                            slot.conn.send(None)
                        except OSError:
                            pass
                for slot in slots:
                    slot.process.join(timeout=30 if slot.shard is None else 0.1)
                    if slot.process.is_alive():
                        slot.process.terminate()
                        slot.process.join(timeout=10)
                    slot.conn.close()
        if failed:
            raise _failed(self.recipe, failed)
        return result

    def _drain(self, slot: _Slot, result: EngineResult, on_image: Callable[[], None] | None) -> None:
        """Handle every message waiting on ``slot``'s pipe."""
        try:
            while slot.conn.poll():
                msg = slot.conn.recv()
                kind = msg[0]
                if kind == "ready":
                    slot.ready = True
                    result.gl_renderer = str(msg[1])
                elif kind == "image":
                    result.images += 1
                    if on_image is not None:
                        on_image()
                elif kind == "done":
                    result.done.append(int(msg[1]))
                    slot.shard = None
                elif kind == "error":
                    _raise_worker_error(int(msg[2]), str(msg[3]), msg[1])
        except (EOFError, OSError):
            return

    def close(self) -> None:
        """Nothing to release: the processes end with each run."""


# -- Ray ---------------------------------------------------------------------------------------------
def import_ray() -> Any:
    """The ``ray`` module, or UsageError naming the extra to install (Ray is optional)."""
    try:
        return importlib.import_module("ray")   # optional: imported only for --engine ray
    except ImportError:
        raise UsageError(f"--engine ray needs Ray, which is not installed: {RAY_INSTALL}") from None


def check_address(address: str, timeout: float = 5.0) -> None:
    """A Ray address that can be reached: ``HOST:PORT`` or ``ray://HOST:PORT`` must accept a TCP
    connection within ``timeout`` seconds (DatasetError, exit 1, otherwise); ``auto`` is left to
    Ray. A malformed address is a UsageError."""
    if address in ("auto", "local"):
        return
    text = address[len("ray://"):] if address.startswith("ray://") else address
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit() or not 0 < int(port) < 65536:
        raise UsageError(f"--address {address[:80]!r}: expected HOST:PORT, ray://HOST:PORT or auto")
    try:
        socket.create_connection((host.strip("[]") or "127.0.0.1", int(port)), timeout=timeout).close()
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise DatasetError(f"--address {address}: no Ray cluster can be reached there ({reason.lower()})") from None


def _assigned_gpu() -> int | None:
    """The EGL device of a Ray actor given a GPU: the first GPU id Ray assigned to it. Ray sets
    ``CUDA_VISIBLE_DEVICES`` for CUDA, but EGL enumerates every GPU of the node, so the context is
    asked for that device by index (None when Ray assigned none)."""
    ids = import_ray().get_gpu_ids()
    return int(ids[0]) if ids else None


class RayShardWorker:
    """The Ray actor: one context, shards on request (see :class:`RayEngine`)."""

    def __init__(self, out: str, recipe: Recipe, threads: int | None, gpu_device: bool = False) -> None:
        _set_threads(threads)
        self.out = Path(out)
        self.renderer = ImageRenderer(recipe, device=_assigned_gpu() if gpu_device else None)

    def gl_renderer(self) -> str:
        return self.renderer.gl_renderer

    def render(self, shard: int, attempt: int) -> tuple[int, int]:
        _crash_hook(shard, attempt)
        try:
            return shard, render_shard(self.renderer, self.out, shard)
        except Exception as exc:
            code, text = _error_message(exc)
            raise RuntimeError(f"[leafview-exit-{code}] {text}") from None


class RayEngine:
    """Ray actors (see the module docstring). Connects in the constructor, so a bad cluster is
    reported before anything is written."""

    name = "ray"

    def __init__(self, out: Path, recipe: Recipe, workers: int, address: str | None = None,
                 gpus_per_worker: float = 0.0, threads: int | None = None) -> None:
        self.ray = import_ray()
        self.out, self.recipe, self.workers = out, recipe, workers
        self.gpus = float(gpus_per_worker)
        if address is not None:
            check_address(address)
        self._started = False
        self._signals = _signal_handlers()   # ray.init installs its own SIGTERM/SIGINT handlers
        if not self.ray.is_initialized():
            options: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False,
                                       "logging_level": logging.ERROR, "configure_logging": False}
            try:
                if address is not None:
                    self.ray.init(address=address, **options)
                else:
                    self.ray.init(num_cpus=workers, num_gpus=0 if not self.gpus else None, **options)
            except Exception as exc:   # ConnectionError, RuntimeError, TimeoutError ... from Ray
                raise DatasetError(f"cannot start Ray{f' at {address}' if address else ''}: "
                                   f"{' '.join(str(exc).split())[:300]}") from None
            self._started = True
        # a cluster's nodes have their own CPU counts: leave llvmpipe's default there
        self.threads = threads if threads is not None else (default_threads(workers) if address is None else None)
        self._actor_cls = self.ray.remote(num_cpus=1, num_gpus=self.gpus, max_restarts=0)(RayShardWorker)

    def _actor(self) -> Any:
        return self._actor_cls.remote(str(self.out), self.recipe, self.threads, self.gpus > 0)

    def run(self, shards: Sequence[int], on_image: Callable[[], None] | None = None) -> EngineResult:
        ray = self.ray
        result = EngineResult()
        queue = [(s, 1) for s in shards]
        if not queue:
            return result
        failed: dict[int, str] = {}
        actors = [self._actor() for _ in range(min(self.workers, len(queue)))]
        try:
            result.gl_renderer = str(ray.get(actors[0].gl_renderer.remote()))
        except ray.exceptions.RayError as exc:
            raise DatasetError(f"a Ray worker could not start: {_ray_reason(exc)}") from None
        pending: dict[Any, tuple[int, int, int]] = {}      # ref -> (actor slot, shard, attempt)
        idle = list(range(len(actors)))
        try:
            while queue or pending:
                while idle and queue:
                    slot = idle.pop(0)
                    shard, attempt = queue.pop(0)
                    pending[actors[slot].render.remote(shard, attempt)] = (slot, shard, attempt)
                done, _ = ray.wait(list(pending), num_returns=1)
                for ref in done:
                    slot, shard, attempt = pending.pop(ref)
                    try:
                        _, n = ray.get(ref)
                    except ray.exceptions.RayActorError as exc:      # the actor's process died
                        actors[slot] = self._actor()
                        if attempt < MAX_ATTEMPTS:
                            result.retried.append(shard)
                            queue.insert(0, (shard, attempt + 1))
                        else:
                            failed[shard] = _ray_reason(exc)
                        idle.append(slot)
                        continue
                    except ray.exceptions.RayTaskError as exc:
                        text = _ray_reason(exc)
                        code = 2 if "[leafview-exit-2]" in text else 1
                        _raise_worker_error(code, text.split("] ", 1)[-1] if "[leafview-exit-" in text else text, shard)
                    result.done.append(shard)
                    result.images += int(n)
                    if on_image is not None:
                        for _ in range(int(n)):
                            on_image()
                    idle.append(slot)
        finally:
            for actor in actors:
                try:
                    ray.kill(actor)
                except Exception:   # already gone
                    pass
        if failed:
            raise _failed(self.recipe, failed)
        return result

    def close(self) -> None:
        """Shut down the Ray this engine started (or disconnect from the cluster)."""
        if self._started:
            self.ray.shutdown()
            self._started = False
            _restore_signal_handlers(self._signals)


_SIGNALS = tuple(s for s in (getattr(signal, n, None) for n in ("SIGINT", "SIGTERM", "SIGHUP")) if s is not None)


def _signal_handlers() -> dict[int, Any]:
    """The handlers in place now (main thread), so that those Ray installs can be undone."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {sig: signal.getsignal(sig) for sig in _SIGNALS}


def _restore_signal_handlers(saved: dict[int, Any]) -> None:
    """Put back the handlers of :func:`_signal_handlers`: after a local Ray is shut down, Ctrl-C and
    SIGTERM act in this process as they did before (leafview's output layer takes only signals
    left at their default)."""
    for sig, handler in saved.items():
        if handler is not None:
            with contextlib.suppress(ValueError, OSError):
                signal.signal(sig, handler)


def _ray_reason(exc: BaseException) -> str:
    """The first meaningful line of a Ray error (its cause's message when there is one)."""
    cause = getattr(exc, "cause", None)
    text = str(cause) if cause is not None else str(exc)
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("RuntimeError: "):
            return line[len("RuntimeError: "):]
        if "[leafview-exit-" in line:
            return line[line.index("[leafview-exit-"):]
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    return (lines[-1] if lines else type(exc).__name__)[:300]


def start_engine(engine: str, out: Path, recipe: Recipe, workers: int, *, address: str | None = None,
                 gpus_per_worker: float = 0.0, threads: int | None = None) -> LocalEngine | RayEngine:
    """The engine for a run (Ray connected already)."""
    if engine == "ray":
        return RayEngine(out, recipe, workers, address, gpus_per_worker, threads)
    return LocalEngine(out, recipe, workers, threads)
