"""The sky of a canopy frame, in numpy: an analytic sky radiance, its spherical-harmonic irradiance,
the tone map, and the contact points of a scene's plants (the twins of ``shaders/sky_model.glsl``
and ``shaders/tonemap.glsl``; :mod:`leafview.gpu.light` packs :func:`sky_model` into the Light
block).

Units. A *folded* irradiance is a physical irradiance divided by π: the radiance a white Lambertian
surface reflects under it. The renderer's lights are folded (``leaf.frag``: an albedo ρ lit head-on
by a sun of intensity E_s reflects ρ E_s), so the Light block stores the sun's intensity and the sky's
irradiance folded; radiances (the sky's) are physical. The sun's physical irradiance is π E_s.

The sky (directions d with d_z ≥ 0; θ the zenith angle of d, γ its angle to the sun, θ_s the sun's
zenith angle) follows the luminance distribution of Perez et al. (1993) with the clear-sky
coefficients of Preetham, Shirley & Smits (1999, appendix A.2) at turbidity T = :data:`TURBIDITY`:

    F(θ, γ) = (1 + A e^{B / cos θ}) (1 + C e^{D γ} + E cos² γ)                      (1)
    L(d) = L_z F(θ, γ) / F(0, θ_s) · mix(c_z, c_h, (1 − cos θ)³) ⊗ glow tint         (2)

where L_z is Preetham's zenith luminance (eq. A.2: (4.0453 T − 4.9710) tan χ − 0.2155 T + 2.4192
kcd/m², χ = (4/9 − T/120)(π − 2θ_s)) scaled by the sun's physical irradiance over :data:`SKY_SCALE`
klux (so a clear sky gives about a third of the sun's horizontal irradiance at 50° elevation),
and c_z, c_h are zenith and horizon chromaticities (luminance 1) that turn paler and warmer as the
sun sets. Near the sun the colour leans towards the sun's: the glow tint mixes it with
lum · c_s by g = ½ C e^{Dγ} / (1 + C e^{Dγ} + E cos²γ). The sun's colour is the transmittance
e^{−τ (m − 1)} of an air mass m (Kasten & Young 1989) with Rayleigh-like τ per channel, scaled
to luminance 1. Below the horizon is the ground, of albedo ρ_g, lit by sun and sky:

    L_g = ρ_g (π E_s c_s max(s_z, 0) + E_sky↑) / π                                  (3)

(E_sky↑ the sky's irradiance on an upward normal, integrated numerically), seen through a haze
that fades it into the horizon's radiance: L(d) = mix(L_g, L(d_h), e^{−k |d_z|}) with d_h the
horizontal direction of d's azimuth and k = :data:`HORIZON_HAZE`.

Ambient: L is projected onto the nine real spherical harmonics Y_lm (l ≤ 2) by a fixed Gauss-Legendre ×
uniform-φ quadrature, and the irradiance of a normal n is the cosine-lobe convolution of Ramamoorthi
& Hanrahan (2001, eqs. 7-8): E(n) = Σ Â_l L_lm Y_lm(n), Â_0 = π, Â_1 = 2π/3, Â_2 = π/4 (a constant
sky L gives E = π L). Against brute-force cosine integration it is within about 3 % for a sun above
30°; the circumsolar glow of a low sun is less smooth and the error grows (about 8 % at 10°,
15 % at 2°, in the least lit directions).

Contact shadows (``ground.frag``): the ground darkens near where plants meet it,
A(p) = Π_i (1 − k e^{−2 r_i² / R_i²}) over contact points (plant origins, :func:`contacts_of`) of
radii R_i (half the crown's radius), none beyond :data:`CONTACT_REACH` R_i; the contacts are binned on
a grid (:func:`contact_grid`) so that a pixel visits only those near it.

Tone map (``tonemap.glsl``): the linear radiance times 2^exposure, then either clamped to [0, 1]
("linear") or through the ACES filmic fit of Narkowicz (2015), f(x) = x (2.51 x + 0.03) /
(x (2.43 x + 0.59) + 0.14) clamped to [0, 1] ("filmic", applied to the exposed value as is),
then sRGB encoded (:func:`leafview.core.colour.linear_to_srgb`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.colour import linear_to_srgb
from leafview.errors import ParamError
from leafview.scene.lighting import TONE_MAPS, LightSettings

__all__ = ["SkyModel", "sky_model", "sky_radiance", "sun_colour", "sh_basis", "project_sh", "SH_BANDS",
           "irradiance", "sh_irradiance", "tone_map", "contacts_of", "ground_height", "GROUND_ALBEDO",
           "TURBIDITY", "SKY_SCALE", "HORIZON_HAZE", "SUN_RADIUS", "MAX_CONTACTS", "contact_occlusion",
           "ContactGrid", "contact_grid", "CONTACT_REACH", "CONTACT_CELLS", "CONTACT_ITEMS"]

TURBIDITY = 2.5            # a clear sky (Preetham et al. 1999: 2 clear .. 10 hazy)
SKY_SCALE = 100.0          # klux of physical sun irradiance per kcd/m² of zenith luminance
HORIZON_HAZE = 10.0        # k of the haze below the horizon, e^{-k |d_z|}
GROUND_ALBEDO = (0.13, 0.11, 0.075)  # soil with a little litter (linear)
SUN_RADIUS = 0.0093        # angular radius of the drawn sun disc (radians; the real sun: 0.0047)
SUN_DISC = 60.0            # the disc's radiance over the sun's folded irradiance (saturates)
MAX_CONTACTS = 256         # contact points the ground shader takes
SH_BANDS = np.array([math.pi, 2.0 * math.pi / 3.0, 2.0 * math.pi / 3.0, 2.0 * math.pi / 3.0,
                     math.pi / 4.0, math.pi / 4.0, math.pi / 4.0, math.pi / 4.0, math.pi / 4.0])
"""Â_l of each of the nine coefficients (Ramamoorthi & Hanrahan 2001, eq. 8)."""

_LUM = np.array([0.2126, 0.7152, 0.0722])       # Rec. 709 luminance
_TAU = np.array([0.022, 0.048, 0.105])          # per unit air mass, Rayleigh-like (∝ λ^-4 in spirit)
_ZENITH_HIGH, _ZENITH_LOW = np.array([0.26, 0.46, 1.0]), np.array([0.42, 0.52, 0.85])
_HORIZON_HIGH, _HORIZON_LOW = np.array([0.68, 0.82, 1.0]), np.array([1.0, 0.62, 0.34])
_QUADRATURE = (96, 192)   # (cos θ, φ) cells of the SH projection


def _lum1(rgb: NDArray[np.float64]) -> NDArray[np.float64]:
    out: NDArray[np.float64] = rgb / float(rgb @ _LUM)
    return out


def perez(turbidity: float) -> NDArray[np.float64]:
    """(A, B, C, D, E) of the luminance distribution, eq. (1) (Preetham et al. 1999, A.2)."""
    t = float(turbidity)
    return np.array([0.1787 * t - 1.4630, -0.3554 * t + 0.4275, -0.0227 * t + 5.3251,
                     0.1206 * t - 2.5771, -0.0670 * t + 0.3703])


def zenith_luminance(turbidity: float, theta_s: float) -> float:
    """Preetham's zenith luminance (kcd/m², eq. A.2) for a sun at zenith angle ``theta_s``."""
    chi = (4.0 / 9.0 - turbidity / 120.0) * (math.pi - 2.0 * theta_s)
    return (4.0453 * turbidity - 4.9710) * math.tan(chi) - 0.2155 * turbidity + 2.4192


