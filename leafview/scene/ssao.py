"""Screen-space ambient occlusion (SSAO) of a canopy: the numpy reference of ``shaders/ssao.frag``
and ``shaders/ssao_blur.frag`` (:class:`leafview.gpu.ssao.SsaoPass`).

The occlusion is an obscurance estimate in the manner of McGuire, Osman, Bukowski & Hennessy
(2011, the Alchemy AO estimator): samples of a normal-oriented hemisphere kernel (Crytek's SSAO
as Chapman 2013 describes it) choose the pixels to look at, and each pixel's *visible surface
point* there, not the sample point, is what occludes. A leaf lying a small gap above another is
then seen from above as what it is in screen space, a step of the gap's height, and darkens the
lower leaf along its edge; a flat open surface occludes itself exactly nothing. It is computed
from a view-space depth image and a world-normal image (the label pass of
:mod:`leafview.gpu.aov`):

1. **Reconstruction.** The pixel ``(x, y)`` (GL window coordinates: column ``x``, row ``y`` counted
   from the *bottom*) has the centre ``c = (x + 1/2, y + 1/2)`` and the normalised device
   coordinates ``q = 2 c / (w, h) - 1``. With the projection ``P`` and the depth ``d`` along the
   optical axis, its view-space position is

   - perspective: ``p = ((q_x + P02) d / P00, (q_y + P12) d / P11, -d)``,
   - orthographic: ``p = ((q_x - P03) / P00, (q_y - P13) / P11, -d)``,

   the inverse of ``q = (P p)_xy / (P p)_w`` (an off-centre frustum included).
2. **Kernel.** ``n`` offsets ``k_i`` in the unit hemisphere: directions with ``z >= 0.15`` (before
   normalising), lengths stratified over [0.1, 1] (one random length in each of ``n`` equal
   strata, so the samples reach across the whole radius), and 16 rotations
   ``r_j = (cos θ_j, sin θ_j, 0)``, all drawn from ``seed`` (:func:`ssao_kernel`). Pixel ``(x, y)``
   uses rotation ``j = 4 (y mod 4) + (x mod 4)``.
3. **Frame.** With the view-space normal ``m = normalize(R n)`` (``R`` the view's rotation, ``n`` the
   visible side's world normal): ``t = normalize(r - m (r·m))`` (``r = (0, 0, 1)`` instead when
   ``|r - m (r·m)|² < 10⁻⁶``), ``b = m × t``; the sample is ``s_i = p + ρ (k_x t + k_y b + k_z m)``
   for the radius ``ρ`` (world units).
4. **Obscurance.** ``s_i`` is projected to the pixel ``f = floor((q + 1) / 2 · (w, h))``
   (perspective: only in front of the camera, ``s_z < 0``); outside the image or over the
   background (depth 0) it finds nothing. Otherwise ``v = P_f - p``, with ``P_f`` the position of
   pixel ``f``'s centre at its depth (step 1), and the sample's obscurance is

   ``o_i = min(1, ρ · max(0, v·m - β) / (|v|² + ε ρ²)) · clamp(1 - |v|² / ρ², 0, 1)``:

   the Alchemy term (surfaces above the tangent plane, the nearer the stronger; ``β`` a bias
   against curvature and round-off, ``ε = 10⁻⁴``), clamped per sample, with a falloff that drops
   surfaces farther than ``ρ`` (no halo from a far background or a distant foreground leaf).
   ``AO_raw = clamp(1 - strength · Σ o_i / n, 0, 1)``; 1 on the background and where there is no
   normal.
5. **Blur.** The 4 × 4 box ``x - 2 … x + 1``, ``y - 2 … y + 1`` (one tile of the rotations, so
   their pattern averages out), over the pixels inside the image, drawn (depth > 0) and within
   ``0.05 ρ`` of the centre's tangent plane (``|(P_q - p)·m|``: surface-aware, so occlusion does
   not bleed from a lower leaf onto the leaf above it, and slanted surfaces blur whole); the
   centre always counts. Background pixels are 1.

Images given to and returned by the functions here have row 0 at the *top* (as every readback of
leafview); they are flipped to GL's rows internally.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.errors import ParamError
from leafview.scene.camera import Camera

__all__ = ["SsaoSettings", "MAX_SAMPLES", "NOISE_TILE", "BLUR_PLANE", "OBSCURANCE_EPS", "ssao_kernel",
           "default_radius", "view_positions", "raw_occlusion", "blur_occlusion", "ambient_occlusion"]

MAX_SAMPLES = 64
"""Most kernel samples a pass takes (the size of ``ssao.frag``'s kernel array)."""
NOISE_TILE = 4
"""Side of the tile of kernel rotations (and of the blur box)."""
MIN_KERNEL_Z = 0.15        # kernel directions at least this far above the tangent plane
MIN_KERNEL_LENGTH = 0.1    # kernel lengths stratified over [0.1, 1] (one per stratum)
RADIUS_OF_LEAF = 0.5       # default radius: this many median leaf lengths
DEGENERATE = 1e-6          # |r - m (r·m)|² under which the rotation is replaced by the view axis
BLUR_PLANE = 0.05          # blur: neighbours within this many ρ of the pixel's tangent plane
OBSCURANCE_EPS = 1e-4      # ε: (ρ² times) the floor of |v|² in the obscurance


@dataclass(frozen=True)
class SsaoSettings:
    """How the occlusion is estimated.

    Attributes
    ----------
    radius: hemisphere radius ρ in world units; None: ``0.5 ×`` the scene's median leaf length
        (:func:`default_radius`).
    samples: kernel samples per pixel (1 … :data:`MAX_SAMPLES`).
    seed: seed of the kernel and of the rotations.
    bias: β as a fraction of ρ (how far above the pixel's tangent plane a surface must rise
        before it occludes: ignores slight curvature and round-off).
    strength: how much the mean obscurance darkens (0 … 4).
    """

    radius: float | None = None
    samples: int = 16
    seed: int = 0
    bias: float = 0.02
    strength: float = 2.0

    def __post_init__(self) -> None:
        def finite(name: str, value: object, lo: float, hi: float, lo_open: bool = False) -> None:
            try:
                v = float(value)   # type: ignore[arg-type]
            except (TypeError, ValueError):
                raise ParamError(f"ssao.{name}", f"must be a number, got {value!r}") from None
            if not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo):
                span = f"({lo:g}, {hi:g}]" if lo_open else f"[{lo:g}, {hi:g}]"
                raise ParamError(f"ssao.{name}", f"must be finite and in {span}, got {value!r}")

        if self.radius is not None:
            finite("radius", self.radius, 0.0, 1e6, lo_open=True)
        if isinstance(self.samples, bool) or not isinstance(self.samples, (int, np.integer)) \
                or not 1 <= int(self.samples) <= MAX_SAMPLES:
            raise ParamError("ssao.samples", f"must be an integer in [1, {MAX_SAMPLES}], got {self.samples!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or int(self.seed) < 0:
            raise ParamError("ssao.seed", f"must be a non-negative integer, got {self.seed!r}")
        finite("bias", self.bias, 0.0, 1.0)
        finite("strength", self.strength, 0.0, 4.0)


def ssao_kernel(samples: int = 16, seed: int = 0) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """``(kernel (samples, 3), rotations (16, 2))`` float32, both from ``seed`` (step 2 of the module
    docstring): hemisphere offsets (``z >= 0.15`` before scaling, length at most 1) and the unit
    rotation vectors of the 4 × 4 tile (rotation ``4 · row + column``)."""
    n = int(samples)
    rng = np.random.default_rng(int(seed))
    direction = np.column_stack([rng.uniform(-1.0, 1.0, (n, 2)), rng.uniform(MIN_KERNEL_Z, 1.0, n)])
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    length = MIN_KERNEL_LENGTH + (1.0 - MIN_KERNEL_LENGTH) * (np.arange(n) + rng.uniform(0.0, 1.0, n)) / n
    kernel = direction * length[:, None]
    theta = rng.uniform(0.0, 2.0 * np.pi, NOISE_TILE * NOISE_TILE)
    rotations = np.column_stack([np.cos(theta), np.sin(theta)])
    return kernel.astype(np.float32), rotations.astype(np.float32)


def default_radius(matrices: ArrayLike) -> float:
    """ρ for a scene whose leaf-to-world ``matrices`` are (N, 4, 4): ``0.5 ×`` the median leaf
    length (a leaf runs from its base to its apex at (0, 1, 0) in leaf space, so its world length is
    the norm of the matrix's second column). Raises ValueError for an empty or degenerate scene."""
    m = np.asarray(matrices, np.float64).reshape(-1, 4, 4)
    if len(m) == 0:
        raise ValueError("default_radius: a scene without leaves has no leaf length")
    length = float(np.median(np.linalg.norm(m[:, :3, 1], axis=1)))
    if not (math.isfinite(length) and length > 0.0):
        raise ValueError(f"default_radius: the median leaf length is {length!r}")
    return RADIUS_OF_LEAF * length


def _gl_rows(image: ArrayLike) -> NDArray[np.float64]:
    return np.ascontiguousarray(np.asarray(image, np.float64)[::-1])


def view_positions(depth: ArrayLike, camera: Camera) -> NDArray[np.float64]:
    """(h, w, 3) view-space positions of the pixels of ``depth`` ((h, w), GL rows: row 0 at the
    *bottom*; distance along the optical axis), reconstructed as step 1 of the module docstring."""
    d = np.asarray(depth, np.float64)
    h, w = d.shape
    p = np.asarray(camera.proj, np.float64)
    qx = (2.0 * (np.arange(w) + 0.5) / w - 1.0)[None, :]
    qy = (2.0 * (np.arange(h) + 0.5) / h - 1.0)[:, None]
    if camera.perspective:
        x, y = (qx + p[0, 2]) * d / p[0, 0], (qy + p[1, 2]) * d / p[1, 1]
    else:
        x, y = np.broadcast_to((qx - p[0, 3]) / p[0, 0], d.shape), np.broadcast_to((qy - p[1, 3]) / p[1, 1], d.shape)
    return np.stack([x, y, -d], axis=-1)


def _smoothstep01(x: NDArray[np.float64]) -> NDArray[np.float64]:
    t = np.clip(x, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def raw_occlusion(depth: ArrayLike, normal: ArrayLike, camera: Camera, radius: float,
                  settings: SsaoSettings | None = None) -> NDArray[np.float32]:
    """Unblurred AO (steps 1-4 of the module docstring) of a depth image (h, w) and a world-normal
    image (h, w, 3 or 4), both row 0 at the top; (h, w) float32, row 0 at the top, 1 = open
    (``settings`` None: the defaults)."""
    settings = SsaoSettings() if settings is None else settings
    d = _gl_rows(depth)
    nw = _gl_rows(np.asarray(normal)[..., :3])
    h, w = d.shape
    kernel, rotations = ssao_kernel(settings.samples, settings.seed)
    kernel64, rot64 = kernel.astype(np.float64), rotations.astype(np.float64)
    rho = float(radius)
    beta = settings.bias * rho
    p = np.asarray(camera.proj, np.float64)
    pos = view_positions(d, camera)
    m, has_normal = _view_normals(nw, camera)
    drawn = (d > 0.0) & has_normal
    ys, xs = np.mgrid[0:h, 0:w]
    j = NOISE_TILE * (ys % NOISE_TILE) + (xs % NOISE_TILE)
    r = np.zeros((h, w, 3))
    r[..., :2] = rot64[j]
    t = r - m * np.sum(r * m, axis=-1, keepdims=True)
    bad = np.sum(t * t, axis=-1) < DEGENERATE
    if bad.any():
        z = np.array([0.0, 0.0, 1.0])
        t[bad] = z - m[bad] * (m[bad] @ z)[:, None]
    t /= np.maximum(np.linalg.norm(t, axis=-1, keepdims=True), 1e-30)
    b = np.cross(m, t)
    total = np.zeros((h, w))
    for k in kernel64:
        s = pos + rho * (k[0] * t + k[1] * b + k[2] * m)
        if camera.perspective:
            front = s[..., 2] < 0.0
            with np.errstate(divide="ignore", invalid="ignore"):
                qx = (p[0, 0] * s[..., 0] + p[0, 2] * s[..., 2]) / -s[..., 2]
                qy = (p[1, 1] * s[..., 1] + p[1, 2] * s[..., 2]) / -s[..., 2]
        else:
            front = np.ones((h, w), bool)
            qx, qy = p[0, 0] * s[..., 0] + p[0, 3], p[1, 1] * s[..., 1] + p[1, 3]
        with np.errstate(invalid="ignore"):
            fx, fy = np.floor((qx * 0.5 + 0.5) * w), np.floor((qy * 0.5 + 0.5) * h)
            inside = front & (fx >= 0) & (fx < w) & (fy >= 0) & (fy < h)
        ix = np.where(inside, fx, 0).astype(np.int64)
        iy = np.where(inside, fy, 0).astype(np.int64)
        hit = inside & (d[iy, ix] > 0.0)
        v = pos[iy, ix] - pos                      # to the surface seen at the sample's pixel
        vv = np.sum(v * v, axis=-1)
        rise = np.minimum(rho * np.maximum(np.sum(v * m, axis=-1) - beta, 0.0) / (vv + OBSCURANCE_EPS * rho * rho), 1.0)
        falloff = np.clip(1.0 - vv / (rho * rho), 0.0, 1.0)
        total += np.where(hit, rise * falloff, 0.0)
    ao = np.clip(1.0 - settings.strength * total / len(kernel64), 0.0, 1.0)
    ao = np.where(drawn, ao, 1.0)
    return np.ascontiguousarray(ao[::-1]).astype(np.float32)


def _view_normals(normal: ArrayLike, camera: Camera) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """(unit view-space normals, where they exist) of a world-normal image in GL rows."""
    m = np.asarray(normal, np.float64)[..., :3] @ np.asarray(camera.view, np.float64)[:3, :3].T
    length = np.linalg.norm(m, axis=-1, keepdims=True)
    return m / np.maximum(length, 1e-30), length[..., 0] > 1e-6


def blur_occlusion(raw: ArrayLike, depth: ArrayLike, normal: ArrayLike, camera: Camera,
                   radius: float) -> NDArray[np.float32]:
    """Surface-aware 4 × 4 blur (step 5 of the module docstring) of ``raw`` AO over ``depth``
    and world ``normal`` (h, w) / (h, w, 3), row 0 at the top; (h, w) float32, row 0 at the top."""
    a, d = _gl_rows(raw), _gl_rows(depth)
    m, has_normal = _view_normals(_gl_rows(np.asarray(normal)[..., :3]), camera)
    pos = view_positions(d, camera)
    h, w = d.shape
    tol = BLUR_PLANE * float(radius)
    total, count = np.zeros((h, w)), np.zeros((h, w))
    pad = NOISE_TILE
    ap, dp = np.pad(a, pad), np.pad(d, pad)      # outside the image: depth 0, never counted
    pp = np.pad(pos, ((pad, pad), (pad, pad), (0, 0)))
    for dy in range(-NOISE_TILE // 2, NOISE_TILE // 2):
        for dx in range(-NOISE_TILE // 2, NOISE_TILE // 2):
            win = (slice(pad + dy, pad + dy + h), slice(pad + dx, pad + dx + w))
            off = np.abs(np.sum((pp[win] - pos) * m, axis=-1))
            ok = (dp[win] > 0.0) & (off <= tol)
            total += np.where(ok, ap[win], 0.0)
            count += ok
    drawn = (d > 0.0) & has_normal
    out = np.where(drawn, total / np.maximum(count, 1.0), 1.0)
    return np.ascontiguousarray(out[::-1]).astype(np.float32)


def ambient_occlusion(depth: ArrayLike, normal: ArrayLike, camera: Camera, radius: float,
                      settings: SsaoSettings | None = None) -> NDArray[np.float32]:
    """The blurred AO of :class:`leafview.gpu.ssao.SsaoPass` from its depth (h, w) and world-normal
    (h, w, 3 or 4) images (row 0 at the top; depth 0 = background): (h, w) float32 in [0, 1],
    1 = unoccluded, row 0 at the top."""
    d = np.asarray(depth, np.float32)
    if d.ndim != 2 or np.asarray(normal).shape[:2] != d.shape:
        raise ValueError(f"ambient_occlusion: depth (h, w) and normal (h, w, 3) images differ: "
                         f"{d.shape} and {np.asarray(normal).shape}")
    raw = raw_occlusion(d, normal, camera, radius, settings)
    return blur_occlusion(raw, d, normal, camera, radius)
