"""Regenerate docs/images/export_reimport.png: four presets rendered by leafview (top row) and
the same leaves exported to .glb, read back with trimesh and drawn by matplotlib (bottom row),
from the same direction. Run from the repository root."""

import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import trimesh
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

import leafview
from leafview.export import export_leaf
from leafview.resources import builtin_presets

NAMES = ("beech", "maize", "willow", "holly")
leaves = [leafview.LeafParams.load(builtin_presets()[n]) for n in NAMES]
images = leafview.gpu.default_renderer().render_many(leaves, (200, 200), "three-quarter", background=(1, 1, 1))

fig, axes = plt.subplots(2, len(NAMES), figsize=(2.2 * len(NAMES), 4.6), dpi=100)
with tempfile.TemporaryDirectory() as tmp:
    for k, (leaf, img) in enumerate(zip(leaves, images)):
        axes[0, k].imshow(img)
        axes[0, k].set_title(f"{leaf.name}: leafview", fontsize=8)
        axes[0, k].axis("off")
        path = export_leaf(leaf, Path(tmp) / f"{leaf.name}.glb", resolution=(17, 33), length_m=1.0)
        scene = trimesh.load(path, process=False)
        mesh = scene.to_geometry() if hasattr(scene, "to_geometry") else scene.dump(concatenate=True)
        # glTF is y-up: back to leafview's z-up world for the same camera
        v = mesh.vertices @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]).T
        ax = fig.add_subplot(2, len(NAMES), len(NAMES) + k + 1, projection="3d")
        axes[1, k].axis("off")
        shade = np.clip(0.4 + 0.6 * np.abs(mesh.face_normals[:, 1]), 0, 1)[:, None]
        colour = np.clip(np.array(leaf.material.front) ** (1 / 2.2), 0, 1)
        ax.add_collection3d(Poly3DCollection(v[mesh.faces], facecolors=shade * colour, edgecolors="none"))
        lo, hi = v.min(0), v.max(0)
        c, r = (lo + hi) / 2, (hi - lo).max() / 2
        ax.set_xlim(c[0] - r, c[0] + r)
        ax.set_ylim(c[1] - r, c[1] + r)
        ax.set_zlim(c[2] - r, c[2] + r)
        ax.view_init(elev=50, azim=-90 + 35)
        ax.set_axis_off()
        ax.set_box_aspect(None, zoom=1.6)
        ax.set_title(f"{leaf.name}: .glb via trimesh", fontsize=8)
fig.tight_layout()
out = Path("docs/images/export_reimport.png")
fig.savefig(out, facecolor="white")
print("wrote", out)

# -- a small scene: exported with one node per leaf, read back by trimesh, drawn by matplotlib ---
from leafview.export import export_scene
from leafview.scene.spec import SceneSpec, build_scene

spec = SceneSpec(species=(leafview.LeafParams.load(builtin_presets()["beech"]),), layout="plant", leaves=160,
                 seed=4, variation=0.15, colour_variation=0.1, plant={"height": 6.0, "branches": 6})
scene = build_scene(spec)
with tempfile.TemporaryDirectory() as tmp:
    path = export_scene(scene, Path(tmp) / "plant.glb", resolution=(9, 17), length_m=1.0, instancing="nodes")
    loaded = trimesh.load(path, process=False)
    fig = plt.figure(figsize=(5, 5), dpi=100)
    ax = fig.add_subplot(projection="3d")
    light = np.array([0.3, 0.8, 0.5]) / np.linalg.norm([0.3, 0.8, 0.5])
    for name, geom in loaded.geometry.items():
        for node in loaded.graph.geometry_nodes[name]:
            m = loaded.graph[node][0]
            v = (geom.vertices @ m[:3, :3].T + m[:3, 3]) @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]).T
            base = np.array(geom.visual.material.baseColorFactor[:3]) / 255.0 if hasattr(geom.visual, "material") \
                and getattr(geom.visual.material, "baseColorFactor", None) is not None else np.array([0.3, 0.5, 0.2])
            tri = v[geom.faces]
            n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
            shade = 0.35 + 0.65 * np.abs(n @ np.array([light[0], light[2], light[1]]))
            colour = np.clip(base ** (1 / 2.2) * shade[:, None], 0, 1)
            ax.add_collection3d(Poly3DCollection(tri, facecolors=colour, edgecolors="none"))
    lo, hi = scene.bounds()
    lo = np.minimum(lo, [lo[0], lo[1], 0.0])          # down to the ground, where the trunk starts
    c, r = (lo + hi) / 2, (hi - lo).max() / 2
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)
    ax.view_init(elev=15, azim=-60)
    ax.set_axis_off()
    ax.set_box_aspect(None, zoom=1.9)
    ax.set_title(f"{len(scene)} leaves + stems: .glb read back with trimesh", fontsize=9)
    out = Path("docs/images/export_scene.png")
    fig.savefig(out, facecolor="white")
    print("wrote", out)
