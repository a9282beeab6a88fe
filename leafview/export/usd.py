"""USD writer (``.usda`` text or ``.usdc`` crate) through the ``pxr`` bindings of usd-core.

Stage layout::

    (upAxis = "Z", metersPerUnit = length_m, defaultPrim = <root>)
    /<root>                      Xform, kind = component
        Looks/                   one UsdPreviewSurface material per side and colour
        <leaf>                   Xform (xformOp:transform = the leaf matrix) for a shape used once
            front, back          Mesh: the two sides (see below)
        Leaves                   PointInstancer for shapes used two or more times:
            Prototypes/<shape>   Xform with the front and back meshes of each shape
        stems                    Mesh with the bark material (scenes with stems)

leafview's world is +z up already, so the vertex data stay in leaf lengths and the stage says
``upAxis = "Z"`` and ``metersPerUnit = length_m`` (one leaf length in metres) instead of scaling
anything. Meshes are triangle meshes with ``subdivisionScheme = "none"``, vertex normals, a
``primvars:st`` of ``((1 - u) / 2, v)`` and their extent. The two sides: UsdPreviewSurface has
a single diffuse colour, so each leaf is two single-sided meshes on the same points, ``front``
(right-handed, the front colour) and ``back`` (``orientation = "leftHanded"``, negated normals,
the back colour), as in the glTF export (``back_faces="double-sided"`` writes one double-sided
mesh with the front colour). Translucency has no UsdPreviewSurface input; it is stored on each
material as the custom attribute ``leafview:translucency`` (with ``leafview:front``/``back``).

Textured leaves (:mod:`leafview.export.textures`): the images are files beside the USD file, each
written once, named by an asset path relative to the layer (``@./front.png@``). A textured
side's material is the usual network: a ``UsdPrimvarReader_float2`` reads ``st`` (the mesh's
``primvars:st``, vertex interpolation, (s, 1 - t) of :func:`leafview.core.texture.texture_st`:
USD's texture origin is the lower left), a ``UsdUVTexture`` (clamped, sRGB) feeds its ``rgb``
into ``diffuseColor`` and its alpha ``a`` into ``opacity``, and ``opacityThreshold`` = 0.5 cuts
the margin out. The front mesh shows the front image, the back mesh the back image (the front
one when there is none; ``back_faces="double-sided"``: the front image only). One material per
image and side, whatever the leaves' colours.

Baked vein textures (:mod:`leafview.export.vein_maps`, ``export --mesh cdt`` of a leaf with
veins) are files beside the layer too: each side's base colour through the same network without
the opacity cut (it covers the blade), and its tangent-space normal map through a second
``UsdUVTexture`` (``sourceColorSpace`` raw, ``scale`` (2, 2, 2, 1), ``bias`` (-1, -1, -1, 0)) into
the surface's ``normal``.

PointInstancer copies are stored as positions, ``orientations`` (quath, read by every USD
version) plus ``orientationsf`` (quatf, full precision, preferred where the schema has it) and
scales; a copy whose matrix is not TRS (shear) becomes its own Xform with the full matrix.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview._version import __version__
from leafview.atomic import atomic_output, brief, check_target, failed_write, outputs
from leafview.errors import OutputError, UsageError
from leafview.export.gltf import ALPHA_CUTOFF, BACK_FACES
from leafview.export.mesh import LeafMesh, check_mesh
from leafview.export.scene import BARK, TRS, TRS_TOLERANCE, ExportPart, ExportScene, parts_trs, scene_textures
from leafview.export.textures import SceneTextures, TextureImage, write_images
from leafview.export.vein_maps import maps_of, with_maps

__all__ = ["usd_layer", "write_usd"]


def _pxr() -> Any:
    try:
        from pxr import Gf, Sdf, Tf, Vt
    except ImportError as exc:  # pragma: no cover - usd-core is a declared dependency
        raise UsageError(f"USD export needs usd-core (pip install usd-core): {exc}") from None
    return Gf, Sdf, Tf, Vt


class _Names:
    """Valid, unique prim names under one parent."""

    def __init__(self) -> None:
        self.taken: set[str] = set()
        self.next: dict[str, int] = {}

    def __call__(self, name: str) -> str:
        Tf = _pxr()[2]
        base = Tf.MakeValidIdentifier(name or "leaf")
        out, k = base, self.next.get(base, 1)
        while out in self.taken:
            k += 1
            out = f"{base}_{k}"
        self.next[base] = k
        self.taken.add(out)
        return out


class _Writer:
    """Authors prims straight into an Sdf layer: with thousands of leaves, the Usd-level API
    (a recomposition after every prim) is a hundred times slower."""

    def __init__(self, layer: Any, root: str, back_faces: str) -> None:
        self.Gf, self.Sdf, self.Tf, self.Vt = _pxr()
        self.T = self.Sdf.ValueTypeNames
        self.layer = layer
        self.root = root
        self.back_faces = back_faces
        self.looks = f"{root}/Looks"
        self.prim(self.looks, "Scope")
        self.look_names = _Names()
        self.materials: dict[tuple[Any, ...], str] = {}

    # -- Sdf helpers ------------------------------------------------------------------------
    def prim(self, path: str, type_name: str) -> Any:
        spec = self.Sdf.CreatePrimInLayer(self.layer, path)
        spec.specifier = self.Sdf.SpecifierDef
        spec.typeName = type_name
        return spec

    def attr(self, prim: Any, name: str, type_name: Any, value: Any = None, *, uniform: bool = False,
             custom: bool = False) -> Any:
        variability = self.Sdf.VariabilityUniform if uniform else self.Sdf.VariabilityVarying
        spec = self.Sdf.AttributeSpec(prim, name, type_name, variability, custom)
        if value is not None:
            spec.default = value
        return spec

    def rel(self, prim: Any, name: str, targets: list[str]) -> None:
        spec = self.Sdf.RelationshipSpec(prim, name, False)
        spec.targetPathList.explicitItems = [self.Sdf.Path(t) for t in targets]

    def connect(self, prim: Any, name: str, type_name: Any, source: str) -> None:
        """An input ``name`` of ``prim`` connected to the attribute ``source``."""
        self.attr(prim, name, type_name).connectionPathList.explicitItems = [self.Sdf.Path(source)]

    def shader(self, path: str, shader_id: str) -> Any:
        spec = self.prim(path, "Shader")
        self.attr(spec, "info:id", self.T.Token, shader_id, uniform=True)
        return spec

    def texture(self, material: str, name: str, image: str, colour_space: str) -> Any:
        """A clamped ``UsdUVTexture`` ``material/name`` of the file ``image`` (beside the layer)
        read at the mesh's ``st`` (one primvar reader per material)."""
        T = self.T
        if self.layer.GetPrimAtPath(f"{material}/TexCoord") is None:
            reader = self.shader(f"{material}/TexCoord", "UsdPrimvarReader_float2")
            self.attr(reader, "inputs:varname", T.String, "st")
            self.attr(reader, "outputs:result", T.Float2)
        tex = self.shader(f"{material}/{name}", "UsdUVTexture")
        self.attr(tex, "inputs:file", T.Asset, self.Sdf.AssetPath(f"./{image}"))
        self.connect(tex, "inputs:st", T.Float2, f"{material}/TexCoord.outputs:result")
        for wrap in ("inputs:wrapS", "inputs:wrapT"):
            self.attr(tex, wrap, T.Token, "clamp")
        self.attr(tex, "inputs:sourceColorSpace", T.Token, colour_space)
        self.attr(tex, "outputs:rgb", T.Float3)
        return tex

    def image_network(self, material: str, surface: Any, image: str, *, mask: bool = True) -> None:
        """Wire ``surface`` (a UsdPreviewSurface spec) to the texture file ``image`` (beside the
        layer): rgb into diffuseColor and, with ``mask``, alpha into opacity, cut at ALPHA_CUTOFF."""
        T = self.T
        tex = self.texture(material, "Image", image, "sRGB")
        self.connect(surface, "inputs:diffuseColor", T.Color3f, f"{material}/Image.outputs:rgb")
        if mask:
            self.attr(tex, "outputs:a", T.Float)
            self.connect(surface, "inputs:opacity", T.Float, f"{material}/Image.outputs:a")
            self.attr(surface, "inputs:opacityThreshold", T.Float, ALPHA_CUTOFF)

    def normal_network(self, material: str, surface: Any, image: str) -> None:
        """Wire the tangent-space normal map ``image`` (``(n + 1) / 2``, linear) into ``surface``'s
        ``normal``, scaled and biased back to [-1, 1] as UsdPreviewSurface expects."""
        T, Gf = self.T, self.Gf
        tex = self.texture(material, "Normal", image, "raw")
        self.attr(tex, "inputs:scale", T.Float4, Gf.Vec4f(2.0, 2.0, 2.0, 1.0))
        self.attr(tex, "inputs:bias", T.Float4, Gf.Vec4f(-1.0, -1.0, -1.0, 0.0))
        self.connect(surface, "inputs:normal", T.Normal3f, f"{material}/Normal.outputs:rgb")

    # -- content ----------------------------------------------------------------------------
    def material(self, name: str, colour: Sequence[float], translucency: float, extra: dict[str, Any],
                 image: str | None = None, *, mask: bool = True, normal: str | None = None) -> str:
        """A UsdPreviewSurface material of ``colour``, or of the texture file ``image`` (cut out by
        its alpha with ``mask``), with the normal map file ``normal`` when given."""
        if image is None:
            key: tuple[Any, ...] = (tuple(colour), translucency, tuple(sorted(
                (k, tuple(v) if isinstance(v, (list, tuple)) else v) for k, v in extra.items())), normal)
        else:
            key = (image, translucency, extra.get("side"), mask, normal)
        if key in self.materials:
            return self.materials[key]
        Gf, T = self.Gf, self.T
        path = f"{self.looks}/{self.look_names(name)}"
        mat = self.prim(path, "Material")
        shader = self.shader(f"{path}/PreviewSurface", "UsdPreviewSurface")
        if image is None:
            self.attr(shader, "inputs:diffuseColor", T.Color3f, Gf.Vec3f(*map(float, colour)))
        else:
            self.image_network(path, shader, image, mask=mask)
        if normal is not None:
            self.normal_network(path, shader, normal)
        self.attr(shader, "inputs:roughness", T.Float, 0.6)
        self.attr(shader, "inputs:metallic", T.Float, 0.0)
        self.attr(shader, "outputs:surface", T.Token)
        out = self.attr(mat, "outputs:surface", T.Token)
        out.connectionPathList.explicitItems = [self.Sdf.Path(f"{path}/PreviewSurface.outputs:surface")]
        self.attr(mat, "leafview:translucency", T.Float, float(translucency), custom=True)
        for k, v in extra.items():
            if isinstance(v, str):
                self.attr(mat, f"leafview:{k}", T.Token, v, custom=True)
            else:
                self.attr(mat, f"leafview:{k}", T.Color3f, Gf.Vec3f(*map(float, v)), custom=True)
        self.materials[key] = path
        return path

    def leaf_materials(self, part: ExportPart, images: tuple[str, str] | None = None,
                       normals: tuple[str, str] | None = None) -> tuple[str, str | None]:
        """The front and back materials of ``part``, textured by the files ``images`` (front,
        back) when given, with the normal map files ``normals`` (front, back) when given."""
        m = part.material
        extra = {"front": m.front, "back": m.back}
        front_img, back_img = images if images is not None else (None, None)
        front_nrm, back_nrm = normals if normals is not None else (None, None)
        mask = part.texture is not None      # a photograph's alpha cuts the margin out; baked maps cover the blade
        if self.back_faces == "double-sided":
            return self.material("leaf", m.front, m.translucency, extra, front_img, mask=mask, normal=front_nrm), None
        return (self.material("leaf_front", m.front, m.translucency, {**extra, "side": "front"}, front_img,
                              mask=mask, normal=front_nrm),
                self.material("leaf_back", m.back, m.translucency, {**extra, "side": "back"}, back_img,
                              mask=mask, normal=back_nrm))

    def mesh(self, path: str, pos: NDArray[np.float32], nrm: NDArray[np.float32], tris: NDArray[np.uint32],
             st: NDArray[np.float32] | None, material: str, *, back: bool = False, double_sided: bool = False) -> None:
        Vt, T = self.Vt, self.T
        spec = self.prim(path, "Mesh")
        spec.SetInfo("apiSchemas", self.Sdf.TokenListOp.Create(prependedItems=["MaterialBindingAPI"]))
        pos = np.ascontiguousarray(pos, np.float32)
        self.attr(spec, "points", T.Point3fArray, Vt.Vec3fArray.FromNumpy(pos))
        self.attr(spec, "extent", T.Float3Array, Vt.Vec3fArray.FromNumpy(np.stack([pos.min(0), pos.max(0)])))
        self.attr(spec, "faceVertexCounts", T.IntArray, Vt.IntArray.FromNumpy(np.full(len(tris), 3, np.int32)))
        self.attr(spec, "faceVertexIndices", T.IntArray,
                  Vt.IntArray.FromNumpy(np.ascontiguousarray(tris, np.int32).ravel()))
        normals = self.attr(spec, "normals", T.Normal3fArray,
                            Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(-nrm if back else nrm, np.float32)))
        normals.SetInfo("interpolation", "vertex")
        self.attr(spec, "subdivisionScheme", T.Token, "none", uniform=True)
        self.attr(spec, "doubleSided", T.Bool, double_sided, uniform=True)
        if back:
            self.attr(spec, "orientation", T.Token, "leftHanded", uniform=True)
        if st is not None:
            pv = self.attr(spec, "primvars:st", T.TexCoord2fArray, Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(st)))
            pv.SetInfo("interpolation", "vertex")
        self.rel(spec, "material:binding", [material])

    def leaf(self, path: str, mesh: LeafMesh, mats: tuple[str, str | None], matrix: NDArray[np.float64] | None) -> None:
        """An Xform at ``path`` holding the leaf's meshes, placed by ``matrix`` (None: identity)."""
        check_mesh(mesh)
        xf = self.prim(path, "Xform")
        if matrix is not None:
            # USD uses row vectors: the transpose of leafview's column-vector matrix
            value = self.Gf.Matrix4d(*np.asarray(matrix, np.float64).T.ravel().tolist())
            self.attr(xf, "xformOp:transform", self.T.Matrix4d, value)
            self.attr(xf, "xformOpOrder", self.T.TokenArray, self.Vt.TokenArray(["xformOp:transform"]), uniform=True)
        front, back = mats
        self.mesh(f"{path}/front", mesh.positions, mesh.normals, mesh.indices, mesh.st, front,
                  double_sided=back is None)
        if back is not None:
            self.mesh(f"{path}/back", mesh.positions, mesh.normals, mesh.indices, mesh.st, back, back=True)

    def instancer(self, path: str, parts: list[tuple[ExportPart, tuple[str, str | None], TRS]]) -> None:
        """One PointInstancer for the TRS copies of ``parts`` (each with its decomposed matrices)."""
        Vt, T = self.Vt, self.T
        inst = self.prim(path, "PointInstancer")
        self.prim(f"{path}/Prototypes", "Scope")
        names = _Names()
        protos, ids, t_all, q_all, s_all = [], [], [], [], []
        for k, (part, mats, trs) in enumerate(parts):
            proto = f"{path}/Prototypes/{names(part.name)}"
            self.leaf(proto, part.mesh, mats, None)
            protos.append(proto)
            ok = trs[3] <= TRS_TOLERANCE
            t, q, s = (a[ok] for a in trs[:3])
            ids.append(np.full(len(t), k, np.int32))
            t_all.append(t)
            q_all.append(q)
            s_all.append(s)
        self.rel(inst, "prototypes", protos)
        self.attr(inst, "protoIndices", T.IntArray, Vt.IntArray.FromNumpy(np.concatenate(ids)))
        self.attr(inst, "positions", T.Point3fArray, Vt.Vec3fArray.FromNumpy(np.concatenate(t_all).astype(np.float32)))
        xyzw = np.ascontiguousarray(np.concatenate(q_all))   # Gf quaternions lie in memory as imaginary, real
        self.attr(inst, "orientations", T.QuathArray, Vt.QuathArray.FromNumpy(xyzw.astype(np.float16)))
        self.attr(inst, "orientationsf", T.QuatfArray, Vt.QuatfArray.FromNumpy(xyzw.astype(np.float32)))
        self.attr(inst, "scales", T.Float3Array, Vt.Vec3fArray.FromNumpy(np.concatenate(s_all).astype(np.float32)))


