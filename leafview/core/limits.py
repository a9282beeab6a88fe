"""The documented limits on counts, sizes and names, in one place (``docs/reliability.md``,
"Inputs and limits", has the table).

Every limit is checked where the value enters (the parameter and scene validation, the command
line's argument types) and before anything is allocated. Counts that scale memory (leaves,
plants) are also checked against the machine: :func:`check_memory` compares an estimate of the
host memory a scene needs with :data:`MEMORY_FRACTION` of the physical memory
(``SC_PHYS_PAGES × SC_PAGE_SIZE``), so a scene that would swap or be killed is refused with a
message instead. The per-item costs are measured (``tracemalloc`` and RSS of ``build_scene``
plus the GPU packing), rounded up.

The file-level limits (size, nesting depth, integer digits) belong to the reader,
:mod:`leafview.inputs`.
"""

from __future__ import annotations

import math
import os
import unicodedata
from typing import Any

from leafview.errors import ParamError

__all__ = ["MAX_NAME_CHARS", "MAX_SILHOUETTE_ROWS", "MAX_LEAVES", "MAX_PLANTS", "MAX_LOBES_PER_SIDE",
           "MAX_MORPH_FRAMES", "MAX_VIEW_FRAMES", "MAX_IMAGE_SIDE", "MAX_GRID", "BYTES_PER_LEAF",
           "BYTES_PER_PLANT", "BYTES_PER_LEAF_PARAMS", "MEMORY_FRACTION", "MAX_WORLD_COORD", "MIN_FRAME_RATIO", "check_name",
           "check_count", "parse_count", "physical_memory", "scene_bytes", "check_memory"]

MAX_NAME_CHARS = 256            # a leaf or scene name: characters, no control characters
MAX_SILHOUETTE_ROWS = 7         # silhouette rows of an extended leaf (degree up to 8)
MAX_LEAVES = 10_000_000         # leaves of a scene or a leaf set (and the memory check below)
MAX_PLANTS = 100_000            # plants of a field or hedge (and the memory check below)
MAX_LOBES_PER_SIDE = 12         # lateral lobes per side of a multilobed leaf (half, positions)
MAX_MORPH_FRAMES = 1000         # frames of a morph sequence
MAX_VIEW_FRAMES = 1_000_000     # --frames of a scripted viewer run
MAX_IMAGE_SIDE = 8192           # pixels per side of an image or window
MAX_GRID = 1025                 # grid samples across or along a blade
BYTES_PER_LEAF = 2600           # host memory per scene leaf: arrays, placement, GPU records (816 B), the
#                                 visible records (240 B) and the branch texture (816 B, rippled, bent
#                                 or extended species) (as gpu.limits)
BYTES_PER_PLANT = 13_000        # host memory per plant: its stem mesh and placement
BYTES_PER_LEAF_PARAMS = 4000    # host memory per leaf read from a leaf set (LeafParams objects)
MEMORY_FRACTION = 0.5           # a scene may plan to use this share of the physical memory
MAX_WORLD_COORD = 3.0e38        # world coordinates must fit float32 (what every file stores)
MIN_FRAME_RATIO = 1e-5          # framed extent / distance from the origin (float32 resolves ~1e-7)


def check_name(name: Any, path: str = "name") -> str:
    """``name`` when it is a string of at most :data:`MAX_NAME_CHARS` characters without control
    characters (NUL, newlines, escapes: they end up in file metadata and terminals)."""
    if not isinstance(name, str):
        raise ParamError(path, f"expected a string, got {type(name).__name__}")
    if len(name) > MAX_NAME_CHARS:
        raise ParamError(path, f"{len(name):,} characters; at most {MAX_NAME_CHARS} are accepted")
    for i, ch in enumerate(name):
        if unicodedata.category(ch) in ("Cc", "Cs") or ch in "\u2028\u2029":
            raise ParamError(path, f"control character U+{ord(ch):04X} at position {i}; names are printable text")
    return name


def check_count(path: str, value: Any, lo: int, hi: int) -> int:
    """``value`` when it is a whole number (not a bool) in ``lo..hi``."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ParamError(path, f"must be a whole number, got {type(value).__name__}")
    if not lo <= value <= hi:
        shown = f"{value:,}" if abs(value) < 10**30 else "a number of more than 30 digits"
        raise ParamError(path, f"must be in {lo:,}..{hi:,}, got {shown}")
    return int(value)


def parse_count(text: str, lo: int, hi: int, what: str, name: str | None = None) -> int:
    """A command-line count of ``what`` (``name`` in range errors): a whole number, with ``_``
    separators or in exponent form (``1e6``); raises ValueError with a one-line message (never
    OverflowError, whatever the text)."""
    t = text.strip().replace("_", "")
    if len(t) > 40:
        raise ValueError(f"expected a whole number of {what}, got a {len(t)}-character text")
    try:
        n = int(t)
    except ValueError:
        n = _whole_float(t, lo, hi, what, text)
    if not lo <= n <= hi:
        raise ValueError(f"{name or what} must be in {lo:,}..{hi:,}, got {text!r}")
    return n


def _whole_float(t: str, lo: int, hi: int, what: str, text: str) -> int:
    """``1e6``-style counts: a finite float with no fraction."""
    try:
        x = float(t)
    except ValueError:
        raise ValueError(f"expected a whole number of {what}, got {text!r}") from None
    if not (math.isfinite(x) and x.is_integer()):
        raise ValueError(f"expected a whole number of {what} in {lo:,}..{hi:,}, got {text!r}")
    return int(x)


def physical_memory() -> int | None:
    """Bytes of physical memory, or None where the system does not say."""
    try:
        pages, size = os.sysconf("SC_PHYS_PAGES"), os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None
    return int(pages) * int(size) if pages > 0 and size > 0 else None


def scene_bytes(leaves: int, plants: int) -> int:
    """Estimated host memory of a scene of ``leaves`` leaves on ``plants`` plants."""
    return int(leaves) * BYTES_PER_LEAF + int(plants) * BYTES_PER_PLANT


def check_memory(path: str, needed: int, what: str) -> None:
    """ParamError at ``path`` when ``needed`` bytes (for ``what``) exceed :data:`MEMORY_FRACTION`
    of the physical memory."""
    total = physical_memory()
    if total is None:
        return
    budget = int(total * MEMORY_FRACTION)
    if needed > budget:
        raise ParamError(path, f"{what} would need about {needed / 2**30:.1f} GiB of memory, more than "
                               f"{MEMORY_FRACTION:.0%} of this machine's {total / 2**30:.1f} GiB")
