"""The artist edits of Chaurasia & Beardsley 2017, sec. 6 as pure functions returning new parameters.

Base and apex stay fixed; the axis control points are edited directly, everything else is a
displacement relative to the axis, so every edit acts on both halves of the leaf at once.
"""

from __future__ import annotations

import math
from typing import Literal

from leafview.core.params import LeafParams, ParamError, parse_params

__all__ = ["scale_width", "skew_axis", "set_silhouette_point", "curve_axis", "curve_longitudinal"]


def _shape(params: LeafParams, **changes: object) -> LeafParams:

    data = params.to_dict()
    data["shape"].update({k: list(v) if isinstance(v, tuple) else v for k, v in changes.items()})
    return parse_params(data)  # re-validate: an edit can never produce an invalid leaf


def _finite(name: str, x: float) -> float:
    x = float(x)
    if not math.isfinite(x):
        raise ParamError(name, f"must be a finite number, got {x!r}")
    return x


def scale_width(params: LeafParams, factor: float) -> LeafParams:
    """Width scaling (Fig. 7a): multiply every lateral displacement x̄s_i (and hence F and G,
    which sit at 1/3 and 2/3 of it, eq. 4) by ``factor`` (> 0); a landmark margin
    (:mod:`leafview.core.margin`) has its x scaled the same way."""
    f = _finite("factor", factor)
    if f <= 0:
        raise ParamError("factor", f"width factor must be positive, got {f!r}")
    rows = tuple((v, x * f, z) for v, x, z in params.shape.silhouette)
    out = _shape(params, silhouette=[list(r) for r in rows])
    return out if params.margin is None else out.replace(margin=params.margin.scaled_width(f))


def skew_axis(params: LeafParams, dx1: float, dx2: float | None = None) -> LeafParams:
    """Asymmetry (Fig. 7b): move the axis control points a1, a2 sideways in the leaf plane by
    ``dx1`` and ``dx2`` (default ``dx1``); all other parameters are unchanged."""
    d1 = _finite("dx1", dx1)
    d2 = d1 if dx2 is None else _finite("dx2", dx2)
    a1, a2 = params.shape.a1, params.shape.a2
    return _shape(params, a1=[a1[0] + d1, a1[1], a1[2]], a2=[a2[0] + d2, a2[1], a2[2]])


def set_silhouette_point(params: LeafParams, index: int, *, v: float | None = None,
                         x: float | None = None) -> LeafParams:
    """Silhouette shape (Fig. 7c-d): place silhouette control point ``index`` (0..N-1 for N rows)
    at axis parameter ``v`` and lateral distance ``x`` (either may be left as is). v̄ must stay
    strictly increasing inside (0, 1); a violating edit raises :class:`ParamError`."""
    rows_n = params.shape.rows
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < rows_n:
        raise ParamError("index", f"silhouette control point index must be 0..{rows_n - 1}, got {index!r}")
    rows = [list(r) for r in params.shape.silhouette]
    if v is not None:
        rows[index][0] = _finite("v", v)
    if x is not None:
        rows[index][1] = _finite("x", x)
    return _shape(params, silhouette=rows)


def set_silhouette_row(params: LeafParams, index: int, *, x: float, tilt: float) -> LeafParams:
    """Extended silhouettes: give row ``index`` the lateral distance ``x`` (x̄s) and tilt ``tilt``
    (degrees, -90..90) with its foot v̄ kept, so its control point can reach any point of the
    leaf plane (eq. 3 with tilt). The result is re-validated like every edit."""
    rows_n = params.shape.rows
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < rows_n:
        raise ParamError("index", f"silhouette row index must be 0..{rows_n - 1}, got {index!r}")
    rows = [list(r) for r in params.shape.silhouette]
    rows[index][1] = _finite("x", x)
    tilts = list(params.shape.tilt) if params.shape.tilt else [0.0] * rows_n
    tilts[index] = _finite("tilt", tilt)
    return _shape(params, silhouette=rows, tilt=tilts)


def curve_axis(params: LeafParams, z1: float, z2: float | None = None) -> LeafParams:
    """Cross-section curvature (Fig. 7e): lift the axis control points out of the leaf plane to
    ``z1`` and ``z2`` (default ``z1``); the whole blade follows because it hangs off the axis."""
    h1 = _finite("z1", z1)
    h2 = h1 if z2 is None else _finite("z2", z2)
    a1, a2 = params.shape.a1, params.shape.a2
    return _shape(params, a1=[a1[0], a1[1], h1], a2=[a2[0], a2[1], h2])


def curve_longitudinal(params: LeafParams, curve: Literal["S", "F", "G"], z: float) -> LeafParams:
    """Per-curve curvature (Fig. 7f): set the out-of-plane displacement of all three control
    points of S (z̄s), F (z̄f) or G (z̄g) to ``z``; rolls each half about an axis parallel to y."""
    h = _finite("z", z)
    if curve == "S":
        rows = [[v, x, h] for v, x, _ in params.shape.silhouette]
        return _shape(params, silhouette=rows)
    if curve in ("F", "G"):
        return _shape(params, **{f"z{curve.lower()}": [h] * params.shape.rows})  # one per silhouette row
    raise ParamError("curve", f"expected 'S', 'F' or 'G', got {curve!r}")


