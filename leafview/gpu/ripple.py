"""The ripple pass: fBm signals synthesised on the GPU (``shaders/fbm.comp``), all leaves of a
draw in one dispatch, into a storage buffer the leaf vertex shader samples (binding 3).

Only a change of a signal's seed or β re-runs the pass; the ripple amplitudes, fluctuation λ,
sampling interval k and phase θ live in the leaf's uniform block.
"""

from __future__ import annotations

from collections.abc import Sequence

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.deform.fbm import MAX_SAMPLES, RIPPLE_SAMPLES
from leafview.gpu.shaders import build_compute

__all__ = ["RipplePass", "RIPPLE_SAMPLES", "SIGNALS_BINDING"]

SIGNALS_BINDING = 3
_JOBS_BINDING = 5
_JOB = np.dtype([("seed", "<u4"), ("beta", "<f4"), ("n", "<u4"), ("offset", "<u4")])


class RipplePass:
    """Owns the synthesis program and the signal buffer.

    :meth:`update` takes one ``(seed, beta)`` per signal row and (re)computes only the rows whose
    key changed, in a single dispatch; rows keep their index, which leaf records refer to.
    """

    def __init__(self, ctx: moderngl.Context, n: int = RIPPLE_SAMPLES) -> None:
        if n % 2 or not 4 <= n <= MAX_SAMPLES:
            raise ValueError(f"ripple signals need an even length in 4..{MAX_SAMPLES}, got {n}")
        self.ctx, self.n = ctx, n
        self.shader = build_compute(ctx, "fbm.comp")
        self.signals: moderngl.Buffer | None = None
        self._jobs: moderngl.Buffer | None = None
        self._keys: list[tuple[int, float] | None] = []
        self.dispatches = 0

    def update(self, keys: Sequence[tuple[int, float]]) -> int:
        """Make row i hold the signal of ``keys[i] = (seed, beta)``; returns rows recomputed."""
        rows = len(keys)
        need = max(rows, 1) * self.n * 4
        if self.signals is None or self.signals.size < need:
            old = self.signals
            self.signals = self.ctx.buffer(reserve=_grow(need))
            if old is not None:
                self.signals.write(old.read())
                old.release()
        stale = [i for i, key in enumerate(keys) if i >= len(self._keys) or self._keys[i] != key]
        self._keys = list(self._keys[:rows]) + [None] * max(0, rows - len(self._keys))
        if not stale:
            return 0
        jobs = np.zeros(len(stale), dtype=_JOB)
        for j, i in enumerate(stale):
            seed, beta = keys[i]
            jobs[j] = (int(seed) & 0xFFFFFFFF, float(beta), self.n, i * self.n)
        if self._jobs is None or self._jobs.size < jobs.nbytes:
            if self._jobs is not None:
                self._jobs.release()
            self._jobs = self.ctx.buffer(reserve=_grow(jobs.nbytes))
        self._jobs.write(jobs.tobytes())
        self._jobs.bind_to_storage_buffer(_JOBS_BINDING)
        self.signals.bind_to_storage_buffer(SIGNALS_BINDING)
        self.shader.run(group_x=len(stale))
        self.ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)
        self.dispatches += 1
        for i in stale:
            self._keys[i] = tuple(keys[i])
        return len(stale)

    def bind(self) -> None:
        if self.signals is None:
            self.update([(0, 1.0)])
        self.signals.bind_to_storage_buffer(SIGNALS_BINDING)

    def read(self, row: int) -> NDArray[np.float32]:
        assert self.signals is not None
        return np.frombuffer(self.signals.read(size=self.n * 4, offset=row * self.n * 4), np.float32).copy()

    def release(self) -> None:
        for obj in (self.shader, self.signals, self._jobs):
            if obj is not None:
                obj.release()
        self.signals = self._jobs = None


def _grow(n: int) -> int:
    return 1 << max(0, int(n - 1).bit_length())
