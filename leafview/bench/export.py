"""``leafview bench export``: export time and file size per leaf for a 10⁴-leaf scene.

Two versions of one scene (a field of plants from :mod:`leafview.scene.spec` with two species when that
module is available, else a scatter of four presets; see ``scene_source`` in the result):

* ``distinct``: every leaf has its own shape (the scene's ±20 % variation of Ω), so every leaf
  is baked and stored: one mesh per leaf;
* ``shared``: the same placement without variation, so leaves share their species' mesh
  (EXT_mesh_gpu_instancing in glTF, a PointInstancer in USD).

Measured, each the median of several runs in this process: baking all distinct shapes through
the GPU readback (``ctx.finish()`` before the clock stops) and through the numpy reference (a
subset, scaled per leaf), then writing .glb, .usdc and .ply (and .obj in full runs) from the
baked meshes. Sizes are per leaf. The parametric side: the scene file (the recipe that
rebuilds all leaves), one leaf's parameter file as minified JSON, and the same with the fields
at their defaults left out (the loader fills them in). Nothing is asserted.
"""

from __future__ import annotations

import json
import sys
import tempfile
from dataclasses import replace
from functools import partial
from pathlib import Path
from typing import Any

import moderngl
import numpy as np

from leafview.bench.timing import log_gl_renderer, median_time
from leafview.core import compact
from leafview.core.params import LeafParams, Transform
from leafview.export import write
from leafview.export.scene import ExportScene, leaf_scene, scene_from
from leafview.gpu import LeafRenderer, default_renderer
from leafview.resources import builtin_presets
from leafview.scene.spec import SceneSpec, build_scene, save_scene

__all__ = ["format_table", "run"]

SCENE_GRID = (9, 15)           # 224 triangles per leaf, as the core benchmark's scene
_CONFIG: dict[bool, dict[str, Any]] = {
    False: {"leaves": 10_000, "repeats": 3, "numpy_leaves": 200, "obj": True},
    True: {"leaves": 400, "repeats": 1, "numpy_leaves": 40, "obj": False},
}


class _StandIn:
    """A scatter of presets when leafview.scene.spec cannot build one."""

    def __init__(self, n: int, distinct: bool) -> None:
        rng = np.random.default_rng(5)
        species = [LeafParams.load(builtin_presets()[k]).replace(transform=Transform())
                   for k in ("beech", "ovate", "maize", "holly")]
        self.species_id = rng.integers(0, len(species), n).astype(np.int32)
        self.matrices = np.stack([Transform(translation=tuple(rng.uniform(-20, 20, 3)),
                                            rotation=tuple(rng.uniform(-180, 180, 3)),
                                            scale=float(rng.uniform(0.6, 1.2))).matrix() for _ in range(n)])
        self.stems = None
        self._species = species
        self._factors = rng.uniform(0.8, 1.2, n) if distinct else None

    @property
    def shape_ids(self) -> np.ndarray:
        return self.species_id if self._factors is None else np.arange(len(self), dtype=np.int32)

    def shapes(self) -> list[LeafParams]:
        if self._factors is None:
            return list(self._species)
        out = []
        for i, f in enumerate(self._factors):
            sp = self._species[int(self.species_id[i])]
            rows = tuple((v, x * f, z) for v, x, z in sp.shape.silhouette)
            out.append(sp.replace(shape=replace(sp.shape, silhouette=rows), name=f"{sp.name}_{i}"))
        return out

    def __len__(self) -> int:
        return len(self.species_id)


def _scenes(n: int) -> tuple[Any, Any, str, int | None]:
    """(distinct scene, shared scene, description, scene-file bytes or None)."""
    try:
        presets = builtin_presets()
        spec = SceneSpec(species=(LeafParams.load(presets["beech"]), LeafParams.load(presets["ovate"])),
                         weights=(2.0, 1.0), layout="field", leaves=n, seed=1, name="bench")
        distinct, shared = build_scene(spec), build_scene(spec.replace(variation=0.0, colour_variation=0.0))
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "scene.toml"
            save_scene(spec, path)
            size = path.stat().st_size
        return distinct, shared, "leafview.scene.spec: field of plants, species beech + ovate, variation 0.2, stems", size
    except Exception as exc:  # noqa: BLE001 - the scene module is young: fall back, say why
        return (_StandIn(n, True), _StandIn(n, False),
                f"stand-in scatter of 4 presets ({type(exc).__name__}: {exc})", None)


