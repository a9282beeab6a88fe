"""Morph sequences rendered through the shader path (Garg & Leow 2011, sec. 6).

:mod:`leafview.botany.morph` gives the path in leaf space (eq. 11) and its frames as landmark
leaves; here each frame is fitted to the shader model Ω (:mod:`leafview.botany.outline_fit`) and
the frames are rendered with one shared camera, so that the sequence does not jump in scale when a
tail or a shoulder grows. ``leafview morph`` (:mod:`leafview.cli.morph`) and the viewer's
morph panel use it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview.botany import leaf_surface
from leafview.botany.asymmetric import ShaderLeaves, shader_leaves
from leafview.botany.catalogue import load_landmark_leaf
from leafview.botany.landmarks import LandmarkLeaf, margin_params
from leafview.botany.morph import keyframe_path, morph_path, smoothness
from leafview.botany.shapes import INSTANCE_TARGET
from leafview.core.defaults import DETAIL_GRID
from leafview.core.io import read_document
from leafview.core.params import LeafParams, ParamError
from leafview.deform.surface import evaluate, grid_uv
from leafview.gpu import default_renderer
from leafview.gpu.sheets import render_leaves
from leafview.scene.camera import frame_view

__all__ = ["MorphSequence", "RefSpec", "parse_ref", "load_morph_leaf", "morph_sequence", "fit_frame",
           "shared_camera", "render_sequence", "MORPH_METHODS"]

MORPH_METHODS = ("nurbs", "keyframe")


@dataclass(frozen=True)
class RefSpec:
    """A reference shape of the morph path and its weight w_k (eq. 11)."""

    spec: str
    weight: float


def parse_ref(text: str) -> RefSpec:
    """``C.toml:W`` or ``cordate:W`` (weight W ≥ 0); ``C`` alone has weight 1."""
    spec, sep, w = text.rpartition(":")
    if not sep or not spec or "/" in w or "\\" in w:
        return RefSpec(text, 1.0)
    try:
        weight = float(w)
    except ValueError:
        raise ParamError("--ref", f"{text!r}: the weight after ':' must be a number, got {w!r}") from None
    if not (math.isfinite(weight) and weight >= 0.0):
        raise ParamError("--ref", f"{text!r}: the weight must be a finite number >= 0, got {w}")
    return RefSpec(spec, weight)


def load_morph_leaf(spec: str, what: str) -> LandmarkLeaf:
    """A landmark leaf from a file (``landmarks = 1``) or a catalogue name, for argument ``what``.

    A shader-model preset (Ω, ``schema = 1``) is refused with a message saying why: morphing
    happens in the landmark space of sec. 6, which an Ω preset does not carry.
    """

    try:
        return load_landmark_leaf(spec)
    except ParamError as exc:
        try:
            data = read_document(spec)
        except (ParamError, OSError):
            data = None
        if isinstance(data, dict) and "landmarks" not in data and "schema" in data:
            raise ParamError(what, f"{spec} is a shader-model preset (Ω); morphing needs a landmark leaf "
                                   "(a file with `landmarks = 1`, see assets/landmarks/) or a catalogue "
                                   "name such as 'ovate' (`leafview shapes` lists them)") from None
        raise ParamError(what, str(exc)) from None


def fit_frame(leaf: LandmarkLeaf, name: str = "", *, polish: bool = True) -> ShaderLeaves:
    """The shader-model leaves of one landmark frame (one leaf, or one per side when the frame is
    asymmetric: :mod:`leafview.botany.asymmetric`) and their outline error (Hausdorff ÷ leaf
    length)."""

    return shader_leaves(leaf, target=INSTANCE_TARGET, polish=polish, name=name or leaf.name)


@dataclass
class MorphSequence:
    """The frames of a morph: landmark leaves, their fitted Ω and where they sit on the path.

    ``parts[i]`` holds frame i's shader-model leaves: one, or (right half, left half) when the
    frame is asymmetric."""

    method: str
    t: NDArray[np.float64]                 # frame positions in [0, 1] (arc length or parameter)
    by: str
    leaves: list[LandmarkLeaf]
    vectors: NDArray[np.float64]           # (frames, dim) in the unified leaf space
    parts: list[tuple[LeafParams, ...]] = field(default_factory=list)
    errors: list[float] = field(default_factory=list)
    smoothness: dict[str, float] = field(default_factory=dict)
    keyframe_smoothness: dict[str, float] = field(default_factory=dict)
    space_names: list[str] = field(default_factory=list)
    reference_distances: list[float] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        """JSON-able description (written as ``morph.json`` by the CLI)."""
        return {
            "method": self.method, "by": self.by, "frames": len(self.leaves),
            "leaf_space": self.space_names,
            "smoothness": self.smoothness, "keyframe_smoothness": self.keyframe_smoothness,
            "reference_distances": self.reference_distances,
            "frame": [{"t": float(t), "vector": [float(x) for x in v], "fit_error": e,
                       "leaves": [p.name for p in parts]}
                      for t, v, e, parts in zip(self.t, self.vectors, self.errors, self.parts)],
        }


def morph_sequence(source: LandmarkLeaf, target: LandmarkLeaf,
                   refs: Sequence[tuple[LandmarkLeaf, float]] = (), frames: int = 24, *,
                   method: str = "nurbs", polish: bool = True, margin: bool = False,
                   progress: Callable[[int], None] | None = None) -> MorphSequence:
    """Frames of the morph from ``source`` to ``target`` through weighted references, fitted to Ω
    (or, with ``margin=True``, drawn with their own landmark margins: no fit).

    Parameters
    ----------
    method
        ``"nurbs"``: the path of eq. 11, frames evenly spaced along its arc length (the paper's
        regular interval). ``"keyframe"``: linear key-framing through the same references, frames
        evenly spaced in its parameter (the comparison of Fig. 10).
    polish
        Least-squares polish of each frame's fit (about 0.25 s a frame; off: about 0.03 s, within
        a few per cent of the leaf length).
    margin
        Give each frame its landmark margin as its silhouette (:mod:`leafview.core.margin`): one
        leaf a frame, asymmetric or not, exact (error 0) and without a fit; ``polish`` is unused.
    progress
        Called with 1 after each fitted frame (a progress bar's ``update``).

    Both paths' smoothness (:func:`leafview.botany.morph.smoothness`) is measured on the same number
    of frames, so the two can be compared side by side.
    """
    if method not in MORPH_METHODS:
        raise ParamError("method", f"must be one of {', '.join(MORPH_METHODS)}, got {method!r}")
    if isinstance(frames, bool) or not isinstance(frames, int) or frames < 2:
        raise ParamError("frames", f"need at least 2 frames, got {frames!r}")
    nurbs = morph_path(source, target, refs)
    key = keyframe_path(source, target, refs)
    path, by = (nurbs, "arclength") if method == "nurbs" else (key, "parameter")
    t = np.linspace(0.0, 1.0, frames)
    leaves = [path.sample(float(x), by=by) for x in t]
    seq = MorphSequence(method, t, by, leaves, path.frame_vectors(frames, by=by),
                        smoothness=smoothness(nurbs.frame_vectors(frames)),
                        keyframe_smoothness=smoothness(key.frame_vectors(frames, by="parameter")),
                        space_names=list(path.space.names),
                        reference_distances=[path.distance_to(v) for v in path.vectors[1:-1]])
    width = len(str(frames - 1))
    if margin:
        for i, params in enumerate(margin_params(leaves)):
            seq.parts.append((params.replace(name=f"morph {i:0{width}d} t={t[i]:.3f}"),))
            seq.errors.append(0.0)
        if progress is not None:
            progress(len(leaves))
        return seq
    for i, leaf in enumerate(leaves):
        fit = fit_frame(leaf, f"morph {i:0{width}d} t={t[i]:.3f}", polish=polish)
        seq.parts.append(fit.parts)
        seq.errors.append(fit.error)
        if progress is not None:
            progress(1)
    return seq


def shared_camera(leaves: Sequence[LeafParams], view: str, size: tuple[int, int],
                  grid: tuple[int, int] = (33, 129)) -> Any:
    """One camera framing every leaf of ``leaves`` (the union of their numpy-evaluated grids: a
    lobed leaf's swept surface on its lobed grid, :func:`leafview.botany.leaf_surface.grid_points`,
    not Ω, whose outline would cut its basal lobes off)."""

    uv = grid_uv(*grid).astype(np.float64)
    points = []
    for p in leaves:
        m = p.transform.matrix()
        local = leaf_surface.grid_points(p, grid) if p.lobes.enabled else evaluate(p, uv[:, 0], uv[:, 1])
        points.append(local @ m[:3, :3].T + m[:3, 3])
    return frame_view(view, np.concatenate(points), size)


def render_sequence(frames: Sequence[Sequence[LeafParams]], size: int, view: str = "top", *,
                    progress: Callable[[int], None] | None = None) -> list[NDArray[np.uint8]]:
    """Render frames (each one or more shader-model leaves) with one shared camera
    (:func:`shared_camera`): single-leaf frames 16 at a time, frames of several leaves (the halves
    of an asymmetric leaf) in one instanced draw each."""

    renderer = default_renderer()
    camera = shared_camera([p for parts in frames for p in parts], view, (size, size), DETAIL_GRID)
    images: list[NDArray[np.uint8]] = []
    start = 0
    while start < len(frames):
        if len(frames[start]) != 1:
            images.append(render_leaves(list(frames[start]), (size, size), view, grid=DETAIL_GRID,
                                        renderer=renderer, camera=camera))
            step = 1
        else:
            batch: list[LeafParams] = []
            while start + len(batch) < len(frames) and len(batch) < 16 and len(frames[start + len(batch)]) == 1:
                batch.append(frames[start + len(batch)][0])
            images += renderer.render_many(batch, (size, size), view, grid=DETAIL_GRID, camera=camera)
            step = len(batch)
        start += step
        if progress is not None:
            progress(step)
    return images
