"""One dataset image: render it and write its files; one shard: its images and its manifest.

Files of image ``NNNNNN`` (its index, six digits), committed together (one
:func:`leafview.atomic.outputs` transaction per image):

==============================  =====================================================================
``images/NNNNNN.png``           the picture: 8-bit sRGB RGB, 4× multisampled, over a random background
``instances/NNNNNN.png``        16-bit grey: leaf index + 1 (the leaf set's order), 0 background
``depth/NNNNNN.exr``            float32, channel ``Y``: distance along the optical axis (world units,
                                "metres"), 0 background
``normals/NNNNNN.exr``          float32, channels ``R, G, B`` = world-space (x, y, z) unit normal of
                                the side the camera sees, 0 background
``uv/NNNNNN.exr``               float32, channels ``R, G`` = the leaf's own (u, v) (u in [-1, 1]
                                across, v in [0, 1] base to apex), 0 background
``cameras/NNNNNN.json``         ``K`` (3×3) and ``world_from_camera`` (4×4), OpenCV convention
                                (:func:`leafview.scene.camera.intrinsics`), ``width``, ``height``
``leaves/NNNNNN.leaves.json``   the image's leaf set (compact form), exactly the leaves drawn
==============================  =====================================================================

The labels (instance, depth, normal, uv) come from one single-sample pass
(:func:`leafview.gpu.aov.render_aovs`): each pixel holds the nearest fragment at its centre.

**Visible fraction.** A leaf's ``visible_fraction`` is its visible pixels (its pixels in the
instance image) over the pixels it covers when drawn alone, in the same image, camera and
rasterisation. "Alone" is measured exactly without one pass per leaf: the leaves' screen boxes
(from the vertices the shader computes, captured once, plus a pixel) are packed greedily into
groups of pairwise disjoint boxes, and each group is drawn once in an instance pass of its own.
Leaves of one group cannot cover each other's pixels, so each leaf's pixels in its group's pass
are exactly its pixels when alone; the pass draws the same triangles with the same vertex shader,
so visible pixels are a subset of them. Only pixels inside the image count: a leaf cut by the
border is not "hidden" there (its fraction measures occlusion by other leaves, not truncation).
A cluttered tray of 100 leaves needs about 10-20 such passes.

After its last image a shard writes ``shards/SSSSSS.json`` (its images' records: split,
annotations, every file's size and SHA-256): the marker that the shard is complete.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import moderngl
import numpy as np
from numpy.typing import NDArray

from leafview.atomic import outputs, write_text
from leafview.core.params import LeafParams
from leafview.dataset.labels import image_annotations
from leafview.dataset.layouts import ImageSetup, setup_image
from leafview.dataset.recipe import Recipe
from leafview.errors import ImageWriteError
from leafview.export.views import camera_document
from leafview.export.views import write_pixels as _write_pixels
from leafview.gpu.aov import render_aovs
from leafview.gpu.context import create_headless_context
from leafview.gpu.frame import Lighting
from leafview.gpu.resources import GpuResources
from leafview.gpu.scene import SceneRenderer
from leafview.scene.camera import Camera
from leafview.scene.spec import scene_from_leaves

__all__ = ["ImageRenderer", "FOLDERS", "image_files", "shard_manifest_path", "write_shard_manifest", "file_digest",
           "render_shard", "SAMPLES"]

FOLDERS = ("images", "instances", "depth", "normals", "uv", "cameras", "leaves")
SAMPLES = 4


def stem(index: int) -> str:
    return f"{index:06d}"


def image_files(index: int) -> dict[str, str]:
    """The relative paths of image ``index``'s files, by kind."""
    s = stem(index)
    return {"images": f"images/{s}.png", "instances": f"instances/{s}.png", "depth": f"depth/{s}.exr",
            "normals": f"normals/{s}.exr", "uv": f"uv/{s}.exr", "cameras": f"cameras/{s}.json",
            "leaves": f"leaves/{s}.leaves.json"}


def shard_manifest_path(out: Path, shard: int) -> Path:
    return out / "shards" / f"{shard:06d}.json"


