"""Where a leaf's venation mesh (:mod:`leafview.export.cdt`) is triangulated: a plane in which every
point's (u, v) can be recovered, and the outline of the blade in it.

Two planes:

* ``"flat"`` (the default): the leaf plane, (x, y) of the flat blade (Chaurasia & Beardsley 2017,
  eqs 1-6, with the jitter of sec. 6, without ripple or bending; :func:`leafview.core.blade.blade_partials`).
  Ripples and the bend are nearly isometric, so angles in this plane are the angles on the
  leaf. Triangle's own vertices are mapped back by Newton's method on each side of the midrib
  (the parameterisation has a crease there), to rounding
  (:attr:`leafview.export.cdt.CdtMesh.inverse_error`, about 1e-15 leaf lengths).
* ``"vein"``: vein space ``q = (u w(v), v)`` (:func:`leafview.botany.vein_field.vein_space`),
  inverted in closed form, ``u = q_x / w(v)``. The blade's parameterisation is strongly sheared
  near the midrib of narrow leaves (the cross-sections leave the axis at 120-170° to it), so its
  angles are not the leaf's; it is the fallback for a blade whose flat map folds (a sign change
  of its Jacobian, or an outline that crosses itself), where the leaf plane has no inverse.

The outline is one loop: base (0, 0), the margin u = +1 with increasing v, the apex (0, 1) and
the margin u = -1 back down (a one-sided leaf, ``shape.half = ±1``: its margin and the midrib
u = 0), sampled at :data:`OUTLINE_NODES` values of v, the jitter's corners (v = k / density) and
the ends of the veins that reach it. Vertices on the outline get u = ±1 (0 on the midrib edge
and at base and apex) exactly.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from leafview.botany.vein_field import HALFWIDTH_SAMPLES, vein_space
from leafview.core.blade import blade_partials
from leafview.core.params import LeafParams
from leafview.errors import UsageError

__all__ = ["MAX_JITTER_CORNERS", "OUTLINE_NODES", "PLANES", "Plane", "leaf_plane", "outline"]

PLANES = ("flat", "vein")
OUTLINE_NODES = 129            # v samples of each side of the outline (Triangle splits them further)
MAX_JITTER_CORNERS = 1024      # the jitter's corners join the outline up to this many teeth
_NEWTON_STEPS = 40
_GUESS_GRID = (33, 257)        # (u, v) samples per side for Newton's first guess


def _u_range(params: LeafParams) -> tuple[float, float]:
    half = params.shape.half
    return (-1.0, 1.0) if not half else ((0.0, 1.0) if half > 0 else (-1.0, 0.0))


class Plane(ABC):
    """Where the leaf is triangulated: ``forward`` maps (u, v) (N, 2) to the plane, ``inverse``
    maps back (and returns the largest residual, 0 for a closed-form inverse)."""

    name = ""

    def __init__(self, params: LeafParams) -> None:
        self.params = params
        self.u_range = _u_range(params)

    @abstractmethod
    def forward(self, uv: NDArray[np.float64]) -> NDArray[np.float64]: ...

    @abstractmethod
    def inverse(self, p: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]: ...


class _VeinPlane(Plane):
    """Vein space, q = (u w(v), v)."""

    name = "vein"

    def forward(self, uv: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(vein_space(self.params, np.asarray(uv, np.float64).reshape(-1, 2)), np.float64)

    def inverse(self, p: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
        v = np.clip(p[:, 1], 0.0, 1.0)
        w = self.forward(np.stack([np.ones_like(v), v], axis=1))[:, 0]
        u = np.divide(p[:, 0], w, out=np.zeros_like(w), where=w > 1e-12)
        return np.stack([np.clip(u, *self.u_range), v], axis=1), 0.0


class _FlatPlane(Plane):
    """The leaf plane: (x, y) of the flat blade, inverted by Newton's method on each side of the
    midrib (the parameterisation has a crease there) from the nearest of a grid of samples."""

    name = "flat"

    def forward(self, uv: NDArray[np.float64]) -> NDArray[np.float64]:
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        return blade_partials(self.params, uv[:, 0], uv[:, 1])[0].L[:, :2]

    def _side(self, p: NDArray[np.float64], sign: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        nu, nv = _GUESS_GRID        # v crowded towards base and apex, without them (no u there)
        uu, vv = np.meshgrid(sign * np.linspace(0.0, 1.0, nu), 0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, nv + 2)[1:-1]))
        grid = np.stack([uu.ravel(), vv.ravel()], axis=1)
        _, k = cKDTree(self.forward(grid)).query(p)
        uv = grid[k]
        lo, hi = (0.0, 1.0) if sign > 0 else (-1.0, -1e-300)
        for _ in range(_NEWTON_STEPS):
            part = blade_partials(self.params, uv[:, 0], uv[:, 1])[0]
            f = part.L[:, :2] - p
            a, b, c, d = part.Lu[:, 0], part.Lv[:, 0], part.Lu[:, 1], part.Lv[:, 1]
            det = a * d - b * c
            ok = np.abs(det) > 1e-14
            safe = np.where(ok, det, 1.0)
            du = np.where(ok, (d * f[:, 0] - b * f[:, 1]) / safe, 0.0)
            dv = np.where(ok, (a * f[:, 1] - c * f[:, 0]) / safe, 0.0)
            uv = np.stack([np.clip(uv[:, 0] - np.clip(du, -0.25, 0.25), lo, hi),
                           np.clip(uv[:, 1] - np.clip(dv, -0.05, 0.05), 0.0, 1.0)], axis=1)
        return uv, np.linalg.norm(self.forward(uv) - p, axis=1)

    def inverse(self, p: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
        if not len(p):
            return np.zeros((0, 2)), 0.0
        sides = [s for s in (1.0, -1.0) if self.u_range[0] < 0.0 or s > 0] if self.u_range[1] > 0 else [-1.0]
        found = [self._side(p, s) for s in sides]
        if len(found) == 1:
            return found[0][0], float(found[0][1].max())
        (uv_p, r_p), (uv_m, r_m) = found
        pick = r_m < r_p
        uv = np.where(pick[:, None], uv_m, uv_p)
        return uv, float(np.where(pick, r_m, r_p).max())

    def folds(self) -> bool:
        """Whether the flat map turns over somewhere (its Jacobian changes sign off the tips)."""
        lo, hi = self.u_range
        uu, vv = np.meshgrid(np.linspace(lo, hi, 65), np.linspace(0.0, 1.0, 257)[1:-1])
        part = blade_partials(self.params, uu.ravel(), vv.ravel())[0]
        det = part.Lu[:, 0] * part.Lv[:, 1] - part.Lu[:, 1] * part.Lv[:, 0]
        return not (np.all(det < 0.0) or np.all(det > 0.0))


def _crosses_itself(loop: NDArray[np.float64]) -> bool:
    """Whether the closed polygon ``loop`` (N, 2) has two non-adjacent edges that intersect."""
    a, b = loop, np.roll(loop, -1, axis=0)
    n = len(loop)
    i, j = np.triu_indices(n, 2)
    keep = ~((i == 0) & (j == n - 1))
    i, j = i[keep], j[keep]

    def orient(p: NDArray[np.float64], q: NDArray[np.float64], r: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.sign((q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0]))

    hit = ((orient(a[i], b[i], a[j]) * orient(a[i], b[i], b[j]) < 0)
           & (orient(a[j], b[j], a[i]) * orient(a[j], b[j], b[i]) < 0))
    return bool(hit.any())


def leaf_plane(params: LeafParams, plane: str = "auto") -> Plane:
    """The plane ``params`` is triangulated in: ``"flat"``, ``"vein"``, or ``"auto"`` (flat
    unless the flat map folds or its outline crosses itself)."""
    if plane not in (*PLANES, "auto"):
        raise UsageError(f"unknown plane {plane!r} (use {', '.join(PLANES)} or auto)")
    if plane == "vein":
        return _VeinPlane(params)
    flat = _FlatPlane(params)
    if plane == "flat":
        return flat
    if flat.folds() or _crosses_itself(flat.forward(outline(flat, {side: [] for side in flat.u_range}, 1e-4))):
        return _VeinPlane(params)
    return flat


def _outline_v(params: LeafParams, extra: list[float]) -> NDArray[np.float64]:
    """The v of one side's outline vertices, 0 and 1 excluded."""
    v = [np.linspace(0.0, 1.0, OUTLINE_NODES), np.linspace(0.0, 1.0, HALFWIDTH_SAMPLES), np.asarray(extra)]
    jit = params.jitter
    if jit.enabled and jit.amplitude > 0.0 and jit.density <= MAX_JITTER_CORNERS:
        v.append(np.arange(1, int(np.ceil(jit.density))) / jit.density)
    out = np.unique(np.concatenate(v))
    out = out[(out > 0.0) & (out < 1.0)]
    return out[np.concatenate([[True], np.diff(out) > 1e-7])]


