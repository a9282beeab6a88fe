"""What veins and leaf tissue do to a leaf's colour: the numpy twin of ``shaders/leaf_veins.glsl``.

A leaf whose venation is enabled (``LeafParams.venation``) is shaded from its vein field
(:func:`leafview.botany.vein_field.vein_field`: per texel the distance ``d`` to the nearest vein's
centre line, that vein's order and width, in leaf lengths) read at the fragment's (u, v) through
:func:`leafview.core.texture.texture_st`, bilinearly, at level 0. This module holds the colour
part, the one place for its constants (``leaf_veins.glsl`` receives them as generated defines,
:func:`glsl_constants`):

* **Skin** (Hong 2005, ch. 8: the lamina is not one flat colour). A subtle chlorophyll gradient,
  lighter at the base and along the midrib, darker toward the apex and the margin
  (:func:`chlorophyll`), and a yellowish margin tint where ``|u| -> 1`` (:func:`margin_tint`).
  The two sides differ: the upper (adaxial, sunny) side keeps its darker material colour and gets
  a narrow gloss in the shader, the lower (abaxial, shadow) side its paler colour and a broad, dim
  sheen (lighting only; nothing of it is in the unlit albedo).
* **Vein strength** (:func:`vein_strength`): the field's nearest vein (R distance, G order, B
  width) and its nearest major vein (A: distance to the nearest vein of order ≤ 2, whose width is
  taken as the secondaries', ``midrib_width · width_ratio``), each weighed by order, the larger of
  the two: near a secondary the tertiaries that meet it do not cut it off.
* **Vein colour.** Veins are lighter and yellower than the lamina (:data:`VEIN_GAIN`,
  :data:`VEIN_LIFT`), by ``venation.contrast`` times an order weight (midrib and primaries 1,
  secondaries 0.7, tertiaries 0.4; :func:`order_weight`, linear in the order so that a filtered
  order weighs as the filtered weights would), weaker on the lower side
  (:data:`VEIN_BACK_STRENGTH`). Coverage (:func:`vein_coverage`) is antialiased over the pixel's
  footprint of ``d`` (GLSL ``fwidth``): a vein narrower than a pixel is drawn a pixel wide and
  correspondingly fainter instead of breaking up.

The relief (a normal perturbed from the vein height profile :func:`vein_height`, Mikkelsen 2010's
surface gradient from screen-space derivatives) and the reduced transmission along veins in back
light (:data:`VEIN_OPACITY`) act on lighting only; their profile functions are here too.

Textured leaves (a photograph) take no vein colour and no skin: the photograph has both.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.params import LeafParams
from leafview.core.texture import bilinear, texture_st

__all__ = ["VEIN_GAIN", "VEIN_LIFT", "VEIN_BACK_STRENGTH", "VEIN_OPACITY", "ORDER_WEIGHT_SLOPE",
           "ORDER_WEIGHT_MIN", "CHLOROPHYLL_GAIN", "CHLOROPHYLL_V", "MARGIN_START", "MARGIN_GAIN", "MARGIN_LIFT",
           "MARGIN_STRENGTH", "RELIEF_BACK", "VEIN_BUMP_PIXELS", "VEIN_BUMP_NONE", "VEIN_BUMP_FULL", "VEIN_LOD_NONE",
           "VEIN_LOD_FULL", "order_weight", "vein_coverage", "vein_height", "chlorophyll",
           "margin_tint", "skin_albedo", "vein_strength", "major_width", "vein_albedo", "sample_field", "glsl_constants",
           "without_veins"]

VEIN_GAIN = (1.22, 1.28, 0.78)
"""Per-channel gain of the vein colour over the lamina's (lighter, yellower: less blue)."""
VEIN_LIFT = (0.05, 0.06, 0.0)
"""Added to the vein colour (linear)."""
VEIN_BACK_STRENGTH = 0.6
"""Vein colour strength on the lower side relative to the upper."""
VEIN_OPACITY = 0.6
"""Fraction of the diffuse transmission a vein (order weight 1, full coverage) blocks."""
ORDER_WEIGHT_SLOPE = 0.3
"""Order weight ``1 - slope * (order - 1)``, ..."""
ORDER_WEIGHT_MIN = 0.4
"""... at least this (tertiaries and finer)."""
CHLOROPHYLL_GAIN = 0.12
"""Albedo factor ``1 + gain * (0.5 - t)`` with ``t`` from 0 (base, midrib) to 1 (apex, margin)."""
CHLOROPHYLL_V = 0.6
"""Share of ``v`` in ``t`` (the rest is ``|u|``)."""
MARGIN_START = 0.85
"""``|u|`` where the margin tint begins (full at 1)."""
MARGIN_GAIN = (1.15, 1.08, 0.6)
MARGIN_LIFT = (0.03, 0.02, 0.0)
MARGIN_STRENGTH = 0.35
RELIEF_BACK = 1.5
"""Vein relief on the lower side relative to the upper (veins stand out below)."""
VEIN_BUMP_PIXELS = 2.0
"""A vein's bump spreads over at least this many pixel footprints (same height, gentler slope):
a narrower bump would alias into dots, the derivatives being taken per 2×2 pixel quad."""
VEIN_LOD_NONE = 0.25
VEIN_LOD_FULL = 0.75
"""A triangle shows its veins in full while its major veins are at least ``VEIN_LOD_FULL`` pixels
wide, fading out to none at ``VEIN_LOD_NONE`` (they would average into the lamina's colour):
``vein_detail`` of ``leaf_veins.glsl``; the unlit twin is for veins at full detail."""
VEIN_BUMP_NONE = 0.5
VEIN_BUMP_FULL = 2.0
"""The relief fades in between these half widths of a vein in pixel footprints (none below the
first: the slopes of a vein narrower than a pixel average out over it)."""


