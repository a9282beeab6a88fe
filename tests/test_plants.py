"""Plant and scatter generators (leafview.scene.plants, leafview.scene.stems): counts,
determinism, proper leaf matrices, petiole attachment, phyllotaxis, size falloff, light facing,
ground clearance, layouts, stem meshes and input errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from leafview.core.params import ParamError
from leafview.scene.plants import (
    LEAF_BOX,
    PETIOLE_LIMIT,
    PETIOLE_SIDES,
    PHYLLOTAXIS,
    Placement,
    PlantSpec,
    auto_twigs,
    divergence,
    grow_plant,
    scatter,
)
from leafview.scene.stems import soft_floor, transport_frames

LIGHT = np.array([0.3, -0.4, 1.0]) / np.linalg.norm([0.3, -0.4, 1.0])


def _column(spec: PlantSpec) -> PlantSpec:
    """The same spec with leaves straight on a vertical trunk (no branches, lean or noise)."""
    return PlantSpec(**{**spec.to_dict(), "branches": 0, "lean": 0.0, "variation": 0.0,
                        "light": tuple(spec.light)})


def _azimuths(pl: Placement) -> np.ndarray:
    """Azimuth (degrees) of each leaf base around the plant's vertical trunk."""
    d = pl.matrices[:, :3, 3] - pl.plant_origins[pl.plant]
    return np.degrees(np.arctan2(d[:, 1], d[:, 0]))


def _wrap(a: np.ndarray) -> np.ndarray:
    return np.mod(a, 360.0)


def _blade_low(m: np.ndarray) -> np.ndarray:
    corners = np.array(np.meshgrid(*LEAF_BOX, indexing="ij")).reshape(3, -1)   # (3, 8)
    return (np.einsum("nij,jk->nik", m[:, :3, :3], corners) + m[:, :3, 3:4])[:, 2].min(axis=1)


# ---------------------------------------------------------------------------------------------
# counts and determinism
@pytest.mark.parametrize("n", [1, 2, 7, 61, 2000])
def test_grow_plant_exact_count(n):
    pl = grow_plant(PlantSpec(), n, seed=5)
    assert len(pl) == n
    assert pl.matrices.shape == (n, 4, 4) and pl.matrices.dtype == np.float64
    assert pl.plant.dtype == np.int32 and np.all(pl.plant == 0)
    assert pl.along.dtype == np.float32 and pl.height.dtype == np.float32
    assert pl.plant_origins.shape == (1, 3)
    assert np.isfinite(pl.matrices).all()


@pytest.mark.parametrize("layout,n", [("plant", 333), ("field", 12_345), ("hedge", 9_001), ("field", 3)])
def test_scatter_exact_count_and_determinism(layout, n):
    a = scatter(layout, n, seed=11)
    b = scatter(layout, n, seed=11)
    c = scatter(layout, n, seed=12)
    assert len(a) == n
    for name in ("matrices", "plant", "along", "height", "plant_origins"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    for x, y in zip(a.stems, b.stems):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a.matrices, c.matrices)
    assert np.all(np.diff(a.plant) >= 0)                      # sorted by plant
    assert set(np.unique(a.plant)) <= set(range(len(a.plant_origins)))


def test_default_plant_count_and_split():
    pl = scatter("field", 20_000, seed=1)
    assert len(pl.plant_origins) == 10
    counts = np.bincount(pl.plant, minlength=10)
    assert counts.sum() == 20_000 and counts.min() > 1000   # ~2000 a plant, varying with size
    assert len(scatter("hedge", 10, seed=1, plants=4).plant_origins) == 4


# ---------------------------------------------------------------------------------------------
# leaf matrices
@pytest.mark.parametrize("mode", PHYLLOTAXIS)
def test_matrices_are_proper_similarities(mode):
    pl = scatter("field", 4000, seed=3, spec=PlantSpec(phyllotaxis=mode), plants=3)
    r = pl.matrices[:, :3, :3]
    s = pl.sizes
    rtr = np.einsum("nki,nkj->nij", r, r)
    np.testing.assert_allclose(rtr, (s**2)[:, None, None] * np.eye(3), atol=1e-9)
    assert np.all(np.linalg.det(r) > 0)
    np.testing.assert_array_equal(pl.matrices[:, 3], np.tile([0.0, 0.0, 0.0, 1.0], (len(pl), 1)))