def _refine(plane: Plane, side: float, v: NDArray[np.float64], tol: float) -> NDArray[np.float64]:
    """``v`` (increasing, 0 and 1 excluded) with midpoints added until every chord of the side
    ``u = side`` between consecutive vertices lies within ``tol`` of the curve (in the plane)."""
    v = np.concatenate([[0.0], v, [1.0]])
    for _ in range(16):
        mid = 0.5 * (v[:-1] + v[1:])
        p = plane.forward(np.stack([np.where((v == 0.0) | (v == 1.0), 0.0, side), v], axis=1))
        pm = plane.forward(np.stack([np.full_like(mid, side), mid], axis=1))
        a, d = p[:-1], p[1:] - p[:-1]
        t = np.clip(np.einsum("ij,ij->i", pm - a, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300), 0.0, 1.0)
        far = np.linalg.norm(pm - a - t[:, None] * d, axis=1) > tol
        if not far.any():
            break
        v = np.sort(np.concatenate([v, mid[far]]))
    return v[1:-1]


def outline(plane: Plane, extra: dict[float, list[float]], tol: float) -> NDArray[np.float64]:
    """The outline loop in (u, v): base, side u = hi upwards, apex, side u = lo downwards, each
    side within ``tol`` of the curve."""
    lo, hi = plane.u_range
    up = _refine(plane, hi, _outline_v(plane.params, extra[hi]), tol)
    down = _refine(plane, lo, _outline_v(plane.params, extra[lo]), tol)[::-1]
    return np.concatenate([[[0.0, 0.0]], np.stack([np.full_like(up, hi), up], axis=1), [[0.0, 1.0]],
                           np.stack([np.full_like(down, lo), down], axis=1)])
