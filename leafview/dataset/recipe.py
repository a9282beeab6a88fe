"""What a dataset is made of: the :class:`Recipe` (every argument that decides the bytes of the
output), validated before any work, and its JSON form for the manifests.

The engine, the number of workers and the Ray address are not part of the recipe: they change how
fast a dataset is made, never what is in it.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from leafview._version import __version__
from leafview.core.compact import compact_dict
from leafview.core.limits import MAX_IMAGE_SIDE
from leafview.core.params import LeafParams, Transform
from leafview.errors import UsageError
from leafview.resources import builtin_presets

__all__ = ["Recipe", "DATASET_FORMAT", "LAYOUTS", "DEFAULT_SPECIES", "DEFAULT_ELEVATION", "DEFAULT_RANGES", "MAX_COUNT",
           "MAX_LEAVES_PER_IMAGE", "MAX_SHARD", "parse_range", "parse_split", "load_species"]

DATASET_FORMAT = 1
LAYOUTS = ("plant", "field", "tray")
# built-in presets of the default mix: six flat shapes and two rippled ones
DEFAULT_SPECIES = ("ovate", "lanceolate", "elliptic", "obovate", "serrate", "deltoid", "beech", "holly")
# camera elevation (degrees above the horizon) by layout, when --elevation is not given
DEFAULT_ELEVATION = {"plant": (5.0, 45.0), "field": (20.0, 60.0), "tray": (50.0, 90.0)}
# the other randomisation ranges (LO, HI) by default
DEFAULT_RANGES: dict[str, tuple[float, float]] = {"azimuth": (0.0, 360.0), "distance": (0.6, 1.0),
                                                  "sun_elevation": (25.0, 75.0), "light_intensity": (0.7, 1.3)}
MAX_COUNT = 1_000_000             # images: six-digit file names
MAX_LEAVES_PER_IMAGE = 10_000     # leaf ids are 16-bit in instances/*.png
MAX_SHARD = 10_000
_SPLIT_NAME = re.compile(r"^[a-z][a-z0-9_]{0,31}$")
SPLIT_TOLERANCE = 1e-9


def parse_range(text: str, flag: str, lo: float, hi: float) -> tuple[float, float]:
    """``LO,HI`` (two finite numbers, LO ≤ HI, both in [lo, hi]) of option ``flag``; UsageError."""
    parts = text.split(",") if len(text) <= 60 else []
    try:
        a, b = (float(p) for p in parts)
    except ValueError:
        raise UsageError(f"{flag}: expected LO,HI (two numbers), got {text[:60]!r}") from None
    return check_range((a, b), flag, lo, hi)


def check_range(pair: Any, flag: str, lo: float, hi: float) -> tuple[float, float]:
    """A (LO, HI) pair of option ``flag`` checked: finite, LO ≤ HI, within [lo, hi]."""
    try:
        a, b = (float(x) for x in pair)
    except (TypeError, ValueError):
        raise UsageError(f"{flag}: expected two numbers (LO, HI), got {pair!r}") from None
    if not (math.isfinite(a) and math.isfinite(b)):
        raise UsageError(f"{flag}: LO and HI must be finite, got {a:g},{b:g}")
    if a > b:
        raise UsageError(f"{flag}: LO must not exceed HI, got {a:g},{b:g}")
    if a < lo or b > hi:
        raise UsageError(f"{flag}: must lie within {lo:g}..{hi:g}, got {a:g},{b:g}")
    return a, b


def parse_split(text: str) -> tuple[tuple[str, float], ...]:
    """``train=0.8,val=0.2``: names (lower-case letters, digits, ``_``) and fractions that sum to
    1 (within 1e-9); UsageError otherwise."""
    out: list[tuple[str, float]] = []
    for item in text.split(",") if len(text) <= 400 else [text[:40]]:
        name, eq, value = item.partition("=")
        name = name.strip()
        try:
            frac = float(value) if eq else float("nan")
        except ValueError:
            frac = float("nan")
        if not eq or not math.isfinite(frac):
            raise UsageError(f"--split: expected NAME=FRACTION,..., such as train=0.8,val=0.2; got {item[:40]!r}")
        out.append((name, frac))
    return check_split(out)


def check_split(split: Any) -> tuple[tuple[str, float], ...]:
    """Split names and fractions validated (see :func:`parse_split`)."""
    items = list(split.items()) if isinstance(split, dict) else list(split)
    if not items:
        raise UsageError("--split: give at least one NAME=FRACTION")
    seen: set[str] = set()
    out: list[tuple[str, float]] = []
    for name, frac in items:
        if not isinstance(name, str) or not _SPLIT_NAME.match(name):
            raise UsageError(f"--split: {str(name)[:40]!r} is not a split name (lower-case letters, digits, _; "
                             "starting with a letter)")
        if name in seen:
            raise UsageError(f"--split: {name!r} is named twice")
        seen.add(name)
        frac = float(frac)
        if not (math.isfinite(frac) and 0.0 <= frac <= 1.0):
            raise UsageError(f"--split: {name}={frac:g} is not a fraction in [0, 1]")
        out.append((name, frac))
    total = math.fsum(f for _, f in out)
    if abs(total - 1.0) > SPLIT_TOLERANCE:
        raise UsageError(f"--split: the fractions sum to {total:.12g}, not 1")
    return tuple(out)


def load_species(names: str | list[str] | tuple[str, ...] | None) -> tuple[LeafParams, ...]:
    """The species presets (built-in names or preset files), each named (its name, else the file's
    stem), names unique; the default mix :data:`DEFAULT_SPECIES` when None."""
    if names is None:
        names = list(DEFAULT_SPECIES)
    elif isinstance(names, str):
        names = [n.strip() for n in names.split(",")]
    if not names or any(not n for n in names):
        raise UsageError("--species: expected a comma-separated list of preset names or files")
    builtin = builtin_presets()
    out: list[LeafParams] = []
    for spec in names:
        from_file = spec not in builtin
        path = builtin.get(spec)
        if path is None:
            path = Path(spec)
            if not path.is_file():
                raise UsageError(f"--species: {spec[:80]!r} is not a preset file or built-in name "
                                 f"(built-in: {', '.join(builtin)})")
        leaf = LeafParams.load(path)
        name = leaf.name or path.name.split(".")[0]
        if from_file and not leaf.name:
            leaf = leaf.replace(name=name)
        out.append(leaf.replace(name=name, transform=Transform()))
    names_seen = [leaf.name for leaf in out]
    dupes = sorted({n for n in names_seen if names_seen.count(n) > 1})
    if dupes:
        raise UsageError(f"--species: two species are named {dupes[0]!r} (each species is one COCO category)")
    return tuple(out)


@dataclass(frozen=True)
class Recipe:
    """Every argument that decides a dataset's bytes (validated on construction: UsageError, exit 2).

    Ranges are (LO, HI): ``elevation`` of the camera in degrees above the horizon (None: the
    layout's default, :data:`DEFAULT_ELEVATION`), ``azimuth`` in degrees around +z, ``distance``
    relative to the framing distance (1: the bounding sphere of the leaves just fits the narrower
    field of view), ``sun_elevation`` of the key light in degrees, ``light_intensity`` of the key
    light (the default renderer's is 1.05).
    """

    count: int
    species: tuple[LeafParams, ...]
    leaves: int = 100
    layout: str = "plant"
    size: tuple[int, int] = (640, 480)
    seed: int = 0
    elevation: tuple[float, float] | None = None
    azimuth: tuple[float, float] = DEFAULT_RANGES["azimuth"]
    distance: tuple[float, float] = DEFAULT_RANGES["distance"]
    sun_elevation: tuple[float, float] = DEFAULT_RANGES["sun_elevation"]
    light_intensity: tuple[float, float] = DEFAULT_RANGES["light_intensity"]
    split: tuple[tuple[str, float], ...] = (("train", 0.8), ("val", 0.2))
    shard_size: int = 16
    _digest: str = field(default="", init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        _int(self.count, "--count", 1, MAX_COUNT)
        _int(self.leaves, "--leaves", 1, MAX_LEAVES_PER_IMAGE)
        _int(self.seed, "--seed", 0, 2**63 - 1)
        _int(self.shard_size, "--shard-size", 1, MAX_SHARD)
        if self.layout not in LAYOUTS:
            raise UsageError(f"--layout: unknown layout {self.layout!r} (use {', '.join(LAYOUTS)})")
        if not self.species:
            raise UsageError("--species: at least one species")
        try:
            w, h = (int(x) for x in self.size)
        except (TypeError, ValueError):
            raise UsageError(f"--size: expected (width, height), got {self.size!r}") from None
        if not (16 <= w <= MAX_IMAGE_SIDE and 16 <= h <= MAX_IMAGE_SIDE):
            raise UsageError(f"--size: {w}x{h} outside 16..{MAX_IMAGE_SIDE} per side")
        object.__setattr__(self, "size", (w, h))
        if self.elevation is not None:
            object.__setattr__(self, "elevation", check_range(self.elevation, "--elevation", 0.0, 90.0))
        object.__setattr__(self, "azimuth", check_range(self.azimuth, "--azimuth", -720.0, 720.0))
        object.__setattr__(self, "distance", check_range(self.distance, "--distance", 0.05, 100.0))
        object.__setattr__(self, "sun_elevation", check_range(self.sun_elevation, "--sun-elevation", 0.0, 90.0))
        object.__setattr__(self, "light_intensity", check_range(self.light_intensity, "--light-intensity", 0.0, 10.0))
        object.__setattr__(self, "split", check_split(self.split))
        object.__setattr__(self, "_digest", hashlib.sha256(
            json.dumps(self.to_dict(), sort_keys=True).encode()).hexdigest()[:16])

    @property
    def camera_elevation(self) -> tuple[float, float]:
        """The elevation range in use (the layout's default when none was given)."""
        return self.elevation if self.elevation is not None else DEFAULT_ELEVATION[self.layout]

    @property
    def shards(self) -> int:
        return -(-self.count // self.shard_size)

    def shard_images(self, shard: int) -> range:
        """Image indices of ``shard``."""
        return range(shard * self.shard_size, min((shard + 1) * self.shard_size, self.count))

    @property
    def digest(self) -> str:
        """A short hash of :meth:`to_dict`: shards made with another recipe are not reused."""
        return self._digest

    @property
    def category_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.species)

    def to_dict(self) -> dict[str, Any]:
        """The recipe as plain JSON values (``dataset.json``'s ``arguments``): species inline in the
        compact form, so the manifest says exactly what was drawn."""
        return {"count": self.count, "leaves": self.leaves, "layout": self.layout, "size": list(self.size),
                "seed": self.seed, "elevation": list(self.camera_elevation), "azimuth": list(self.azimuth),
                "distance": list(self.distance), "sun_elevation": list(self.sun_elevation),
                "light_intensity": list(self.light_intensity), "split": dict(self.split),
                "shard_size": self.shard_size, "leafview": __version__, "format": DATASET_FORMAT,
                "species": [compact_dict(s, version=False) for s in self.species]}


def _int(value: Any, flag: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise UsageError(f"{flag}: expected a whole number, got {value!r}")
    if not lo <= value <= hi:
        raise UsageError(f"{flag}: must be in {lo}..{hi:,}, got {value:,}")
    return value
