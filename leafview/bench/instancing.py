"""Parameters against baked meshes: one measurement reported by two tables (``leafview bench``
core and scene).

``n`` scattered leaves (grid 9×15 = 224 triangles each) drawn into a 512×512 framebuffer with
depth test: the parametric path (:class:`~leafview.gpu.instanced.InstancedLeaves`, one instanced
draw from the leaf record, fed as per-instance vertex attributes) against the same triangles pre-baked
(:class:`~leafview.gpu.instanced.BakedLeaves`, one indexed draw); and the bytes per leaf of a
baked 32×64 mesh against the record.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import moderngl
import numpy as np

from leafview.bench.timing import Progress, interleaved
from leafview.gpu.context import check_error
from leafview.gpu.instanced import BakedLeaves, InstancedLeaves, OffscreenTarget, pack_leaves, read_rgba, scatter_leaves
from leafview.gpu.layout import LEAF_BLOCK
from leafview.scene.camera import frame_view

__all__ = ["SCENE_GRID", "SCENE_SIZE", "BYTES_GRID", "instanced_vs_baked", "bytes_per_leaf"]

SCENE_GRID = (9, 15)        # 2·8·14 = 224 triangles per leaf
SCENE_SIZE = (512, 512)
BYTES_GRID = (32, 64)


def bytes_per_leaf() -> dict[str, Any]:
    """Bytes of a baked BYTES_GRID leaf mesh (f32 position, normal, uv; u32 indices) against the
    leaf record: its host-set parameter fields, and the whole record with derived data."""
    nu, nv = BYTES_GRID
    verts, tri_count = nu * nv, 2 * (nu - 1) * (nv - 1)
    baked = verts * (3 + 3 + 2) * 4 + tri_count * 3 * 4
    return {"baked_bytes_per_leaf": baked, "param_bytes_per_leaf": LEAF_BLOCK.parameter_nbytes,
            "record_bytes_per_leaf": LEAF_BLOCK.nbytes,
            "baked_vs_param_bytes": baked / LEAF_BLOCK.parameter_nbytes,
            "baked_vs_record_bytes": baked / LEAF_BLOCK.nbytes}


def instanced_vs_baked(ctx: moderngl.Context, n_leaves: int, repeats: int, progress: Progress) -> dict[str, Any]:
    """Median seconds per frame of ``n_leaves`` scattered leaves, instanced vs baked.

    Keys: ``t_instanced``, ``t_baked``, ``ratio`` (median over interleaved pairs of baked time ÷
    instanced time, so drift cancels per pair), ``ratio_range``, ``mean_abs_diff`` of the two
    8-bit images, ``coverage``, ``triangles_per_leaf``."""
    params = scatter_leaves(n_leaves, seed=1)
    records, tables = pack_leaves(params)
    with OffscreenTarget(ctx, SCENE_SIZE) as target:
        fbo = target.fbo
        fbo.use()
        with InstancedLeaves(ctx, records, SCENE_GRID, jitter_tables=tables) as inst:
            # bake by capturing the instanced vertex shader: bit-identical vertices, and seconds
            # faster than 10⁴ numpy tessellations (the tests compare both bakes)
            pos, nrm = inst.capture()
            camera = frame_view("three-quarter", pos.reshape(-1, 3), SCENE_SIZE)
            with BakedLeaves(ctx, pos, nrm, SCENE_GRID, records["front"],
                             records["back"][:, :3]) as baked:
                del pos, nrm
                check_error(ctx, "scene setup")
                images = []
                for batch in (inst, baked):  # warm-up: JIT-compiles the shader variants
                    batch.set_camera(camera)
                    fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
                    batch.draw()
                    check_error(ctx, f"{type(batch).__name__}.draw")
                    images.append(read_rgba(fbo))

                def frame(batch: InstancedLeaves | BakedLeaves) -> Callable[[], None]:
                    def go() -> None:
                        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
                        batch.draw()
                    return go

                progress.step("instanced vs baked leaves")
                timed = interleaved(frame(inst), frame(baked), repeats, ctx.finish)   # ratio: baked ÷ instanced
                check_error(ctx, "scene draws")
                tris = inst.triangles_per_leaf
    a, b = (im.astype(np.int16) for im in images)
    return {"t_instanced": timed["base_ms"] / 1e3, "t_baked": timed["other_ms"] / 1e3,
            "ratio": timed["ratio"], "ratio_range": tuple(timed["range"]),
            "mean_abs_diff": float(np.abs(a - b).mean()),
            "coverage": float((images[0][..., 3] > 0).mean()), "triangles_per_leaf": tris}
