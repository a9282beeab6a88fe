"""The sec. 6 edits return new, valid parameters that change exactly what they say."""

import numpy as np
import pytest

from leafview.core.edits import curve_axis, curve_longitudinal, scale_width, set_silhouette_point, skew_axis
from leafview.core.params import LeafParams, ParamError
from leafview.deform.surface import evaluate


def test_scale_width_scales_lateral_extent():
    p = LeafParams()
    q = scale_width(p, 1.5)
    u, v = np.linspace(-1, 1, 21), np.full(21, 0.5)
    np.testing.assert_allclose(evaluate(q, u, v)[:, 0], 1.5 * evaluate(p, u, v)[:, 0], atol=1e-12)
    assert q.shape.vbar.tolist() == p.shape.vbar.tolist() and p.shape.xs[0] == LeafParams().shape.xs[0]
    with pytest.raises(ParamError, match="factor"):
        scale_width(p, 0)


def test_skew_axis_moves_only_the_axis_in_plane():
    p = skew_axis(LeafParams(), 0.1, 0.05)
    assert p.shape.a1[0] == pytest.approx(0.1) and p.shape.a2[0] == pytest.approx(0.05)
    assert p.shape.a1[1:] == LeafParams().shape.a1[1:]
    mid = evaluate(p, 0.0, 0.5)[0]
    assert mid[0] > 0.05 and abs(mid[2]) < 1e-15  # the midrib bows towards +x, stays in plane


def test_set_silhouette_point_and_order_check():
    p = set_silhouette_point(LeafParams(), 1, v=0.45, x=0.6)
    assert p.shape.silhouette[1][:2] == (0.45, 0.6)
    with pytest.raises(ParamError, match=r"shape\.silhouette\[1\]\[0\].*increasing"):
        set_silhouette_point(LeafParams(), 1, v=0.1)
    with pytest.raises(ParamError, match="index"):
        set_silhouette_point(LeafParams(), 3, x=0.1)


def test_curve_axis_lifts_the_whole_blade():
    p = curve_axis(LeafParams(), 0.2)
    z = evaluate(p, np.linspace(-1, 1, 9), np.full(9, 0.5))[:, 2]
    assert np.all(z > 0.1)  # every point of the cross-section rises with the axis


def test_curve_longitudinal_rolls_the_halves():
    peaks = {}
    for curve in ("S", "F", "G"):
        p = curve_longitudinal(LeafParams(), curve, 0.1)
        z = evaluate(p, np.linspace(-1, 1, 17), np.full(17, 0.5))[:, 2]
        assert np.all(z[1:8] > 0) and np.all(z[9:16] > 0)  # both halves rise ...
        np.testing.assert_allclose(z, z[::-1], atol=1e-12)  # ... symmetrically
        assert z[8] == pytest.approx(0.0, abs=1e-12)  # the midrib stays
        assert (z[16] > 0) == (curve == "S")  # only S moves the margin
        peaks[curve] = int(np.argmax(z[8:]))
    assert peaks["F"] < peaks["G"] < peaks["S"]  # F sits at 1/3 width, G at 2/3 (eq. 4)
    with pytest.raises(ParamError, match="curve"):
        curve_longitudinal(LeafParams(), "X", 0.1)
