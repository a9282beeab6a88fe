"""Synthetic photographs of leaves on paper, with a known truth: what the photo fit's tests and
``leafview bench fit`` measure against, since no real leaf photograph can be fetched here.

:func:`synthetic_photo` draws one seeded photo, as hard as a real one:

* **the leaf's top view**: a built-in preset flattened onto the paper (its margin is
  ``evaluate(params, ±1, v)`` with the preset's jitter; Chaurasia & Beardsley 2017, eq. 6 and
  sec. 6), or a random instance of a catalogue shape (Garg & Leow 2011, Fig. 8), asymmetric ones
  with independently drawn sides or the sides of two shapes (Fig. 6), serrated ones with the
  jitter on or with apically pointing teeth; its width scaled by up to ±20 %;
* placed at any rotation, a length of 35-80 % of the shorter image side and a random position;
  about half the leaves with a slightly curved petiole (5-25 % of the length);
* **texture**: a base-to-apex colour gradient, a midrib and curved secondary veins, a reticulate
  tertiary net and mottling; an underside (``face_down``) is paler with raised, embossed veins;
  with ``veins="tree"`` the primary leaf's veins come from a known pinnate vein tree instead
  (:func:`leafview.botany.venation.vein_tree` on the preset, lighter or darker than the blade),
  with ``veins="none"`` there are none;
* **paper**: white, cream, light blue, grey or pink (never green), grain, uneven illumination
  (vignetting and a gradient), a soft drop shadow and non-green debris (specks, crumbs, hairs)
  kept clear of the leaves;
* **camera**: Gaussian blur, Poisson-Gaussian sensor noise and a JPEG round trip through
  OpenImageIO, so that ``image`` holds what a file would.

Every random number comes from ``numpy.random.default_rng(seed)``: one seed gives the same bytes.
The leaves and their placement live in :mod:`leafview.fit.synthetic_leaf`, their texture and the
paper in :mod:`leafview.fit.synthetic_surfaces`; this module puts the photo together, runs the
camera and writes files. Pixel coordinates are (x right, y down) with pixel centres at integers, as
``skimage.draw.polygon`` and ``skimage.measure.find_contours`` use them.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio
from numpy.typing import NDArray
from scipy import ndimage

from leafview.atomic import atomic_output, outputs, write_text
from leafview.botany.venation import Vein, check_veins, vein_tree
from leafview.core.params import LeafParams
from leafview.core.venation import Venation, venation_dict
from leafview.deform.surface import evaluate
from leafview.errors import ImageWriteError, ParamError
from leafview.fit.blas import single_threaded
from leafview.fit.synthetic_leaf import F32, KINDS, LOBED, Arr, Placed, area_mask, arrange, coverage, paste, tree_veins
from leafview.fit.synthetic_leaf import SUPERSAMPLE as SUPERSAMPLE  # re-exported: coverage's default
from leafview.fit.synthetic_lobed import LOBED_PRESETS
from leafview.fit.synthetic_surfaces import (
    BACKGROUNDS,
    drop_shadow,
    illumination,
    leaf_rgb,
    paper_surface,
    scatter_debris,
)

__all__ = ["BACKGROUNDS", "CUTS", "KINDS", "LOBED", "LOBED_PRESETS", "VEINS", "SyntheticPhoto", "coverage", "synthetic_photo", "write_photo",
           "write_photo_set"]

CUTS = ("left", "right", "top", "bottom")
VEINS = ("procedural", "tree", "none")
"""How the veins are drawn: ``procedural`` (curved secondaries from a random field, no vein tree:
the benchmark's photos), ``tree`` (the primary leaf's veins from a known pinnate vein tree,
:func:`leafview.botany.venation.vein_tree`, lighter or darker than the blade; ``truth["veins"]``
holds its parameters) or ``none`` (a plain blade)."""


@dataclass(frozen=True)
class SyntheticPhoto:
    """One synthetic photo and its truth (pixel coordinates: x right, y down, centres at integers).

    ``image`` is (h, w, 3) uint8 sRGB after blur, noise and the JPEG round trip. ``mask`` (blade
    and petiole), ``blade``, ``outline`` (the closed blade margin, (m, 2), not repeating its first
    point), ``base`` (where the petiole joins, v = 0), ``apex``, ``length_px`` (= |apex - base|)
    and ``petiole_px`` (0 when none) describe the primary leaf: the first; beside it, leaves that
    do not touch it are shorter and at most 60 % of its area. Masks are the true geometry (half
    coverage or more) before any degradation; ``all_leaves`` holds every leaf's pixels. With
    ``empty`` the masks are all false, ``outline`` is (0, 2) and base and apex are NaN.
    ``truth`` is JSON-able: the seed, the leaf (``kind``, ``name``, ``rotation_deg``: the apex
    direction turned clockwise from straight up, ``scale``: length / shorter side, width factor,
    serration), the paper, shadow, debris and camera settings, ``dpi`` and ``leaf_cm``, and
    ``others`` (the other leaves' outlines, bases and apexes) when there are several. With
    ``veins="tree"``, ``secondaries`` are the primary leaf's secondary veins leaving the midrib
    (pixel polylines from the midrib out) and ``secondary_sides`` their sides (-1 the u < 0 half,
    +1 the other), and ``truth["veins"]`` their tree's parameters."""

    image: NDArray[np.uint8]
    mask: NDArray[np.bool_]
    blade: NDArray[np.bool_]
    outline: Arr
    base: Arr
    apex: Arr
    length_px: float
    petiole_px: float
    dpi: float
    face_down: bool
    truth: dict[str, Any]
    all_leaves: NDArray[np.bool_]
    secondaries: tuple[Arr, ...] = ()
    secondary_sides: tuple[int, ...] = ()


# ---------------------------------------------------------------------------------------------
# camera
# ---------------------------------------------------------------------------------------------

def _jpeg(image: NDArray[np.uint8], quality: int) -> NDArray[np.uint8]:
    """``image`` written as a JPEG of ``quality`` and read back, through OpenImageIO."""
    h, w = image.shape[:2]
    with tempfile.TemporaryDirectory(prefix="leafview-jpeg-") as folder:
        path = os.path.join(folder, "photo.jpg")
        spec = oiio.ImageSpec(w, h, 3, "uint8")
        spec.attribute("Compression", f"jpeg:{quality}")
        out = oiio.ImageOutput.create(path)
        if out is None or not out.open(path, spec) or not out.write_image(image) or not out.close():
            raise ImageWriteError(f"JPEG round trip: {oiio.geterror()}")
        inp = oiio.ImageInput.open(path)
        if inp is None:
            raise ImageWriteError(f"JPEG round trip: {oiio.geterror()}")
        back = inp.read_image("uint8")
        inp.close()
    if back is None:
        raise ImageWriteError(f"JPEG round trip: {oiio.geterror()}")
    return np.ascontiguousarray(np.asarray(back, dtype=np.uint8).reshape(h, w, 3))


def _camera(rng: np.random.Generator, rgb: F32, quality: int) -> tuple[NDArray[np.uint8], dict[str, Any]]:
    """Lens blur, Poisson-Gaussian sensor noise (variance ``gain · signal + read²``; luminance
    noise per pixel, chroma noise per 2 × 2 block as after demosaicking), 8 bits, the JPEG.
    ``rgb`` is planar (3, h, w); the result is (h, w, 3)."""
    blur = float(rng.uniform(0.5, 1.5))
    gain, read = float(rng.uniform(0.0003, 0.003)), float(rng.uniform(0.003, 0.012))
    h, w = rgb.shape[1:]
    img = ndimage.gaussian_filter(rgb, (0.0, blur, blur), truncate=2.5)
    np.clip(img, 0.0, 1.0, out=img)
    sd = np.sqrt(gain * img[1] + read * read)
    img += sd * rng.standard_normal((h, w), dtype=np.float32)
    hh, hw = -(-h // 2), -(-w // 2)
    chroma = 0.4 * sd[::2, ::2] * rng.standard_normal((2, hh, hw), dtype=np.float32)
    for ch, noise in ((0, chroma[0]), (2, chroma[1])):
        if h % 2 == 0 and w % 2 == 0:            # each noise value on its 2 × 2 block, by broadcasting
            img[ch].reshape(hh, 2, hw, 2)[...] += noise[:, None, :, None]
        else:
            img[ch] += np.repeat(np.repeat(noise, 2, axis=0), 2, axis=1)[:h, :w]
    img *= 255.0
    img += 0.5
    out = np.ascontiguousarray(np.clip(img, 0.0, 255.0, out=img).astype(np.uint8).transpose(1, 2, 0))
    if quality:
        out = _jpeg(out, quality)
    return out, {"blur_sigma": blur, "noise_gain": gain, "noise_read": read, "jpeg_quality": quality or None}


# ---------------------------------------------------------------------------------------------
# the photo
# ---------------------------------------------------------------------------------------------

MAX_PIXELS = 50_000_000


def _check_options(seed: int, size: tuple[int, int], kind: str | None, background: str | None,
                   jpeg_quality: int | None, leaves: int, touching: bool, cut: str | None, empty: bool,
                   veins: str, lobed_preset: str | None = None) -> None:
    def integer(value: Any) -> bool:
        return isinstance(value, (int, np.integer)) and not isinstance(value, bool)

    if not integer(seed) or seed < 0:
        raise ParamError("seed", f"must be an integer >= 0, got {seed!r}")
    if (not isinstance(size, (tuple, list)) or len(size) != 2 or not all(integer(v) and v >= 32 for v in size)
            or size[0] * size[1] > MAX_PIXELS):
        raise ParamError("size", f"must be (width, height), each >= 32 px, at most {MAX_PIXELS:,} pixels; got {size!r}")
    if kind is not None and kind not in KINDS + (LOBED,):
        raise ParamError("kind", f"must be one of {', '.join(KINDS + (LOBED,))}, got {kind!r}")
    if lobed_preset is not None and (lobed_preset not in LOBED_PRESETS or kind not in (None, LOBED)):
        raise ParamError("lobed_preset", f"must be one of {', '.join(LOBED_PRESETS)} (with kind {LOBED!r} or "
                                         f"unset), got {lobed_preset!r}")
    if background is not None and background not in BACKGROUNDS:
        raise ParamError("background", f"must be one of {', '.join(BACKGROUNDS)}, got {background!r}")
    if jpeg_quality is not None and (not integer(jpeg_quality) or not 0 <= jpeg_quality <= 100):
        raise ParamError("jpeg_quality", f"must be 1-100 (0: no JPEG round trip), got {jpeg_quality!r}")
    if not integer(leaves) or not 1 <= leaves <= 6:
        raise ParamError("leaves", f"must be an integer from 1 to 6, got {leaves!r}")
    if cut is not None and cut not in CUTS:
        raise ParamError("cut", f"must be one of {', '.join(CUTS)}, got {cut!r}")
    if touching and cut is not None:
        raise ParamError("cut", "cannot be combined with touching")
    if empty and (touching or cut is not None or leaves != 1):
        raise ParamError("empty", "an empty page has no leaves: leave touching, cut and leaves unset")
    if veins not in VEINS:
        raise ParamError("veins", f"must be one of {', '.join(VEINS)}, got {veins!r}")
    if veins == "tree" and (empty or kind not in (None, "preset", "serrated") or lobed_preset is not None):
        raise ParamError("veins", "a vein tree is drawn on a preset's leaf: kind must be preset, serrated or unset, "
                                  "and the page not empty")


def _leaf_truth(leaf: Placed) -> dict[str, Any]:
    lobes = {"lobes": leaf.view.info["lobes"]} if "lobes" in leaf.view.info else {}
    return {**lobes, "kind": leaf.view.info["kind"], "name": leaf.view.info["name"],
            "serration": leaf.view.info["serration"], "width_factor": leaf.view.info["width_factor"],
            "rotation_deg": math.degrees(leaf.theta) % 360.0, "length_px": leaf.length,
            "petiole_px": leaf.petiole_len * leaf.length, "base": leaf.px(np.zeros(2)).tolist(),
            "apex": leaf.px(np.array([0.0, 1.0])).tolist()}


def _vein_tree(seed: int, leaf: Placed) -> tuple[list[Vein], LeafParams, dict[str, Any]]:
    """A random pinnate venation on the primary leaf (from the stream ``(seed, 17)``, apart from the
    photo's own) and its vein tree on the leaf's flat preset; the truth: its parameters, whether
    the veins are darker than the blade, and the secondaries leaving the midrib on each side."""
    rng = np.random.default_rng([seed, 17])
    if leaf.view.params is None:
        raise ParamError("veins", "a vein tree is drawn on a preset's leaf")
    for _ in range(20):
        loop = float(rng.uniform(0.65, 0.9)) if rng.random() < 0.4 else 0.0
        venation = Venation(enabled=True, pattern="pinnate", seed=int(rng.integers(0, 10_000)),
                            secondaries=int(rng.integers(5, 13)), angle=float(rng.uniform(30.0, 70.0)),
                            curvature=float(rng.uniform(0.0, 0.6)), irregularity=float(rng.uniform(0.0, 0.3)),
                            alternate=float(rng.uniform(0.0, 1.0)), loop=loop, tertiary=float(rng.uniform(0.0, 30.0)),
                            midrib_width=float(rng.uniform(0.006, 0.014)), width_ratio=float(rng.uniform(0.35, 0.6)))
        params = leaf.view.params.replace(venation=venation)
        try:
            check_veins(params)
        except ParamError:
            continue
        break
    tree = vein_tree(params)
    sides = [int(np.sign(vein.uv[-1, 0])) for vein in tree if vein.order == 2 and vein.parent == 0]
    info = {"mode": "tree", "dark": bool(rng.random() < 0.35), "venation": venation_dict(venation),
            "secondaries_per_side": {"-1": sides.count(-1), "+1": sides.count(1)}}
    return tree, params, info


def _secondaries(leaf: Placed, tree: list[Vein]) -> tuple[tuple[Arr, ...], tuple[int, ...]]:
    """The secondaries of ``tree`` that leave the midrib, as pixel polylines, and their sides. A
    looping vein is given up to where its loop begins (the vein of the tree without loops cut at
    ``loop`` of its length), without the arch that joins it to the next."""
    params = leaf.view.params
    if not tree or params is None:
        return (), ()
    venation = params.venation
    if venation.loop > 0.0:
        tree = vein_tree(params.replace(venation=replace(venation, loop=0.0)))
    picked = [v for v in tree if v.order == 2 and v.parent == 0]
    lines = []
    for v in picked:
        px = leaf.px(evaluate(params, v.uv[:, 0], v.uv[:, 1])[:, :2])
        if venation.loop > 0.0:
            arc = np.r_[0.0, np.cumsum(np.hypot(*np.diff(px, axis=0).T))]
            at = np.linspace(0.0, venation.loop * arc[-1], max(len(px), 2))
            px = np.stack([np.interp(at, arc, px[:, 0]), np.interp(at, arc, px[:, 1])], axis=1)
        lines.append(px)
    return tuple(lines), tuple(int(np.sign(v.uv[-1, 0])) for v in picked)


@single_threaded
def synthetic_photo(seed: int, *, size: tuple[int, int] = (1000, 1000), kind: str | None = None,
                    background: str | None = None, petiole: bool | None = None, jpeg_quality: int | None = None,
                    leaves: int = 1, touching: bool = False, cut: str | None = None,
                    empty: bool = False, veins: str = "procedural", lobed_preset: str | None = None) -> SyntheticPhoto:
    """One seeded synthetic photo of a leaf on paper (see the module docstring).

    Parameters
    ----------
    seed : int
        Seed of ``numpy.random.default_rng``; the same seed and options give identical bytes.
    size : (width, height)
        The image size in pixels.
    kind : str, optional
        ``preset``, ``landmark``, ``serrated`` or ``asymmetric`` (:data:`KINDS`); random if None.
        ``lobed`` (:data:`LOBED`, never drawn at random): a lobed preset's margin with varied lobe
        depth and spread (:mod:`leafview.fit.synthetic_lobed`); its apex is the terminal lobe's
        tip (a bilobed leaf's: the sinus between its lobes).
    background : str, optional
        A paper of :data:`BACKGROUNDS`; random if None.
    petiole : bool, optional
        Whether the leaves have a petiole; about half of them if None.
    jpeg_quality : int, optional
        The JPEG round trip's quality, 1-100; random 70-85 if None; 0 skips the round trip.
    leaves : int
        How many leaves, 1-6, apart (3 % of the shorter side at least); the first is the primary,
        the others shorter and at most 60 % of its area.
    touching : bool
        The first two leaves (of similar size) overlap by 0.5-3 % of the smaller blade.
    cut : str, optional
        ``left``, ``right``, ``top`` or ``bottom``: the primary leaf runs off that border by
        10-25 % of its length (measured across the border); base or apex may lie outside.
    empty : bool
        Paper, debris and camera only: no leaf, no shadow.
    veins : str
        ``procedural``, ``tree`` or ``none`` (:data:`VEINS`). With ``tree`` the primary leaf is a
        broad preset at its own width (serrated with ``kind="serrated"``) carrying a random
        pinnate :class:`~leafview.core.venation.Venation` drawn from a second stream of the seed,
        so the other draws stay as they are.
    lobed_preset : str, optional
        With kind ``lobed`` (implied when unset): ``maple``, ``oak`` or ``bilobed``; random if None.
    """
    _check_options(seed, size, kind, background, jpeg_quality, leaves, touching, cut, empty, veins, lobed_preset)
    if lobed_preset is not None:
        kind = LOBED
    rng = np.random.default_rng(int(seed))
    w, h = int(size[0]), int(size[1])
    # drawn whatever the options, so that an option changes only what it names
    drawn_kind, drawn_paper, drawn_quality = str(rng.choice(KINDS)), str(rng.choice(list(BACKGROUNDS))), int(
        rng.integers(70, 86))
    if veins == "tree" and kind is None:
        kind = drawn_kind if drawn_kind in ("preset", "serrated") else "preset"
    kind, background = kind or drawn_kind, background or drawn_paper
    quality = drawn_quality if jpeg_quality is None else int(jpeg_quality)
    n = 0 if empty else max(leaves, 2 if touching else 1)
    placed, layout = (arrange(rng, n, kind, petiole, (w, h), touching, cut, veins == "tree", lobed_preset) if n
                      else ([], {}))
    faces = [bool(rng.random() < 0.3) for _ in placed]

    albedo, grain, paper_info = paper_surface(rng, h, w, background)
    light, cast, light_info = illumination(rng, h, w)
    blades = [coverage(p.polygons()[0], h, w) for p in placed]
    stalks = [coverage(p.polygons()[1], h, w) if p.petiole is not None else None for p in placed]
    alpha = np.zeros((h, w), np.float32)
    for crop in blades + stalks:
        if crop is not None:
            r0, c0, a = crop
            win = alpha[r0:r0 + a.shape[0], c0:c0 + a.shape[1]]
            np.maximum(win, a, out=win)
    shadow_info = None
    if n:
        crops = [c for c in blades + stalks if c is not None and c[2].size]
        box = (min(c[0] for c in crops), max(c[0] + c[2].shape[0] for c in crops),
               min(c[1] for c in crops), max(c[1] + c[2].shape[1] for c in crops))
        (r0, c0, shade), shadow_info = drop_shadow(rng, alpha, box)
        grain[r0:r0 + shade.shape[0], c0:c0 + shade.shape[1]] *= 1.0 - shade
    grain *= light
    img = grain[None] * (albedo * cast).astype(np.float32)[:, None, None]     # planar (3, h, w)
    cell = 8
    coarse = area_mask([q for p in placed for q in p.polygons()], 1.0 / cell, (-(-h // cell), -(-w // cell))) > 0
    reach = 2 + int(((shadow_info or {}).get("blur_px", 0.0) * 2 + 6) / cell)
    keepout = ndimage.binary_dilation(coarse, iterations=reach) if n else coarse
    debris = scatter_debris(rng, img, keepout, cell, light, cast)
    tree, tree_params, vein_info = (_vein_tree(int(seed), placed[0]) if veins == "tree"
                                    else (None, None, {"mode": veins}))
    for i, (leaf, blade, stalk, down) in enumerate(zip(placed, blades, stalks, faces, strict=True)):
        drawn = (np.zeros_like(blade[2]) if veins == "none" else
                 tree_veins(leaf, blade, tree) if tree is not None and i == 0 else None)
        rgb, idx, stalk_rgb = leaf_rgb(rng, leaf, blade, down, veins_drawn=drawn,
                                       dark_veins=bool(vein_info.get("dark", False)) and i == 0)
        if stalk is not None:
            r0, c0, a = stalk
            sl = np.s_[r0:r0 + a.shape[0], c0:c0 + a.shape[1]]
            img[(slice(None),) + sl] += ((stalk_rgb * cast).astype(np.float32)[:, None, None] * light[sl]
                                         - img[(slice(None),) + sl]) * a
        r0, c0, a = blade
        rows, cols = np.divmod(idx, a.shape[1])
        at = (rows + r0) * w + cols + c0                     # flat pixel indices in the image
        lit, cover = light.ravel()[at], a.ravel()[idx]
        for ch in range(3):
            plane = img[ch].reshape(-1)
            plane[at] += (rgb[ch] * (lit * np.float32(cast[ch])) - plane[at]) * cover
    image, camera = _camera(rng, img, quality)

    short = min(w, h)
    truth: dict[str, Any] = {"seed": int(seed), "size": [w, h], "empty": empty, "leaves": n, **layout,
                             **paper_info, "veins": vein_info, "illumination": light_info, "shadow": shadow_info, "debris": debris,
                             **camera}
    if not n:
        nan = np.full(2, np.nan)
        dpi = float(rng.integers(150, 601))
        truth.update(dpi=dpi, kind=None)
        none = np.zeros((h, w), bool)
        return SyntheticPhoto(image, none, none.copy(), np.zeros((0, 2)), nan, nan.copy(), 0.0, 0.0, dpi, False,
                              truth, none.copy())
    first = placed[0]
    leaf_cm = float(rng.uniform(3.0, 15.0))
    dpi = float(max(round(first.length / (leaf_cm / 2.54)), 20))
    mask = paste(blades[0], h, w)
    if stalks[0] is not None:
        mask = np.maximum(mask, paste(stalks[0], h, w))
    truth.update(_leaf_truth(first), scale=first.length / short, face_down=faces[0], petiole=first.petiole is not None,
                 dpi=dpi, leaf_cm=first.length / dpi * 2.54)
    if n > 1:
        truth["others"] = [{**_leaf_truth(p), "face_down": f, "outline": np.round(p.px(p.view.outline), 3).tolist()}
                           for p, f in zip(placed[1:], faces[1:], strict=True)]
    lines, sides = _secondaries(replace(first, view=replace(first.view, params=tree_params)), tree) if tree else ((), ())
    return SyntheticPhoto(image, mask >= 0.5, paste(blades[0], h, w) >= 0.5, first.px(first.view.outline),
                          first.px(np.zeros(2)), first.px(np.array([0.0, 1.0])), float(first.length),
                          float(first.petiole_len * first.length), dpi, faces[0], truth, alpha >= 0.5, lines, sides)


# ---------------------------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------------------------

_SUFFIXES = {".jpg": "jpeg", ".jpeg": "jpeg", ".png": "png", ".tif": "tiff", ".tiff": "tiff"}


def write_photo(photo: SyntheticPhoto, path: str | os.PathLike[str], *, quality: int | None = None) -> Path:
    """Write ``photo.image`` as JPEG, PNG or TIFF (by the suffix) with its DPI in the metadata
    (``XResolution``, ``YResolution``, ``ResolutionUnit`` = ``in``), atomically. A JPEG is encoded
    at ``quality``, else at the photo's own JPEG quality (95 when it had none)."""
    target = Path(path)
    fmt = _SUFFIXES.get(target.suffix.lower())
    if fmt is None:
        raise ImageWriteError(f"{target}: unknown image type {target.suffix!r} (use .jpg, .png or .tif)")
    if quality is not None and (not isinstance(quality, int) or not 1 <= quality <= 100):
        raise ParamError("quality", f"must be 1-100, got {quality!r}")
    h, w = photo.image.shape[:2]
    spec = oiio.ImageSpec(w, h, 3, "uint8")
    for name in ("XResolution", "YResolution"):
        spec.attribute(name, float(photo.dpi))
    spec.attribute("ResolutionUnit", "in")
    spec.attribute("Software", "leafview synthetic photo")
    if fmt == "jpeg":
        spec.attribute("Compression", f"jpeg:{quality or photo.truth.get('jpeg_quality') or 95}")
    with atomic_output(target) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None:
            raise ImageWriteError(f"{target}: cannot create a {fmt} writer: {oiio.geterror()}")
        ok = out.open(str(tmp), spec) and out.write_image(np.ascontiguousarray(photo.image))
        if not out.close() or not ok:
            raise ImageWriteError(f"{target}: writing failed: {out.geterror() or oiio.geterror()}")
    return target


def _json_point(p: Arr) -> list[float] | None:
    return None if np.any(np.isnan(p)) else [round(float(x), 4) for x in p]


def write_photo_set(folder: str | os.PathLike[str], n: int, seed: int, *, suffix: str = ".png",
                    **options: Any) -> list[Path]:
    """``n`` photos ``photo_0000.png`` ... into ``folder`` and ``truth.json`` beside them, all or
    nothing. Photo i has the seed ``SeedSequence(seed).generate_state(n)[i]`` and ``options``
    (:func:`synthetic_photo`'s keywords). ``truth.json`` lists per file its outline, base, apex,
    length_px, petiole_px, dpi, face_down and truth. Returns the photos' paths."""
    if not isinstance(n, int) or isinstance(n, bool) or not 1 <= n <= 100_000:
        raise ParamError("n", f"must be an integer from 1 to 100000, got {n!r}")
    if suffix.lower() not in _SUFFIXES:
        raise ParamError("suffix", f"must be one of {', '.join(_SUFFIXES)}, got {suffix!r}")
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise ParamError("seed", f"must be an integer >= 0, got {seed!r}")
    root = Path(folder)
    seeds = np.random.SeedSequence(seed).generate_state(n)
    paths: list[Path] = []
    records = []
    with outputs():
        for i, s in enumerate(seeds):
            photo = synthetic_photo(int(s), **options)
            path = write_photo(photo, root / f"photo_{i:04d}{suffix}")
            paths.append(path)
            records.append({"file": path.name, "seed": int(s),
                            "outline": np.round(photo.outline, 3).tolist(), "base": _json_point(photo.base),
                            "apex": _json_point(photo.apex), "length_px": photo.length_px,
                            "petiole_px": photo.petiole_px, "dpi": photo.dpi, "face_down": photo.face_down,
                            "truth": photo.truth})
        write_text(root / "truth.json", json.dumps({"seed": seed, "options": options, "photos": records}, indent=1))
    return paths
