"""Baked vein textures for exported leaves: the unlit colour of each side and tangent-space normal
maps of the vein relief, as PNG images in the leaf's texture space, so that a file viewer shows
what ``shaders/leaf_veins.glsl`` draws.

Every texel is the shader's computation at the texel's (u, v) (:func:`leafview.core.texture.uv_of_st`
of its centre, the convention of the image textures and of the vein field), from the leaf's vein
field (:func:`leafview.botany.vein_field.vein_field`) with the texel as the pixel footprint (the
shader's ``fwidth``):

* **base colour** (front and back): :func:`leafview.botany.vein_shading.vein_albedo` of the side's
  material colour, the vein strength :func:`~leafview.botany.vein_shading.vein_strength` and the
  venation's ``contrast`` (skin, chlorophyll gradient, margin tint, paler and yellower veins),
  sRGB-encoded. A leaf with a photograph keeps its photograph (the shader gives it no vein colour);
* **normal** (front and back): the relief height, the larger of
  :func:`~leafview.botany.vein_shading.vein_height` of the nearest vein (field R, B) and of the
  nearest major vein (A, :func:`~leafview.botany.vein_shading.major_width`), times
  :data:`~leafview.botany.vein_shading.RELIEF_BACK` on the back; its gradient on the flat blade
  (Chaurasia & Beardsley 2017, eqs 1-6) in the tangent frame glTF and USD use: +X along
  increasing s (towards u = -1), +Y up the image (towards the apex, +v), +Z the side's normal;
  stored as ``(n + 1) / 2`` in linear 8-bit RGB. Both sides' veins stand out of their own side,
  as in the shader: the back's tangent frame has the back normal, so the same encoding serves.

:attr:`ExportPart.vein_maps <leafview.export.scene.ExportPart>` carries a part's :class:`VeinMaps` to the
writers, read through :func:`maps_of` (the ``--mesh cdt`` venation mesh and the default (u, v) grid
alike: both have the texture coordinates of :func:`leafview.core.texture.texture_st`, so the same
images apply) (:mod:`.gltf`: ``baseColorTexture`` and ``normalTexture``; :mod:`.usd`: a ``UsdUVTexture`` into ``diffuseColor`` and one into ``normal``;
:mod:`.objply`: ``map_Kd`` and ``map_Bump``, PLY ``TextureFile``), and :func:`with_maps` merges the
images into the export's :class:`~leafview.export.textures.SceneTextures` so that each is written
once beside the file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from leafview.atomic import safe_component
from leafview.botany.vein_field import check_field_size, vein_field
from leafview.botany.vein_shading import RELIEF_BACK, major_width, vein_albedo, vein_height, vein_strength
from leafview.core.blade import blade_partials
from leafview.core.colour import linear_to_srgb
from leafview.core.params import LeafParams
from leafview.deform.surface import vein_grid_uv
from leafview.export.images import png_bytes
from leafview.export.mesh import LeafMesh
from leafview.export.scene import ExportPart, ExportScene, leaf_scene
from leafview.export.textures import PNG, SceneTextures, TextureImage

__all__ = ["MAPS_SIZE", "MAX_SLOPE", "VeinMaps", "bake_vein_maps", "maps_of", "normal_map",
           "tangents", "vein_scene", "with_maps"]

MAPS_SIZE = 512     # texels a side: twice the renderer's vein field (FIELD_SIZE)
MAX_SLOPE = 4.0     # the largest height gradient a normal map stores (tan 76°): the pinched tips


@dataclass(frozen=True, eq=False)
class VeinMaps:
    """The baked images of one leaf: base colour of the front and back side (None for a leaf with
    a photograph) and the normal maps of both sides."""

    front: TextureImage | None
    back: TextureImage | None
    normal: TextureImage
    back_normal: TextureImage

    @property
    def images(self) -> list[TextureImage]:
        return [image for image in (self.front, self.back, self.normal, self.back_normal) if image is not None]


def maps_of(part: ExportPart) -> VeinMaps | None:
    """The baked vein textures of ``part`` (None for a part without)."""
    maps = part.vein_maps
    return maps if isinstance(maps, VeinMaps) else None


def _footprint(d: NDArray[np.float64]) -> NDArray[np.float64]:
    """GLSL ``fwidth`` of ``d`` over the texel grid: |∂d/∂x| + |∂d/∂y| per texel."""
    return np.abs(np.gradient(d, axis=1)) + np.abs(np.gradient(d, axis=0))


def normal_map(params: LeafParams, height: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit tangent-space normals (size, size, 3) of the relief ``height`` (leaf lengths, texel
    grid of :func:`leafview.deform.surface.vein_grid_uv`) on the flat blade: the height's gradient along the unit tangent T
    (direction of increasing s) and bitangent B (in the tangent plane, perpendicular to T, towards
    the apex), ``n = normalize(-∂h/∂T, -∂h/∂B, 1)``, the slope clamped to :data:`MAX_SLOPE`."""
    size = height.shape[0]
    u, v = vein_grid_uv(size, size)
    p = blade_partials(params, u.ravel(), v.ravel())[0]
    lu, lv = p.Lu.reshape(size, size, 3), p.Lv.reshape(size, size, 3)
    # h_u, h_v: a column is du = -2 / size, a row dv = -1 / size
    h_u = np.gradient(height, axis=1) * (-0.5 * size)
    h_v = np.gradient(height, axis=0) * (-1.0 * size)
    # the surface gradient: grad h = (h_u (Lv·Lv) - h_v (Lu·Lv)) Lu + (h_v (Lu·Lu) - h_u (Lu·Lv)) Lv, / det
    e, f, g = (np.einsum("ijk,ijk->ij", a, b) for a, b in ((lu, lu), (lu, lv), (lv, lv)))
    det = e * g - f * f
    ok = det > 1e-12 * np.maximum(e * g, 1e-300)
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    grad = ((h_u * g - h_v * f) * inv)[..., None] * lu + ((h_v * e - h_u * f) * inv)[..., None] * lv
    t_dir = -lu / np.maximum(np.linalg.norm(lu, axis=-1, keepdims=True), 1e-300)     # increasing s
    normal = np.cross(lu, lv)
    b_dir = np.cross(normal, t_dir)
    b_dir /= np.maximum(np.linalg.norm(b_dir, axis=-1, keepdims=True), 1e-300)
    b_dir *= np.where(np.einsum("ijk,ijk->ij", b_dir, lv) < 0.0, -1.0, 1.0)[..., None]   # towards the apex
    slope = np.stack([np.einsum("ijk,ijk->ij", grad, t_dir), np.einsum("ijk,ijk->ij", grad, b_dir)], axis=-1)
    slope = np.where(np.isfinite(slope), slope, 0.0)
    length = np.linalg.norm(slope, axis=-1, keepdims=True)
    slope *= np.minimum(1.0, MAX_SLOPE / np.maximum(length, 1e-300))
    n = np.concatenate([-slope, np.ones(slope.shape[:-1] + (1,))], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def tangents(mesh: LeafMesh) -> NDArray[np.float32]:
    """(V, 4) float32 glTF ``TANGENT`` of ``mesh`` for its normal maps: xyz the unit direction of
    increasing s (:func:`leafview.core.texture.texture_st`) on the surface, made perpendicular to
    the vertex normal (the area-weighted sum over its triangles of the triangles' ∂P/∂s), w = ±1 so
    that ``cross(normal, tangent) · w`` points towards the apex (increasing v), the +Y of the maps.
    Where ∂P/∂s vanishes (the pinched tips) the tangent is the normal's nearest perpendicular to x."""
    pos = mesh.positions.astype(np.float64)
    nrm = mesh.normals.astype(np.float64)
    tris = mesh.indices.astype(np.int64)
    s = (1.0 - mesh.uv[:, 0]) / 2.0             # texture_st's s, and v for "up"
    up = mesh.uv[:, 1]
    e1, e2 = pos[tris[:, 1]] - pos[tris[:, 0]], pos[tris[:, 2]] - pos[tris[:, 0]]
    s1, s2 = s[tris[:, 1]] - s[tris[:, 0]], s[tris[:, 2]] - s[tris[:, 0]]
    v1, v2 = up[tris[:, 1]] - up[tris[:, 0]], up[tris[:, 2]] - up[tris[:, 0]]
    det = s1 * v2 - s2 * v1
    sign = np.where(det < 0.0, -1.0, 1.0)[:, None]       # |det| weights by the area in (s, v)
    dp_ds = sign * (e1 * v2[:, None] - e2 * v1[:, None])
    dp_dv = sign * (e2 * s1[:, None] - e1 * s2[:, None])
    acc_s, acc_v = np.zeros_like(pos), np.zeros_like(pos)
    for k in range(3):
        np.add.at(acc_s, tris[:, k], dp_ds)
        np.add.at(acc_v, tris[:, k], dp_dv)
    t = acc_s - nrm * np.einsum("ij,ij->i", acc_s, nrm)[:, None]
    length = np.linalg.norm(t, axis=1)
    weak = ~(length > 1e-9 * np.maximum(np.linalg.norm(acc_s, axis=1), 1e-300)) | ~np.isfinite(length)
    x = np.array([1.0, 0.0, 0.0])
    fallback = x - nrm * nrm[:, :1]
    t = np.where(weak[:, None], fallback, t)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    w = np.where(np.einsum("ij,ij->i", np.cross(nrm, t), acc_v) < 0.0, -1.0, 1.0)
    return np.concatenate([t, w[:, None]], axis=1).astype(np.float32)


def _png(name: str, pixels: NDArray[np.float64], *, srgb: bool) -> TextureImage:
    values = linear_to_srgb(pixels) if srgb else np.clip(pixels, 0.0, 1.0)
    data = png_bytes(np.round(values * 255.0).astype(np.uint8))
    return TextureImage(Path(name), data, PNG, name)


def _stem(name: str) -> str:
    """A file-name stem from the leaf's name: one safe path component, ASCII without blanks
    (``.mtl`` files and PLY headers split on blanks)."""
    stem = safe_component(name or "leaf", fallback="leaf")
    return "".join(c if c.isascii() and not c.isspace() else "_" for c in stem)


def bake_vein_maps(params: LeafParams, size: int | None = None) -> VeinMaps | None:
    """The vein textures of ``params`` at ``size`` × ``size`` texels (default :data:`MAPS_SIZE`; a
    multiple of the field's tile, see :func:`leafview.botany.vein_field.check_field_size`); None
    when its venation is off, and for a lobed leaf (``lobes.outline`` set: it is drawn without
    veins, its texture coordinates are its flat position, not the (u, v) the maps are baked over)."""
    venation = params.venation
    if not venation.enabled or params.lobes.enabled:
        return None
    size = check_field_size(MAPS_SIZE if size is None else size, "size")
    field = vein_field(params, size).astype(np.float64)
    u, v = vein_grid_uv(size, size)
    fw = np.stack([_footprint(field[..., 0]), _footprint(field[..., 3])], axis=-1)
    major = major_width(venation)
    height = np.maximum(vein_height(field[..., 0], field[..., 2], venation.relief, fw[..., 0]),
                        vein_height(field[..., 3], major, venation.relief, fw[..., 1]))
    stem = _stem(params.name)
    front = back = None
    if params.texture is None:
        strength = vein_strength(field, major, fw)
        m = params.material
        front = _png(f"{stem}_basecolor.png", vein_albedo(m.front, strength, u, v, venation.contrast), srgb=True)
        back = _png(f"{stem}_back_basecolor.png",
                    vein_albedo(m.back, strength, u, v, venation.contrast, front=False), srgb=True)
    normal = _png(f"{stem}_normal.png", 0.5 * (normal_map(params, height) + 1.0), srgb=False)
    back_normal = _png(f"{stem}_back_normal.png", 0.5 * (normal_map(params, RELIEF_BACK * height) + 1.0),
                       srgb=False)
    return VeinMaps(front, back, normal, back_normal)


def vein_scene(params: LeafParams, mesh: LeafMesh, maps: VeinMaps | None, *, length_m: float = 0.1) -> ExportScene:
    """:func:`leafview.export.scene.leaf_scene` whose part carries ``maps`` (the venation mesh of
    ``--mesh cdt`` or the (u, v) grid; None: a part without vein textures)."""
    return leaf_scene(params, mesh, length_m=length_m, maps=maps)


def with_maps(scene: ExportScene, textures: SceneTextures, *, one_sided: bool = False,
              normals: bool = True) -> SceneTextures:
    """``textures`` (the parts' photographs) with every part's baked maps: a part without a
    photograph shows its base colours (``one_sided``: the front one on both sides, for OBJ and
    PLY), and every map image that the writer uses (``normals``: the normal maps too) is listed
    once in ``images``."""
    sides = dict(textures.sides)
    images = list(textures.images)
    for k, part in enumerate(scene.parts):
        maps = maps_of(part)
        if maps is None:
            continue
        if k not in sides and maps.front is not None and maps.back is not None:
            sides[k] = (maps.front, maps.front if one_sided else maps.back)
        wanted = [maps.front, maps.normal] if one_sided else maps.images
        if not normals:
            wanted = [image for image in wanted if image is not maps.normal and image is not maps.back_normal]
        images += [image for image in wanted if image is not None and image not in images]
    return SceneTextures(images, sides)
