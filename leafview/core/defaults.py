"""One place for each default that several layers share: the (u, v) grids the leaf is drawn,
baked and compared on, and the outline-fit tolerances. Everything else keeps its default beside
the code that uses it."""

from __future__ import annotations

__all__ = ["DEFAULT_GRID", "DETAIL_GRID", "LOBED_GRID", "OUTLINE_FIT_TARGET", "INSTANCE_FIT_TARGET"]

DEFAULT_GRID: tuple[int, int] = (33, 65)
"""u × v samples of a drawn, baked or exported leaf: 2·32·64 = 4096 triangles, odd u so that a
column lies on the midrib."""

DETAIL_GRID: tuple[int, int] = (33, 129)
"""u × v samples for shapes with sharp features along v: extended silhouettes (catalogue sheets,
morph frames) and lobed leaves."""

LOBED_GRID: tuple[int, int] = (9, 257)
"""t × tour samples of a lobed leaf at full detail: 9 along each railroad tie (skeleton to margin)
and one row per tie of its sweep table (``leafview.deform.sweep.SWEEP_ROWS`` + 1, the first row
repeated at the end). Other requested grids map to a lobed one by ``leafview.gpu.lobe_tables.
lobed_grid`` (rows every 1, 2 or 4 ties)."""

OUTLINE_FIT_TARGET = 0.005
"""Outline fits take the fewest silhouette rows whose error is below this (Hausdorff ÷ leaf length)."""

INSTANCE_FIT_TARGET = 0.01
"""Random shape instances and batch fits stop once within this (Hausdorff ÷ leaf length): 1 %."""