def sun_colour(elevation_deg: float) -> NDArray[np.float64]:
    """The sun's colour at ``elevation_deg`` (luminance 1): e^{−τ (m − 1)} with the air mass of
    Kasten & Young (1989), m = 1 / (sin h + 0.50572 (h + 6.07995°)^−1.6364)."""
    h = max(float(elevation_deg), 0.0)
    m = 1.0 / (math.sin(math.radians(h)) + 0.50572 * (h + 6.07995) ** -1.6364)
    return _lum1(np.exp(-_TAU * (m - 1.0)))


@dataclass(frozen=True)
class SkyModel:
    """Everything the sky of one :class:`LightSettings` needs (what the Light block holds)."""

    sun: NDArray[np.float64]          # (3,) unit, towards the sun
    sun_irradiance: float             # folded (the settings' sun_intensity)
    sun_colour: NDArray[np.float64]   # (3,) luminance 1
    zenith: NDArray[np.float64]       # (3,) L_z c_z
    horizon: NDArray[np.float64]      # (3,) L_z c_h
    perez: NDArray[np.float64]        # (5,) A..E of eq. (1)
    inv_f0: float                     # 1 / F(0, θ_s)
    ground_albedo: NDArray[np.float64]
    ground_radiance: NDArray[np.float64]   # (3,) L_g of eq. (3)
    sh: NDArray[np.float64]           # (9, 3) L_lm of the whole sphere (sky and ground), not convolved


