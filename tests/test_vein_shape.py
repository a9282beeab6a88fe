"""Veins carry the shape (leafview.botany.vein_shape; Hong 2005, ch. 7.1-7.2, App. B; Geng, Hu &
Zhang 2014, sec. 5.2.3): vein edits move the blade by Laplace interpolation, the ripple follows
the secondary veins, folds are refused, and the shader's vein grid lookup matches its numpy twin."""

from __future__ import annotations

import numpy as np
import pytest

from leafview.botany import vein_shape
from leafview.botany.vein_shape import GRID_N, jacobian_ratio, solve_shape, vein_grid, veins
from leafview.botany.venation import edit_slots, edited_uv, vein_tree
from leafview.core.blade import blade_partials
from leafview.core.params import Bending, Jitter, LeafParams, Ripple
from leafview.core.texture import texture_st
from leafview.core.venation import VeinEdit, Venation
from leafview.deform.surface import evaluate, normals, partials, sample_vein_grid, vein_grid_uv
from leafview.errors import ParamError
from leafview.resources import builtin_presets

RIPPLE = Ripple(enabled=True, amplitude=(0.03, 0.025), veins=40.0, fluctuation=(0.3, 0.5), interval=(0.2, 0.3))


def _leaf(preset: str = "ovate", *edits: VeinEdit, **venation: object) -> LeafParams:
    p = LeafParams.load(builtin_presets()[preset])
    return p.replace(venation=Venation(enabled=True, edits=tuple(edits), **venation))  # type: ignore[arg-type]


EDITED = (VeinEdit(vein=3, side=1, angle=6.0), VeinEdit(vein=2, side=-1, bulge=0.02))


def test_grid_convention_and_pinned_ends():
    u, v = vein_grid_uv(5, 4)
    s, t = texture_st(u, v)
    np.testing.assert_allclose(s, ((np.arange(5) + 0.5) / 5)[None, :].repeat(4, 0))
    np.testing.assert_allclose(t, ((np.arange(4) + 0.5) / 4)[:, None].repeat(5, 1))
    g = np.asarray(vein_grid(_leaf("ovate", *EDITED)))
    assert g.shape == (GRID_N, GRID_N, 4) and g.dtype == np.float32
    uu = np.linspace(-1, 1, 9)
    for end in (0.0, 1.0):   # the pinched base and apex stay closed: no displacement, w = v
        val = sample_vein_grid(g, uu, np.full(9, end))[0]
        np.testing.assert_allclose(val, np.tile([0, 0, 0, end], (9, 1)), atol=1e-12)
    # the texel centres read back their own values
    uc, vc = vein_grid_uv(GRID_N, GRID_N)
    np.testing.assert_allclose(sample_vein_grid(g, uc.ravel(), vc.ravel())[0], g.reshape(-1, 4), atol=1e-7)


def test_lookup_partials_match_finite_differences():
    g = np.asarray(vein_grid(_leaf("ovate", *EDITED)), np.float64)
    rng = np.random.default_rng(3)
    u, v = rng.uniform(-0.99, 0.99, 200), rng.uniform(0.002, 0.998, 200)
    h = 1e-7
    val, du, dv, duv = sample_vein_grid(g, u, v)
    np.testing.assert_allclose(du, (sample_vein_grid(g, u + h, v)[0] - sample_vein_grid(g, u - h, v)[0]) / (2 * h),
                               atol=2e-5 * np.abs(du).max() + 1e-6)
    np.testing.assert_allclose(dv, (sample_vein_grid(g, u, v + h)[0] - sample_vein_grid(g, u, v - h)[0]) / (2 * h),
                               atol=2e-5 * np.abs(dv).max() + 1e-6)
    cross = (sample_vein_grid(g, u, v + h)[1] - sample_vein_grid(g, u, v - h)[1]) / (2 * h)
    np.testing.assert_allclose(duv, cross, atol=2e-5 * np.abs(duv).max() + 1e-6)
    # the whole surface: displacement and the ripple on w, then bending
    p = _leaf("ovate", *EDITED).replace(ripple=RIPPLE, bending=Bending(load=10.0, twist=20.0))
    pt = partials(p, u, v, vein_grid=g)
    fd_u = (evaluate(p, u + h, v, vein_grid=g) - evaluate(p, u - h, v, vein_grid=g)) / (2 * h)
    fd_v = (evaluate(p, u, v + h, vein_grid=g) - evaluate(p, u, v - h, vein_grid=g)) / (2 * h)
    np.testing.assert_allclose(pt.Lu, fd_u, atol=1e-5)
    np.testing.assert_allclose(pt.Lv, fd_v, atol=1e-5)


