"""Multilobed leaves (Garg & Leow 2011, sec. 5): eqs 7-9, valleys, clean joins in the rendered image."""

import dataclasses

import numpy as np
import pytest

from leafview.botany.lobes import (
    Z_STEP,
    LobedLeaf,
    load_lobed_leaf,
    lobe_leaves,
    lobe_outlines,
    lobed_from_dict,
    place_lobes,
    scale_width_exact,
    valleys,
)
from leafview.core.params import Material, ParamError
from leafview.deform.surface import control_polygons
from leafview.shapes import shapes_params


def test_lateral_lobes_follow_eqs_7_to_9():
    leaf = LobedLeaf(kind="pinnate", shape="ovate", half=4, r1=0.15, spacing=0.02, theta=(70.0, 40.0),
                     length=(0.2, 0.35), terminal="obovate", terminal_base=0.6, terminal_length=0.4)
    parts = place_lobes(leaf)
    lateral = [p for p in parts if p.role == "lateral"]
    assert len(lateral) == 8 and parts[-1].role == "terminal"
    right = sorted((p for p in lateral if p.angle < 0), key=lambda p: p.base[1])
    for i, p in enumerate(right, start=1):
        assert p.base[1] == pytest.approx(i * 0.15 + i * (i - 1) / 2 * 0.02)      # eq. 7
        assert -p.angle == pytest.approx(70.0 + (i - 1) * (40.0 - 70.0) / 3)     # eq. 8
        assert p.length == pytest.approx(0.2 + (i - 1) * (0.35 - 0.2) / 3)      # eq. 9
    left = sorted((p for p in lateral if p.angle > 0), key=lambda p: p.base[1])
    assert [p.angle for p in left] == [-p.angle for p in right]                  # mirrored
    bilobed = place_lobes(LobedLeaf(kind="bilobed", half=1, theta=(30.0, 30.0), terminal="ovate"))
    assert sorted(p.angle for p in bilobed) == [-30.0, 30.0]                       # no terminal lobe
    user = place_lobes(LobedLeaf(kind="palmate", positions=((0.0, 40.0, 0.7), (0.1, 95.0, 0.4)), terminal=""))
    assert sorted((p.base[1], abs(p.angle), p.length) for p in user)[::2] == [(0.0, 40.0, 0.7), (0.1, 95.0, 0.4)]


def test_each_part_is_a_shader_leaf_in_its_own_frame_with_ordered_z():
    maple = load_lobed_leaf("maple")
    leaves = lobe_leaves(maple)
    parts = maple.lobes()
    assert len(leaves) == len(parts) == 6
    z = [p.transform.translation[2] for p in leaves]
    assert np.all(np.diff(z) == pytest.approx(Z_STEP))    # strictly ordered levels, web lowest
    assert parts[0].role == "web" and parts[-1].role == "terminal"
    for leaf, part in zip(leaves, parts):
        assert leaf.transform.rotation[2] == part.angle and leaf.transform.scale == part.length
        tip = leaf.transform.matrix() @ [0.0, 1.0, 0.0, 1.0]   # the lobe's apex in the leaf frame
        a = np.radians(part.angle)
        np.testing.assert_allclose(tip[:2], np.add(part.base, part.length * np.array([-np.sin(a), np.cos(a)])),
                                   atol=1e-12)


def test_valleys_are_where_adjacent_margins_cross():
    maple = load_lobed_leaf("maple")
    vs = valleys(maple)
    assert len(vs) == 4 and all(v is not None for v in vs)   # 5 lobes: 4 valleys
    rings = lobe_outlines(maple)
    for v in vs:
        d = min(np.min(np.linalg.norm(r - v, axis=1)) for r in rings)
        assert d < 0.02                                   # on a margin
        assert 0.1 < np.linalg.norm(v) < 0.8              # between base and lobe tips
    far = dataclasses.replace(maple, web="", lobe_width=0.2)   # thin lobes do not meet
    assert any(v is None for v in valleys(far))


def test_scale_width_exact_scales_x_only():
    p = shapes_params("cordate")
    q = scale_width_exact(p, 0.6)
    a, b = control_polygons(p)["S-"], control_polygons(q)["S-"]
    np.testing.assert_allclose(b[:, 0], 0.6 * a[:, 0], atol=1e-12)
    np.testing.assert_allclose(b[:, 1], a[:, 1], atol=1e-12)


def test_lobed_files_name_bad_fields(tmp_path):
    good = (tmp_path / "ok.toml")
    good.write_text('lobed = 1\nkind = "palmate"\nshape = "ovate"\n')
    assert load_lobed_leaf(good).name == "ok"
    cases = {
        'lobed = 1\nkind = "whorled"\n': "kind: unknown kind 'whorled'",
        'lobed = 1\nshape = "ovatee"\n': "shape: unknown catalogue shape 'ovatee'",
        'lobed = 1\nhalf = 0\n': "half: expected a whole number",
        'lobed = 1\ntheta = [1.0]\n': "theta: expected two finite numbers",
        'lobed = 1\nsize = 3\n': "size: unknown key",
        'lobed = 1\nlength = [0.5, -0.2]\n': "length[1]: lobe length must be > 0",
        'lobed = 1\n[material]\nfront = [2.0, 0.0, 0.0]\n': "material.front[0]",
        'kind = "palmate"\n': "lobed = 1",
        'lobed = 1\nkind = \n': "TOML syntax error",
    }
    for text, message in cases.items():
        path = tmp_path / "bad.toml"
        path.write_text(text)
        with pytest.raises(ParamError) as err:
            load_lobed_leaf(path)
        assert message in str(err.value) and str(path) in str(err.value), str(err.value)
    with pytest.raises(ParamError, match="built-in: .*maple"):
        load_lobed_leaf("mapel")
    assert lobed_from_dict({"lobed": 1, "kind": "bilobed", "half": 1}).kind == "bilobed"