def test_petiole_ends_at_the_blade_base():
    pl = grow_plant(PlantSpec(), 500, seed=2)
    start, stop = pl.stem_ranges["petioles"]
    assert stop - start == len(pl) * 2 * PETIOLE_SIDES
    rings = pl.stems[0][start:stop].astype(np.float64).reshape(len(pl), 2, PETIOLE_SIDES, 3)
    tip = rings[:, 1].mean(axis=1)
    np.testing.assert_allclose(tip, pl.matrices[:, :3, 3], atol=2e-5 * (1 + np.abs(tip).max()))
    base = rings[:, 0].mean(axis=1)
    length = np.linalg.norm(tip - base, axis=1)
    assert np.all(length > 0.2 * PlantSpec().petiole * pl.sizes)   # a real stalk, not a point


def test_no_petioles_for_large_counts_and_stems_off():
    pl = scatter("plant", PETIOLE_LIMIT + 1, seed=0)
    assert "petioles" not in pl.stem_ranges and "twigs" in pl.stem_ranges
    assert scatter("plant", 50, seed=0, stems=False).stems is None


def test_scale_scales_everything():
    spec = PlantSpec()
    a = grow_plant(spec, 300, seed=9, scale=1.0)
    b = grow_plant(spec, 300, seed=9, scale=2.0)
    np.testing.assert_allclose(b.matrices[:, :3, :], 2.0 * a.matrices[:, :3, :], atol=1e-9)
    np.testing.assert_allclose(b.stems[0], 2.0 * a.stems[0], rtol=1e-6, atol=1e-5)


def test_origin_translates():
    a = grow_plant(PlantSpec(), 100, seed=4)
    b = grow_plant(PlantSpec(), 100, seed=4, origin=(10.0, -3.0, 0.0))
    np.testing.assert_allclose(b.matrices[:, :3, 3] - a.matrices[:, :3, 3], np.tile([10.0, -3.0, 0.0], (100, 1)),
                               atol=1e-9)
    np.testing.assert_array_equal(b.plant_origins, [[10.0, -3.0, 0.0]])


# ---------------------------------------------------------------------------------------------
# phyllotaxis, size, tilt, light
@pytest.mark.parametrize("mode,whorl", [("golden", 3), ("alternate", 3), ("opposite", 3), ("whorled", 3),
                                        ("whorled", 5)])
def test_divergence_between_successive_leaves(mode, whorl):
    spec = _column(PlantSpec(phyllotaxis=mode, whorl=whorl))
    pl = grow_plant(spec, 60, seed=1)
    k = spec.per_node
    az = _azimuths(pl)
    z = pl.matrices[:, 2, 3] - pl.matrices[:, :3, 3][:, 2] * 0       # leaf base heights
    nodes = az.reshape(-1, k)                                       # 60 is a multiple of 1, 2, 3, 5
    # leaves of one node: evenly spaced by 360/k, all on the same level of the trunk
    for slot in range(1, k):
        np.testing.assert_allclose(_wrap(nodes[:, slot] - nodes[:, 0]), slot * 360.0 / k, atol=1e-6)
    # successive nodes: turned by the divergence angle
    expected = {"golden": 137.50776405, "alternate": 180.0, "opposite": 90.0, "whorled": 180.0 / whorl}[mode]
    assert divergence(spec) == pytest.approx(expected)
    np.testing.assert_allclose(_wrap(np.diff(nodes[:, 0])), expected, atol=1e-6)
    assert np.all(np.diff(z.reshape(-1, k)[:, 0]) > 0)            # nodes climb the trunk


def test_divergence_survives_curved_axes():
    """Frames carried by rotation-minimising transport: a vector's azimuth measured in the frame
    does not drift along a curved (helical) spine."""
    s = np.linspace(0.0, 4.0 * np.pi, 200)
    helix = np.stack([np.cos(s), np.sin(s), 0.5 * s], axis=1)[None]
    t = np.diff(helix, axis=1)
    t /= np.linalg.norm(t, axis=2, keepdims=True)
    n, b = transport_frames(t, np.array([[0.0, 0.0, 1.0]]))
    np.testing.assert_allclose(np.einsum("aki,aki->ak", n, t), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(n, axis=2), 1.0, atol=1e-12)
    # minimal rotation: successive normals never twist about the tangent
    twist = np.einsum("aki,aki->ak", np.cross(n[:, :-1], n[:, 1:]), t[:, 1:])
    assert np.abs(twist).max() < 1e-3