def _vec(x: tuple[float, ...]) -> NDArray[np.float64]:
    return np.asarray(x, np.float64)


def _smoothstep(e0: ArrayLike, e1: ArrayLike, x: ArrayLike) -> NDArray[np.float64]:
    """GLSL ``smoothstep`` (e0 < e1)."""
    e0, e1, x = (np.asarray(a, np.float64) for a in (e0, e1, x))
    t = np.clip((x - e0) / np.maximum(e1 - e0, 1e-30), 0.0, 1.0)
    out: NDArray[np.float64] = t * t * (3.0 - 2.0 * t)
    return out


def order_weight(order: ArrayLike) -> NDArray[np.float64]:
    """Strength of a vein of (filtered) ``order``: 1 for order 1, 0.7 for 2, 0.4 for 3 and finer."""
    o = np.asarray(order, np.float64)
    return np.clip(1.0 - ORDER_WEIGHT_SLOPE * (o - 1.0), ORDER_WEIGHT_MIN, 1.0)


def vein_coverage(d: ArrayLike, width: ArrayLike, footprint: ArrayLike) -> NDArray[np.float64]:
    """Antialiased coverage in [0, 1] of a vein of full ``width`` at distance ``d`` from its centre
    line, for a pixel whose footprint in ``d`` is ``footprint`` (GLSL ``fwidth(d)``): the edge
    ramps over one footprint; a vein narrower than that is drawn that wide and fainter by
    ``half width / (footprint / 2)``."""
    d = np.asarray(d, np.float64)
    r = 0.5 * np.asarray(width, np.float64)
    aa = 0.5 * np.asarray(footprint, np.float64)
    hw = np.maximum(np.maximum(r, aa), 1e-7)
    out: NDArray[np.float64] = (1.0 - _smoothstep(hw - aa, hw + aa, d)) * (r / hw)
    return out


def vein_height(d: ArrayLike, width: ArrayLike, relief: ArrayLike, footprint: ArrayLike = 0.0) -> NDArray[np.float64]:
    """Height (leaf lengths) of a vein of full ``width`` at distance ``d``: ``relief`` times its half
    width times ``(1 - x²)²``, ``x = d / max(half width, VEIN_BUMP_PIXELS · footprint)`` (flat joins
    with the lamina at the edge; spread over a few pixels when the vein is narrower), faded out as
    the half width falls from :data:`VEIN_BUMP_FULL` to :data:`VEIN_BUMP_NONE` footprints (no
    fading at ``footprint`` 0)."""
    r = np.maximum(0.5 * np.asarray(width, np.float64), 1e-7)
    fw = np.asarray(footprint, np.float64)
    spread = np.maximum(r, VEIN_BUMP_PIXELS * fw)
    x = np.clip(np.asarray(d, np.float64) / spread, 0.0, 1.0)
    fade = np.clip((r / np.maximum(fw, 1e-12) - VEIN_BUMP_NONE) / (VEIN_BUMP_FULL - VEIN_BUMP_NONE), 0.0, 1.0)
    out: NDArray[np.float64] = np.asarray(relief, np.float64) * r * (1.0 - x * x) ** 2 * fade
    return out


