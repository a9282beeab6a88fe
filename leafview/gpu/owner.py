"""Ownership of GL objects: who releases what, in one place.

Every GL object of the package is created by an owner that releases it explicitly
(``release()`` or a ``with`` block); nothing relies on ``__del__`` or the garbage collector.
The helpers here are the three shapes ownership takes:

* :class:`GLObjects`: the objects an owner created, released together in reverse order;
* :class:`ReleasingLRU`: a bounded cache whose evicted values are released (grids, targets);
* :class:`GrowingBuffer`: a buffer replaced by a larger one (power-of-two sizes) when a request
  does not fit, so repeated batches reuse it.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any, Generic, Protocol, TypeVar

import moderngl

__all__ = ["Releasable", "GLObjects", "ReleasingLRU", "GrowingBuffer", "release_all", "next_pow2"]


class Releasable(Protocol):
    def release(self) -> None: ...


R = TypeVar("R", bound=Releasable)
V = TypeVar("V", bound=Releasable)


def release_all(*objects: Releasable | None) -> None:
    """Release each object that is not None, in the order given."""
    for obj in objects:
        if obj is not None:
            obj.release()


def next_pow2(n: int) -> int:
    """Capacity for ``n``: the next power of two (at least 1)."""
    return 1 << max(0, int(n - 1).bit_length())


class GLObjects:
    """The GL objects (or owners of them) that one owner created; :meth:`release` releases them
    newest first and forgets them, so it may be called again."""

    def __init__(self) -> None:
        self._objects: list[Releasable] = []

    def own(self, obj: R) -> R:
        """Take ``obj`` into this owner's care; returns it."""
        self._objects.append(obj)
        return obj

    def __len__(self) -> int:
        return len(self._objects)

    def release(self) -> None:
        while self._objects:
            self._objects.pop().release()


class ReleasingLRU(Generic[V]):
    """A cache of at most ``limit`` values; the least recently used one is released when a new
    one would exceed it. Callers use a value right after getting it and never keep it across
    calls (it may be evicted by the next one)."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self._items: OrderedDict[Hashable, V] = OrderedDict()

    def get(self, key: Hashable, make: Callable[[], V]) -> V:
        if key in self._items:
            self._items.move_to_end(key)
            return self._items[key]
        value = self._items[key] = make()
        while len(self._items) > self.limit:
            _, old = self._items.popitem(last=False)
            old.release()
        return value

    def __len__(self) -> int:
        return len(self._items)

    def values(self) -> list[V]:
        return list(self._items.values())

    def release(self) -> None:
        """Release every cached value (the cache stays usable)."""
        while self._items:
            _, value = self._items.popitem(last=False)
            value.release()


class GrowingBuffer:
    """One GL buffer of at least the size last asked for (grown to powers of two)."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self._buffer: moderngl.Buffer | None = None

    @property
    def buffer(self) -> moderngl.Buffer:
        if self._buffer is None:
            raise RuntimeError("GrowingBuffer.ensure() was not called")
        return self._buffer

    @property
    def size(self) -> int:
        return 0 if self._buffer is None else int(self._buffer.size)

    def ensure(self, nbytes: int, *, keep: bool = False) -> moderngl.Buffer:
        """The buffer, replaced by one of ``next_pow2(nbytes)`` bytes if smaller than ``nbytes``;
        ``keep`` copies the old contents into the new buffer."""
        old = self._buffer
        if old is not None and old.size >= nbytes:
            return old
        new = self.ctx.buffer(reserve=next_pow2(max(int(nbytes), 1)))
        if old is not None:
            if keep:
                new.write(old.read())
            old.release()
        self._buffer = new
        return new

    def write(self, data: Any) -> moderngl.Buffer:
        """Write ``data`` (bytes-like) at offset 0, growing first if needed."""
        view = memoryview(data)
        buf = self.ensure(view.nbytes)
        buf.write(view)
        return buf

    def release(self) -> None:
        if self._buffer is not None:
            self._buffer.release()
            self._buffer = None
