"""Asymmetric leaves (Garg & Leow 2011, Fig. 6) in the shader model: one leaf per side of the midrib.

The shader model Ω is mirror-symmetric about its axis: both halves of the blade share the
silhouette rows (Chaurasia & Beardsley 2017, eqs 3-6). A landmark leaf whose sides differ is therefore drawn as two
one-sided leaves (``shape.half``): the side x > 0 (the u < 0 half, ``half = -1``) is fitted to the
right margin alone, the side x < 0 (``half = +1``) to the left margin mirrored, each with
:func:`leafview.botany.outline_fit.fit_outline`. Both keep the straight axis A(v) = (0, v, 0), and
the surface at u = 0 is A(v) itself (eq. 6 at s = 0), so the two halves meet exactly along the
midrib: no crack, no overlap, nothing to z-fight. The vertex shader spreads the grid over the
drawn half (:func:`leafview.deform.surface.drawn_uv`), so each half keeps the full grid resolution.

A symmetric landmark leaf stays one ordinary leaf.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from leafview.botany.landmarks import LandmarkLeaf, outline_sides
from leafview.botany.outline_fit import DEFAULT_TARGET, fit_outline
from leafview.core.params import LeafParams

__all__ = ["ShaderLeaves", "shader_leaves", "with_half", "RIGHT_HALF", "LEFT_HALF"]

RIGHT_HALF = -1   # x > 0: the u < 0 half of the model
LEFT_HALF = 1     # x < 0: the u >= 0 half


@dataclass(frozen=True)
class ShaderLeaves:
    """The shader-model leaves drawing one landmark leaf and how closely they follow it.

    Attributes
    ----------
    parts : tuple of LeafParams
        One symmetric leaf, or (right half, left half) of an asymmetric one.
    error : float
        Largest Hausdorff distance ÷ leaf length between a drawn margin and its landmark side.
    side_errors : (float, float)
        The same for the right (x > 0) and the left side.
    """

    parts: tuple[LeafParams, ...]
    error: float
    side_errors: tuple[float, float]

    @property
    def asymmetric(self) -> bool:
        return len(self.parts) == 2


def with_half(params: LeafParams, half: int, name: str) -> LeafParams:
    """``params`` drawing only one half (``RIGHT_HALF`` or ``LEFT_HALF``), renamed ``name``."""
    return params.replace(shape=replace(params.shape, half=half), name=name)


def shader_leaves(leaf: LandmarkLeaf, *, n: int = 256, target: float = DEFAULT_TARGET, polish: bool = True,
                  name: str | None = None) -> ShaderLeaves:
    """Fit the shader model to ``leaf``: one leaf if it is symmetric, else one per side.

    Parameters
    ----------
    n
        Margin samples per side.
    target, polish
        As for :func:`~leafview.botany.outline_fit.fit_outline`.
    name
        Name of the result (default: the landmark leaf's); halves get ``" (right)"`` / ``" (left)"``.
    """
    name = leaf.name if name is None else name
    right, left = outline_sides(leaf, n)
    if leaf.is_symmetric:
        fit = fit_outline(right=right, left=left, target=target, polish=polish, name=name)
        er, el = fit.error_sides
        return ShaderLeaves((fit.params,), float(fit.error), (float(er), float(el)))
    mirror = np.array([-1.0, 1.0])
    fr = fit_outline(right=right, target=target, polish=polish)
    fl = fit_outline(right=left * mirror, target=target, polish=polish)
    parts = (with_half(fr.params, RIGHT_HALF, f"{name} (right)" if name else "right"),
             with_half(fl.params, LEFT_HALF, f"{name} (left)" if name else "left"))
    errors = (float(fr.error), float(fl.error))
    return ShaderLeaves(parts, max(errors), errors)