def run(quick: bool = False, ctx: moderngl.Context | None = None) -> dict[str, Any]:
    """Run the export benchmark on ``ctx`` (default the shared default renderer's context); see
    the module docstring for what is measured."""
    cfg = _CONFIG[quick]
    renderer = LeafRenderer(ctx) if ctx is not None else default_renderer()
    finish = renderer.ctx.finish
    n = cfg["leaves"]
    distinct, shared, source, scene_file = _scenes(n)
    res: dict[str, Any] = {"gl_renderer": renderer.gl_renderer, "leaves": len(distinct), "grid": list(SCENE_GRID),
                           "scene_source": source, "repeats": cfg["repeats"]}
    log_gl_renderer("export", renderer.gl_renderer)

    baked: dict[str, ExportScene] = {}

    def bake_distinct() -> None:
        baked["distinct"] = scene_from(distinct, SCENE_GRID, renderer=renderer, name="bench")

    res["bake_gpu_s"] = median_time(bake_distinct, cfg["repeats"], finish)
    baked["shared"] = scene_from(shared, SCENE_GRID, renderer=renderer, name="bench")
    part = baked["distinct"].parts[0]
    res["vertices_per_leaf"], res["triangles_per_leaf"] = part.mesh.n_vertices, part.mesh.n_triangles
    res["distinct_shapes"] = len(baked["distinct"].parts)
    res["shared_shapes"] = len(baked["shared"].parts)
    res["stem_triangles"] = 0 if baked["distinct"].stems is None else len(baked["distinct"].stems[2])

    sample = distinct.shapes()[: cfg["numpy_leaves"]]
    sub = _Subset(sample)
    res["bake_numpy_s_per_leaf"] = median_time(lambda: scene_from(sub, SCENE_GRID, backend="numpy"),
                                                cfg["repeats"]) / len(sample)
    res["bake_gpu_ms_per_leaf"] = 1e3 * res["bake_gpu_s"] / res["distinct_shapes"]
    res["numpy_vs_gpu_bake"] = 1e3 * res["bake_numpy_s_per_leaf"] / res["bake_gpu_ms_per_leaf"]
    presets = _Subset([LeafParams.load(p) for p in builtin_presets().values()])   # the 33×65 default grid
    res["bake_gpu_ms_per_leaf_33x65"] = 1e3 * median_time(
        lambda: scene_from(presets, (33, 65), renderer=renderer), cfg["repeats"], finish) / len(presets)
    res["bake_numpy_ms_per_leaf_33x65"] = 1e3 * median_time(
        lambda: scene_from(presets, (33, 65), backend="numpy"), cfg["repeats"]) / len(presets)

    formats = [".glb", ".usdc", ".ply"] + ([".obj"] if cfg["obj"] else [])
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ("distinct", "shared"):
            for suffix in formats if kind == "distinct" else [".glb", ".usdc"]:
                path = Path(tmp) / f"{kind}{suffix}"
                seconds = median_time(partial(write, baked[kind], path), cfg["repeats"])
                key = f"{kind}_{suffix[1:]}"
                res[f"{key}_s"] = seconds
                res[f"{key}_bytes"] = path.stat().st_size
                res[f"{key}_bytes_per_leaf"] = path.stat().st_size / n
                res[f"{key}_us_per_leaf"] = 1e6 * seconds / n
                print(f"  {key}: {seconds:.2f} s, {path.stat().st_size / 1e6:.1f} MB", file=sys.stderr, flush=True)
            path.unlink(missing_ok=True)
        leaf = LeafParams.load(builtin_presets()["beech"])
        single = Path(tmp) / "beech.glb"
        write(leaf_scene(leaf, scene_from(_Subset([leaf]), (33, 65), renderer=renderer).parts[0].mesh), single)
        res["single_leaf_glb_bytes_33x65"] = single.stat().st_size
        res["preset_toml_bytes"] = builtin_presets()["beech"].stat().st_size

    shapes = distinct.shapes()
    res["leaf_json_bytes"] = float(np.mean([len(json.dumps(p.to_dict(), separators=(",", ":"))) for p in shapes[:200]]))
    placed = distinct.placed_leaves() if hasattr(distinct, "placed_leaves") else shapes
    res["leaf_set_bytes_per_leaf"] = len(compact.dumps_leaves(placed)) / len(placed)
    res["leaf_set6_bytes_per_leaf"] = len(compact.dumps_leaves(placed, digits=6)) / len(placed)
    preset_sizes = [len(compact.dumps(LeafParams.load(p))) for p in builtin_presets().values()]
    res["preset_compact_bytes_median"] = float(np.median(preset_sizes))
    res["preset_compact_bytes_range"] = [min(preset_sizes), max(preset_sizes)]
    res["scene_file_bytes"] = scene_file
    res["glb_vs_leaf_json"] = res["distinct_glb_bytes_per_leaf"] / res["leaf_json_bytes"]
    res["glb_vs_leaf_set"] = res["distinct_glb_bytes_per_leaf"] / res["leaf_set_bytes_per_leaf"]
    res["glb_vs_leaf_set6"] = res["distinct_glb_bytes_per_leaf"] / res["leaf_set6_bytes_per_leaf"]
    if scene_file:
        res["glb_vs_scene_file"] = res["distinct_glb_bytes"] / scene_file
    res["single_glb_vs_preset"] = res["single_leaf_glb_bytes_33x65"] / res["preset_toml_bytes"]
    if ctx is not None:
        renderer.release()
    return res