def _f(perez_c: NDArray[np.float64], cos_t: NDArray[np.float64], gamma: NDArray[np.float64]) -> NDArray[np.float64]:
    a, b, c, d, e = perez_c
    out: NDArray[np.float64] = ((1.0 + a * np.exp(b / np.maximum(cos_t, 1e-4)))
                                * (1.0 + c * np.exp(d * gamma) + e * np.cos(gamma) ** 2))
    return out


def _upper(model: SkyModel, d: NDArray[np.float64]) -> NDArray[np.float64]:
    """Eq. (2) for unit directions ``d`` (..., 3) (d_z taken as max(d_z, 0))."""
    cos_t = np.maximum(d[..., 2:3], 0.0)
    gamma = np.arccos(np.clip(d @ model.sun, -1.0, 1.0))[..., None]
    a, b, c, dd, e = model.perez
    glow = c * np.exp(dd * gamma)
    g = 0.5 * glow / (1.0 + glow + e * np.cos(gamma) ** 2)
    chroma = model.zenith + (model.horizon - model.zenith) * (1.0 - cos_t) ** 3
    tinted = chroma + g * ((chroma @ _LUM)[..., None] * model.sun_colour - chroma)
    out: NDArray[np.float64] = _f(model.perez, cos_t, gamma) * model.inv_f0 * tinted
    return out


