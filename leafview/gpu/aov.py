"""Per-pixel ground truth of a scene (arbitrary output variables, AOVs): what a dataset stores
next to each picture.

:func:`render_aovs` draws a :class:`~leafview.gpu.scene.SceneRenderer`'s scene for one camera and
returns any of :data:`AOV_NAMES`:

``rgb``
    The picture, exactly as :meth:`SceneRenderer.render <leafview.gpu.scene.SceneRenderer.render>`
    gives it (sRGB RGBA, multisampled with ``samples``, over ``background``).
``instance``, ``depth``, ``normal``, ``uv``
    The labels, from one single-sample pass with multiple render targets
    (:class:`~leafview.gpu.targets.AovTarget`, the outputs declared in
    :data:`~leafview.gpu.layout.AOV_OUTPUTS`): no multisampling and no blending, so each pixel
    holds the values of the one fragment nearest the camera at the pixel's centre, with the same
    depth test, culling and level of detail as the picture. The program is ``leaf.vert`` +
    ``leaf.frag`` with ``LEAF_AOV`` (``leaf.vert`` passes the scene's leaf index, batch offset
    included, as ``v_leaf``); the stems are drawn first, as in the picture, with ``LEAF_STEMS``.

Textured leaves (:mod:`leafview.gpu.textures`) are labelled where the picture shows them: the
label pass discards the texels whose alpha is below 0.5, as the picture does, so holes and teeth
of the mask show what lies behind them in both.

Lobed leaves (``LeafParams.lobes``) are labelled like the others, drawn on their own grids by the
same multi-draws (:class:`~leafview.gpu.scene.SceneRenderer`): their ``instance``, ``depth`` and
``normal`` mean the same; their ``uv`` is the flat leaf's position (x, y in leaf lengths, the
margin's plane, Mündermann et al. 2003, eq. 1), which is what ``leaf.vert`` shades a swept
surface at, not the (u, v) of Ω.

Stems take part in the label pass: they hide the leaves behind them and write their depth and
normal, but their instance is 0 and their (u, v) is (0, 0), like the background. A pixel with
``instance == 0`` and ``depth > 0`` is therefore a stem.

Depth is the distance along the optical axis (``-z`` in view space), in world units: the ``z`` of
the camera coordinates of :func:`leafview.scene.camera.intrinsics`. For an orthographic camera it
is the distance from the camera's plane.

Every image has row 0 at the top. The numpy reference of every label (the leaf evaluated at the
read (u, v), placed and projected with ``K``) is ``tests/test_aov.py``.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leafview.gpu.context import check_error
from leafview.gpu.limits import ensure_alive
from leafview.gpu.scene import CullSettings, SceneRenderer
from leafview.gpu.targets import AovTarget
from leafview.scene.camera import Camera

__all__ = ["AOV_NAMES", "AovImages", "render_aovs"]

AOV_NAMES: tuple[str, ...] = ("rgb", "depth", "instance", "normal", "uv")
_LABELS = ("instance", "depth", "normal", "uv")
_AOV_DEFINES = {"LEAF_AOV": 1}
_DEFAULT_SETTINGS = CullSettings()   # frozen: a shared default is safe


@dataclass
class AovImages:
    """The per-pixel outputs of one view (None: not requested); (h, w, ...), row 0 at the top.

    Attributes
    ----------
    rgb: (h, w, 4) uint8 sRGB RGBA, as :meth:`SceneRenderer.render
        <leafview.gpu.scene.SceneRenderer.render>` (multisampled edges, ``background`` behind).
    depth: (h, w) float32, world units along the camera's optical axis (``-z`` in view space);
        0 where nothing is drawn. Stems have their depth.
    instance: (h, w) uint32, the scene's leaf index + 1 (leaf ``k - 1`` of ``scene.matrices``);
        0 for background and for stems.
    normal: (h, w, 3) float32, world-space unit normal of the side the camera sees (the upper
        side's normal, negated on back faces), interpolated over the drawn triangle; stems have
        theirs; 0 background.
    uv: (h, w, 2) float32, the leaf's own (u, v) (``v_uv`` of ``leaf.vert``: u in [-1, 1] across
        the blade, one-sided leaves already mapped to their half; v in [0, 1] base to apex; a
        lobed leaf's flat position instead); 0 background and stems.
    """

    rgb: NDArray[np.uint8] | None = None
    depth: NDArray[np.float32] | None = None
    instance: NDArray[np.uint32] | None = None
    normal: NDArray[np.float32] | None = None
    uv: NDArray[np.float32] | None = None


def _check_names(aovs: Iterable[str]) -> tuple[str, ...]:
    if isinstance(aovs, str):
        aovs = (aovs,)
    names = tuple(dict.fromkeys(str(a) for a in aovs))
    bad = [n for n in names if n not in AOV_NAMES]
    if bad:
        raise ValueError(f"unknown AOV {bad[0]!r} (choose from {', '.join(AOV_NAMES)})")
    return names


def render_aovs(renderer: SceneRenderer, camera: Camera, size: tuple[int, int], aovs: Iterable[str] = AOV_NAMES, *,
                settings: CullSettings = _DEFAULT_SETTINGS, samples: int = 4,
                background: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)) -> AovImages:
    """Draw ``renderer``'s scene from ``camera`` at ``size`` = (w, h) and return the requested
    ``aovs`` (any of :data:`AOV_NAMES`; see the module docstring for what each holds).

    ``rgb`` is one :meth:`SceneRenderer.render <leafview.gpu.scene.SceneRenderer.render>` (with
    ``samples`` and ``background``), drawn only when asked for; the labels share one
    single-sample pass into a :class:`~leafview.gpu.targets.AovTarget` made for the call and
    released after it (sizes checked against the context's limits first). ``settings`` (culling
    and level of detail) apply to both passes, so labels and picture show the same geometry.

    Raises ValueError naming an unknown AOV (before anything is drawn),
    :class:`~leafview.errors.GpuLimitError` for a size the context cannot hold and
    :class:`~leafview.errors.GLContextLost` for a released context. The framebuffer binding
    is left at the default framebuffer when labels were drawn.
    """
    names = _check_names(aovs)
    size = (int(size[0]), int(size[1]))
    ctx = renderer.ctx
    ensure_alive(ctx, "rendering the AOVs of a scene")
    out = AovImages()
    if "rgb" in names:
        out.rgb = renderer.render(camera, size, settings, samples=samples, background=background)
    labels = [n for n in _LABELS if n in names]
    if not labels:
        return out
    with AovTarget(ctx, size) as target:
        target.use()
        ctx.viewport = (0, 0, *size)
        target.clear()
        renderer.set_camera(camera, size)
        renderer.draw(settings, defines=_AOV_DEFINES)
        for name in labels:
            image = target.read(name)
            if name == "normal":
                image = np.ascontiguousarray(image[..., :3])
            setattr(out, name, image)
        check_error(ctx, "scene AOV frame")
    return out