def test_leaves_shrink_towards_tips():
    pl = grow_plant(_column(PlantSpec(size_falloff=0.6)), 40, seed=0)
    s = pl.sizes
    assert np.all(np.diff(s) < 0)                                   # strictly, base to tip
    np.testing.assert_allclose(s, 1.0 - 0.6 * pl.along.astype(np.float64), rtol=1e-6)  # along is float32
    tree = grow_plant(PlantSpec(), 2000, seed=0)
    assert np.corrcoef(tree.along, tree.sizes)[0, 1] < -0.5
    assert tree.sizes.max() <= 1.0 * (1 + PlantSpec().variation) + 1e-9
    assert 0.0 <= tree.along.min() and tree.along.max() <= 1.0
    assert 0.0 <= tree.height.min() and tree.height.max() == pytest.approx(1.0)


def test_tilt_more_upright_at_the_top():
    spec = PlantSpec(light_following=0.0, leaf_jitter=0.0, tilt=20.0, tilt_top=70.0)
    pl = grow_plant(spec, 2000, seed=8)
    y = pl.matrices[:, :3, 1] / pl.sizes[:, None]
    elevation = np.degrees(np.arcsin(np.clip(y[:, 2], -1, 1)))
    np.testing.assert_allclose(elevation, 20.0 + 50.0 * pl.height, atol=1e-6)


def test_leaves_face_the_light():
    facing = {}
    for f in (0.0, 0.6, 1.0):
        pl = scatter("field", 6000, seed=4, spec=PlantSpec(light_following=f), plants=3)
        facing[f] = float(np.mean(pl.normals @ LIGHT))
    assert facing[0.0] > 0.4                 # blades held up, upper side roughly skywards (0.53)
    assert facing[0.0] < facing[0.6] < facing[1.0]
    assert facing[1.0] == pytest.approx(1.0, abs=1e-9)   # fully turned: normal = light
    side = PlantSpec(light=(1.0, 0.0, 0.2), light_following=0.8)
    n = grow_plant(side, 500, seed=1).normals
    assert np.mean(n[:, 0]) > 0.6            # a low light from +x turns the blades sideways


# ---------------------------------------------------------------------------------------------
# ground and shape of the plant
@pytest.mark.parametrize("spec", [
    PlantSpec(),
    PlantSpec(crown_base=0.0, branch_angle=115.0, gravitropism=-1.0, height=3.0, light=(1, 0, -0.2),
              light_following=1.0),
    PlantSpec(branches=0, crown_base=0.0, height=2.0, tilt=-80, tilt_top=-80, light_following=0.0),
    PlantSpec(phyllotaxis="whorled", whorl=6, branches=40, twigs=10, gravitropism=-0.8, branch_angle=100),
], ids=["default", "weeping-shrub", "drooping-column", "whorled-weeping"])
def test_everything_above_the_ground(spec):
    pl = scatter("field", 3000, seed=6, spec=spec, plants=2)
    assert np.isfinite(pl.matrices).all()
    assert _blade_low(pl.matrices).min() > 0.0
    wood = pl.stems[0][pl.stem_ranges["trunks"][1]:]
    assert wood[:, 2].min() > 0.0                                   # branches, twigs, petioles
    # the trunk's bottom ring is perpendicular to the (leaning) trunk: it dips at most r sin(lean)
    trunk = pl.stems[0][:pl.stem_ranges["trunks"][1]]
    assert trunk[:, 2].min() >= -spec.radius * math.sin(math.radians(spec.lean)) - 1e-6


def test_soft_floor():
    z = np.linspace(-5.0, 5.0, 1001)
    f = soft_floor(z, 0.5)
    assert np.all(f > 0) and np.all(np.diff(f) > 0)
    np.testing.assert_array_equal(f[z >= 0.5], z[z >= 0.5])
    np.testing.assert_allclose(np.gradient(f, z)[np.abs(z - 0.5) < 0.02], 1.0, atol=0.05)


def test_branching_structure():
    spec = PlantSpec(twigs=5)
    pl = grow_plant(spec, 1500, seed=2)
    r = pl.stem_ranges
    assert (r["trunks"][1] - r["trunks"][0]) % 12 == 0           # 12-sided rings
    assert (r["branches"][1] - r["branches"][0]) == spec.branches * 7 * 6
    assert (r["twigs"][1] - r["twigs"][0]) == spec.branches * 5 * 5 * 4
    # crown: leaves sit around the trunk, above the crown base, within reach of the branches
    base = pl.matrices[:, :3, 3]
    assert base[:, 2].min() > spec.crown_base * spec.height * 0.8
    assert np.hypot(base[:, 0], base[:, 1]).max() < spec.height
    assert auto_twigs(PlantSpec(), 20_000) > auto_twigs(PlantSpec(), 2000) > auto_twigs(PlantSpec(), 100)
    assert auto_twigs(PlantSpec(twigs=3), 20_000) == 3 and auto_twigs(PlantSpec(branches=0), 5000) == 0


