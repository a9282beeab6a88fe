"""The ripple pass: fBm signals synthesised on the GPU (``shaders/fbm.comp``, Geng, Hu & Zhang
2014, eqs 1-2), all leaves of a draw in one dispatch, into a storage buffer the leaf vertex
shader samples (``SIGNALS_BINDING``).

Only a change of a signal's seed or β re-runs the pass; the ripple amplitudes, fluctuation λ,
sampling interval k and phase θ live in the leaf's uniform block.
"""

from __future__ import annotations

from collections.abc import Sequence

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.deform.fbm import MAX_SAMPLES, RIPPLE_SAMPLES
from leafview.gpu.layout import FBM_JOB_DTYPE, FBM_JOBS_BINDING, SIGNALS_BINDING
from leafview.gpu.owner import GrowingBuffer
from leafview.gpu.programs import ProgramCache
from leafview.gpu.shaders import build_compute

__all__ = ["RipplePass", "RIPPLE_SAMPLES", "SIGNALS_BINDING"]


class RipplePass:
    """Owns the signal buffer (and, without a shared ``programs`` cache, the synthesis program).

    :meth:`update` takes one ``(seed, beta)`` per signal row and (re)computes only the rows whose
    key changed, in a single dispatch; rows keep their index, which leaf records refer to.
    """

    def __init__(self, ctx: moderngl.Context, n: int = RIPPLE_SAMPLES, *,
                 programs: ProgramCache | None = None) -> None:
        if n % 2 or not 4 <= n <= MAX_SAMPLES:
            raise ValueError(f"ripple signals need an even length in 4..{MAX_SAMPLES}, got {n}")
        self.ctx, self.n = ctx, n
        self._owns_shader = programs is None
        self.shader = build_compute(ctx, "fbm.comp") if programs is None else programs.compute("fbm.comp")
        self._signals = GrowingBuffer(ctx)
        self._jobs = GrowingBuffer(ctx)
        self._keys: list[tuple[int, float] | None] = []
        self.dispatches = 0

    @property
    def signals(self) -> moderngl.Buffer | None:
        """The signal buffer (None before the first :meth:`update`)."""
        return self._signals.buffer if self._signals.size else None

    def update(self, keys: Sequence[tuple[int, float]]) -> int:
        """Make row i hold the signal of ``keys[i] = (seed, beta)``; returns rows recomputed."""
        rows = len(keys)
        signals = self._signals.ensure(max(rows, 1) * self.n * 4, keep=True)
        stale = [i for i, key in enumerate(keys) if i >= len(self._keys) or self._keys[i] != key]
        self._keys = list(self._keys[:rows]) + [None] * max(0, rows - len(self._keys))
        if not stale:
            return 0
        jobs = np.zeros(len(stale), dtype=FBM_JOB_DTYPE)
        for j, i in enumerate(stale):
            seed, beta = keys[i]
            jobs[j] = (int(seed) & 0xFFFFFFFF, float(beta), self.n, i * self.n)
        self._jobs.write(jobs.tobytes()).bind_to_storage_buffer(FBM_JOBS_BINDING)
        signals.bind_to_storage_buffer(SIGNALS_BINDING)
        self.shader.run(group_x=len(stale))
        self.ctx.memory_barrier(moderngl.ALL_BARRIER_BITS)
        self.dispatches += 1
        for i in stale:
            seed, beta = keys[i]
            self._keys[i] = (int(seed), float(beta))
        return len(stale)

    def bind(self) -> None:
        if not self._signals.size:
            self.update([(0, 1.0)])
        self._signals.buffer.bind_to_storage_buffer(SIGNALS_BINDING)

    def read(self, row: int) -> NDArray[np.float32]:
        raw = self._signals.buffer.read(size=self.n * 4, offset=row * self.n * 4)
        return np.frombuffer(raw, np.float32).copy()

    def release(self) -> None:
        if self._owns_shader:
            self.shader.release()
        self._owns_shader = False
        self._signals.release()
        self._jobs.release()
