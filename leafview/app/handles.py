"""Direct manipulation (Chaurasia & Beardsley 2017, sec. 6, Fig. 7): the draggable control points in the viewport.

Handles are the two free axis control points ``a1``, ``a2`` (dragging them sideways skews the
leaf: asymmetry, Fig. 7b) and the N inner silhouette control points of each half, ``s1+`` ..
``sN-`` (outline, Fig. 7c-d; N = 3 for the paper's quartic, up to 7 for an extended silhouette).
A drag moves the handle within the leaf plane (z of leaf space is kept); :func:`drag_handle` turns
the new leaf-space position back into parameters:

* ``a1``/``a2``: the control point's x and y;
* ``sK±`` of the paper's quartic: v̄_K is the axis parameter whose normal line passes through the
  point (eq. 3: ``s = A(v̄) + σ x̄s n(v̄) + z̄s ẑ``), kept strictly between its neighbours, and x̄s
  the signed distance along σ·n(v̄), so both halves follow (the model is symmetric in x̄s);
* ``sK±`` of an extended silhouette (more rows or tilted rows): the foot A(v̄_K) stays and the
  row's x̄s and tilt φ_K follow the point; the row leaves A(v̄) in the direction
  ``σ cos φ n(v̄) - sin φ t(v̄)``, so the other half mirrors the change.

When the leaf bends (``params.bending``), handles and control polygons are shown bent with the
midrib (:class:`LeafFrame`), and a drag is mapped back through the bend at the handle's axis
parameter, so the handle follows the cursor on the bent blade too.

numpy only; the viewport projects these points and calls :func:`pick`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.app.state import with_field
from leafview.core.bezier import bernstein, derivative_points
from leafview.core.edits import set_silhouette_point, set_silhouette_row
from leafview.core.params import LeafParams, ParamError
from leafview.deform.beam import bend_profile, rotation, sample_clamped
from leafview.deform.surface import control_polygons

__all__ = ["HANDLE_NAMES", "handle_names", "handle_points", "handle_parameters", "LeafFrame", "pick", "drag_handle",
           "to_world", "to_leaf_space", "plane_hit", "drag_plane_normal", "V_GAP"]

HANDLE_NAMES = ("a1", "a2", "s1+", "s2+", "s3+", "s1-", "s2-", "s3-")   # the paper's quartic (N = 3)
V_GAP = 0.01          # smallest spacing kept between consecutive v̄ while dragging
_V_SAMPLES = 2001


def handle_names(params: LeafParams) -> tuple[str, ...]:
    """``a1``, ``a2``, then ``s1+`` .. ``sN+`` and ``s1-`` .. ``sN-`` for N silhouette rows."""
    rows = range(1, params.shape.rows + 1)
    return ("a1", "a2", *(f"s{k}+" for k in rows), *(f"s{k}-" for k in rows))


def handle_points(params: LeafParams) -> dict[str, NDArray[np.float64]]:
    """Leaf-space positions of every handle (the points drawn in the control polygons)."""
    polys = control_polygons(params)
    out = {"a1": polys["A"][1], "a2": polys["A"][2]}
    for k in range(params.shape.rows):
        out[f"s{k + 1}+"] = polys["S+"][k + 1]
        out[f"s{k + 1}-"] = polys["S-"][k + 1]
    return out


def handle_parameters(params: LeafParams) -> dict[str, float]:
    """The axis parameter v each handle belongs to (for the midrib bend): a1, a2 at 1/3, 2/3
    (their Greville abscissae), sK± at v̄_K (they are placed relative to A(v̄_K), eq. 3)."""
    out = {"a1": 1.0 / 3.0, "a2": 2.0 / 3.0}
    for k, v in enumerate(params.shape.vbar):
        out[f"s{k + 1}+"] = out[f"s{k + 1}-"] = float(v)
    return out


@lru_cache(maxsize=4)
def _bend_profile(params: LeafParams) -> Any:
    """The midrib bend of ``params`` (``leafview.deform.beam``), or None when it does not bend."""
    bending = getattr(params, "bending", None)
    if bending is None or not getattr(bending, "active", False):
        return None
    profile = bend_profile(params)
    return None if profile.identity else profile


class LeafFrame:
    """Maps overlay points between leaf space (the unbent model of eqs 1-6, where control points
    live) and world space: the midrib bend and twist of ``leafview.deform.surface`` (``p' = A(v) +
    Δ(v) + R(v)(p - A(v))`` at the point's axis parameter ``v``), then the leaf's transform."""

    def __init__(self, params: LeafParams) -> None:
        self.matrix = params.transform.matrix()
        self.inverse = np.linalg.inv(self.matrix)
        self.profile = _bend_profile(params)
        self.axis_points = params.shape.axis_points()

    def _bend(self, v: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """A(v), Δ(v) and R(v) for points at axis parameters ``v``."""

        vv = np.clip(np.atleast_1d(np.asarray(v, np.float64)), 0.0, 1.0)
        a = bernstein(3, vv) @ self.axis_points
        prof = self.profile
        phi, _ = sample_clamped(prof.phi, vv)
        delta, _ = sample_clamped(prof.delta, vv)
        r = rotation(prof.axis, phi) @ rotation([0.0, 1.0, 0.0], prof.twist * vv)
        return a, delta, r

    def to_world(self, points: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
        """Leaf-space ``points`` (N, 3) at axis parameters ``v`` (N,) to world space."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if self.profile is not None:
            a, delta, r = self._bend(v)
            p = a + delta + np.einsum("nij,nj->ni", r, p - a)
        return p @ self.matrix[:3, :3].T + self.matrix[:3, 3]

    def to_leaf(self, points: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
        """The inverse of :meth:`to_world` (for the same ``v``)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        p = p @ self.inverse[:3, :3].T + self.inverse[:3, 3]
        if self.profile is not None:
            a, delta, r = self._bend(v)
            p = a + np.einsum("nji,nj->ni", r, p - a - delta)
        return p

    def plane_normal(self, v: float) -> NDArray[np.float64]:
        """World normal of the (bent) leaf plane at axis parameter ``v``."""
        n = np.array([0.0, 0.0, 1.0])
        if self.profile is not None:
            n = self._bend([v])[2][0] @ n
        n = self.matrix[:3, :3] @ n
        return n / np.linalg.norm(n)


def to_world(params: LeafParams, points: ArrayLike) -> NDArray[np.float64]:
    """Leaf space to world space with the leaf's transform (no bend: for surface points that
    already include it, such as :func:`leafview.deform.surface.tessellate` vertices)."""
    m = params.transform.matrix()
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return p @ m[:3, :3].T + m[:3, 3]


def to_leaf_space(params: LeafParams, points: ArrayLike) -> NDArray[np.float64]:
    """World space back to leaf space (the inverse of the leaf's transform, no bend)."""
    inv = np.linalg.inv(params.transform.matrix())
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return p @ inv[:3, :3].T + inv[:3, 3]


def pick(screen: NDArray[np.float64], names: Iterable[str], x: float, y: float,
         radius: float = 10.0) -> str | None:
    """The handle whose projected position ``screen`` (N, 2) is nearest to (x, y) within
    ``radius`` pixels, or None."""
    names = list(names)
    if not names:
        return None
    d = np.hypot(screen[:, 0] - x, screen[:, 1] - y)
    d = np.where(np.isfinite(d), d, np.inf)
    i = int(np.argmin(d))
    return names[i] if d[i] <= radius else None


def plane_hit(origin: NDArray[np.float64], direction: NDArray[np.float64], point: NDArray[np.float64],
              normal: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """Where the ray meets the plane through ``point`` with ``normal``; None when parallel or
    behind the eye."""
    denom = float(np.dot(direction, normal))
    if abs(denom) < 1e-9:
        return None
    t = float(np.dot(point - origin, normal)) / denom
    return None if t <= 0 else origin + t * direction


def drag_plane_normal(frame: LeafFrame, v: float, view_dir: NDArray[np.float64]) -> NDArray[np.float64]:
    """World normal of the plane a handle at axis parameter ``v`` moves in: the (bent) leaf
    plane there, or the plane facing the camera when that is seen almost edge-on."""
    n = frame.plane_normal(v)
    if abs(float(np.dot(n, view_dir))) < 0.15:
        return -view_dir / np.linalg.norm(view_dir)
    return n


def _axis(params: LeafParams, v: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A(v) and the unit in-plane normal n(v) of eq. 2."""
    pa = params.shape.axis_points()
    a = bernstein(3, v) @ pa
    d = bernstein(2, v) @ derivative_points(pa)
    m = np.stack([-d[:, 1], d[:, 0], np.zeros_like(v)], axis=-1)
    return a, m / np.linalg.norm(m, axis=-1, keepdims=True)


def _drag_tilted_row(params: LeafParams, k: int, sigma: float, p: NDArray[np.float64]) -> LeafParams:
    """Extended silhouettes: the foot A(v̄_k) stays, the row's length x̄s and tilt φ follow the
    point (polar coordinates in the frame σ n(v̄), -t(v̄) of eq. 3 with tilt; φ kept in
    [-90°, 90°] by letting x̄s change sign). Fitted extended silhouettes often place feet 1e-3
    apart, so moving the foot would jam against its neighbours."""
    a, n = _axis(params, np.array([params.shape.vbar[k]]))
    t = np.array([n[0, 1], -n[0, 0]])
    rel = p[:2] - a[0, :2]
    c, s = float(np.dot(rel, sigma * n[0, :2])), float(np.dot(rel, -t))
    r, phi = math.hypot(c, s), math.degrees(math.atan2(s, c))
    if phi > 90.0:
        r, phi = -r, phi - 180.0
    elif phi < -90.0:
        r, phi = -r, phi + 180.0
    return set_silhouette_row(params, k, x=r, tilt=phi)


def drag_handle(params: LeafParams, name: str, leaf_point: ArrayLike) -> LeafParams:
    """New parameters with handle ``name`` moved to ``leaf_point`` (leaf space; its z is ignored:
    handles move in the leaf plane). Raises :class:`ParamError` for an unknown handle or a
    position the model cannot take."""
    p = np.asarray(leaf_point, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(p)):
        raise ParamError(name, "the handle left the view (no finite position)")
    sh = params.shape
    if name in ("a1", "a2"):

        old = getattr(sh, name)
        return with_field(params, f"shape.{name}", [float(p[0]), float(p[1]), old[2]])
    names = handle_names(params)
    if name not in names:
        raise ParamError(name, f"unknown handle (known: {', '.join(names)})")
    k = int(name[1:-1]) - 1
    sigma = 1.0 if name.endswith("+") else -1.0
    if sh.extended:
        return _drag_tilted_row(params, k, sigma, p)
    vbar = sh.vbar
    # keep V_GAP to the neighbours, or the spacing the leaf already has where that is smaller
    # (fitted silhouettes may place feet 1e-3 apart)
    below = vbar[k - 1] if k > 0 else 0.0
    above = vbar[k + 1] if k < sh.rows - 1 else 1.0
    lo = below + min(V_GAP, 0.5 * (vbar[k] - below))
    hi = above - min(V_GAP, 0.5 * (above - vbar[k]))
    if lo >= hi:
        return params
    phi = float(sh.phi[k]) if sh.extended else 0.0
    v = np.linspace(lo, hi, _V_SAMPLES)
    a, n = _axis(params, v)
    rel = p[:2] - a[:, :2]
    tangent = np.stack([n[:, 1], -n[:, 0]], axis=-1)           # unit axis tangent t(v)
    direction = sigma * np.cos(phi) * n[:, :2] - np.sin(phi) * tangent
    across = np.stack([-direction[:, 1], direction[:, 0]], axis=-1)
    # the point lies on the row line at v̄ where its offset across that line vanishes: take the
    # smallest |offset| (ties broken towards the current v̄)
    signed = np.sum(rel * across, axis=-1)
    i = int(np.argmin(np.abs(signed) + 1e-6 * np.abs(v - vbar[k])))
    vi = float(v[i])
    # between samples: the zero of the linear interpolation of the signed offset (steep or nearly
    # axial tilted row lines move far along themselves per sample)
    for j in (i - 1, i):
        if 0 <= j < len(v) - 1 and signed[j] * signed[j + 1] < 0.0:
            vi = float(v[j] + (v[j + 1] - v[j]) * signed[j] / (signed[j] - signed[j + 1]))
            break
    a1, n1 = _axis(params, np.array([vi]))
    t1 = np.array([n1[0, 1], -n1[0, 0]])
    d1 = sigma * np.cos(phi) * n1[0, :2] - np.sin(phi) * t1
    x = float(np.dot(p[:2] - a1[0, :2], d1))
    return set_silhouette_point(params, k, v=vi, x=x)
