"""Leaves drawn with their landmark margin (leafview.core.margin; Garg & Leow 2011, eqs 2-6):
the numpy surface against the landmark B-spline itself, its derivatives against finite
differences, the shader read back against the numpy surface, the record's texels, and the file
formats with their refusals."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import leafview
from leafview.botany.catalogue import catalogue_names, landmark_leaf, random_instance
from leafview.botany.landmarks import margin_params, margins, outline_sides
from leafview.core import compact
from leafview.core.margin import MARGIN_TEXELS, Margin
from leafview.core.params import LeafParams, Lobes, ParamError
from leafview.deform.surface import partials
from leafview.gpu.layout import MARGIN_ROWS, pack_leaf, pack_leaves, read_margin, read_slot, without_derived
from tests.conftest import assert_matches_reference, run_prepare

TOL = 2e-5   # leaf space, as the other readback tests


def _instances(count: int = 62, seed: int = 0) -> list:
    names = catalogue_names()
    return [random_instance(landmark_leaf(names[i % len(names)]), seed=seed + i, amount=0.2) for i in range(count)]


def _curved() -> LeafParams:
    """A template with a bent, lifted midrib and cupped heights: the margin must follow it."""
    base = LeafParams()
    shape = dataclasses.replace(base.shape, a1=(0.06, 0.3, 0.02), a2=(-0.05, 0.72, 0.05),
                                zf=(0.02, 0.03, 0.01), zg=(0.03, 0.05, 0.0))
    return base.replace(shape=shape)


def test_margin_at_the_edge_is_the_landmark_b_spline():
    """With a straight midrib the blade's edge (|u| = 1) is the landmark margin, point for point
    at the same B-spline parameter, on all 62 catalogue shapes: nothing is fitted."""
    leaves = _instances()
    worst = 0.0
    for leaf, params in zip(leaves, margin_params(leaves)):
        right, left = outline_sides(leaf, 65, spacing="parameter")
        v = np.linspace(0.0, 1.0, 65)
        edge_right = leafview.evaluate(params, -np.ones(65), v)   # u < 0 is drawn at +x: the right side
        edge_left = leafview.evaluate(params, np.ones(65), v)
        worst = max(worst, float(np.abs(edge_right[:, :2] - right).max()), float(np.abs(edge_left[:, :2] - left).max()))
        assert np.all(edge_right[:, 2] == 0.0)
    assert worst < 1e-12


def test_margin_follows_a_bent_midrib():
    """The side's x runs along the midrib's normal at the height y: at u = 0 the blade is the
    midrib, and the edge sits x away from A(y) along n(y)."""
    leaf = _instances(1, seed=7)[0]
    params = margin_params([leaf], _curved())[0]
    v = np.linspace(0.0, 1.0, 41)
    mid = leafview.evaluate(params, np.zeros_like(v), v)
    axis = np.asarray(params.shape.axis_points())
    t = v[:, None]
    a = (1 - t) ** 3 * axis[0] + 3 * (1 - t) ** 2 * t * axis[1] + 3 * (1 - t) * t * t * axis[2] + t**3 * axis[3]
    np.testing.assert_allclose(mid, a, atol=1e-12)
    xy, _ = params.margin.right.evaluate(v)
    edge = leafview.evaluate(params, -np.ones_like(v), v)
    y = xy[0][:, 1:2]
    ay = (1 - y) ** 3 * axis[0] + 3 * (1 - y) ** 2 * y * axis[1] + 3 * (1 - y) * y * y * axis[2] + y**3 * axis[3]
    assert np.abs(edge[:, :2] - ay[:, :2]).max() > 1e-3            # not the straight-midrib margin
    np.testing.assert_allclose(np.linalg.norm(edge[:, :2] - ay[:, :2], axis=1), xy[0][:, 0], atol=1e-12)


def test_partials_match_finite_differences():
    leaves = _instances(8, seed=40)
    rng = np.random.default_rng(3)
    h = 1e-6
    for params in margin_params(leaves, _curved()):
        u = rng.uniform(-0.95, 0.95, 50)
        u = np.where(np.abs(u) < 0.05, 0.3, u)
        v = rng.uniform(0.02, 0.98, 50)
        p = partials(params, u, v)
        du = (leafview.evaluate(params, u + h, v) - leafview.evaluate(params, u - h, v)) / (2 * h)
        dv = (leafview.evaluate(params, u, v + h) - leafview.evaluate(params, u, v - h)) / (2 * h)
        # a knot of the B-spline (C1 there) may fall between v - h and v + h: compare away from them
        far = np.ones_like(v, bool)
        for side in (params.margin.right, params.margin.left):
            ks = np.asarray(side.knots)
            mids = 0.5 * (ks[1:] + ks[:-1])
            far &= np.min(np.abs(v[:, None] - np.r_[ks, mids][None, :]), axis=1) > 1e-4
        np.testing.assert_allclose(p.Lu, du, atol=2e-6)
        np.testing.assert_allclose(p.Lv[far], dv[far], atol=2e-6)


@pytest.mark.gl
def test_shader_reads_back_the_numpy_surface(gl):
    """62 random catalogue instances on a bent, cupped midrib, one with jitter and ripples: the
    rendering vertex shader (transform feedback) against the numpy surface, positions and normals."""
    rng = np.random.default_rng(11)
    leaves = _instances(62, seed=100)
    worst, worst_cos = 0.0, 1.0
    template = _curved()
    params = margin_params(leaves, template)
    params[5] = params[5].replace(jitter=dataclasses.replace(params[5].jitter, enabled=True, amplitude=0.03),
                                  ripple=dataclasses.replace(params[5].ripple, enabled=True))
    for p in params:
        u = np.r_[rng.uniform(-1, 1, 300), -1, 1, 0, 0.5]
        v = np.r_[rng.uniform(0, 1, 300), 0.5, 0.5, 1, 0]
        pos, nrm = gl.capture(p, u, v)
        worst = max(worst, float(np.abs(pos - leafview.evaluate(p, u, v)).max()))
        ref = leafview.normals(p, u, v)
        inner = (v > 0.01) & (v < 0.99)
        worst_cos = min(worst_cos, float(np.sum(nrm[inner] * ref[inner], axis=1).min()))
    assert worst <= TOL, f"largest GPU/CPU difference {worst:.3g} > {TOL}"
    assert worst_cos > 1 - 1e-4


def test_record_holds_the_margin_texels():
    params = margin_params(_instances(4, seed=9))
    recs, _ = pack_leaves(params)
    assert read_slot(recs, "leaf_rows").tolist() == [MARGIN_ROWS] * 4
    for rec, p in zip(recs, params):
        np.testing.assert_array_equal(read_margin(rec), p.margin.texels())
    np.testing.assert_array_equal(read_margin(without_derived(recs)), read_margin(recs))
    plain = pack_leaf(LeafParams())
    assert read_slot(plain, "leaf_rows") == 0 and not read_margin(plain).any()


@pytest.mark.gl
def test_prepare_pass_keeps_the_margin_texels(gl):
    params = margin_params(_instances(3, seed=20))
    recs, _ = pack_leaves(params)
    out = run_prepare(gl, recs)
    np.testing.assert_array_equal(read_margin(out), read_margin(recs))
    assert read_margin(out).shape == (3, MARGIN_TEXELS, 4)
    assert np.abs(out["heights"]).sum() >= 0.0 and np.isfinite(out["axis"]).all()


def test_files_round_trip(tmp_path):
    leaf = margin_params(_instances(1, seed=3), _curved())[0]
    for name in ("m.toml", "m.json", "m.leaf.json"):
        leaf.save(tmp_path / name)
        back = LeafParams.load(tmp_path / name)
        assert back == leaf, name
    text = compact.dumps(leaf)
    assert compact.loads(text) == leaf
    assert json.loads(text)["margin"]["right"]["knots"][0] == 0


def test_symmetric_margin_may_leave_out_left():
    m = margins(_instances(1, seed=2))[0]
    doc = LeafParams(margin=m).to_dict()
    doc["margin"] = {"right": doc["margin"]["right"]}
    assert LeafParams.from_dict(doc).margin == Margin(m.right, m.right)


@pytest.mark.parametrize("edit, path", [
    (lambda d: d["margin"]["right"].update(knots=[0.0, 0.6, 0.4, 1.0]), "margin.right.knots"),
    (lambda d: d["margin"]["left"]["points"].pop(), "margin.left.points"),
    (lambda d: d["margin"]["right"]["points"].__setitem__(0, [0.1, 0.0]), "margin.right.points"),
    (lambda d: d["margin"]["right"]["points"].__setitem__(1, [float("nan"), 0.0]), "margin.right.points[1][0]"),
    (lambda d: d["margin"]["right"]["points"].__setitem__(1, "x"), "margin.right.points[1]"),
    (lambda d: d["margin"].update(middle={}), "margin.middle"),
    (lambda d: d["shape"].update(tilt=[5.0, 0.0, 0.0]), "margin"),
])
def test_bad_margins_name_the_field(edit, path):
    m = margins(_instances(1, seed=4))[0]
    doc = json.loads(json.dumps(LeafParams(margin=Margin(m.right, m.left)).to_dict()))
    edit(doc)
    with pytest.raises(ParamError) as err:
        LeafParams.from_dict(doc)
    assert err.value.path == path, err.value


def test_a_lobed_leaf_has_no_landmark_margin():
    m = margins(_instances(1, seed=5))[0]
    ring = tuple((0.4 * np.cos(a), 0.5 + 0.5 * np.sin(a)) for a in np.linspace(0, 2 * np.pi, 12, endpoint=False))
    lobes = Lobes(outline=ring)
    assert lobes.enabled
    with pytest.raises(ParamError, match="lobed"):
        LeafParams(lobes=lobes, margin=m)


@pytest.mark.gl
def test_margin_leaves_look_like_their_shapes(gl, request):
    """Cordate, obcordate, drip-tip and reniform leaves drawn from their own margins, 64 px each,
    top view (looked at: basal lobes, the apical notch and the drip tip are all there)."""
    names = ["cordate", "obcordate", "ovate-drip", "reniform"]
    params = margin_params([landmark_leaf(n) for n in names])
    tiles = gl.render_many(params, (64, 64), "top")
    img = np.concatenate(tiles, axis=1)
    for tile in tiles:
        alpha = tile[..., 3] > 0
        assert 0.15 < alpha.mean() < 0.8
    # the obcordate apex is notched: at the top of its tile the middle column is empty and the
    # columns either side are not
    ob = tiles[1][..., 3] > 0
    rows = np.nonzero(ob.any(axis=1))[0]
    cols = np.nonzero(ob.any(axis=0))[0]
    mid = (cols[0] + cols[-1]) // 2
    top = rows[0] + 2
    assert not ob[top, mid] and ob[top, cols[0]:mid].any() and ob[top, mid:cols[-1] + 1].any()
    assert_matches_reference(img, "margin_shapes", request)


def test_width_edit_scales_the_margin():
    """The artist's width edit (Chaurasia & Beardsley 2017, Fig. 7a) widens a margin leaf too:
    every edge point moves out by the factor, the midrib stays."""
    from leafview.core.edits import scale_width

    leaf = margin_params(_instances(1, seed=12))[0]
    wide = scale_width(leaf, 1.5)
    v = np.linspace(0.0, 1.0, 33)
    for u in (-1.0, 1.0):
        a = leafview.evaluate(leaf, np.full_like(v, u), v)
        b = leafview.evaluate(wide, np.full_like(v, u), v)
        np.testing.assert_allclose(b[:, 0], 1.5 * a[:, 0], atol=1e-12)
        np.testing.assert_allclose(b[:, 1], a[:, 1], atol=1e-12)


@pytest.mark.gl
@pytest.mark.parametrize("a1, a2", [((0.0, 0.0, 0.0), (0.0, 2 / 3, 0.0)), ((0.1, 1 / 3, 0.0), (0.0, 1.0, 0.0))],
                         ids=["a1-on-the-base", "a2-on-the-apex"])
def test_a_midrib_whose_tangent_vanishes_at_an_end(gl, a1, a2):
    """a1 on the base (or a2 on the apex) makes the midrib's tangent vanish there; the normal then
    takes the tangent's limit direction (core.bezier.in_plane_normal), for a margin leaf and for a
    jittered one alike: finite in numpy, equal on the GPU, and continuous into the blade."""
    from leafview.core.bezier import in_plane_normal
    from leafview.core.params import Jitter

    base = LeafParams()
    shape = dataclasses.replace(base.shape, a1=a1, a2=a2)
    leaves = [margin_params([landmark_leaf("cordate")], base.replace(shape=shape))[0],
              base.replace(shape=shape, jitter=Jitter(enabled=True, amplitude=0.05, density=20.0))]
    uv = leafview.deform.surface.grid_uv(9, 17).astype(np.float64)
    for p in leaves:
        ref = leafview.evaluate(p, uv[:, 0], uv[:, 1])
        nrm = leafview.normals(p, uv[:, 0], uv[:, 1])
        assert np.isfinite(ref).all() and np.isfinite(nrm).all()
        pos, gpu_n = gl.capture(p, uv[:, 0], uv[:, 1])
        assert np.abs(pos - ref).max() <= TOL
        assert np.isfinite(gpu_n).all()
    axis = np.asarray(shape.axis_points())
    d1 = lambda t: 3 * ((1 - t) ** 2 * (axis[1] - axis[0]) + 2 * (1 - t) * t * (axis[2] - axis[1])  # noqa: E731
                        + t * t * (axis[3] - axis[2]))
    d2 = lambda t: 6 * ((1 - t) * (axis[2] - 2 * axis[1] + axis[0]) + t * (axis[3] - 2 * axis[2] + axis[1]))  # noqa: E731
    end = 0.0 if a1 == (0.0, 0.0, 0.0) else 1.0
    near = abs(end - 1e-6)
    n_end, _ = in_plane_normal(d1(np.array([[end]])), d2(np.array([[end]])), [end])
    n_near, _ = in_plane_normal(d1(np.array([[near]])), d2(np.array([[near]])), [near])
    np.testing.assert_allclose(n_end, n_near, atol=1e-5)


@pytest.mark.gl
def test_landmark_files_load_as_margin_leaves(gl, tmp_path, capsys):
    """A landmark leaf file (``landmarks = 1``) renders and exports wherever a leaf file does,
    drawn with its own margin; a bad one is refused naming the file and the field."""
    from leafview.botany.catalogue import load_landmark_leaf
    from leafview.cli import main
    from leafview.core.io import load_leaves
    from leafview.export.images import PARAMS_ATTRIBUTE, read_image
    from leafview.resources import asset_dir

    src = asset_dir() / "landmarks" / "broad-cordate.toml"
    (leaf,) = load_leaves(src)
    assert leaf.name == "broad-cordate" and leaf.margin == margins([load_landmark_leaf(str(src))])[0]
    out = tmp_path / "bc.png"
    assert main(["render", str(src), "-o", str(out), "--size", "48"]) == 0
    _, meta = read_image(out)
    assert LeafParams.from_dict(json.loads(meta[PARAMS_ATTRIBUTE])).margin == leaf.margin
    bad = tmp_path / "bad.toml"
    bad.write_text('landmarks = 1\nname = "x"\n[right]\nwaist = [0.4, 0.5]\n', encoding="utf-8")
    capsys.readouterr()
    assert main(["render", str(bad), "-o", str(tmp_path / "bad.png")]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and "right." in err, err
    assert not (tmp_path / "bad.png").exists()
