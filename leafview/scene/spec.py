"""Scenes of many leaves: what a scene file holds and the per-leaf arrays it expands to.

A scene is stored as a recipe, not as a list of leaves (:class:`SceneSpec`, a TOML or JSON file
with ``schema = 1``): the layout (one plant, a field or a hedge of plants, see
:mod:`leafview.scene.plants`), the leaf count, a seed, the species (each a leaf parameter
table, written in the compact form of :mod:`leafview.core.compact`, so a file is
self-contained) with weights, and how much leaves vary within a species.
:func:`build_scene` expands it deterministically into a :class:`Scene`: per-leaf arrays that the
GPU path packs into one storage-buffer row per leaf.

Variation within a species (Garg & Leow 2011, sec. 4 uses up to ±20 %): every leaf gets its own factors
``f ∈ [1 - variation, 1 + variation]``, one per Ω component (:data:`VARIED`), multiplying the
species' value; ``v̄`` positions stay inside (0, 1). The leaf colour is multiplied by
``1 ± colour_variation`` (one factor per leaf). Each plant takes one species, drawn by weight.
A lobed species (``LeafParams.lobes`` with an outline) is drawn from its sweep table, not from Ω:
its leaves vary in placement and colour only (their factors are 1; the table, cup included, is
shared by the species, one GPU layer each, so varying it per leaf would cost a table per leaf).

Bending in scenes: the cantilever solve (Geng, Hu & Zhang 2014, eq. 4) runs once per species, in the species'
own rest frame, and every leaf of that species carries that droop (a per-leaf solve costs about a
millisecond, too much for 10⁶ leaves). A leaf whose shape factors differ from 1 therefore droops
like its species, not exactly as its own solve would give; :func:`bend_deviation` measures it.

Per-leaf variety (Geng, Hu & Zhang 2014, sec. 6; :mod:`leafview.scene.variety`): a species' ``variety``
table (``[[species]] variety = {...}``) sets ranges for its leaves' ripple phase offset, ripple
amplitude factor and bend load factor. :func:`build_scene` draws them after every other number
(``Scene.ripple_phase``, ``ripple_scale``, ``load_scale``; None when no species varies them). A
leaf with a load factor is drawn with its species' profile interpolated at that load between the
species' solves at a few loads (:func:`leaf_bend`), within 2e-4 leaf lengths of its own solve.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w
from numpy.typing import NDArray

from leafview.atomic import write_text
from leafview.botany import leaf_surface
from leafview.botany.vein_shape import shape_grid
from leafview.core.compact import compact_dict, parse_compact
from leafview.core.display import png_of
from leafview.core.io import load_params, read_document
from leafview.core.limits import (
    MAX_LEAVES,
    MAX_PLANTS,
    check_count,
    check_memory,
    check_name,
    scene_bytes,
)
from leafview.core.params import (
    Bending,
    LeafParams,
    ParamError,
    Shape,
    Transform,
    Vec3,
    parse_params,
    transform_matrices,
)
from leafview.deform.beam import BendProfile, bend_profile
from leafview.deform.surface import grid_uv, partials
from leafview.deform.wind import WindSettings
from leafview.resources import builtin_presets
from leafview.scene.lighting import LightSettings
from leafview.scene.plants import LEAVES_PER_PLANT, Placement, PlantSpec, scatter_later
from leafview.scene.scene_edits import SceneEdit, apply_edits, parse_edits
from leafview.scene.variety import (
    Variety,
    check_variety,
    draw_variety,
    interpolate_bend,
    leaf_bending,
    leaf_ripple,
    load_table,
)

__all__ = ["SceneSpec", "Scene", "build_scene", "load_scene", "save_scene", "scene_from_leaves", "LAYOUTS", "VARIED",
           "MAX_LEAVES", "vary_shape", "evaluate_leaf", "leaf_bend", "bend_deviation", "transform_matrices"]

LAYOUTS = ("plant", "field", "hedge")
# MAX_LEAVES and MAX_PLANTS: leafview.core.limits (with the memory check of SceneSpec)
SCENE_SCHEMA = 1
_FACTOR_CHUNK = 1 << 16     # leaves whose Ω factors are drawn at once

# Ω components that vary per leaf (column order of Scene.factors)
VARIED = ("a1.x", "a1.y", "a1.z", "a2.x", "a2.y", "a2.z",
          "vbar1", "xs1", "zs1", "vbar2", "xs2", "zs2", "vbar3", "xs3", "zs3",
          "zf1", "zf2", "zf3", "zg1", "zg2", "zg3")


@dataclass(frozen=True)
class SceneSpec:
    """The recipe of a scene (the content of a scene file).

    ``species``: leaf parameters (their transform is ignored: placement comes from the layout)
    and ``weights`` (relative frequency per plant). ``plant``: keyword arguments of
    :class:`leafview.scene.plants.PlantSpec` (phyllotaxis, height, branches, ...).
    """

    species: tuple[LeafParams, ...]
    weights: tuple[float, ...] = ()
    layout: str = "field"
    leaves: int = 10_000
    seed: int = 0
    plants: int = 0                 # 0: chosen from the leaf count
    variation: float = 0.2          # ± fraction per Ω component
    colour_variation: float = 0.1   # ± fraction of the leaf colour
    stems: bool = True
    plant: Mapping[str, Any] = field(default_factory=dict)
    name: str = ""
    light: LightSettings = field(default_factory=LightSettings)   # [light]: sun, sky, ground, tone
    wind: WindSettings = field(default_factory=WindSettings)      # [wind]: speed, direction, time
    edits: tuple[SceneEdit, ...] = ()   # [[edits]]: scene-wide edits (leafview.scene.scene_edits), applied last
    # per species (``[[species]] variety``): the ranges its leaves' ripple and bend load vary in
    varieties: tuple[Variety, ...] = ()

    def __post_init__(self) -> None:
        if not self.species:
            raise ParamError("species", "a scene needs at least one species")
        weights = self.weights or (1.0,) * len(self.species)
        if len(weights) != len(self.species):
            raise ParamError("species", f"{len(weights)} weights for {len(self.species)} species")
        for i, w in enumerate(weights):
            if not (math.isfinite(w) and w > 0):
                raise ParamError(f"species[{i}].weight", f"must be a positive number, got {w!r}")
        object.__setattr__(self, "weights", tuple(float(w) for w in weights))
        varieties = tuple(self.varieties)
        if len(varieties) != len(self.species) and not any(isinstance(v, Variety) and v.active for v in varieties):
            varieties = (Variety(),) * len(self.species)   # none set (e.g. the species replaced): the defaults
        if len(varieties) != len(self.species):
            raise ParamError("species", f"{len(varieties)} varieties for {len(self.species)} species")
        for i, (leaf, v) in enumerate(zip(self.species, varieties)):
            if not isinstance(v, Variety):
                raise ParamError(f"species[{i}].variety", f"expected a Variety, got {type(v).__name__}")
            check_variety(leaf, v, f"species[{i}].variety")
        object.__setattr__(self, "varieties", tuple(varieties))
        if self.layout not in LAYOUTS:
            raise ParamError("scene.layout", f"unknown layout {self.layout!r} (use {', '.join(LAYOUTS)})")
        check_count("scene.leaves", self.leaves, 1, MAX_LEAVES)
        check_count("scene.seed", self.seed, 0, 2**63 - 1)
        check_count("scene.plants", self.plants, 0, MAX_PLANTS)
        check_name(self.name, "scene.name")
        plants = self.plants or (1 if self.layout == "plant" else max(1, round(self.leaves / LEAVES_PER_PLANT)))
        stem_plants = plants if self.stems else 0
        check_memory("scene.plants" if scene_bytes(0, stem_plants) > scene_bytes(self.leaves, 0) else "scene.leaves",
                     scene_bytes(self.leaves, stem_plants),
                     f"{self.leaves:,} leaves on {plants:,} plants")
        for key, hi in (("variation", 0.5), ("colour_variation", 0.5)):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= hi:
                raise ParamError(f"scene.{key}", f"must be a number in [0, {hi}], got {value!r}")
        if not isinstance(self.stems, bool):
            raise ParamError("scene.stems", f"must be true or false, got {self.stems!r}")
        self.plant_spec()  # validates [plant]
        object.__setattr__(self, "edits", tuple(self.edits))
        for i, e in enumerate(self.edits):
            if not isinstance(e, SceneEdit):
                raise ParamError(f"edits[{i}]", f"must be a SceneEdit, got {type(e).__name__}")
            if e.target == "species" and e.species >= len(self.species):
                raise ParamError(f"edits[{i}].species", f"species {e.species} out of range 0..{len(self.species) - 1}")
            if e.target == "leaves" and e.leaves[-1] >= self.leaves:
                raise ParamError(f"edits[{i}].leaves", f"leaf {e.leaves[-1]} out of range 0..{self.leaves - 1}")

    def plant_spec(self) -> PlantSpec:
        """The :class:`~leafview.scene.plants.PlantSpec` of ``[plant]`` (validated)."""

        known = {f.name for f in fields(PlantSpec)}
        for key in self.plant:
            if key not in known:
                raise ParamError(f"plant.{key}", f"unknown setting (known: {', '.join(sorted(known))})")
        # values come from a file: PlantSpec validates each one
        settings: dict[str, Any] = {k: (tuple(v) if isinstance(v, list) else v) for k, v in self.plant.items()}
        try:
            return PlantSpec(**settings)
        except ParamError as exc:
            path = exc.path if exc.path.startswith("plant") else f"plant.{exc.path}".rstrip(".")
            raise ParamError(path, exc.message) from None
        except (TypeError, ValueError) as exc:
            raise ParamError("plant", str(exc)) from None

    def replace(self, **changes: Any) -> SceneSpec:
        return replace(self, **changes)

    # -- the file form ---------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        scene: dict[str, Any] = {"layout": self.layout, "leaves": self.leaves, "seed": self.seed,
                                 "plants": self.plants, "variation": self.variation,
                                 "colour_variation": self.colour_variation, "stems": self.stems}
        if self.name:
            scene["name"] = self.name

        species = [{"weight": w, "leaf": compact_dict(leaf.replace(transform=Transform()), version=False)}
                   for leaf, w in zip(self.species, self.weights)]
        for entry, variety in zip(species, self.varieties):
            if variety.active:
                entry["variety"] = variety.to_dict()
        out: dict[str, Any] = {"schema": SCENE_SCHEMA, "scene": scene, "species": species}
        if self.plant:
            out["plant"] = {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.plant.items()}
        for key in ("light", "wind"):
            table = getattr(self, key).to_dict()
            if table:
                out[key] = table
        if self.edits:
            out["edits"] = [e.to_dict() for e in self.edits]
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, base: Path | None = None,
                  allow_outside: bool = False) -> SceneSpec:
        """Validate a scene document. A species is ``{leaf = {...}}`` (inline parameters, full or
        compact: :mod:`leafview.core.compact`) or ``{preset = "name or path"}``: a built-in name,
        or a path resolved against ``base`` (the file's folder; the working directory when None)
        that must stay inside it (no absolute path, no ``..``, no link out of it) unless
        ``allow_outside``."""
        if not isinstance(data, Mapping):
            raise ParamError("", "expected a table at the top level")
        unknown = set(data) - {"schema", "scene", "species", "plant", "light", "wind", "edits"}
        if unknown:
            raise ParamError(sorted(unknown)[0],
                             "unknown table (expected schema, scene, species, plant, light, wind, edits)")
        if data.get("schema") != SCENE_SCHEMA:
            raise ParamError("schema", f"expected schema = {SCENE_SCHEMA}, got {data.get('schema')!r}")
        scene = data.get("scene", {})
        if not isinstance(scene, Mapping):
            raise ParamError("scene", "must be a table")
        keys = {"layout", "leaves", "seed", "plants", "variation", "colour_variation", "stems", "name"}
        for key in scene:
            if key not in keys:
                raise ParamError(f"scene.{key}", f"unknown setting (known: {', '.join(sorted(keys))})")
        raw_species = data.get("species")
        if not isinstance(raw_species, list) or not raw_species:
            raise ParamError("species", "expected a non-empty list of [[species]] tables")
        species, weights, varieties = [], [], []
        for i, item in enumerate(raw_species):
            where = f"species[{i}]"
            if not isinstance(item, Mapping):
                raise ParamError(where, "must be a table")
            extra = set(item) - {"leaf", "preset", "weight", "variety"}
            if extra:
                raise ParamError(f"{where}.{sorted(extra)[0]}", "unknown key (expected leaf, preset, weight, variety)")
            if ("leaf" in item) == ("preset" in item):
                raise ParamError(where, "give exactly one of 'leaf' (a parameter table) or 'preset'")
            if "preset" in item:
                species.append(_load_preset(item["preset"], base, where, allow_outside))
            else:
                species.append(_species_leaf(item["leaf"], f"{where}.leaf"))
            weight = item.get("weight", 1.0)
            if isinstance(weight, bool) or not isinstance(weight, (int, float)):
                raise ParamError(f"{where}.weight", f"must be a positive number, got {weight!r}")
            weights.append(weight)
            varieties.append(Variety.from_dict(item.get("variety", {}), f"{where}.variety"))
        plant = data.get("plant", {})
        if not isinstance(plant, Mapping):
            raise ParamError("plant", "must be a table")
        defaults = cls.__dataclass_fields__
        return cls(species=tuple(species), weights=tuple(weights), varieties=tuple(varieties),
                   layout=scene.get("layout", defaults["layout"].default),
                   leaves=scene.get("leaves", defaults["leaves"].default),
                   seed=scene.get("seed", defaults["seed"].default),
                   plants=scene.get("plants", defaults["plants"].default),
                   variation=scene.get("variation", defaults["variation"].default),
                   colour_variation=scene.get("colour_variation", defaults["colour_variation"].default),
                   stems=scene.get("stems", defaults["stems"].default),
                   plant=dict(plant), name=check_name(scene.get("name", ""), "scene.name"),
                   light=LightSettings.from_dict(data.get("light", {})),
                   wind=WindSettings.from_dict(data.get("wind", {})),
                   edits=parse_edits(data.get("edits", [])))


def _species_leaf(table: Any, where: str) -> LeafParams:
    """A species' inline leaf: the compact form (it has ``omega``) or the full parameter table
    (``schema`` may be left out)."""

    if isinstance(table, Mapping) and "omega" in table:
        return parse_compact(table, where=where, version="leafview" in table)
    if isinstance(table, Mapping):
        table = {"schema": 1, **table}
    try:
        return parse_params(table)
    except ParamError as exc:
        raise ParamError(f"{where}.{exc.path}".rstrip("."), exc.message) from None


def _load_preset(spec: Any, base: Path | None, where: str, allow_outside: bool = False) -> LeafParams:
    """A species preset: a built-in name, or a file inside ``base`` (see :meth:`SceneSpec.from_dict`).
    A file that fails to load is named with the reason, never with its content (it may be any
    file on the machine)."""
    if not isinstance(spec, str) or not spec:
        raise ParamError(f"{where}.preset", "must be a preset name or a path")
    check_name(spec, f"{where}.preset")
    builtin = builtin_presets()
    if spec in builtin:
        path = builtin[spec]
    else:
        folder = (base if base is not None else Path.cwd()).resolve()
        given = Path(spec)
        outside = given.is_absolute() or ".." in given.parts
        path = (folder / given).resolve() if not given.is_absolute() else given.resolve()
        if not outside and not path.is_relative_to(folder):
            outside = True          # a link that leads out of the folder
        if outside and not allow_outside:
            raise ParamError(f"{where}.preset", f"{spec!r} leaves the scene file's folder (an absolute path, "
                                                "'..' or a link out of it); use a path inside it, a built-in "
                                                "name, or --allow-outside-presets")
        if not path.exists():
            raise ParamError(f"{where}.preset", f"no such preset file or built-in name: {spec!r}")
    try:
        return load_params(path)
    except ParamError as exc:
        raise ParamError(f"{where}.preset", f"{spec!r} is not a usable leaf preset: {_reason(exc)}") from None


_FIELD_PATH = re.compile(r"^(schema|name|shape|jitter|material|transform|ripple|bending|omega|half|leafview|leaves)"
                         r"(\.[a-z_0-9]+)?(\[\d+\])*$")


def _reason(exc: ParamError) -> str:
    """Why a preset failed, without its content: the kind of problem, the line of a syntax error
    and the field path when it is one of the known fields."""
    src = exc.source or ""
    m = re.search(r":(\d+):\d+$", src)
    msg = exc.message
    if "syntax error" in msg:
        return f"a syntax error at line {m.group(1)}" if m else "a syntax error"
    if not exc.path:     # the reader refused the file itself (size, type, encoding, nesting)
        return msg.split(":")[0] if msg.startswith("not UTF-8") else msg
    if msg.startswith("unknown key"):
        return "it is not a leaf parameter file (unknown keys)"
    field = exc.path.split(" ")[0]
    return f"an invalid value at {field}" if _FIELD_PATH.match(field) else "an invalid value"


def load_scene(path: str | os.PathLike[str], *, allow_outside_presets: bool = False) -> SceneSpec:
    """Read a scene file (``.toml`` or ``.json``); errors name the file and field or line. Species
    presets given as paths must lie in the file's folder unless ``allow_outside_presets``."""

    p = Path(path)
    data = read_document(p)
    try:
        return SceneSpec.from_dict(data, base=p.parent, allow_outside=allow_outside_presets)
    except ParamError as exc:
        raise exc.with_source(str(p)) from None


def save_scene(spec: SceneSpec, path: str | os.PathLike[str]) -> None:
    """Write ``spec`` atomically as TOML or JSON (self-contained: species inline)."""


    p = Path(path)
    if p.suffix.lower() not in (".toml", ".json"):
        raise ParamError("", f"unknown scene format {p.suffix!r} (use .toml or .json)", str(p))
    data = spec.to_dict()
    text = tomli_w.dumps(data) if p.suffix.lower() == ".toml" else json.dumps(data, indent=2) + "\n"
    write_text(p, text)   # checked target, atomic rename, every byte on the disk


# -- the expanded scene ----------------------------------------------------------------------
VBAR_GAP = 1e-3   # smallest spacing of a varied leaf's first three silhouette feet v̄


def vary_shape(shape: Shape, factors: NDArray[np.floating], offsets: NDArray[np.floating] | None = None) -> Shape:
    """``shape`` with each Ω component of :data:`VARIED` multiplied by its factor and, with
    ``offsets`` (a scene-wide edit's additions, :mod:`leafview.scene.scene_edits`), that offset
    added; ``v̄`` clamped to [0.02, 0.98] and kept increasing (each row at least :data:`VBAR_GAP`
    above the one before, so a varied leaf is a valid leaf: it saves and reads back). The
    vectorised twin for GPU records is :func:`leafview.gpu.scene.pack_scene` (a test checks they
    agree)."""
    f = np.asarray(factors, np.float64)
    o = np.zeros(len(VARIED)) if offsets is None else np.asarray(offsets, np.float64)
    a1 = _vec3(np.asarray(shape.a1) * f[0:3] + o[0:3])
    a2 = _vec3(np.asarray(shape.a2) * f[3:6] + o[3:6])
    rows: list[Vec3] = []
    for k, (vb, xs, zs) in enumerate(shape.silhouette[:3]):
        g, d = f[6 + 3 * k: 9 + 3 * k], o[6 + 3 * k: 9 + 3 * k]
        v = float(np.clip(vb * g[0] + d[0], 0.02, 0.98))
        if rows:   # the rows' feet stay in order: a row varied past the one above it stops VBAR_GAP above it
            v = max(v, rows[-1][0] + VBAR_GAP)
        rows.append((v, float(xs * g[1] + d[1]), float(zs * g[2] + d[2])))
    rows += [(r[0], r[1], r[2]) for r in shape.silhouette[3:]]
    # rows beyond the paper's three (an extended silhouette) keep their species' values
    zf = tuple(float(x) for x in np.asarray(shape.zf[:3]) * f[15:18] + o[15:18]) + tuple(shape.zf[3:])
    zg = tuple(float(x) for x in np.asarray(shape.zg[:3]) * f[18:21] + o[18:21]) + tuple(shape.zg[3:])
    return replace(shape, a1=a1, a2=a2, silhouette=tuple(rows), zf=zf, zg=zg)


def _vec3(values: NDArray[np.float64]) -> Vec3:
    """Three numbers as a tuple of Python floats."""
    x, y, z = (float(c) for c in values)
    return x, y, z


@dataclass
class Scene:
    """Per-leaf arrays of an expanded scene (``N`` leaves).

    Attributes
    ----------
    spec: the recipe.
    species: the species parameters with an identity transform.
    species_id: (N,) int32, the species of each leaf.
    factors: (N, 21) float32 Ω factors (:data:`VARIED` order); all ones without variation.
    tint: (N,) float32 colour factor.
    matrices: (N, 4, 4) float64 leaf space -> world (column vectors), +z up.
    stems: branch geometry (positions, normals, triangle indices) or None.
    placement: the :class:`~leafview.scene.plants.Placement` it came from (None for a scene of
        explicit leaves, :func:`scene_from_leaves`).
    """

    spec: SceneSpec
    species: tuple[LeafParams, ...]
    species_id: NDArray[np.int32]
    factors: NDArray[np.float32]
    tint: NDArray[np.float32]
    matrices: NDArray[np.float64]
    stems: tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.uint32]] | None
    placement: Placement | None
    # per-leaf additions to Ω (VARIED order) made by scene-wide edits (leafview.scene.scene_edits):
    # a leaf's Ω is its species' × factors + offsets; None: no offsets
    offsets: NDArray[np.float32] | None = None
    # per-leaf variety (leafview.scene.variety): ripple phase offset, ripple amplitude factor, bend
    # load factor, each (N,) float32; None: every leaf takes its species' value
    ripple_phase: NDArray[np.float32] | None = None
    ripple_scale: NDArray[np.float32] | None = None
    load_scale: NDArray[np.float32] | None = None

    def __len__(self) -> int:
        return int(self.species_id.shape[0])

    @property
    def varied(self) -> bool:
        """Whether leaves differ from their species (shape, colour, or variety: ripple, bend load)."""
        return (self.spec.variation > 0 or self.spec.colour_variation > 0 or self.ripple_phase is not None
                or self.ripple_scale is not None or self.load_scale is not None)

    @property
    def shape_ids(self) -> NDArray[np.int32]:
        """Index into :meth:`shapes` of each leaf: leaves with the same id share one mesh."""
        return self.species_id if not self.varied else np.arange(len(self), dtype=np.int32)

    def shapes(self) -> list[LeafParams]:
        """The distinct leaf shapes (identity transform): the species when nothing varies, else
        one per leaf."""
        if not self.varied:
            return list(self.species)
        return [self.leaf(i) for i in range(len(self))]

    def leaf(self, i: int) -> LeafParams:
        """Leaf ``i``'s own parameters in its leaf space (identity transform; place it with
        ``matrices[i]``). Its ripple and bend load carry its variety (:mod:`leafview.scene.variety`);
        its bend is drawn from its species' profile (or, with a load range, interpolated between
        its species' solved loads: :func:`leaf_bend`), see the module docstring."""
        sp = self.species[int(self.species_id[i])]
        t = float(self.tint[i])
        mat = sp.material
        mat = replace(mat, front=_tinted(mat.front, t), back=_tinted(mat.back, t))
        # a lobed leaf's Ω is not its shape (its sweep table is): it keeps its species' (build_scene)
        shape = sp.shape if sp.lobes.enabled else vary_shape(
            sp.shape, self.factors[i], None if self.offsets is None else self.offsets[i])
        ripple, bending = sp.ripple, sp.bending
        if self.ripple_phase is not None or self.ripple_scale is not None:
            ripple = leaf_ripple(ripple, 0.0 if self.ripple_phase is None else float(self.ripple_phase[i]),
                                 1.0 if self.ripple_scale is None else float(self.ripple_scale[i]))
        if self.load_scale is not None:
            bending = leaf_bending(bending, float(self.load_scale[i]))
        return sp.replace(shape=shape, material=mat, ripple=ripple, bending=bending, name=f"{sp.name or 'leaf'}_{i}")

    def placed_leaf(self, i: int) -> LeafParams:
        """Leaf ``i`` as a stand-alone leaf: :meth:`leaf` with ``matrices[i]`` as its transform and
        no name (what a leaf set, :mod:`leafview.core.compact`, stores per leaf)."""
        return self.leaf(i).replace(transform=Transform.from_matrix(self.matrices[i]), name="")

    def placed_leaves(self, progress: Callable[[int], object] | None = None) -> list[LeafParams]:
        """Every :meth:`placed_leaf`, in order (``progress(1)`` after each, e.g. a tqdm update)."""
        out = []
        for i in range(len(self)):
            out.append(self.placed_leaf(i))
            if progress is not None:
                progress(1)
        return out

    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Axis-aligned world box (lo, hi) of the leaf bases and stems (a camera framing hint)."""
        # a component at a time (10⁶ leaves: one strided pass each, not reductions 3 wide), the
        # largest column length as the root of the largest square (the same numbers)
        m = self.matrices
        lo = np.array([m[:, c, 3].min() for c in range(3)])
        hi = np.array([m[:, c, 3].max() for c in range(3)])
        x, y, z = m[:, 0, 0], m[:, 1, 0], m[:, 2, 0]
        square = x * x
        square += y * y
        square += z * z
        size = float(np.sqrt(square.max(initial=0.0)))
        return lo - size, hi + size

    def _repr_png_(self) -> bytes | None:
        """A 256×256 PNG of the scene for Jupyter (:func:`leafview.core.display.png_of`), or None
        where no renderer is registered or OpenGL is unavailable (Jupyter shows the text repr)."""
        return png_of("scene", self)


def _tinted(colour: Vec3, t: float) -> Vec3:
    """``colour`` times the tint factor ``t``, clamped to [0, 1]."""
    r, g, b = (float(min(max(c * t, 0.0), 1.0)) for c in colour)
    return r, g, b


def build_scene(spec: SceneSpec) -> Scene:
    """Expand ``spec`` (deterministic: the same spec gives the same arrays)."""

    # the stem mesh of a large scene is built on a second thread while the numbers below are drawn
    placement, stems_done = scatter_later(spec.layout, spec.leaves, spec.seed, spec.plant_spec(),
                                          plants=spec.plants or None, stems=spec.stems)
    n = len(placement)
    rng = np.random.default_rng([spec.seed, 0x5CE4E])
    n_plants = int(placement.plant.max(initial=-1)) + 1
    w = np.asarray(spec.weights, np.float64)
    w = w / w.max()          # first to at most 1: weights of 1e308 would sum to inf
    p = w / w.sum()
    plant_species = rng.choice(len(spec.species), size=max(n_plants, 1), p=p).astype(np.int32)
    species_id = plant_species[placement.plant]
    factors = np.ones((n, len(VARIED)), np.float32)
    if spec.variation > 0:
        # drawn in chunks (the same numbers as one draw) so that no float64 copy of the whole table is made
        for start in range(0, n, _FACTOR_CHUNK):
            f = rng.uniform(-1.0, 1.0, (min(_FACTOR_CHUNK, n - start), len(VARIED)))
            f *= spec.variation
            f += 1.0
            factors[start:start + len(f)] = f
        # a lobed species' leaves vary in transform and colour only: its Ω factors would change
        # nothing it draws (its shape is its sweep table), so they stay 1 (drawn all the same, so
        # that the other species' leaves keep their numbers)
        lobed = np.array([bool(s.lobes.enabled) for s in spec.species], bool)
        if lobed.any():
            factors[lobed[species_id]] = 1.0
    tint = np.ones(n, np.float32)
    if spec.colour_variation > 0:
        tint = (1.0 + spec.colour_variation * rng.uniform(-1.0, 1.0, n)).astype(np.float32)
    species = tuple(s.replace(transform=Transform()) for s in spec.species)
    # per-leaf variety: drawn after every other number, so scenes without it keep theirs
    ripple_phase, ripple_scale, load_scale = draw_variety(rng, species_id, spec.varieties)
    stems_done()
    scene = Scene(spec, species, species_id.astype(np.int32), factors, tint,
                  np.asarray(placement.matrices, np.float64), placement.stems, placement,
                  ripple_phase=ripple_phase, ripple_scale=ripple_scale, load_scale=load_scale)
    apply_edits(scene, spec.edits)   # the scene-wide edits, last (leafview.scene.scene_edits)
    return scene


def scene_from_leaves(leaves: Sequence[LeafParams], name: str = "") -> Scene:
    """A scene of explicit, placed leaves (a leaf set, :mod:`leafview.core.compact`): each leaf
    is its own species, drawn once at its own transform, without variation or stems. Its
    per-species work therefore runs per leaf, vectorised: the shapes go straight into the rows
    (:func:`leafview.gpu.scene.species_tables`), the culling spheres and level-of-detail errors
    come from one GPU dispatch (:mod:`leafview.gpu.bounds`), and the cantilevers of bent leaves
    are solved together (:func:`leafview.deform.beam.bend_profiles`)."""
    if not leaves:
        raise ParamError("leaves", "a scene needs at least one leaf")
    identity = Transform()
    species = tuple(_unplaced(leaf, identity) for leaf in leaves)
    spec = SceneSpec(species=species, leaves=len(leaves), variation=0.0, colour_variation=0.0, stems=False,
                     name=name)
    n = len(leaves)
    matrices = transform_matrices([leaf.transform for leaf in leaves])
    return Scene(spec, species, np.arange(n, dtype=np.int32), np.ones((n, len(VARIED)), np.float32),
                 np.ones(n, np.float32), matrices, None, None)


def _unplaced(leaf: LeafParams, identity: Transform) -> LeafParams:
    """``leaf.replace(transform=identity)``, five times faster: a field-for-field copy of the
    frozen dataclass with the transform swapped (its ``__post_init__``, skipped here, checks
    nothing of the transform). A leaf
    set may hold 10⁵ leaves; ``dataclasses.replace`` introspects the fields on every call."""
    out: LeafParams = object.__new__(LeafParams)
    fields_ = out.__dict__
    fields_.update(leaf.__dict__)
    fields_["transform"] = identity
    return out


def evaluate_leaf(scene: Scene, i: int, u: NDArray[np.floating], v: NDArray[np.floating]) -> NDArray[np.float64]:
    """Leaf-space points of leaf ``i`` as the scene draws it: its own shape, jitter and ripples,
    bent by its species' cantilever profile (:func:`leaf_bend`) and shaped by its species' vein
    grid (the numpy reference of the GPU rows). A lobed leaf: its swept surface
    (:func:`leafview.botany.leaf_surface.evaluate`, ``u, v`` on its lobed grid)."""

    own = scene.leaf(int(i))
    sp = scene.species[int(scene.species_id[i])]
    if sp.lobes.enabled:
        return leaf_surface.evaluate(own, u, v)
    grid = shape_grid(sp)   # every leaf of a species reads its species' vein grid (one field layer each)
    if not sp.bending.active:
        return partials(own, u, v, vein_grid=grid).L
    return partials(own.replace(bending=Bending()), u, v, bend=leaf_bend(scene, int(i)), vein_grid=grid).L


def leaf_bend(scene: Scene, i: int) -> BendProfile:
    """The bend profile leaf ``i`` is drawn with: its species' (Geng, Hu & Zhang 2014, eq. 4, solved
    once per species), or, when its species has a bend load range, the profile interpolated at the
    leaf's load factor between the species' solved loads (:func:`leafview.scene.variety.interpolate_bend`;
    axis and twist do not depend on the load)."""
    sp = scene.species[int(scene.species_id[i])]
    profile = bend_profile(sp)
    if scene.load_scale is None:
        return profile
    table = load_table(scene.species, scene.spec.varieties)
    if table is None:
        return profile
    which, phi, delta = interpolate_bend(table, scene.species_id[i:i + 1], scene.load_scale[i:i + 1])
    if not which.size:
        return profile
    return BendProfile(profile.axis.copy(), phi[0], delta[0], profile.twist)


def bend_deviation(scene: Scene, sample: Sequence[int]) -> float:
    """Largest distance (in leaf lengths) between a bent leaf with its own cantilever solve (its
    own shape and load) and with the profile it is drawn with (:func:`leaf_bend`: its species', or
    interpolated at its load factor), over the leaves in ``sample``."""

    uv = grid_uv(9, 17).astype(np.float64)
    worst = 0.0
    for i in sample:
        own = scene.leaf(int(i))
        if own.bending.active and not own.lobes.enabled:   # the bend of a swept surface is not drawn
            drawn = evaluate_leaf(scene, int(i), uv[:, 0], uv[:, 1])
            worst = max(worst, float(np.abs(leaf_surface.evaluate(own, uv[:, 0], uv[:, 1]) - drawn).max()))
    return worst
