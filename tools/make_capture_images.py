"""Make the pictures of docs/capture.md: the capture pipeline on one view of a synthetic plant, and
one occluded leaf's cloud with its fit.

    python tools/make_capture_images.py            # writes docs/images/capture_*.png

Everything is synthetic and seeded (no capture can be downloaded here): the plant is
``leafview scene --layout plant --leaves 60 --seed 3`` rendered in 4 views with depth noise and
grazing holes; the leaf is a curved ovate preset with ~30 % of one side hidden.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
from skimage.segmentation import find_boundaries

from leafview.core.params import LeafParams
from leafview.export.images import contact_sheet, write_image
from leafview.export.views import render_instance_ids, render_views
from leafview.fit.capture import capture, default_delta, leaf_coloured
from leafview.fit.cloud import fit_cloud
from leafview.fit.segment import segment_view
from leafview.fit.synthetic import curled, occluded_cloud
from leafview.fit.views import read_views
from leafview.gpu.context import create_headless_context
from leafview.resources import builtin_presets
from leafview.scene.spec import SceneSpec, build_scene

OUT = Path(__file__).resolve().parent.parent / "docs" / "images"
SIZE = (480, 360)


def _palette(n: int, seed: int = 5) -> np.ndarray:
    rng = np.random.default_rng(seed)
    colours = rng.integers(60, 256, (n + 1, 3)).astype(np.uint8)
    colours[0] = (20, 20, 24)
    return colours


def _labels(image: np.ndarray) -> np.ndarray:
    return _palette(int(image.max(initial=0)))[image]


def _depth(depth: np.ndarray) -> np.ndarray:
    d = depth.astype(np.float64)
    on = d > 0
    out = np.full((*d.shape, 3), 20, np.uint8)
    if on.any():
        lo, hi = np.percentile(d[on], [2, 98])
        t = np.clip((d - lo) / max(hi - lo, 1e-9), 0.0, 1.0)
        grey = (235 - 180 * t).astype(np.uint8)
        out[on] = np.stack([grey, grey, grey], axis=-1)[on]
    return out


def pipeline(tmp: Path) -> None:
    spec = SceneSpec(species=(LeafParams.load(builtin_presets()["ovate"]),), name="plant", leaves=60, layout="plant",
                     seed=3)
    scene = build_scene(spec)
    ctx = create_headless_context()
    try:
        render_views(ctx, scene, tmp / "views", views=4, size=SIZE, depth_noise=0.005, holes=True, seed=3)
        views = read_views(tmp / "views")
        result = capture(views, seed=0)
        view = views[0]
        masked = [leaf_coloured(v) for v in views]   # what capture() segments (leaf_colour="green")
        seg = segment_view(masked[0], 0, delta_plane=default_delta(masked))
        fitted = render_instance_ids(ctx, list(result.leaves), view.k, view.world_from_camera, SIZE)
    finally:
        ctx.release()
    sp = np.asarray(seg.labels)
    bounds = view.color.copy()
    bounds[find_boundaries(sp, mode="inner") & (sp >= 0)] = (255, 230, 60)
    cand = np.zeros(sp.shape, np.int64)
    for i, c in enumerate(seg.candidates):
        cand.ravel()[c.pixels] = i + 1
    over = view.color.copy()
    mask = fitted > 0
    over[mask] = (0.35 * view.color[mask] + 0.65 * _labels(fitted)[mask]).astype(np.uint8)
    assert view.instance is not None
    tiles = [view.color, _depth(view.depth), bounds, _labels(cand), over, _labels(view.instance)]
    labels = ["colour", "depth (noise, holes)", "SLIC superpixels", f"candidates ({len(seg.candidates)})",
              f"fitted leaves ({len(result.leaves)}, all views)", "truth instances"]
    sheet = contact_sheet([np.dstack([t, np.full(t.shape[:2], 255, np.uint8)]) for t in tiles], labels, columns=3)
    write_image(OUT / "capture_pipeline.png", sheet)


def one_leaf() -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from leafview.deform.surface import evaluate

    truth = curled(LeafParams.load(builtin_presets()["ovate"]), seed=101, length=0.08)
    case = occluded_cloud(truth, 5000, seed=101)
    fit = fit_cloud(case.cloud)
    u, v = np.meshgrid(np.linspace(-1, 1, 17), np.linspace(0, 1, 33))
    m = fit.params.transform.matrix()
    surf = evaluate(fit.params, u.ravel(), v.ravel()) @ m[:3, :3].T + m[:3, 3]
    fig = plt.figure(figsize=(5.6, 2.8), dpi=100)
    for k, (elev, azim) in enumerate(((60, -60), (5, 20))):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        ax.scatter(*case.cloud[::4].T, s=0.6, c="0.35", label="cloud")
        ax.scatter(*case.hidden[::6].T, s=0.6, c="tab:red", label="hidden truth")
        x, y, z = (surf[:, i].reshape(u.shape) for i in range(3))
        ax.plot_wireframe(x, y, z, color="tab:green", linewidth=0.4, label="fit")
        ax.view_init(elev=elev, azim=azim)
        ax.set_axis_off()
        ax.set_box_aspect(np.ptp(case.cloud, axis=0))
    handles, names = fig.axes[0].get_legend_handles_labels()
    fig.legend(handles, names, loc="lower center", ncol=3, fontsize=7, frameon=False, markerscale=6)
    fig.tight_layout()
    fig.savefig(OUT / "capture_leaf.png")
    plt.close(fig)


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="leafview-capture-images-") as tmp:
        pipeline(Path(tmp))
    one_leaf()
    print(f"wrote {OUT / 'capture_pipeline.png'} and {OUT / 'capture_leaf.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