def file_digest(path: Path) -> dict[str, Any]:
    """``{"bytes": size, "sha256": hex}`` of a file."""
    data = path.read_bytes()
    return {"bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}


# -- rendering -------------------------------------------------------------------------------------
class _LitSceneRenderer(SceneRenderer):
    """A scene renderer whose pictures use ``self.lighting`` (the image's key light)."""

    lighting: type[Lighting] = Lighting

    def set_camera(self, camera: Camera, size: tuple[int, int], *, srgb: bool = True,
                   lighting: type[Lighting] | None = None) -> None:
        super().set_camera(camera, size, srgb=srgb, lighting=self.lighting if lighting is None else lighting)


def screen_boxes(points: NDArray[np.float32], matrices: NDArray[np.float64], camera: Camera,
                 size: tuple[int, int]) -> NDArray[np.int64]:
    """(N, 4) pixel boxes ``x0, y0, x1, y1`` (half-open, clipped to the image, one pixel of margin)
    of leaves whose leaf-space vertices are ``points`` (N, V, 3), placed by ``matrices``; a leaf
    with a vertex behind the camera gets the whole image, an empty box means off screen."""
    w, h = size
    world = np.einsum("nij,nvj->nvi", matrices[:, :3, :3], points.astype(np.float64)) + matrices[:, None, :3, 3]
    clip = np.einsum("ij,nvj->nvi", camera.proj @ camera.view, np.concatenate(
        [world, np.ones(world.shape[:2] + (1,))], axis=2))
    wc = clip[..., 3]
    behind = (wc <= 1e-9).any(axis=1)
    safe = np.where(wc > 1e-9, wc, 1.0)
    x = (clip[..., 0] / safe + 1.0) * 0.5 * w
    y = (1.0 - clip[..., 1] / safe) * 0.5 * h
    boxes = np.stack([np.floor(x.min(axis=1)) - 1, np.floor(y.min(axis=1)) - 1,
                      np.ceil(x.max(axis=1)) + 2, np.ceil(y.max(axis=1)) + 2], axis=1)
    boxes[behind] = (0, 0, w, h)
    boxes = np.clip(boxes, 0, [w, h, w, h]).astype(np.int64)
    return boxes


def disjoint_groups(boxes: NDArray[np.int64]) -> list[list[int]]:
    """Leaves (indices of ``boxes``, empty boxes left out) in groups of pairwise disjoint boxes,
    greedily in index order."""
    groups: list[list[int]] = []
    members: list[NDArray[np.int64]] = []
    for i, b in enumerate(boxes):
        if b[0] >= b[2] or b[1] >= b[3]:
            continue
        for k, held in enumerate(members):
            overlap = (held[:, 0] < b[2]) & (b[0] < held[:, 2]) & (held[:, 1] < b[3]) & (b[1] < held[:, 3])
            if not overlap.any():
                groups[k].append(i)
                members[k] = np.vstack([held, b])
                break
        else:
            groups.append([i])
            members.append(b[None, :].copy())
    return groups


@dataclass
class RenderedImage:
    setup: ImageSetup
    rgb: NDArray[np.uint8]
    instance: NDArray[np.uint32]
    depth: NDArray[np.float32]
    normal: NDArray[np.float32]
    uv: NDArray[np.float32]
    alone: NDArray[np.int64]
    passes: int


class ImageRenderer:
    """One GL context (headless EGL; ``device``: the EGL device index, None: the default) and its
    shared resources, rendering images of one recipe. Create it after ``LP_NUM_THREADS`` is set:
    llvmpipe reads it when the context is made."""

    def __init__(self, recipe: Recipe, ctx: moderngl.Context | None = None, device: int | None = None) -> None:
        self.recipe = recipe
        self._own_ctx = ctx is None
        self.ctx = create_headless_context(device=device) if ctx is None else ctx
        self.resources = GpuResources(self.ctx)

    @property
    def gl_renderer(self) -> str:
        return str(self.ctx.info["GL_RENDERER"])

    def _renderer(self, leaves: Sequence[LeafParams], lighting: type[Lighting]) -> _LitSceneRenderer:
        r = _LitSceneRenderer(self.ctx, scene_from_leaves(leaves), resources=self.resources)
        r.lighting = lighting
        return r

    def render(self, index: int) -> RenderedImage:
        """Image ``index``: picture, labels and each leaf's pixels when alone."""
        setup = setup_image(self.recipe, index)
        size = self.recipe.size
        bg = (*setup.background, 1.0)
        with self._renderer(setup.leaves, setup.lighting) as r:
            aov = render_aovs(r, setup.camera, size, samples=SAMPLES, background=bg)
            points = r.capture(range(len(setup.leaves)), level=0)
            matrices = r.scene.matrices
        assert aov.rgb is not None and aov.instance is not None and aov.depth is not None
        assert aov.normal is not None and aov.uv is not None
        groups = disjoint_groups(screen_boxes(points, matrices, setup.camera, size))
        alone = np.zeros(len(setup.leaves), np.int64)
        for group in groups:
            with self._renderer([setup.leaves[i] for i in group], setup.lighting) as r:
                inst = render_aovs(r, setup.camera, size, ("instance",)).instance
            assert inst is not None
            alone[group] = np.bincount(inst.ravel(), minlength=len(group) + 1)[1:len(group) + 1]
        return RenderedImage(setup, aov.rgb, aov.instance, aov.depth, aov.normal, aov.uv, alone, len(groups))

    def release(self) -> None:
        self.resources.release()
        if self._own_ctx:
            self.ctx.release()


def write_image_files(out: Path, img: RenderedImage, size: tuple[int, int]) -> dict[str, Any]:
    """Write image files of ``img`` into ``out`` (one transaction) and return its record for the
    shard manifest (without file digests)."""
    index = img.setup.index
    files = image_files(index)
    if int(img.instance.max(initial=0)) > 0xFFFF:
        raise ImageWriteError(f"{files['instances']}: more than 65,535 leaves cannot be 16-bit ids")
    with outputs():
        _write_pixels(out / files["images"], np.ascontiguousarray(img.rgb[..., :3]), "uint8", ("R", "G", "B"))
        _write_pixels(out / files["instances"], img.instance.astype(np.uint16)[..., None], "uint16", ("Y",))
        _write_pixels(out / files["depth"], img.depth.astype(np.float32)[..., None], "float", ("Y",))
        _write_pixels(out / files["normals"], img.normal.astype(np.float32), "float", ("R", "G", "B"))
        _write_pixels(out / files["uv"], img.uv.astype(np.float32), "float", ("R", "G"))
        write_text(out / files["cameras"], camera_document(img.setup.camera, size))
        write_text(out / files["leaves"], img.setup.leaves_text)
    return {"index": index, "file_name": files["images"], "width": size[0], "height": size[1],
            "split": img.setup.split,
            "annotations": image_annotations(img.instance, img.setup.species_id, img.alone)}


def write_shard_manifest(out: Path, recipe: Recipe, shard: int, records: list[dict[str, Any]]) -> Path:
    """``shards/SSSSSS.json``: the shard's image records with every file's size and SHA-256 (the
    marker of a finished shard; written after all its images)."""
    for rec in records:
        rec["files"] = {rel: file_digest(out / rel) for rel in image_files(int(rec["index"])).values()}
    doc = {"shard": shard, "recipe": recipe.digest, "images": records}
    path = shard_manifest_path(out, shard)
    write_text(path, json.dumps(doc, separators=(",", ":")) + "\n")
    return path


def render_shard(renderer: ImageRenderer, out: Path, shard: int,
                 on_image: Callable[[], None] | None = None) -> int:
    """Render and write every image of ``shard``, then its manifest; returns the number of images."""
    recipe = renderer.recipe
    records = []
    for index in recipe.shard_images(shard):
        img = renderer.render(index)
        records.append(write_image_files(out, img, recipe.size))
        if on_image is not None:
            on_image()
    write_shard_manifest(out, recipe, shard, records)
    return len(records)


def shard_is_complete(out: Path, recipe: Recipe, shard: int) -> bool:
    """Whether ``shard`` is finished: its manifest reads, names this recipe and its images, and
    every file it lists exists with the size it records."""
    path = shard_manifest_path(out, shard)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        if doc.get("recipe") != recipe.digest or doc.get("shard") != shard:
            return False
        images = doc["images"]
        if [int(r["index"]) for r in images] != list(recipe.shard_images(shard)):
            return False
        for rec in images:
            for rel, info in rec["files"].items():
                if os.stat(out / rel).st_size != int(info["bytes"]):
                    return False
    except (OSError, ValueError, KeyError, TypeError):
        return False
    return True
