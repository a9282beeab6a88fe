"""``leafview bench fit``: leaves fitted to photographs (:func:`leafview.fit.photo.fit_image`),
on seeded synthetic photos with a known truth (:mod:`leafview.fit.synthetic_photos`).

The photos are 1 MP (1000 × 1000), of every kind the generator draws in turn (a preset's top view,
a random catalogue instance, serrated, asymmetric), every other one with a petiole, on the papers
in turn (white, cream, blue, grey, pink), written as JPEG files with their resolution first. Per
photo, end to end: the file read from disk, the leaf traced, Ω fitted, the texture resampled.

* **IoU**: the fitted top view (both parts' margins as a polygon) against the true blade outline,
  both filled at the pixel centres (median and worst).
* **base** and **apex**: the distance from the true one in % of the true length (median, worst).
* **photos/s**: photos over the summed wall time of their fits, on this machine, as loaded as it
  is (``cpu_ms`` is this process's CPU time per photo, all threads: other jobs move it less).

The goals of issue 15 are printed beside the figures; nothing is asserted. The GL renderer is
logged and part of the result: it draws the textured leaves of the figure (:func:`write_figure`,
``python -m leafview.bench.fit_photo --figure docs/images/fit_photos.png``), and
:func:`fit_cells` draws the photo | fit overlay | render cells that ``leafview fit DIR`` puts on
its contact sheet.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import moderngl
import numpy as np
from numpy.typing import NDArray
from skimage.draw import disk

from leafview.bench.timing import Progress, bench_context, gl_info, log_gl_renderer
from leafview.core.params import LeafParams
from leafview.core.texture import LeafTexture
from leafview.errors import LeafviewError
from leafview.export.images import contact_sheet, write_image
from leafview.fit.photo import ImageFit, fit_image, polygon_mask, top_view_iou
from leafview.fit.photo_batch import default_jobs, fit_photos
from leafview.fit.photo_texture import texture_uint8
from leafview.fit.synthetic_photos import (
    BACKGROUNDS,
    KINDS,
    LOBED_PRESETS,
    SyntheticPhoto,
    synthetic_photo,
    write_photo,
)
from leafview.gpu.morph import shared_camera
from leafview.gpu.renderer import LeafRenderer

__all__ = ["run", "format_table", "fit_cells", "photo_cell", "write_figure", "GOALS", "PHOTOS", "SIZE"]

GOALS = {"iou_median": 0.97, "iou_worst": 0.93, "landmark_pct": 2.0, "photos_per_s": 5.0}
PHOTOS, QUICK_PHOTOS = 24, 2
LOBED_PHOTOS, LOBED_SEED = 12, 3500   # the lobed set (maple, oak, bilobed in turn; synthetic_photo kind="lobed")
SIZE = (1000, 1000)
SEED = 1500
FIGURE_PHOTOS, FIGURE_CELL, FIGURE_SEED = 8, 192, 2500
_TRACED = (1.0, 0.82, 0.1)       # the traced outline on the overlay (yellow)
_FITTED = (0.95, 0.1, 0.85)      # the fitted margin (magenta)
_BASE, _APEX, _PETIOLE = (0.1, 0.45, 1.0), (1.0, 0.2, 0.1), (0.1, 0.9, 0.95)

U8 = NDArray[np.uint8]


# -- cells: photo | fit overlay | render -------------------------------------------------------------
def _block_mean(rgb: NDArray[np.float32], f: int) -> NDArray[np.float32]:
    if f <= 1:
        return rgb
    h, w = (rgb.shape[0] // f) * f, (rgb.shape[1] // f) * f
    return np.asarray(rgb[:h, :w].reshape(h // f, f, w // f, f, 3).mean(axis=(1, 3)), np.float32)


def photo_cell(rgb: NDArray[np.floating], cell: int) -> tuple[U8, float, tuple[float, float]]:
    """The photo shrunk into a ``cell`` × ``cell`` RGBA tile (aspect kept, centred, transparent
    around), the scale from photo to tile pixels and the tile offset (x, y) of the photo's corner."""
    h, w = rgb.shape[:2]
    f = max(1, int(max(h, w) / cell))
    small = _block_mean(np.asarray(rgb, np.float32), f)
    k = cell / max(h, w)
    th, tw = max(1, min(cell, round(h * k))), max(1, min(cell, round(w * k)))
    rows = np.clip(((np.arange(th) + 0.5) / th * small.shape[0]).astype(np.intp), 0, small.shape[0] - 1)
    cols = np.clip(((np.arange(tw) + 0.5) / tw * small.shape[1]).astype(np.intp), 0, small.shape[1] - 1)
    tile = np.zeros((cell, cell, 4), np.uint8)
    oy, ox = (cell - th) // 2, (cell - tw) // 2
    tile[oy:oy + th, ox:ox + tw, :3] = np.rint(np.clip(small[rows][:, cols], 0.0, 1.0) * 255.0)
    tile[oy:oy + th, ox:ox + tw, 3] = 255
    return tile, k, (float(ox), float(oy))


