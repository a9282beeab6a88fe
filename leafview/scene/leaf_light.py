"""The canopy shading of a leaf (``leaf.frag`` under ``LEAF_CANOPY``), in numpy: the reference a test
compares the shader's pixels with.

For one point of a leaf, seen from the side with unit normal n (the side facing the camera; the
shading normal, with a veined leaf's relief), with the unit vector towards the sun l, towards the
camera v, h = (l + v) / |l + v|, the side's albedo ρ (its colour, its texture's texel or its vein
colour) and translucency τ (lower along veins), the light's transmission t and gloss g:

1. the back-light tint, the colour of light that went through the leaf: each channel weighed by its
   own reflectance once more, scaled back to the albedo's luminance Y (Rec. 709 weights),

       T(ρ) = min(ρ² Y(ρ) / Y(ρ²), 1)                                              (1)

   as bright as the reflected light (a leaf transmits about as much as it reflects in the visible),
   deeper in colour (it crossed the pigments twice over): a back-lit green leaf glows a saturated
   green, and its veins, where τ is lower, show dark against it;
2. the sun, of irradiance E_s and colour c_s, seen with visibility V (the shadow maps; 1 unshadowed)
   on the side facing it and shining through to the other side:

       L_sun = E_s c_s V [ max(n·l, 0) ρ + t τ max(−n·l, 0) T(ρ) + g s lobe(max(n·h, 0)) [n·l ≥ 0] ]   (2)

   with the cuticle's specular lobe of ``leaf.frag``'s ``spec_lobe`` (Hong 2005, ch. 8: a narrow
   gloss, exponent 60, on a veined leaf's sunny upper side, a broad dim sheen, exponent 8, on its
   shadowed lower side; exponent 40 on a plain leaf) and its strength s (:func:`sheen`);
3. the sky, whose irradiance E(n) comes from its spherical harmonics (:mod:`leafview.scene.sky`),
   from the side's own hemisphere and, transmitted, from the other one, times the ambient
   occlusion A (screen-space; 1 without):

       L_amb = A [ E(n) ρ + t τ E(−n) T(ρ) ]                                        (3)

The radiance L = L_sun + L_amb is then tone mapped (``tonemap.glsl``; its twin in
:mod:`leafview.scene.sky`). Units follow the renderer's lights: an albedo ρ lit head-on by E_s = 1
reflects ρ (the 1/π of a Lambertian surface is folded into the irradiances).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["backlight_tint", "spec_lobe", "sheen", "canopy_radiance", "LOBE_PLAIN", "LOBE_UPPER", "LOBE_LOWER",
           "STEM_SHEEN", "LUMINANCE"]

LOBE_PLAIN, LOBE_UPPER, LOBE_LOWER = 0, 1, 2
_EXPONENTS = {LOBE_PLAIN: 40.0, LOBE_UPPER: 60.0, LOBE_LOWER: 8.0}
STEM_SHEEN = 0.02     # bark: a faint broad sheen (lobe LOBE_LOWER)
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])   # Rec. 709 weights of eq. (1)


def backlight_tint(albedo: ArrayLike) -> NDArray[np.float64]:
    """Eq. (1): T(ρ) = min(ρ² Y(ρ) / Y(ρ²), 1) over the last axis (0 for black)."""
    rho = np.asarray(albedo, dtype=np.float64)
    sq = rho * rho
    scale = (rho @ LUMINANCE) / np.maximum(sq @ LUMINANCE, 1e-8)
    out: NDArray[np.float64] = np.minimum(sq * scale[..., None], 1.0)
    return out


def spec_lobe(c: ArrayLike, lobe: int) -> NDArray[np.float64]:
    """``leaf.frag``'s ``spec_lobe``: c^40 (plain leaf), c^60 (veined upper side), c^8 (lower side)."""
    return np.power(np.clip(np.asarray(c, dtype=np.float64), 0.0, None), _EXPONENTS[lobe])


def sheen(front: bool, veined: bool) -> tuple[float, int]:
    """(strength s, lobe) of eq. (2) for the visible side: ``leaf.frag``'s 0.12 / 0.03 for a plain
    leaf's upper / lower side, 0.14 / 0.05 for a veined one's."""
    if veined:
        return (0.14, LOBE_UPPER) if front else (0.05, LOBE_LOWER)
    return (0.12 if front else 0.03), LOBE_PLAIN


def _unit(x: ArrayLike) -> NDArray[np.float64]:
    a = np.asarray(x, dtype=np.float64)
    out: NDArray[np.float64] = a / np.linalg.norm(a, axis=-1, keepdims=True)
    return out


def _dot(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    out: NDArray[np.float64] = np.sum(a * b, axis=-1, keepdims=True)
    return out


def canopy_radiance(albedo: ArrayLike, normal: ArrayLike, view: ArrayLike, *, sun: ArrayLike,
                    sun_irradiance: float, sun_colour: ArrayLike = (1.0, 1.0, 1.0),
                    sky_front: ArrayLike, sky_back: ArrayLike, translucency: ArrayLike,
                    transmission: float = 1.0, gloss: float = 1.0, front: bool = True, veined: bool = False,
                    stem: bool = False, visibility: ArrayLike = 1.0, ao: ArrayLike = 1.0) -> NDArray[np.float64]:
    """Linear radiance L = L_sun + L_amb of eqs. (2)-(3), before the tone map.

    Parameters
    ----------
    albedo: (..., 3) the visible side's albedo ρ (linear).
    normal: (..., 3) the visible side's normal n (normalised here).
    view: (..., 3) towards the camera v (normalised here).
    sun: (3,) towards the sun l (unit); ``sun_irradiance`` E_s and ``sun_colour`` c_s.
    sky_front, sky_back: (..., 3) the sky's irradiance E(n) and E(−n) (``sh_irradiance``).
    translucency: τ (..., 1) or scalar; ``transmission`` t and ``gloss`` g: the light settings'.
    front, veined: which side and lobe (:func:`sheen`); ``stem``: a branch's bark (STEM_SHEEN).
    visibility, ao: V and A (scalars or (..., 1)).
    """
    rho = np.asarray(albedo, dtype=np.float64)
    n, v = _unit(normal), _unit(view)
    light = _unit(sun)
    s, lobe = (STEM_SHEEN, LOBE_LOWER) if stem else sheen(front, veined)
    ndl = _dot(n, np.broadcast_to(light, n.shape))
    h = _unit(light + v)
    through = float(transmission) * np.asarray(translucency, dtype=np.float64)
    tint = backlight_tint(rho)
    spec = gloss * s * spec_lobe(np.maximum(_dot(n, h), 0.0), lobe) * (ndl >= 0.0)
    sun_term = np.maximum(ndl, 0.0) * rho + through * np.maximum(-ndl, 0.0) * tint + spec
    ambient = np.asarray(sky_front, dtype=np.float64) * rho + through * np.asarray(sky_back, dtype=np.float64) * tint
    colour = float(sun_irradiance) * np.asarray(sun_colour, dtype=np.float64)
    vis = np.asarray(visibility, dtype=np.float64)
    out: NDArray[Any] = colour * vis * sun_term + np.asarray(ao, dtype=np.float64) * ambient
    return np.asarray(out, dtype=np.float64)