def test_stem_mesh_is_valid_and_faces_outwards():
    pl = grow_plant(PlantSpec(), 300, seed=1)
    pos, nrm, idx = pl.stems
    assert pos.dtype == np.float32 and nrm.dtype == np.float32 and idx.dtype == np.uint32
    assert idx.shape[1] == 3 and idx.max() < len(pos)
    np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-5)
    tri = pos[idx].astype(np.float64)
    face = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    vn = nrm[idx].astype(np.float64).sum(axis=1)
    big = np.linalg.norm(face, axis=1) > 1e-10
    assert np.mean(np.einsum("ij,ij->i", face[big], vn[big]) > 0) > 0.999   # counter-clockwise outside
    # trunk: radius tapers from `radius` at the ground to radius (1 - taper) at the top
    t0, t1 = pl.stem_ranges["trunks"]
    rings = pos[t0:t1].astype(np.float64).reshape(-1, 12, 3)
    radius = np.linalg.norm(rings - rings.mean(axis=1, keepdims=True), axis=2).mean(axis=1)
    np.testing.assert_allclose(radius[[0, -1]], [0.15, 0.15 * 0.3], rtol=1e-4)


# ---------------------------------------------------------------------------------------------
# layouts
def test_hedge_plants_touch_along_a_line():
    pl = scatter("hedge", 8000, seed=3, plants=5)
    o = pl.plant_origins
    assert np.all(np.diff(o[:, 0]) > 0) and np.abs(o[:, 1]).max() < 0.2 * np.ptp(o[:, 0])
    x = pl.matrices[:, 0, 3]
    lo = np.array([np.min(x[pl.plant == i] - pl.sizes[pl.plant == i]) for i in range(5)])
    hi = np.array([np.max(x[pl.plant == i] + pl.sizes[pl.plant == i]) for i in range(5)])
    np.testing.assert_allclose(hi[:-1], lo[1:], atol=1e-9)         # each crown meets the next
    assert abs(lo[0] + hi[-1]) < 1e-9                             # centred on the origin
    even = scatter("hedge", 8000, seed=3, plants=5, extent=50.0)
    np.testing.assert_allclose(np.diff(even.plant_origins[:, 0]), 10.0, atol=1e-9)


def test_field_fills_the_square_and_scales_vary():
    pl = scatter("field", 50_000, seed=7, plants=25, extent=40.0)
    o = pl.plant_origins
    assert np.abs(o[:, :2]).max() <= 20.0 and np.all(o[:, 2] == 0.0)
    d = np.linalg.norm(o[:, None, :2] - o[None, :, :2], axis=2) + np.eye(25) * 1e9
    assert d.min() > 0.4 * 40.0 / 5                              # one plant per grid cell
    trunk_h = np.array([pl.height[pl.plant == i].size for i in range(25)])
    assert trunk_h.min() != trunk_h.max()
    size = np.array([pl.sizes[pl.plant == i].max() for i in range(25)])
    assert 0.75 < size.min() < size.max() < 1.2 * 1.2 * (1 + PlantSpec().variation)
    assert size.max() / size.min() > 1.1                          # ±20 % plant scales


@pytest.mark.slow
def test_a_million_leaves():
    pl = scatter("field", 1_000_000, seed=1)
    assert len(pl) == 1_000_000 and np.isfinite(pl.matrices).all()
    assert len(pl.plant_origins) == 500
    assert "petioles" not in pl.stem_ranges and len(pl.stems[0]) < 2_000_000
    assert _blade_low(pl.matrices[::97]).min() > 0.0