def test_without_venation_the_grid_changes_nothing():
    p = LeafParams.load(builtin_presets()["ovate"]).replace(venation=Venation(), ripple=RIPPLE)
    g = vein_grid(p, 16, 12)
    assert not g[..., :3].any()
    rng = np.random.default_rng(5)
    u, v = rng.uniform(-1, 1, 300), rng.uniform(0, 1, 300)
    # (w = v stored in float32: equal to its rounding)
    np.testing.assert_allclose(evaluate(p, u, v, vein_grid=g), evaluate(p, u, v), atol=1e-7)
    np.testing.assert_allclose(normals(p, u, v, vein_grid=g), normals(p, u, v), atol=1e-5)
    # vein_grid=None is the leaf as before (same code path)
    assert np.array_equal(evaluate(p, u, v, vein_grid=None), evaluate(p, u, v))


def test_unedited_veins_give_the_ripple_coordinate_only():
    p = _leaf("ovate")
    g = vein_grid(p)
    assert not g[..., :3].any()
    tree = vein_tree(p)
    mid = tree[0]
    w = sample_vein_grid(g, mid.uv[:, 0], mid.uv[:, 1])[0][:, 3]
    np.testing.assert_allclose(w, mid.uv[:, 1], atol=0.01)       # w = v on the midrib
    for k in edit_slots(p)[1][1:6]:                            # w = v of the junction along each secondary
        sec = tree[k]
        inner = sec.uv[2:-1]
        w = sample_vein_grid(g, inner[:, 0], inner[:, 1])[0][:, 3]
        np.testing.assert_allclose(w, sec.uv[0, 1], atol=0.02)
    # parallel venation: no transverse beams, w = v
    grass = _leaf("maize", pattern="parallel")
    gg = np.asarray(vein_grid(grass, 16, 16))
    np.testing.assert_allclose(gg[..., 3], vein_grid_uv(16, 16)[1], atol=1e-6)


def test_ripple_is_constant_along_a_secondary():
    p = _leaf("ovate").replace(ripple=Ripple(enabled=True, amplitude=(0.04, 0.04), veins=40.0,
                                             fluctuation=(0.0, 0.0), interval=(0.3, 0.3)))
    g = vein_grid(p)
    flat = p.replace(ripple=Ripple())
    sec = vein_tree(p)[edit_slots(p)[1][3]]
    uv = sec.uv[3:-2]
    s = np.abs(uv[:, 0])
    tau = 1.0 - (2.0 * uv[:, 1] - 1.0) ** 4
    c = 0.5 * s * s * (3.0 - s)
    load = (evaluate(p, uv[:, 0], uv[:, 1], vein_grid=g) - evaluate(flat, uv[:, 0], uv[:, 1], vein_grid=g))[:, 2]
    r_veins = load / (tau * c)
    load_v = (evaluate(p, uv[:, 0], uv[:, 1]) - evaluate(flat, uv[:, 0], uv[:, 1]))[:, 2] / (tau * c)
    assert np.ptp(r_veins) < 0.05 * np.ptp(load_v)   # the beam carries one load; cross-sections differ


def test_edits_move_the_blade_with_the_veins():
    p = _leaf("ovate", *EDITED)
    shape = solve_shape(p)
    g = shape.texels()
    tree = shape.tree
    slots = edit_slots(p)
    k = slots[1][3]
    after = edited_uv(p)[k]
    target = blade_partials(p.replace(jitter=Jitter()), after[:, 0], after[:, 1])[0].L
    flat = p.replace(jitter=Jitter())
    moved = blade_partials(flat, tree[k].uv[:, 0], tree[k].uv[:, 1])[0].L + \
        sample_vein_grid(g, tree[k].uv[:, 0], tree[k].uv[:, 1])[0][:, :3]
    step = np.abs(target - np.asarray(vein_tree(p)[k].points)).max()
    assert step > 0.02                                            # the edit moves the vein ...
    assert np.abs(moved - target).max() < 0.1 * step              # ... and the blade goes with it
    far = tree[slots[1][7]]
    assert np.abs(sample_vein_grid(g, far.uv[:, 0], far.uv[:, 1])[0][:, :3]).max() < 1e-3   # held
    # veins(): the final surface at each vein's (u, v)
    out = veins(p.replace(ripple=RIPPLE))
    assert len(out) == len(tree)
    np.testing.assert_allclose(out[k].points, evaluate(p.replace(ripple=RIPPLE), tree[k].uv[:, 0], tree[k].uv[:, 1],
                                                       vein_grid=vein_grid(p)))
    assert jacobian_ratio(p, np.asarray(vein_grid(p)))[0] > vein_shape.MIN_JACOBIAN