# -- rendered ------------------------------------------------------------------------------------
def _mask_and_union(leaf, size, gl):
    """The rendered coverage (flat top view) and the union of the part outlines rasterised the same
    way (the top view frames the drawn vertices' xy box into 90 % of the image)."""
    from matplotlib.path import Path as MplPath

    from leafview.gpu.sheets import render_leaves

    leaves = lobe_leaves(leaf)
    img = render_leaves(leaves, (size, size), "top", flat=True, renderer=gl)
    rings = lobe_outlines(leaf)
    pts = np.vstack(rings)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    scale = 0.9 * size / (hi - lo).max()
    centre = (lo + hi) / 2
    ys, xs = np.mgrid[0:size, 0:size] + 0.5
    q = np.c_[(xs.ravel() - size / 2) / scale + centre[0], (size / 2 - ys.ravel()) / scale + centre[1]]
    inside = np.stack([MplPath(r).contains_points(q).reshape(size, size) for r in rings])
    return img, inside


@pytest.mark.gl
@pytest.mark.parametrize("name", ["maple", "oak"])
def test_rendered_lobed_leaf_is_the_union_without_cracks(gl, name):
    from scipy import ndimage

    img, inside = _mask_and_union(load_lobed_leaf(name), 160, gl)
    mask = img[..., 3] > 127
    union = inside.any(axis=0)
    iou = (mask & union).sum() / (mask | union).sum()
    assert iou > 0.97, f"{name}: rendered vs union of lobe outlines IoU {iou:.3f}"
    assert ndimage.label(mask)[1] == 1                           # one piece
    assert (ndimage.binary_fill_holes(mask) == mask).all()       # no cracks or pinholes inside


@pytest.mark.gl
def test_overlaps_resolve_by_the_z_order_not_by_z_fighting(gl):
    """Each part gets its own flat colour; wherever two parts overlap, the pixel shows the part
    drawn higher, in every such pixel."""
    maple = load_lobed_leaf("maple")
    parts = maple.lobes()
    rng = np.random.default_rng(2)
    colours = rng.uniform(0.05, 0.95, (len(parts), 3))
    base = lobe_leaves(maple)
    leaves = [p.replace(material=Material(front=tuple(c), back=tuple(c))) for p, c in zip(base, colours)]

    from leafview.gpu.sheets import render_leaves

    img = render_leaves(leaves, (160, 160), "top", flat=True, renderer=gl)
    _, inside = _mask_and_union(maple, 160, gl)
    rgb = img[..., :3].astype(float) / 255.0
    srgb = np.where(colours <= 0.0031308, 12.92 * colours, 1.055 * colours ** (1 / 2.4) - 0.055)
    label = np.argmin(((rgb[:, :, None, :] - srgb[None, None]) ** 2).sum(-1), axis=-1)
    from scipy import ndimage

    # pixels two or more pixels away from every part's outline (edges may straddle a pixel, and
    # the framing here is rebuilt from the outlines, not from the drawn vertices)
    edge = np.zeros(inside.shape[1:], bool)
    for k in range(len(parts)):
        edge |= ndimage.binary_dilation(inside[k], iterations=2) & ~ndimage.binary_erosion(inside[k], iterations=2)
    # and away from the midribs, which leaf.frag draws as a lighter line (a colour of its own)
    size = inside.shape[1]
    pts = np.vstack(lobe_outlines(maple))
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    scale, centre = 0.9 * size / (hi - lo).max(), (lo + hi) / 2
    ys, xs = np.mgrid[0:size, 0:size] + 0.5
    q = np.c_[(xs.ravel() - size / 2) / scale + centre[0], (size / 2 - ys.ravel()) / scale + centre[1]]
    for leaf in base:
        m = leaf.transform.matrix()
        a, b = m[:2, 3], (m @ [0.0, 1.0, 0.0, 1.0])[:2]
        t = np.clip((q - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
        dist = np.linalg.norm(q - (a + t[:, None] * (b - a)), axis=1) * scale
        edge |= (dist < 2.5).reshape(size, size)
    owner = np.full(inside.shape[1:], -1)
    for k in range(len(parts)):                      # parts are listed lowest first
        owner = np.where(inside[k], k, owner)
    checked = 0
    for a in range(len(parts)):
        for b in range(a + 1, len(parts)):
            both = inside[a] & inside[b] & ~edge
            if both.sum() < 5:
                continue
            assert (label[both] == owner[both]).mean() > 0.995, (parts[a], parts[b])
            checked += 1
    assert checked >= 4
