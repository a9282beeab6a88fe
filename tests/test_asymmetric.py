"""Asymmetric landmark leaves (Garg & Leow 2011, Fig. 6) through the shader: one one-sided leaf per side
(``shape.half``), each fitted to its own margin, joined along the midrib."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from leafview.botany.asymmetric import LEFT_HALF, RIGHT_HALF, shader_leaves
from leafview.botany.catalogue import combine_sides, landmark_leaf, random_instance
from leafview.botany.landmarks import outline, outline_sides
from leafview.botany.outline_fit import hausdorff
from leafview.core.params import LeafParams, ParamError
from leafview.deform.surface import evaluate


def _drawn_margin(params: LeafParams, n: int = 801) -> np.ndarray:
    v = np.linspace(0.0, 1.0, n)
    u = np.full(n, -1.0 if params.shape.half == RIGHT_HALF else 1.0)
    return evaluate(params, u, v)[:, :2]


def test_each_side_follows_its_own_margin():
    leaf = combine_sides("ovate", "obovate", name="fig6")
    fit = shader_leaves(leaf)
    assert fit.asymmetric and [p.shape.half for p in fit.parts] == [RIGHT_HALF, LEFT_HALF]
    right, left = outline_sides(leaf, 512)
    d_right = hausdorff(_drawn_margin(fit.parts[0]), right)
    d_left = hausdorff(_drawn_margin(fit.parts[1]), left)
    assert max(d_right, d_left) <= 0.01
    assert fit.error == pytest.approx(max(fit.side_errors))
    # the mean-of-sides symmetric fit (what one leaf can do) misses by far more
    from leafview.botany.outline_fit import fit_outline

    sym = fit_outline(outline(leaf, 256))
    assert sym.error > 3 * fit.error
    # the halves meet along the midrib exactly: the straight axis A(v) = (0, v, 0) at u = 0
    v = np.linspace(0, 1, 33)
    for p in fit.parts:
        np.testing.assert_allclose(evaluate(p, 0 * v, v), np.c_[0 * v, v, 0 * v], atol=1e-12)


def test_random_asymmetric_instances_and_symmetric_leaves():
    errors = []
    for seed in range(6):
        leaf = random_instance("ovate", seed, 0.2, independent_sides=True)
        assert not leaf.is_symmetric
        errors.append(shader_leaves(leaf, polish=False).error)
    assert max(errors) < 0.03          # linear fits (polish=False)
    single = shader_leaves(landmark_leaf("cordate"))
    assert not single.asymmetric and single.parts[0].shape.half == 0 and single.error <= 0.01


def test_half_is_validated_and_optional_in_files(presets):
    d = presets["ovate"].to_dict()
    assert d["shape"]["half"] == 0
    del d["shape"]["half"]                               # files written before it existed stay valid
    assert LeafParams.from_dict(d) == presets["ovate"]
    one_sided = presets["ovate"].replace(shape=replace(presets["ovate"].shape, half=-1))
    assert LeafParams.from_dict(one_sided.to_dict()) == one_sided
    for bad, message in ((2, "maximum"), (0.5, "integer"), (True, "integer")):
        d["shape"]["half"] = bad
        with pytest.raises(ParamError, match=message) as err:
            LeafParams.from_dict(d)
        assert err.value.path == "shape.half"


@pytest.mark.gl
def test_rendered_asymmetric_leaf_is_its_outline_without_a_crack(gl):
    from matplotlib.path import Path as MplPath
    from scipy import ndimage

    from leafview.gpu.sheets import render_leaves

    leaf = combine_sides("ovate", "obovate", name="fig6")
    fit = shader_leaves(leaf)
    size = 160
    img = render_leaves(list(fit.parts), (size, size), "top", flat=True, renderer=gl)
    ring = outline(leaf, 512)
    lo, hi = ring.min(axis=0), ring.max(axis=0)
    scale = 0.9 * size / (hi - lo).max()
    centre = (lo + hi) / 2
    ys, xs = np.mgrid[0:size, 0:size] + 0.5
    q = np.c_[(xs.ravel() - size / 2) / scale + centre[0], (size / 2 - ys.ravel()) / scale + centre[1]]
    inside = MplPath(ring).contains_points(q).reshape(size, size)
    mask = img[..., 3] > 127
    iou = (mask & inside).sum() / (mask | inside).sum()
    assert iou > 0.97, f"rendered vs landmark outline IoU {iou:.3f}"
    assert ndimage.label(mask)[1] == 1 and (ndimage.binary_fill_holes(mask) == mask).all()   # no crack
    # the sides differ: the mask is not mirror-symmetric about the midrib column
    mid = int(round(size / 2 - centre[0] * scale))
    w = min(mid, size - mid - 1)
    left_half, right_half = mask[:, mid - w:mid], mask[:, mid + 1:mid + 1 + w][:, ::-1]
    assert (left_half ^ right_half).mean() > 0.02