def _draw_polyline(tile: U8, points: NDArray[np.float64], colour: Sequence[float], closed: bool) -> None:
    """A 2-px polyline through ``points`` (tile pixels), densified to half-pixel steps."""
    p = np.vstack([points, points[:1]]) if closed else points
    if len(p) < 2:
        return
    seg = np.diff(p, axis=0)
    k = np.maximum(np.ceil(np.hypot(seg[:, 0], seg[:, 1]) * 2.0).astype(int), 1)
    idx = np.repeat(np.arange(len(seg)), k)
    frac = (np.arange(idx.size) - np.repeat(np.cumsum(k) - k, k)) / k[idx]
    dense = p[idx] + frac[:, None] * seg[idx]
    c = np.rint(dense).astype(np.intp)
    rgba = np.array([*(round(255 * x) for x in colour), 255], np.uint8)
    n = tile.shape[0]
    for dy, dx in ((0, 0), (1, 0), (0, 1), (1, 1)):
        y, x = c[:, 1] + dy, c[:, 0] + dx
        ok = (y >= 0) & (y < n) & (x >= 0) & (x < tile.shape[1])
        tile[y[ok], x[ok]] = rgba


def _dot(tile: U8, centre: NDArray[np.float64], colour: Sequence[float], radius: float) -> None:
    rr, cc = disk((float(centre[1]), float(centre[0])), radius, shape=tile.shape[:2])
    tile[rr, cc] = np.array([*(round(255 * x) for x in colour), 255], np.uint8)


