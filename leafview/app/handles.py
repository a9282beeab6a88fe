"""Direct manipulation (seed 004 sec. 6, Fig. 7): the draggable control points in the viewport.

Handles are the two free axis control points ``a1``, ``a2`` (dragging them sideways skews the
leaf: asymmetry, Fig. 7b) and the three inner silhouette control points of each half, ``s1+`` ..
``s3-`` (outline, Fig. 7c-d). A drag moves the handle within the leaf plane (z of leaf space is
kept); :func:`drag_handle` turns the new leaf-space position back into parameters:

* ``a1``/``a2``: the control point's x and y;
* ``sK±``: v̄_K is the axis parameter whose in-plane normal line passes through the point
  (eq. 3: ``s = A(v̄) + σ x̄s n(v̄) + z̄s ẑ``), kept strictly between its neighbours, and x̄s the
  signed distance along σ·n(v̄), so both halves follow (the model is symmetric in x̄s).

numpy only; the viewport projects these points and calls :func:`pick`.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..model.bezier import bernstein, derivative_points
from ..model.edits import set_silhouette_point
from ..model.leaf import control_polygons
from ..model.params import LeafParams, ParamError

__all__ = ["HANDLE_NAMES", "handle_points", "pick", "drag_handle", "to_leaf_space", "plane_hit",
           "V_GAP"]

HANDLE_NAMES = ("a1", "a2", "s1+", "s2+", "s3+", "s1-", "s2-", "s3-")
V_GAP = 0.01          # smallest spacing kept between consecutive v̄ while dragging
_V_SAMPLES = 2001


def handle_points(params: LeafParams) -> dict[str, NDArray[np.float64]]:
    """Leaf-space positions of every handle (the points drawn in the control polygons)."""
    polys = control_polygons(params)
    out = {"a1": polys["A"][1], "a2": polys["A"][2]}
    for k in range(3):
        out[f"s{k + 1}+"] = polys["S+"][k + 1]
        out[f"s{k + 1}-"] = polys["S-"][k + 1]
    return out


def to_world(params: LeafParams, points: ArrayLike) -> NDArray[np.float64]:
    """Leaf space to world space with the leaf's transform."""
    m = params.transform.matrix()
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return p @ m[:3, :3].T + m[:3, 3]


def to_leaf_space(params: LeafParams, points: ArrayLike) -> NDArray[np.float64]:
    """World space back to leaf space (the inverse of the leaf's transform)."""
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


def drag_plane_normal(params: LeafParams, view_dir: NDArray[np.float64]) -> NDArray[np.float64]:
    """World normal of the plane a handle moves in: the leaf plane, or the plane facing the
    camera when the leaf is seen almost edge-on (then the in-plane motion is its projection)."""
    m = params.transform.matrix()
    n = m[:3, :3] @ np.array([0.0, 0.0, 1.0])
    n /= np.linalg.norm(n)
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


def drag_handle(params: LeafParams, name: str, leaf_point: ArrayLike) -> LeafParams:
    """New parameters with handle ``name`` moved to ``leaf_point`` (leaf space; its z is ignored:
    handles move in the leaf plane). Raises :class:`ParamError` for an unknown handle or a
    position the model cannot take."""
    p = np.asarray(leaf_point, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(p)):
        raise ParamError(name, "the handle left the view (no finite position)")
    sh = params.shape
    if name in ("a1", "a2"):
        from .state import with_field

        old = getattr(sh, name)
        return with_field(params, f"shape.{name}", [float(p[0]), float(p[1]), old[2]])
    if name not in HANDLE_NAMES:
        raise ParamError(name, f"unknown handle (known: {', '.join(HANDLE_NAMES)})")
    k = int(name[1]) - 1
    sigma = 1.0 if name.endswith("+") else -1.0
    vbar = sh.vbar
    lo = (vbar[k - 1] if k > 0 else 0.0) + V_GAP
    hi = (vbar[k + 1] if k < 2 else 1.0) - V_GAP
    if lo >= hi:
        return params
    v = np.linspace(lo, hi, _V_SAMPLES)
    a, n = _axis(params, v)
    rel = p[:2] - a[:, :2]
    # the point lies on the normal line at v̄ where its tangential offset vanishes: take the
    # smallest |offset along the tangent| (ties broken towards the current v̄)
    tangent = np.stack([n[:, 1], -n[:, 0]], axis=-1)
    along = np.abs(np.sum(rel * tangent, axis=-1))
    i = int(np.argmin(along + 1e-6 * np.abs(v - vbar[k])))
    x = float(np.dot(rel[i], n[i, :2])) * sigma
    return set_silhouette_point(params, k, v=float(v[i]), x=x)