def chlorophyll(u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
    """Albedo factor of the chlorophyll gradient at (u, v): ``1 + CHLOROPHYLL_GAIN · (0.5 - t)``,
    ``t = CHLOROPHYLL_V · v + (1 - CHLOROPHYLL_V) · |u|`` (lighter at the base and midrib)."""
    t = CHLOROPHYLL_V * np.asarray(v, np.float64) + (1.0 - CHLOROPHYLL_V) * np.abs(np.asarray(u, np.float64))
    out: NDArray[np.float64] = 1.0 + CHLOROPHYLL_GAIN * (0.5 - t)
    return out


def margin_tint(albedo: ArrayLike, u: ArrayLike) -> NDArray[np.float64]:
    """``albedo`` (..., 3) tinted toward yellow near the margin (``|u| -> 1``)."""
    a = np.asarray(albedo, np.float64)
    m = MARGIN_STRENGTH * _smoothstep(MARGIN_START, 1.0, np.abs(np.asarray(u, np.float64)))[..., None]
    out: NDArray[np.float64] = a + (a * _vec(MARGIN_GAIN) + _vec(MARGIN_LIFT) - a) * m
    return out


def skin_albedo(base: ArrayLike, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
    """The lamina's albedo (..., 3) at (u, v) from its material colour ``base`` (linear rgb of the
    visible side): chlorophyll gradient, then margin tint."""
    return margin_tint(np.asarray(base, np.float64) * chlorophyll(u, v)[..., None], u)


def major_width(venation: Any) -> float:
    """Width (leaf lengths) the shading gives the nearest major vein of the field's A channel: the
    secondaries', ``midrib_width · width_ratio`` of ``venation``."""
    return float(venation.midrib_width) * float(venation.width_ratio)


def vein_strength(texel: ArrayLike, major: float, footprint: ArrayLike) -> NDArray[np.float64]:
    """Order-weighted antialiased vein coverage in [0, 1] of a field ``texel`` (..., 4): the larger
    of the nearest vein's (R, G, B) and the nearest major vein's (A, order 2, width ``major``).
    ``footprint`` (..., 2): the pixel's footprints in R and in A (GLSL ``fwidth``)."""
    f = np.asarray(texel, np.float64)
    fw = np.asarray(footprint, np.float64)
    near = order_weight(f[..., 1]) * vein_coverage(f[..., 0], f[..., 2], fw[..., 0])
    main = order_weight(2.0) * vein_coverage(f[..., 3], major, fw[..., 1])
    return np.maximum(near, main)


def vein_albedo(base: ArrayLike, strength: ArrayLike, u: ArrayLike, v: ArrayLike, contrast: float, *,
                front: bool = True) -> NDArray[np.float64]:
    """The unlit colour (..., 3) of an untextured veined leaf's side: :func:`skin_albedo` of
    ``base``, then the vein colour by ``contrast`` × ``strength`` (:func:`vein_strength`),
    × :data:`VEIN_BACK_STRENGTH` on the lower side."""
    lamina = skin_albedo(base, u, v)
    k = np.clip(contrast * np.asarray(strength, np.float64) * (1.0 if front else VEIN_BACK_STRENGTH), 0.0, 1.0)
    vein = np.minimum(lamina * _vec(VEIN_GAIN) + _vec(VEIN_LIFT), 1.0)
    out: NDArray[np.float64] = lamina + (vein - lamina) * k[..., None]
    return out


def sample_field(field: ArrayLike, u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
    """GL's linear filtering of a vein field (size, size, C) at (u, v), level 0, clamped to the
    edge: texel (i, j) (column, row) centred at ``((i + 0.5) / w, (j + 0.5) / h)`` in the
    (s, t) of :func:`~leafview.core.texture.texture_st`, row 0 at t = 0 (the apex)."""
    return bilinear(field, *texture_st(u, v))


def glsl_constants() -> str:
    """The constants above as GLSL (``generated/vein_shading.glsl``, included by ``leaf_veins.glsl``)."""
    def vec3(x: tuple[float, ...]) -> str:
        return f"vec3({', '.join(repr(float(c)) for c in x)})"

    scalars = {"VEIN_BACK_STRENGTH": VEIN_BACK_STRENGTH, "VEIN_OPACITY": VEIN_OPACITY,
               "ORDER_WEIGHT_SLOPE": ORDER_WEIGHT_SLOPE, "ORDER_WEIGHT_MIN": ORDER_WEIGHT_MIN,
               "CHLOROPHYLL_GAIN": CHLOROPHYLL_GAIN, "CHLOROPHYLL_V": CHLOROPHYLL_V,
               "MARGIN_START": MARGIN_START, "MARGIN_STRENGTH": MARGIN_STRENGTH, "RELIEF_BACK": RELIEF_BACK,
               "VEIN_BUMP_PIXELS": VEIN_BUMP_PIXELS, "VEIN_BUMP_NONE": VEIN_BUMP_NONE,
               "VEIN_BUMP_FULL": VEIN_BUMP_FULL, "VEIN_LOD_NONE": VEIN_LOD_NONE, "VEIN_LOD_FULL": VEIN_LOD_FULL}
    lines = ["// generated from leafview/botany/vein_shading.py (the numpy twin's constants)"]
    lines += [f"const float {name} = {float(value)!r};" for name, value in scalars.items()]
    lines += [f"const vec3 {name} = {vec3(value)};" for name, value in
              (("VEIN_GAIN", VEIN_GAIN), ("VEIN_LIFT", VEIN_LIFT), ("MARGIN_GAIN", MARGIN_GAIN),
               ("MARGIN_LIFT", MARGIN_LIFT))]
    return "\n".join(lines) + "\n"


def without_veins(leaves: Iterable[LeafParams]) -> list[LeafParams]:
    """``leaves`` with their venation disabled (``--veins off``): drawn as leaves without veins
    (no vein field, no vein-driven shape); leaves without venation are returned as they are."""
    return [p.replace(venation=dataclasses.replace(p.venation, enabled=False)) if p.venation.enabled else p
            for p in leaves]