def overlay_cell(fit: ImageFit, cell: int) -> U8:
    """The photo with the traced outline (yellow), petiole (cyan), fitted margin (magenta), base
    (blue) and apex (red) drawn over it."""
    tile, k, (ox, oy) = photo_cell(fit.photo.rgb, cell)

    def to_tile(p: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray((np.asarray(p, np.float64) + 0.5) * k - 0.5 + [ox, oy], np.float64)

    tile[..., :3] = (tile[..., :3] * 0.8 + 0.2 * 255).astype(np.uint8)   # paler, so the lines show
    _draw_polyline(tile, to_tile(fit.outline.outline), _TRACED, True)
    if len(fit.outline.petiole) > 1:
        _draw_polyline(tile, to_tile(fit.outline.petiole), _PETIOLE, False)
    _draw_polyline(tile, to_tile(fit.margin_pixels(257)), _FITTED, True)
    radius = max(2.0, cell / 90)
    _dot(tile, to_tile(fit.outline.base), _BASE, radius)
    _dot(tile, to_tile(fit.outline.apex), _APEX, radius)
    return tile


def render_parts(parts: Sequence[LeafParams], cell: int, renderer: LeafRenderer) -> U8:
    """The leaf drawn from above by the ordinary render path,
    :meth:`~leafview.gpu.renderer.LeafRenderer.render_many` (as ``leafview render``); the two
    halves of an asymmetric one each with one camera framing both
    (:func:`leafview.gpu.morph.shared_camera`), laid over each other (they meet at the midrib)."""
    if len(parts) == 1:
        image: U8 = renderer.render_many([parts[0]], (cell, cell), "top")[0]
        return image
    camera = shared_camera(list(parts), "top", (cell, cell))
    first, second = renderer.render_many(list(parts), (cell, cell), "top", camera=camera)
    return np.asarray(np.where(first[..., 3:] > 0, first, second), np.uint8)


def fit_cells(fit: ImageFit, cell: int, renderer: LeafRenderer | None,
              parts: Sequence[LeafParams] | None = None) -> list[U8]:
    """Three ``cell`` × ``cell`` RGBA tiles: the photo, the fit drawn over it, and the fitted leaf
    rendered (``parts``, default the fit's own; with their textures, where they name files) —
    a blank tile when ``renderer`` is None."""
    render = (render_parts(parts or fit.parts, cell, renderer) if renderer is not None
              else np.zeros((cell, cell, 4), np.uint8))
    return [photo_cell(fit.photo.rgb, cell)[0], overlay_cell(fit, cell), render]


def fit_label(fit: ImageFit) -> str:
    """A short caption: IoU and Hausdorff distance (% of the length) against the traced leaf."""
    r = fit.report
    return f"IoU {r['iou']:.3f}, H {r['hausdorff_pct']:.1f} %"


# -- the table -------------------------------------------------------------------------------------------
def _options(i: int) -> dict[str, Any]:
    papers = list(BACKGROUNDS)
    return {"kind": KINDS[i % len(KINDS)], "background": papers[i % len(papers)], "petiole": i % 2 == 1}


def _measure(sp: SyntheticPhoto, path: Path) -> dict[str, Any]:
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        fit = fit_image(path)
    except LeafviewError as exc:
        return {"error": str(exc), "seconds": time.perf_counter() - t0, "cpu_s": time.process_time() - c0}
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    truth = polygon_mask(sp.outline, sp.blade.shape)
    length = sp.length_px
    return {"iou": top_view_iou(fit.margin_pixels(), truth), "iou_mask": fit.report["iou"],
            "base_pct": 100.0 * float(np.hypot(*(fit.outline.base - sp.base))) / length,
            "apex_pct": 100.0 * float(np.hypot(*(fit.outline.apex - sp.apex))) / length,
            "hausdorff_pct": fit.report["hausdorff_pct"], "asymmetric": fit.asymmetric, "rows": fit.report["rows"],
            "face_detected": fit.report["face_detected"], "face_score": fit.report["face_score"],
            "petiole": fit.report["petiole_length"], "true_petiole": sp.petiole_px / length,
            "seconds": seconds, "cpu_s": cpu, "stage_seconds": fit.report["stage_seconds"]}


def _lobed_rows(count: int) -> list[dict[str, Any]]:
    """The lobed set: per photo the top view's IoU with the true outline, base and apex errors (% of
    the length), whether it was fitted as lobed, and the seconds."""
    rows = []
    for i in range(count):
        preset = LOBED_PRESETS[i % len(LOBED_PRESETS)]
        sp = synthetic_photo(LOBED_SEED + i, size=SIZE, lobed_preset=preset)
        t0 = time.perf_counter()
        try:
            fit = fit_image(sp.image, dpi=sp.dpi)
        except LeafviewError as exc:
            rows.append({"seed": LOBED_SEED + i, "preset": preset, "error": str(exc)})
            continue
        seconds = time.perf_counter() - t0
        rows.append({"seed": LOBED_SEED + i, "preset": preset, "lobed": bool(fit.report["lobed"]),
                     "iou": top_view_iou(fit.margin_pixels(), polygon_mask(sp.outline, sp.blade.shape)),
                     "base_pct": 100.0 * float(np.hypot(*(fit.outline.base - sp.base))) / sp.length_px,
                     "apex_pct": 100.0 * float(np.hypot(*(fit.outline.apex - sp.apex))) / sp.length_px,
                     "controls": fit.report.get("controls"), "seconds": seconds})
    return rows


def _lobed_summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    ok = [r for r in rows if "error" not in r]
    ious = [r.get("iou", 0.0) for r in rows] or [float("nan")]
    base = [r["base_pct"] for r in ok] or [float("nan")]
    apex = [r["apex_pct"] for r in ok] or [float("nan")]
    return {"lobed_photos": len(rows), "lobed_failed": len(rows) - len(ok),
            "lobed_detected": sum(1 for r in ok if r["lobed"]),
            "lobed_iou_median": statistics.median(ious), "lobed_iou_worst": min(ious),
            "lobed_base_pct_median": statistics.median(base), "lobed_base_pct_worst": max(base),
            "lobed_apex_pct_median": statistics.median(apex), "lobed_apex_pct_worst": max(apex),
            "lobed_seconds_median": statistics.median([r["seconds"] for r in ok]) if ok else float("nan"),
            "lobed_rows": rows}


def run(quick: bool = False, ctx: moderngl.Context | None = None) -> dict[str, Any]:
    """Measure (see the module docstring); ``quick``: 2 photos."""
    count = QUICK_PHOTOS if quick else PHOTOS
    with bench_context(ctx) as c:
        info = gl_info(c)
    log_gl_renderer("fit", info["gl_renderer"])
    rows: list[dict[str, Any]] = []
    jobs = default_jobs()
    with Progress(count + 2) as progress, tempfile.TemporaryDirectory(prefix="leafview-bench-fit-") as tmp:
        paths: list[Path] = []
        for i in range(count):
            progress.step(f"photo {i + 1} of {count}")
            options = _options(i)
            sp = synthetic_photo(SEED + i, size=SIZE, **options)
            paths.append(write_photo(sp, Path(tmp) / f"photo_{i:03d}.jpg"))
            rows.append({"seed": SEED + i, **options, "face_down": sp.face_down, **_measure(sp, paths[-1])})
        # the same photos again, one worker process per core (what `leafview fit DIR` does): the
        # rate once the first fit is back, and the pool's start-up (the first fit's wait) apart
        progress.step(f"the {count} photos in {jobs} worker processes")
        t0 = time.perf_counter()
        results = fit_photos(paths, [p.stem for p in paths], jobs=jobs)
        pooled = [next(results)]
        t1 = time.perf_counter()
        pooled += list(results)
        pooled_s, first_s = time.perf_counter() - t1, t1 - t0
        progress.step("the lobed photos")
        lobed = _lobed_summary(_lobed_rows(QUICK_PHOTOS if quick else LOBED_PHOTOS))
    ok = [r for r in rows if "error" not in r]
    ious = [r["iou"] if "error" not in r else 0.0 for r in rows]
    base = [r["base_pct"] for r in ok] or [float("nan")]
    apex = [r["apex_pct"] for r in ok] or [float("nan")]
    total = sum(r["seconds"] for r in rows)
    stages = {k: statistics.median(r["stage_seconds"][k] for r in ok) for k in ok[0]["stage_seconds"]} if ok else {}
    face = _face_counts(ok)
    return {**info, "quick": quick, "goals": GOALS, "photos": count, "size": list(SIZE), "failed": count - len(ok),
            "iou_median": statistics.median(ious), "iou_worst": min(ious),
            "base_pct_median": statistics.median(base), "base_pct_worst": max(base),
            "apex_pct_median": statistics.median(apex), "apex_pct_worst": max(apex),
            "photos_per_s": count / total if total > 0 else 0.0,
            "jobs": jobs, "photos_per_s_pooled": (count - 1) / pooled_s if count > 1 else 1.0 / first_s,
            "pool_first_s": first_s, "photos_per_s_pooled_overall": count / (first_s + pooled_s),
            "pooled_failed": sum(1 for f in pooled if isinstance(f, str)),
            "cpu_ms": 1e3 * sum(r["cpu_s"] for r in rows) / count, "stage_ms": {k: 1e3 * v for k, v in stages.items()},
            "asymmetric_fits": sum(1 for r in ok if r["asymmetric"]), **face, "rows": rows, **lobed}


def _face_counts(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Which side faces the camera (:func:`leafview.fit.photo_face.detect_face`) against each
    photo's truth (``face_down``): right, wrong and unknown, all and split by the true face."""
    out: dict[str, Any] = {}
    for key, subset in (("face", rows), ("face_up", [r for r in rows if not r["face_down"]]),
                        ("face_down", [r for r in rows if r["face_down"]])):
        truth = ["down" if r["face_down"] else "up" for r in subset]
        found = [r["face_detected"] for r in subset]
        out[f"{key}_right"] = sum(1 for t, f in zip(truth, found) if f == t)
        out[f"{key}_unknown"] = sum(1 for f in found if f == "unknown")
        out[f"{key}_wrong"] = len(subset) - out[f"{key}_right"] - out[f"{key}_unknown"]
    return out


def format_table(res: dict[str, Any]) -> str:
    """The readable report printed by ``leafview bench fit``."""
    g = res["goals"]

    def mark(ok: bool) -> str:
        return "met" if ok else "NOT met"

    lines = [f"leafview photo fit benchmark{' (quick)' if res['quick'] else ''}: {res['photos']} synthetic photos of "
             f"{res['size'][0]}×{res['size'][1]} (JPEG; kinds, papers and petioles mixed); GL {res['gl_renderer']}",
             f"  IoU with the true outline, median   {res['iou_median']:.4f}  (goal ≥ {g['iou_median']:g}: "
             f"{mark(res['iou_median'] >= g['iou_median'])})",
             f"  IoU, worst photo                    {res['iou_worst']:.4f}  (goal ≥ {g['iou_worst']:g}: "
             f"{mark(res['iou_worst'] >= g['iou_worst'])})",
             f"  base found, median / worst          {res['base_pct_median']:.2f} % / {res['base_pct_worst']:.2f} % of the"
             f" length  (goal ≤ {g['landmark_pct']:g} %: {mark(res['base_pct_worst'] <= g['landmark_pct'])})",
             f"  apex found, median / worst          {res['apex_pct_median']:.2f} % / {res['apex_pct_worst']:.2f} %  "
             f"(goal ≤ {g['landmark_pct']:g} %: {mark(res['apex_pct_worst'] <= g['landmark_pct'])})",
             f"  photos per second, one process      {res['photos_per_s']:.2f} /s  ({res['cpu_ms']:.0f} ms CPU a photo)",
             f"  photos per second, {res['jobs']} processes     {res['photos_per_s_pooled']:.2f} /s  once the first is "
             f"back (goal ≥ {g['photos_per_s']:g} /s on 2 cores: {mark(res['photos_per_s_pooled'] >= g['photos_per_s'])}); "
             f"first after {res['pool_first_s']:.2f} s (the pool's start), {res['photos_per_s_pooled_overall']:.2f} /s "
             "with it",
             "  wall time per stage, median        " + ", ".join(f"{k} {v:.0f} ms" for k, v in res["stage_ms"].items()),
             f"  failed photos {res['failed']}, fitted as two halves {res['asymmetric_fits']}",
             f"  face up or down (found against the truth)  right {res['face_right']}, wrong {res['face_wrong']}, "
             f"unknown {res['face_unknown']}  (face up: {res['face_up_right']} / {res['face_up_wrong']} / "
             f"{res['face_up_unknown']}; face down: {res['face_down_right']} / {res['face_down_wrong']} / "
             f"{res['face_down_unknown']})",
             f"  lobed photos ({res['lobed_photos']}: maple, oak, bilobed): fitted as lobed {res['lobed_detected']}, "
             f"IoU median {res['lobed_iou_median']:.4f} / worst {res['lobed_iou_worst']:.4f}, base median / worst "
             f"{res['lobed_base_pct_median']:.2f} / {res['lobed_base_pct_worst']:.2f} %, apex "
             f"{res['lobed_apex_pct_median']:.2f} / {res['lobed_apex_pct_worst']:.2f} %, "
             f"{1e3 * res['lobed_seconds_median']:.0f} ms a photo"]
    for r in res["rows"]:
        what = (f"error: {r['error'][:80]}" if "error" in r else
                f"IoU {r['iou']:.4f}  base {r['base_pct']:5.2f} %  apex {r['apex_pct']:5.2f} %  rows {r['rows']}"
                f"{'  halves' if r['asymmetric'] else ''}  face {r['face_detected']}"
                f"{'' if r['face_detected'] == ('down' if r['face_down'] else 'up') else ' (' + ('down' if r['face_down'] else 'up') + ')'}"
                f"  {1e3 * r['seconds']:.0f} ms")
        lines.append(f"    seed {r['seed']} {r['kind']:<10} {r['background']:<5} "
                     f"{'petiole' if r['petiole'] else '       '}  {what}")
    return "\n".join(lines)


# -- the figure --------------------------------------------------------------------------------------------
def write_figure(path: str | Path, *, photos: int = FIGURE_PHOTOS, cell: int = FIGURE_CELL,
                 ctx: moderngl.Context | None = None) -> Path:
    """A picture of ``photos`` synthetic photos and their fits (the fit drawn over the photo | the
    fitted leaf rendered with its texture, four photos a row) written to ``path``."""
    images: list[U8] = []
    labels: list[str] = []
    with bench_context(ctx) as c, LeafRenderer(c) as renderer, tempfile.TemporaryDirectory() as tmp:
        log_gl_renderer("fit figure", gl_info(c)["gl_renderer"])
        for i in range(photos):
            options = _options(i)
            sp = synthetic_photo(FIGURE_SEED + i, size=SIZE, **options)
            fit = fit_image(sp.image, dpi=sp.dpi, name=f"photo {i}")
            name = f"leaf{i}.front.png"
            write_image(Path(tmp) / name, texture_uint8(fit.texture))
            texture = LeafTexture(name, folder=tmp)
            images += fit_cells(fit, cell, renderer, [p.replace(texture=texture) for p in fit.parts])[1:]
            labels += [f"{options['kind']}, {options['background']}" + (" (2 halves)" if fit.asymmetric else ""),
                       fit_label(fit)]
        sheet = contact_sheet(images, labels, columns=8)
    return write_image(path, sheet, description="leafview: synthetic leaf photos and their fits")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m leafview.bench.fit_photo", description=__doc__.split("\n")[0])
    parser.add_argument("--figure", type=Path, help="write the figure of 8 photos and their fits to this PNG")
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    if args.figure is not None:
        print(f"wrote {write_figure(args.figure)}")
        return 0
    print(format_table(run(quick=args.quick)))
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
