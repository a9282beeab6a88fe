"""Garg & Leow 2011, sec. 6: the unified leaf space (eq. 10), the NURBS morph path (eq. 11) and linear
key-framing."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from leafview.botany.catalogue import catalogue, landmark_leaf, outline
from leafview.botany.landmarks import side_fit
from leafview.botany.morph import (
    LeafSpace,
    insertion_error,
    keyframe_path,
    leaf_from_vector,
    leaf_space,
    leaf_vector,
    max_step,
    morph_path,
    smoothness,
    unify,
)
from leafview.core.params import ParamError


def test_vector_round_trip_and_dimensions():
    dims = {}
    for e in catalogue():
        leaf = landmark_leaf(e)
        v = leaf_vector(leaf)
        back = leaf_from_vector(v, leaf_space(leaf))
        assert back.right == leaf.right and back.left == leaf.left
        dims[(leaf.has_tail, leaf.has_shoulder)] = len(v)
    # per side 4 numbers, 7 with one extension, 10 with both (sec. 6.2); right and left sides
    assert dims == {(False, False): 8, (True, False): 14, (False, True): 14, (True, True): 20}
    assert LeafSpace(right_tail=True).names[4:7] == ["right.tail_x", "right.tail_y", "right.tail_angle"]


def test_vectors_need_a_matching_space():
    with pytest.raises(ParamError) as err:
        leaf_vector(landmark_leaf("ovate"), LeafSpace(True, False, True, False))
    assert err.value.path == "right.tail" and "unify" in str(err.value)
    with pytest.raises(ParamError):
        leaf_vector(landmark_leaf("cordate"), LeafSpace())
    with pytest.raises(ParamError) as err:
        leaf_from_vector(np.zeros(8), LeafSpace())
    assert err.value.path.startswith("right.")
    with pytest.raises(ParamError):
        leaf_from_vector(np.zeros(5), LeafSpace())


def _arc(spline, u0, u1):
    u = np.linspace(u0, u1, 20001)
    p = spline(u)
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def test_inserted_tail_satisfies_eq_10():
    plain, cordate = landmark_leaf("elliptic"), landmark_leaf("cordate")
    space, (a, b) = unify([plain, cordate])
    assert space == LeafSpace(True, False, True, False)
    assert b == cordate                                      # a shape that has the tail keeps it
    # the ratio L(p_t, p_w) / L(p_t, p_b) of the giver ...
    fit_b = side_fit(cordate.right)
    want = _arc(fit_b.spline, fit_b.u[1], fit_b.u[2]) / _arc(fit_b.spline, 0.0, fit_b.u[1])
    # ... is the ratio at the inserted point on the receiver's original margin
    fit_a = side_fit(plain.right)
    u = np.linspace(0.0, fit_a.u[1], 200001)
    pts = fit_a.spline(u)
    i = int(np.argmin(np.linalg.norm(pts - a.right.tail, axis=1)))
    assert np.linalg.norm(pts[i] - a.right.tail) < 1e-5          # on the margin
    got = _arc(fit_a.spline, u[i], fit_a.u[1]) / _arc(fit_a.spline, 0.0, u[i])
    assert got == pytest.approx(want, rel=1e-3)
    d = fit_a.spline(u[i], nu=1)
    assert abs(a.right.tail_angle - math.atan2(d[1], d[0])) < 1e-3   # with the margin's tangent
    assert insertion_error(plain, a) < 0.02                  # the refitted margin barely moves


def test_extensions_spread_along_the_list_as_in_sec_6_3():
    chain = [landmark_leaf("elliptic"), landmark_leaf("ovate"), landmark_leaf("lanceolate"), landmark_leaf("cordate"),
             landmark_leaf("obcordate")]
    space, out = unify(chain)
    assert space.dim == 20
    assert all(leaf.right.tail is not None and leaf.right.shoulder is not None for leaf in out)
    assert out[3].right.tail == chain[3].right.tail and out[4].right.shoulder == chain[4].right.shoulder
    # the shoulder travelled from obcordate through cordate, lanceolate ... to elliptic
    assert all(0.0 < leaf.right.shoulder[1] < 1.0 for leaf in out[:4])
    for orig, uni in zip(chain, out):
        assert insertion_error(orig, uni) < 0.02


def _refs():
    return landmark_leaf("cordate"), landmark_leaf("obcordate"), landmark_leaf("elliptic-extended-extended")


def test_morph_endpoints_are_exact():
    src, tgt, ref = _refs()
    path = morph_path(src, tgt, [(ref, 3.0)])
    r = path.vectors
    ends = path(np.array([0.0, 1.0]))
    np.testing.assert_allclose(ends, r[[0, -1]], atol=1e-12, rtol=0)
    assert path.sample(0.0) == src and path.sample(1.0) == tgt
    frames = path.frames(9)
    assert frames[0] == src and frames[-1] == tgt and len(frames) == 9
    np.testing.assert_allclose(path.frame_vectors(9)[[0, -1]], r[[0, -1]], atol=1e-12, rtol=0)
    for leaf in frames[1:-1]:                                  # in between: valid, symmetric leaves
        assert leaf.is_symmetric and leaf.has_tail and leaf.has_shoulder
        assert np.all(np.isfinite(outline(leaf, 32)))


def test_larger_weights_pull_the_path_closer_to_the_reference():
    src, tgt, ref = _refs()
    distances = []
    for w in (0.25, 0.5, 1.0, 2.0, 4.0, 16.0, 256.0):
        path = morph_path(src, tgt, [(ref, w)])
        distances.append(path.distance_to(path.vectors[1]))
    assert all(a > b for a, b in itertools.pairwise(distances)), distances
    assert distances[-1] < 0.02 * distances[0]


def test_two_references_and_zero_weight():
    src, tgt, ref = _refs()
    ovate = landmark_leaf("ovate")
    path = morph_path(src, tgt, [(ref, 2.0), (ovate, 2.0)])
    assert path.degree == 2 and len(path.knots) == 4 + 3
    near = [path.distance_to(v) for v in path.vectors[1:3]]
    far = [morph_path(src, tgt, [(ref, 0.5), (ovate, 0.5)]).distance_to(v) for v in path.vectors[1:3]]
    assert all(n < f for n, f in zip(near, far))
    # weight 0 is no constraint at all (Fig. 11, row 1)
    free, dropped = morph_path(src, tgt), morph_path(src, tgt, [(ref, 0.0)])
    np.testing.assert_allclose(free.frame_vectors(7), dropped.frame_vectors(7))
    with pytest.raises(ParamError) as err:
        morph_path(src, tgt, [(ref, -1.0)])
    assert err.value.path == "refs[0].weight"


def test_without_references_both_methods_are_the_straight_segment():
    src, tgt = landmark_leaf("lanceolate"), landmark_leaf("orbicular")
    a = morph_path(src, tgt).frame_vectors(11)
    b = keyframe_path(src, tgt).frame_vectors(11, by="parameter")
    np.testing.assert_allclose(a, b, atol=1e-9)
    np.testing.assert_allclose(a[5], 0.5 * (leaf_vector(src) + leaf_vector(tgt)), atol=1e-9)


def test_keyframes_pass_through_the_references():
    src, tgt, ref = _refs()
    key = keyframe_path(src, tgt, [(ref, 1.0), ("ovate", 1.0)])
    np.testing.assert_allclose(key(np.linspace(0, 1, 4)), key.vectors, atol=1e-12)


def test_nurbs_path_is_smoother_than_linear_keyframing():
    """Fig. 10: same source, target and references, same number of frames. The NURBS path, sampled
    evenly along its length, takes smaller and more even steps with smaller second differences; its
    turn between consecutive steps vanishes as frames are added (no kinks), while key-framing keeps
    a fixed kink at every key frame."""
    src, tgt = landmark_leaf("lanceolate"), landmark_leaf("reniform")
    refs = [(landmark_leaf("obcordate"), 1.0), (landmark_leaf("oblong"), 1.0)]
    nurbs_path, key_path = morph_path(src, tgt, refs), keyframe_path(src, tgt, refs)
    nurbs = {f: smoothness(nurbs_path.frame_vectors(f)) for f in (50, 400)}
    linear = {f: smoothness(key_path.frame_vectors(f, by="parameter")) for f in (50, 400)}
    for f in (50, 400):
        assert nurbs[f]["max_step"] < 0.8 * linear[f]["max_step"]
        assert nurbs[f]["max_accel"] < 0.8 * linear[f]["max_accel"]
        assert nurbs[f]["step_ratio"] < 1.01                   # even steps along the path
    assert nurbs[400]["max_turn"] < 0.35 * nurbs[50]["max_turn"]
    assert linear[400]["max_turn"] > 0.9 * linear[50]["max_turn"] > 1.0
    assert max_step(nurbs_path.frame_vectors(50)) == nurbs[50]["max_step"]