def test_children_ride_with_their_parent():
    p = _leaf("ovate", VeinEdit(vein=1, side=1, angle=-2.0), pattern="palmate")
    shape = solve_shape(p)
    primary = edit_slots(p)[1][1]
    kids = [k for k, vein in enumerate(shape.tree) if vein.parent == primary and vein.order == 2]
    assert kids and all(shape.moved[k] for k in kids)
    for k in kids:   # rigid: distances between a child's points are kept
        d0 = np.linalg.norm(np.diff(shape.old[k][:, :2], axis=0), axis=1)
        d1 = np.linalg.norm(np.diff(shape.new[k][:, :2], axis=0), axis=1)
        np.testing.assert_allclose(d1, d0, rtol=1e-9, atol=1e-12)
        assert np.abs(shape.new[k] - shape.old[k]).max() > 1e-3
    vein_grid(p)   # no fold


def test_folds_are_refused_naming_the_edit():
    with pytest.raises(ParamError) as err:
        vein_grid(_leaf("ovate", VeinEdit(vein=3, side=1, angle=15.0)))
    assert err.value.path == "venation.edits[0].angle" and "folds" in str(err.value)
    # the first edit that folds is named, here the second
    with pytest.raises(ParamError) as err:
        vein_grid(_leaf("ovate", VeinEdit(vein=2, side=-1, angle=-3.0), VeinEdit(vein=3, side=1, angle=10.0)))
    assert err.value.path == "venation.edits[1].angle"
    with pytest.raises(ParamError) as err:
        vein_grid(_leaf("ovate", VeinEdit(vein=3, side=1, bulge=0.09)))
    assert err.value.path == "venation.edits[0].bulge"
    with pytest.raises(ParamError) as err:   # an edit of a vein that does not exist (H1's check)
        vein_grid(_leaf("ovate", VeinEdit(vein=40, side=1, angle=1.0)))
    assert err.value.path == "venation.edits[0].vein"


@pytest.mark.gl
def test_readback_matches_the_numpy_twin(gl):
    """leaf_eval.glsl's vein grid lookup, displacement and ripple on w against surface.py."""
    rng = np.random.default_rng(11)
    u = np.r_[rng.uniform(-1, 1, 400), -1, 1, 0, 0.3, 0.5, -0.7]
    v = np.r_[rng.uniform(0, 1, 400), 0.5, 0.5, 0, 1, 0.999, 0.004]
    base = _leaf("ovate", *EDITED).replace(ripple=RIPPLE)
    cases = [base, base.replace(bending=Bending(load=12.0, twist=30.0), jitter=Jitter(enabled=True, amplitude=0.02)),
             _leaf("ovate", VeinEdit(vein=1, side=1, angle=-2.0), pattern="palmate").replace(ripple=RIPPLE)]
    for p in cases:
        g = vein_grid(p)
        pos, nrm = gl.capture(p, u, v)
        ref = evaluate(p, u, v, vein_grid=g)
        assert np.abs(ref - evaluate(p, u, v)).max() > 0.01           # the grid does something
        assert np.abs(pos - ref).max() <= 2e-5
        assert np.sum(nrm * normals(p, u, v, vein_grid=g), axis=1).min() > 1 - 1e-4
    # a program without veins (LEAF_NO_VEINS) and a leaf drawn with veins off read no grid
    pos, _ = gl.capture(base, u, v, defines={"LEAF_NO_VEINS": 1})
    assert np.abs(pos - evaluate(base, u, v)).max() <= 2e-5
    gl.veins = False
    try:
        pos, _ = gl.capture(base, u, v)
    finally:
        gl.veins = True
    assert np.abs(pos - evaluate(base, u, v)).max() <= 2e-5