# ---------------------------------------------------------------------------------------------
# errors
@pytest.mark.parametrize("kwargs,path", [
    ({"phyllotaxis": "spiral"}, "plant.phyllotaxis"), ({"whorl": 1}, "plant.whorl"),
    ({"whorl": 2.5}, "plant.whorl"), ({"height": 0.0}, "plant.height"), ({"height": float("nan")}, "plant.height"),
    ({"branches": -1}, "plant.branches"), ({"branches": True}, "plant.branches"),
    ({"branch_angle": 150}, "plant.branch_angle"), ({"leaf_size": -1}, "plant.leaf_size"),
    ({"size_falloff": 1.0}, "plant.size_falloff"), ({"light": (0, 0, 0)}, "plant.light"),
    ({"light": (1, 2)}, "plant.light"), ({"light": (1, "x", 2)}, "plant.light[1]"),
    ({"light_following": 1.5}, "plant.light_following"), ({"tilt": 95}, "plant.tilt"),
    ({"twigs": -2}, "plant.twigs"), ({"gravitropism": 2}, "plant.gravitropism"),
    ({"variation": "lots"}, "plant.variation"),
])
def test_bad_spec_names_the_field(kwargs, path):
    with pytest.raises(ParamError) as err:
        PlantSpec(**kwargs)
    assert err.value.path == path
    assert path in str(err.value)


@pytest.mark.parametrize("call,path", [
    (lambda: scatter("forest", 10, 0), "layout"), (lambda: scatter("field", 0, 0), "n_leaves"),
    (lambda: scatter("field", 10, -1), "seed"), (lambda: scatter("plant", 10, 0, plants=3), "plants"),
    (lambda: scatter("field", 10, 0, plants=0), "plants"), (lambda: scatter("field", 10, 0, extent=-1), "extent"),
    (lambda: grow_plant(PlantSpec(), 2.5, 0), "n_leaves"), (lambda: grow_plant(PlantSpec(), 5, 0, scale=0), "scale"),
    (lambda: grow_plant(PlantSpec(), 5, 0, origin=(0, 0)), "origin"),
    (lambda: grow_plant({"height": 3}, 5, 0), "plant"),
])
def test_bad_arguments_name_the_argument(call, path):
    with pytest.raises(ParamError) as err:
        call()
    assert err.value.path == path


def test_spec_accepts_integers_and_lists():
    spec = PlantSpec(height=10, light=[0, 0, 2], branches=np.int64(4))
    assert isinstance(spec.height, float) and spec.light == (0.0, 0.0, 2.0) and spec.branches == 4
    assert PlantSpec(**spec.to_dict()) == spec


# ---------------------------------------------------------------------------------------------
# the documentation figure
def phyllotaxis_figure(path: str) -> None:
    """The four modes seen from above: each leaf's outline on a bare column (drawn for
    docs/images/plant_phyllotaxis.png)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.linspace(0.0, 1.0, 24)
    outline = np.concatenate([np.stack([0.35 * np.sin(np.pi * t), t], 1),
                              np.stack([-0.35 * np.sin(np.pi * t[::-1]), t[::-1]], 1)])
    fig, axes = plt.subplots(1, 4, figsize=(8.0, 2.5), dpi=80, layout="constrained")
    for ax, mode in zip(axes, ("alternate", "opposite", "whorled", "golden")):
        spec = _column(PlantSpec(phyllotaxis=mode, whorl=3, petiole=0.6, light_following=0.0, leaf_jitter=0.0,
                                 size_falloff=0.5, tilt=10.0, tilt_top=10.0))
        pl = grow_plant(spec, 12, seed=0)
        cmap = plt.get_cmap("viridis")
        for i in range(len(pl))[::-1]:                                    # top leaves drawn last
            m = pl.matrices[i]
            pts = outline @ m[:3, :2].T + m[:3, 3]
            c = cmap(pl.height[i])
            ax.fill(pts[:, 0], pts[:, 1], color=c, alpha=0.85, lw=0.6, ec="k", zorder=10 + i)
            ax.plot([0, m[0, 3]], [0, m[1, 3]], color="0.4", lw=0.8, zorder=10 + i)
        ax.plot(0, 0, "o", color="saddlebrown", ms=5, zorder=100)
        label = f"whorled ({spec.whorl})" if mode == "whorled" else mode
        ax.set_title(f"{label}\n{divergence(spec):.1f}° per node", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlim(-1.6, 1.6)
        ax.set_ylim(-1.6, 1.6)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.savefig(path)
    plt.close(fig)


def test_phyllotaxis_figure(tmp_path):
    out = tmp_path / "phyllotaxis.png"
    phyllotaxis_figure(str(out))
    import matplotlib.image as mpimg
    img = mpimg.imread(out)
    assert img.shape[0] > 100 and img.shape[1] > 400
    assert np.ptp(img[..., :3]) > 0.5                                   # something was drawn