def usd_layer(scene: ExportScene, path: str | Path, *, back_faces: str = "primitive",
              textures: SceneTextures | None = None, files: dict[TextureImage, str] | None = None) -> Any:
    """Author ``scene`` into a new Sdf layer that will be saved at ``path``. Textured parts refer
    to their images (``textures``, read from the scene when not given) by the file names
    ``files`` (default: each image's own name) beside ``path``; writing them is the caller's."""
    if back_faces not in BACK_FACES:
        raise UsageError(f"unknown back-face mode {back_faces!r} (use {', '.join(BACK_FACES)})")
    if not (np.isfinite(scene.length_m) and scene.length_m > 0):
        raise UsageError(f"length_m must be a positive number of metres, got {scene.length_m!r}")
    _, Sdf, Tf, _ = _pxr()
    textures = with_maps(scene, scene_textures(scene)) if textures is None else textures
    files = files or {}
    layer = Sdf.Layer.CreateNew(str(path))
    root_name = Tf.MakeValidIdentifier(scene.name or "leafview")
    root = "/" + root_name
    with Sdf.ChangeBlock():
        layer.pseudoRoot.SetInfo("upAxis", "Z")
        layer.pseudoRoot.SetInfo("metersPerUnit", float(scene.length_m))
        layer.defaultPrim = root_name
        layer.documentation = f"leafview {__version__}: {scene.n_leaves} leaves, 1 unit = 1 leaf length"
        w = _Writer(layer, root, back_faces)
        w.prim(root, "Xform").kind = "component"
        names = _Names()
        names("Looks")
        names("Leaves")
        names("stems")
        instanced = []
        for k, (part, trs) in enumerate(zip(scene.parts, parts_trs(scene.parts))):
            sides = textures.of(k)
            maps = maps_of(part)
            mats = w.leaf_materials(part, None if sides is None else
                                    (files.get(sides[0], sides[0].name), files.get(sides[1], sides[1].name)),
                                    None if maps is None else (files.get(maps.normal, maps.normal.name),
                                                               files.get(maps.back_normal, maps.back_normal.name)))
            ok = trs[3] <= TRS_TOLERANCE
            if len(part.matrices) >= 2 and ok.sum() >= 2:
                instanced.append((part, mats, trs))
                rest = np.flatnonzero(~ok)
            else:
                rest = np.arange(len(part.matrices))
            for i in rest:
                label = part.name if len(part.matrices) == 1 else f"{part.name}_{i}"
                w.leaf(f"{root}/{names(label)}", part.mesh, mats, part.matrices[i])
        if instanced:
            w.instancer(f"{root}/Leaves", instanced)
        if scene.stems is not None:
            pos, nrm, idx = scene.stems
            bark = w.material("bark", BARK, 0.0, {"side": "bark"})
            w.mesh(f"{root}/stems", pos, nrm, idx, None, bark)
    return layer


def write_usd(scene: ExportScene, path: str | Path, *, back_faces: str = "primitive") -> Path:
    """Write ``scene`` to ``path`` (``.usda`` or ``.usdc``) atomically, with the images of its
    textured leaves beside it (all files or none)."""
    path = Path(path)
    if path.suffix.lower() not in (".usda", ".usdc", ".usd"):
        raise UsageError(f"{path}: a USD file ends in .usda, .usdc or .usd")
    check_target(path)
    textures = with_maps(scene, scene_textures(scene))   # every image read and checked before anything is written
    with outputs(), atomic_output(path) as tmp:
        files = write_images(textures, path.parent)
        layer = usd_layer(scene, tmp, back_faces=back_faces, textures=textures, files=files)
        try:
            saved, detail = bool(layer.Save()), ""
        except RuntimeError as exc:        # pxr.Tf.ErrorException: USD's own writer failed
            saved, detail = False, brief(str(exc))
        finally:
            del layer
        if not saved:
            raise failed_write(path, f"USD: {detail or 'the layer was not saved'}") or OutputError(
                f"cannot write {path}: USD could not save the layer{': ' + detail if detail else ''}", str(path))
    return path