def sky_radiance(model: SkyModel, directions: ArrayLike, *, disc: bool = False) -> NDArray[np.float64]:
    """Radiance (..., 3) of the sky (eq. 2) and, below the horizon, the hazy ground (eq. 3) seen
    along unit ``directions`` (..., 3); ``disc`` adds the sun's disc (what the sky pass draws; the
    sun itself is no part of the ambient)."""
    d = np.asarray(directions, np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    up = _upper(model, d)
    flat = d * np.array([1.0, 1.0, 0.0])
    flat = flat / np.maximum(np.linalg.norm(flat, axis=-1, keepdims=True), 1e-6)
    horizon = _upper(model, flat)
    haze = np.exp(-HORIZON_HAZE * np.abs(d[..., 2:3]))
    below = model.ground_radiance + (horizon - model.ground_radiance) * haze
    out: NDArray[np.float64] = np.where(d[..., 2:3] >= 0.0, up, below)
    if disc:
        angle = np.arccos(np.clip(d @ model.sun, -1.0, 1.0))[..., None]
        out = out + _disc_weight(angle) * SUN_DISC * model.sun_irradiance * model.sun_colour
    return out


def _disc_weight(angle: NDArray[np.float64]) -> NDArray[np.float64]:
    """1 inside the sun's disc, 0 outside, a smoothstep across 0.8..1.2 of its radius."""
    t = np.clip((angle - 0.8 * SUN_RADIUS) / (0.4 * SUN_RADIUS), 0.0, 1.0)
    out: NDArray[np.float64] = 1.0 - t * t * (3.0 - 2.0 * t)
    return out


def sh_basis(directions: ArrayLike) -> NDArray[np.float64]:
    """The nine real spherical harmonics Y_00, Y_1-1, Y_10, Y_11, Y_2-2, Y_2-1, Y_20, Y_21, Y_22 of
    unit ``directions`` (..., 3) → (..., 9) (Ramamoorthi & Hanrahan 2001, eq. 3)."""
    d = np.asarray(directions, np.float64)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    c0, c1 = 0.5 / math.sqrt(math.pi), math.sqrt(3.0 / (4.0 * math.pi))
    c2, c20, c22 = 0.5 * math.sqrt(15.0 / math.pi), 0.25 * math.sqrt(5.0 / math.pi), 0.25 * math.sqrt(15.0 / math.pi)
    return np.stack([np.full_like(x, c0), c1 * y, c1 * z, c1 * x, c2 * x * y, c2 * y * z,
                     c20 * (3.0 * z * z - 1.0), c2 * x * z, c22 * (x * x - y * y)], axis=-1)


def sphere_quadrature(n_z: int, n_phi: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Directions (n_z · n_phi, 3) and their solid angles (n_z · n_phi,): Gauss-Legendre nodes in
    cos θ times evenly spaced φ (exact for spherical harmonics of degree < min(2 n_z, n_phi))."""
    z, wz = np.polynomial.legendre.leggauss(int(n_z))
    phi = (np.arange(n_phi) + 0.5) * (2.0 * math.pi / n_phi)
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    r = np.sqrt(1.0 - zz * zz)
    dirs = np.stack([r * np.cos(pp), r * np.sin(pp), zz], axis=-1).reshape(-1, 3)
    weights = np.repeat(wz * (2.0 * math.pi / n_phi), n_phi)
    return dirs, weights


def project_sh(radiance: NDArray[np.float64], directions: NDArray[np.float64], weights: ArrayLike) -> NDArray[np.float64]:
    """L_lm (9, 3) = Σ L(d) Y_lm(d) dω over a quadrature (``weights`` the solid angle of each direction)."""
    w = np.broadcast_to(np.asarray(weights, np.float64), (len(directions),))
    out: NDArray[np.float64] = sh_basis(directions).T @ (radiance * w[:, None])
    return out


def irradiance(normals: ArrayLike, sh: ArrayLike) -> NDArray[np.float64]:
    """Physical irradiance (..., 3) of unit ``normals`` (..., 3) under the radiance whose
    coefficients are ``sh`` (9, 3): E(n) = Σ Â_l L_lm Y_lm(n) (a constant L gives π L)."""
    out: NDArray[np.float64] = sh_basis(normals) @ (SH_BANDS[:, None] * np.asarray(sh, np.float64))
    return out


def sh_irradiance(model: SkyModel, normals: ArrayLike) -> NDArray[np.float64]:
    """Folded irradiance E(n)/π (..., 3): the twin of ``sh_irradiance`` in sky_model.glsl, what an
    albedo multiplies."""
    out: NDArray[np.float64] = irradiance(normals, model.sh) / math.pi
    return out


def sky_model(light: LightSettings, ground_albedo: ArrayLike = GROUND_ALBEDO) -> SkyModel:
    """The sky, ground and ambient of ``light`` (eqs. 1-3 and their SH projection)."""
    light.check()
    albedo = np.asarray(ground_albedo, np.float64).reshape(3)
    if not (np.isfinite(albedo).all() and (albedo >= 0.0).all() and (albedo <= 1.0).all()):
        raise ParamError("light.ground_albedo", f"must be three numbers in [0, 1], got {ground_albedo!r}")
    el = float(light.sun[1])
    s = light.direction
    theta_s = math.radians(90.0 - el)
    e_sun = float(light.sun_intensity)
    lz = math.pi * e_sun * zenith_luminance(TURBIDITY, theta_s) / SKY_SCALE
    low = math.exp(-el / 12.0)
    zen = _lum1(_ZENITH_HIGH + (_ZENITH_LOW - _ZENITH_HIGH) * low)
    hor = _lum1(_HORIZON_HIGH + (_HORIZON_LOW - _HORIZON_HIGH) * low)
    p = perez(TURBIDITY)
    f0 = float(_f(p, np.array(1.0), np.array(theta_s)))
    colour = sun_colour(el)
    base = SkyModel(s, e_sun, colour, lz * zen, lz * hor, p, 1.0 / f0, albedo, np.zeros(3), np.zeros((9, 3)))
    dirs, w = sphere_quadrature(*_QUADRATURE)
    up = dirs[:, 2] > 0.0
    sky = _upper(base, dirs[up])
    e_sky = (sky * (dirs[up, 2] * w[up])[:, None]).sum(axis=0)         # physical, upward normal
    ground = albedo * (math.pi * e_sun * colour * max(float(s[2]), 0.0) + e_sky) / math.pi
    model = SkyModel(s, e_sun, colour, lz * zen, lz * hor, p, 1.0 / f0, albedo, ground, np.zeros((9, 3)))
    sh = project_sh(sky_radiance(model, dirs), dirs, w)
    return SkyModel(s, e_sun, colour, lz * zen, lz * hor, p, 1.0 / f0, albedo, ground, sh)


def tone_map(linear_rgb: ArrayLike, exposure: float = 0.0, kind: str = "filmic", *, srgb: bool = True) -> NDArray[np.float64]:
    """``tonemap.glsl``'s ``canopy_output``: linear radiance (negative values as 0) × 2^exposure, the tone curve ("filmic":
    Narkowicz 2015's ACES fit; "linear": a clamp), then sRGB encoded unless ``srgb`` is False."""
    if kind not in TONE_MAPS:
        raise ParamError("light.tone", f"unknown tone map {kind!r} (choose from {', '.join(TONE_MAPS)})")
    x = np.maximum(np.asarray(linear_rgb, np.float64), 0.0) * 2.0 ** float(exposure)
    if kind == "filmic":
        x = x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14)
    x = np.clip(x, 0.0, 1.0)
    return linear_to_srgb(x) if srgb else x


def ground_height(scene: Any) -> float:
    """Height of the ground under ``scene`` (a :class:`~leafview.scene.spec.Scene`): where its trunks
    meet the ground (the lowest plant origin), else the bottom of its bounds."""
    placement = getattr(scene, "placement", None)
    if placement is not None and len(placement.plant_origins):
        return float(np.min(placement.plant_origins[:, 2]))
    return float(scene.bounds()[0][2])


def contacts_of(scene: Any, limit: int = MAX_CONTACTS, spread: float = 0.5) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Contact points (M, 3) and radii (M,) where ``scene``'s plants meet the ground: each plant's
    origin, with ``spread`` × its crown's radius (the largest horizontal distance of its leaf bases
    from the origin); at most ``limit``, the largest plants first. A scene without plants (explicit
    leaves) has none."""
    placement = getattr(scene, "placement", None)
    if placement is None or not len(placement.plant_origins):
        return np.zeros((0, 3)), np.zeros(0)
    origins = np.asarray(placement.plant_origins, np.float64)
    bases = np.asarray(scene.matrices[:, :3, 3], np.float64)
    plant = np.asarray(placement.plant, np.int64)
    reach = np.linalg.norm(bases[:, :2] - origins[plant, :2], axis=1)
    crown = np.zeros(len(origins))
    np.maximum.at(crown, plant, reach)
    radii = spread * np.maximum(crown, 1e-3)
    order = np.argsort(-radii, kind="stable")[: int(limit)]
    return origins[order], radii[order]


CONTACT_REACH = 3.0        # a contact darkens nothing beyond this many of its radii (e^{-18})
CONTACT_CELLS = 16         # the contact grid's cells per side
CONTACT_ITEMS = 4096       # entries of the contact grid's cell lists (one byte each in the shader)


def contact_occlusion(points: ArrayLike, contacts: ArrayLike, radii: ArrayLike, strength: float = 0.6) -> NDArray[np.float64]:
    """The ground's contact occlusion at ``points`` (..., 3): Π_i (1 − strength e^{−2 (r_i / R_i)²})
    with r_i the horizontal distance to contact i of radius R_i, none beyond r_i =
    :data:`CONTACT_REACH` R_i (the twin of ``ground.frag``)."""
    p = np.asarray(points, np.float64)[..., None, :2]
    c = np.asarray(contacts, np.float64).reshape(-1, 3)[:, :2]
    rad = np.asarray(radii, np.float64).reshape(-1)
    q = np.sum((p - c) ** 2, axis=-1) / np.maximum(rad, 1e-9) ** 2
    near = q < CONTACT_REACH * CONTACT_REACH
    out: NDArray[np.float64] = np.prod(np.where(near, 1.0 - strength * np.exp(-2.0 * q), 1.0), axis=-1)
    return out


@dataclass(frozen=True)
class ContactGrid:
    """The contacts binned for ``ground.frag``: a :data:`CONTACT_CELLS`² grid over their reach,
    cell (i, j) (i along x) listing the contacts whose reach square overlaps it, in
    ``items[start[c] : start[c] + count[c]]`` with c = j · cells + i."""

    origin: NDArray[np.float64]     # (2,) lower corner (world xy)
    inv_cell: NDArray[np.float64]   # (2,) cells per world unit
    start: NDArray[np.int32]        # (cells²,)
    count: NDArray[np.int32]        # (cells²,)
    items: NDArray[np.int32]        # (capacity,) contact indices, 0 past the end

    def packed(self) -> NDArray[np.int32]:
        """``items`` four to an int, byte k & 3 of int k >> 2 (little end first): the shader's
        ``contact_items``."""
        b = self.items.astype(np.uint32).reshape(-1, 4)
        word = b[:, 0] | (b[:, 1] << 8) | (b[:, 2] << 16) | (b[:, 3] << 24)
        return word.view(np.int32)
    kept: NDArray[np.bool_]         # (M,) contacts that found room (False: dropped, the list was full)


def contact_grid(contacts: ArrayLike, radii: ArrayLike, cells: int = CONTACT_CELLS,
                 capacity: int = CONTACT_ITEMS) -> ContactGrid:
    """Bin ``contacts`` (M, 3) of ``radii`` (M,) (:func:`contacts_of`: largest first) into a grid, so
    the shader visits only the few contacts near each pixel. A contact whose cells would overflow
    the ``capacity`` entries is dropped (later, smaller contacts first)."""
    pts = np.asarray(contacts, np.float64).reshape(-1, 3)[:, :2]
    rad = np.asarray(radii, np.float64).reshape(-1)
    if len(pts) > MAX_CONTACTS or capacity % 16:
        raise ValueError(f"contact_grid: at most {MAX_CONTACTS} contacts (one byte each) and a capacity "
                         f"of whole ivec4s of bytes, got {len(pts)} and {capacity}")
    reach = CONTACT_REACH * rad
    if len(pts):
        lo, hi = (pts - reach[:, None]).min(axis=0), (pts + reach[:, None]).max(axis=0)
    else:
        lo, hi = np.zeros(2), np.ones(2)
    inv = cells / np.maximum(hi - lo, 1e-9)
    first = np.clip(np.floor((pts - reach[:, None] - lo) * inv), 0, cells - 1).astype(np.int64)
    last = np.clip(np.floor((pts + reach[:, None] - lo) * inv), 0, cells - 1).astype(np.int64)
    lists: list[list[int]] = [[] for _ in range(cells * cells)]
    kept = np.zeros(len(pts), bool)
    used = 0
    for k in range(len(pts)):
        n = int((last[k, 0] - first[k, 0] + 1) * (last[k, 1] - first[k, 1] + 1))
        if used + n > capacity:
            continue
        used += n
        kept[k] = True
        for j in range(first[k, 1], last[k, 1] + 1):
            for i in range(first[k, 0], last[k, 0] + 1):
                lists[j * cells + i].append(k)
    count = np.array([len(c) for c in lists], np.int32)
    start = (np.cumsum(count) - count).astype(np.int32)
    items = np.zeros(capacity, np.int32)
    flat = [k for c in lists for k in c]
    items[: len(flat)] = flat
    return ContactGrid(lo, inv, start, count, items, kept)