class _Subset:
    """A scene of the given leaves, one each, at the origin (for timing the bake alone)."""

    def __init__(self, leaves: list[LeafParams]) -> None:
        self._leaves = leaves
        self.shape_ids = np.arange(len(leaves), dtype=np.int32)
        self.matrices = np.repeat(np.eye(4)[None], len(leaves), axis=0)
        self.stems = None

    def shapes(self) -> list[LeafParams]:
        return self._leaves

    def __len__(self) -> int:
        return len(self._leaves)


def format_table(res: dict[str, Any]) -> str:
    """The readable report printed by ``leafview bench export``."""
    n = res["leaves"]
    g = res["grid"]
    rows = [
        ("GL renderer", res["gl_renderer"], ""),
        ("scene", f"{n:,} leaves", res["scene_source"]),
        ("mesh per leaf", f"{res['vertices_per_leaf']} vertices, {res['triangles_per_leaf']} triangles",
         f"grid {g[0]}×{g[1]}, pinched tips welded out"),
        ("bake (GPU readback)", f"{res['bake_gpu_ms_per_leaf']:.3f} ms/leaf",
         f"{res['bake_gpu_s']:.2f} s for {res['distinct_shapes']:,} distinct shapes"),
        ("bake (numpy reference)", f"{1e3 * res['bake_numpy_s_per_leaf']:.3f} ms/leaf",
         f"{res['numpy_vs_gpu_bake']:.1f}× the GPU time"),
        ("bake 33×65, GPU / numpy", (f"{res['bake_gpu_ms_per_leaf_33x65']:.2f} / "
         f"{res['bake_numpy_ms_per_leaf_33x65']:.2f} ms/leaf"), "the built-in presets, the default export grid"),
    ]
    for kind, label in (("distinct", "one mesh per leaf"), ("shared", f"{res['shared_shapes']} shared meshes")):
        for fmt in ("glb", "usdc", "ply", "obj"):
            key = f"{kind}_{fmt}"
            if f"{key}_s" in res:
                rows.append((f"write .{fmt} ({kind})", (f"{res[f'{key}_us_per_leaf']:.0f} µs/leaf, "
                             f"{res[f'{key}_bytes_per_leaf']:,.0f} B/leaf"),
                             f"{res[f'{key}_s']:.2f} s, {res[f'{key}_bytes'] / 1e6:.1f} MB, {label}"))
    lo, hi = res["preset_compact_bytes_range"]
    rows += [
        ("leaf parameters, full JSON", f"{res['leaf_json_bytes']:.0f} B/leaf", "every field spelled out"),
        ("compact leaf set (exact)", f"{res['leaf_set_bytes_per_leaf']:.0f} B/leaf",
         "Ω, tinted colours and placement of every leaf, shortest float64 decimals"),
        ("compact leaf set (6 digits)", f"{res['leaf_set6_bytes_per_leaf']:.0f} B/leaf", "--digits 6"),
        ("compact preset (.leaf.json)", f"{res['preset_compact_bytes_median']:.0f} B median",
         f"{lo}-{hi} B over the built-in presets"),
        ("baked .glb ÷ leaf parameters", f"{res['glb_vs_leaf_set']:.0f}× exact",
         f"{res['glb_vs_leaf_set6']:.0f}× at 6 digits, {res['glb_vs_leaf_json']:.0f}× full JSON"),
    ]
    if res.get("scene_file_bytes"):
        rows.append(("baked .glb ÷ scene file", f"{res['glb_vs_scene_file']:,.0f}×",
                     f"the {res['scene_file_bytes']:,}-byte recipe rebuilds all {n:,} leaves"))
    rows.append(("one leaf .glb (33×65) ÷ preset", f"{res['single_glb_vs_preset']:.0f}×",
                 (f"{res['single_leaf_glb_bytes_33x65']:,} B ÷ {res['preset_toml_bytes']:,} B TOML")))
    w0 = max(len(r[0]) for r in rows)
    w1 = max(len(r[1]) for r in rows)
    lines = ["export benchmark" + (" (quick: not a measurement)" if n < 10_000 else "")]
    lines += [f"  {a:<{w0}}  {b:<{w1}}  {c}".rstrip() for a, b, c in rows]
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover
    out = run(quick=True)
    print(format_table(out))
