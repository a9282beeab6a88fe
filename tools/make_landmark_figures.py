"""Regenerate docs/images/landmark_*.png: margins of the landmark model (Garg & Leow 2011) drawn as
polylines with matplotlib (no OpenGL): the catalogue (Table 1, Figs 4-5), the fit (Fig. 1b),
variation (Figs 6, 8) and morphing (Figs 10-11). Run from the repository root; prints the
smoothness figures quoted in docs/shapes.md."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from leafview.botany.catalogue import (
    catalogue,
    combine_sides,
    landmark_leaf,
    outline,
    random_instance,
)
from leafview.botany.landmarks import side_fit
from leafview.botany.morph import keyframe_path, morph_path, smoothness

FILL, EDGE = "#9cc97e", "#2d5a1b"


def draw(ax, leaf, title="", marks=True, color=FILL):
    poly = outline(leaf, 96)
    poly = np.vstack([poly, poly[:1]])
    ax.fill(poly[:, 0], poly[:, 1], color=color, ec=EDGE, lw=0.8)
    ax.plot([0, 0], [0, 1], color=EDGE, lw=0.4)
    if marks:
        for side, sign in ((leaf.right, 1.0), (leaf.left, -1.0)):
            pts, _ = side.landmarks()
            ax.plot(sign * pts[1:-1, 0], pts[1:-1, 1], ".", color="#c0392b", ms=2.5)
    ax.set_title(title, fontsize=6, pad=1)
    ax.set_aspect("equal")
    ax.set_xlim(-0.7, 0.7)
    ax.set_ylim(-0.25, 1.15)
    ax.axis("off")


def catalogue_figure(path: str) -> None:
    cat = catalogue()
    cols = 12
    rows = -(-len(cat) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(cols * 0.95, rows * 1.2))
    for ax, e in zip(axes.flat, cat):
        label = e.name if e.named else "\n".join(e.name.split("-", 1))
        draw(ax, landmark_leaf(e), label)
    for ax in axes.flat[len(cat):]:
        ax.axis("off")
    fig.tight_layout(pad=0.2, h_pad=0.1, w_pad=0.1)
    fig.savefig(path, dpi=80)


def fit_figure(path: str) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(6.0, 2.6))
    for ax, name in zip(axes, ("ovate-concave-convex", "cordate", "oblong")):
        leaf = landmark_leaf(name)
        fit = side_fit(leaf.right)
        u = np.linspace(0, 1, 200)
        curve = fit.spline(u)
        q = fit.control_points
        pts, tan = leaf.right.landmarks()
        ax.plot(curve[:, 0], curve[:, 1], color=EDGE, lw=1.5)
        ax.plot(q[:, 0], q[:, 1], "--o", color="#7f8c8d", ms=2.5, lw=0.6)
        ax.quiver(pts[:, 0], pts[:, 1], tan[:, 0], tan[:, 1], color="#c0392b", scale=9, width=0.012)
        ax.plot(pts[:, 0], pts[:, 1], "o", color="#c0392b", ms=3.5)
        ax.plot([0, 0], [0, 1], color=EDGE, lw=0.4)
        ax.set_title(f"{name}: N={len(pts)}, cond={fit.condition:.0f}", fontsize=7)
        ax.set_aspect("equal")
        ax.set_xlim(-0.1, 0.55)
        ax.set_ylim(-0.2, 1.2)
        ax.axis("off")
    fig.tight_layout(pad=0.2)
    fig.savefig(path, dpi=90)


def variation_figure(path: str) -> None:
    rows = [("ovate", [random_instance("ovate", s) for s in range(1, 6)]),  # ±20 % (Fig. 8)
            ("cordate", [random_instance("cordate", s) for s in range(1, 6)]),
            ("elliptic-concave-convex", [random_instance("elliptic-concave-convex", s, independent_sides=True)
                                         for s in range(1, 6)])]
    asym = [(combine_sides("ovate", "elliptic"), "R ovate, L elliptic"),
            (combine_sides("cordate", "ovate"), "R cordate, L ovate"),
            (landmark_leaf("elliptic", left_waist=(0.18, 0.6)), "L waist moved"),
            (combine_sides("obovate", "oblanceolate"), "R obovate, L oblanc."),
            (landmark_leaf("ovate", left_theta_a=1.2, right_theta_a=0.2), "θa 0.2 | 1.2 rad")]
    fig, axes = plt.subplots(4, 6, figsize=(6.0, 4.6))
    for r, (name, insts) in enumerate(rows):
        draw(axes[r, 0], landmark_leaf(name), name.replace("-", "\n", 1), color="#d4e6c3")
        for c, leaf in enumerate(insts, 1):
            draw(axes[r, c], leaf, f"seed {c}" + (", per side" if r == 2 else ""), marks=False)
    axes[3, 0].axis("off")
    axes[3, 0].text(0.5, 0.5, "asymmetric\n(Fig. 6)", ha="center", va="center", fontsize=7)
    for c, (leaf, label) in enumerate(asym, 1):
        draw(axes[3, c], leaf, label, marks=False)
    fig.tight_layout(pad=0.2, h_pad=0.2, w_pad=0.1)
    fig.savefig(path, dpi=90)


def morph_figure(path: str) -> dict:
    src, tgt = landmark_leaf("elliptic"), landmark_leaf("deltoid")
    ref = landmark_leaf("elliptic-extended-extended")
    frames = 8
    rows = [("linear key-framing", keyframe_path(src, tgt, [(ref, 1.0)]).frames(frames, by="parameter")),
            ("NURBS, w = 0", morph_path(src, tgt, [(ref, 0.0)]).frames(frames)),
            ("NURBS, w = 1", morph_path(src, tgt, [(ref, 1.0)]).frames(frames)),
            ("NURBS, w = 4", morph_path(src, tgt, [(ref, 4.0)]).frames(frames))]
    fig, axes = plt.subplots(len(rows), frames + 1, figsize=((frames + 1) * 0.75, len(rows) * 0.95))
    for r, (label, leaves) in enumerate(rows):
        axes[r, 0].axis("off")
        axes[r, 0].text(1.0, 0.5, label, ha="right", va="center", fontsize=6, transform=axes[r, 0].transAxes)
        for c, leaf in enumerate(leaves, 1):
            draw(axes[r, c], leaf, marks=False)
    fig.tight_layout(pad=0.2, h_pad=0.05, w_pad=0.05)
    fig.savefig(path, dpi=90)
    figures = {}
    for w in (1.0, 4.0):
        for n in (8, 50, 400):
            a = smoothness(morph_path(src, tgt, [(ref, w)]).frame_vectors(n))
            b = smoothness(keyframe_path(src, tgt, [(ref, w)]).frame_vectors(n, by="parameter"))
            figures[(w, n)] = (a, b)
    return figures


if __name__ == "__main__":
    catalogue_figure("docs/images/landmark_catalogue.png")
    fit_figure("docs/images/landmark_fit.png")
    variation_figure("docs/images/landmark_variation.png")
    figs = morph_figure("docs/images/landmark_morph.png")
    print("wrote docs/images/landmark_{catalogue,fit,variation,morph}.png")
    print("elliptic -> deltoid, reference elliptic-extended-extended (weight w), frames n:")
    print(f"{'w':>4} {'n':>4}  {'NURBS max step':>15} {'linear max step':>16} {'NURBS max turn':>15} "
          f"{'linear max turn':>16}")
    for (w, n), (a, b) in figs.items():
        print(f"{w:4.0f} {n:4d}  {a['max_step']:15.4f} {b['max_step']:16.4f} {a['max_turn']:15.3f} "
              f"{b['max_turn']:16.3f}")
