"""Unilobed-to-lobed morphing in margin space (Garg & Leow 2011, eq. 11, Figs 12-13):
:mod:`leafview.botany.lobe_morph`."""

from __future__ import annotations

import numpy as np
import pytest

from leafview.botany.catalogue import landmark_leaf
from leafview.botany.landmarks import outline
from leafview.botany.lobe_morph import (
    LobeMorphPath,
    closed_margin,
    is_lobed,
    load_key_shape,
    lobe_morph,
    lobe_morph_path,
)
from leafview.botany.morph import smoothness
from leafview.botany.outline_fit import hausdorff, margin
from leafview.botany.shapes import shapes_params
from leafview.core.bspline import evaluate_closed, fit_closed, sample_closed, signed_area
from leafview.core.lobes import Lobes, parse_outline
from leafview.core.params import LeafParams, ParamError


def star(lobes: int = 5, depth: float = 0.35, controls: int = 64, name: str = "star") -> LeafParams:
    """A palmately lobed test leaf: base (0, 0), clockwise, ``lobes`` rounded lobes."""
    th = -np.pi / 2 - np.linspace(0.0, 2.0 * np.pi, 2000, endpoint=False)
    r = 0.5 * (1.0 - depth * (0.5 - 0.5 * np.cos(lobes * (th + np.pi / 2))))
    ring = np.stack([r * np.cos(th), 0.5 + r * np.sin(th)], axis=1)
    return LeafParams(lobes=Lobes(outline=parse_outline(fit_closed(ring, controls).tolist())), name=name)


def _ctrl(p: LeafParams) -> np.ndarray:
    return np.asarray(p.lobes.outline, dtype=np.float64)


@pytest.fixture(scope="module")
def star5() -> LeafParams:
    return star()


# -- closed_margin ----------------------------------------------------------------------------------

@pytest.mark.parametrize("shape", ["ovate", "cordate", "ovate-drip", "PARAMS"])
def test_closed_margin_follows_the_lobed_convention(shape):
    src = shapes_params("ovate") if shape == "PARAMS" else shape
    c = closed_margin(src, 96)
    ring = sample_closed(c, 4096)
    assert c.shape == (96, 2) and signed_area(ring) < 0.0                 # clockwise
    assert np.linalg.norm(evaluate_closed(c, 0.0)) < 0.01                 # C(0) at the base
    assert np.linalg.norm(evaluate_closed(c, 0.5) - [0.0, 1.0]) < 0.01    # symmetric: apex half way
    assert evaluate_closed(c, 0.25)[0] < 0.0 < evaluate_closed(c, 0.75)[0]   # left side first
    if shape == "PARAMS":
        right, left = margin(src)
        target = np.vstack([right, left[::-1]])      # one closed loop (hausdorff densifies it)
    else:
        target = outline(landmark_leaf(shape), 1024)
    assert hausdorff(ring, target) < 0.004


def test_closed_margin_of_a_lobed_leaf_refits_its_outline(star5):
    fine = sample_closed(_ctrl(star5), 4096)
    for m in (64, 96, 160):
        assert hausdorff(sample_closed(closed_margin(star5, m), 4096), fine) < 0.003
    # a counter-clockwise outline is turned round at its base
    ccw = star5.replace(lobes=Lobes(outline=parse_outline(np.roll(_ctrl(star5)[::-1], 2, axis=0).tolist())))
    assert hausdorff(sample_closed(closed_margin(ccw, 64), 4096), fine) < 0.003
    with pytest.raises(ParamError, match="controls"):
        closed_margin(star5, 4)


# -- the morph ---------------------------------------------------------------------------------------

def test_frames_are_valid_lobed_leaves_and_reproduce_the_ends(star5):
    frames = lobe_morph("ovate", star5, 9)
    assert len(frames) == 9 and all(is_lobed(f) for f in frames)
    m = len(frames[0].lobes.outline)
    assert m == 96                                     # DEFAULT_CONTROLS (the star has 64)
    for f in frames:
        assert parse_outline(f.lobes.outline) == f.lobes.outline
        assert f.lobes.valleys == () and f.lobes.branches == ()
    np.testing.assert_allclose(_ctrl(frames[0]), closed_margin("ovate", m), atol=1e-6)
    np.testing.assert_allclose(_ctrl(frames[-1]), closed_margin(star5, m), atol=1e-6)
    # the target's own margin, to its fit
    assert hausdorff(sample_closed(_ctrl(frames[-1]), 4096), sample_closed(_ctrl(star5), 4096)) < 0.003


def test_frames_are_evenly_spaced_and_smooth(star5):
    path = lobe_morph_path(shapes_params("lanceolate"), star5, references=["reniform"], weights=[1.0])
    steps = 17
    v = path.frame_vectors(steps)
    d = np.linalg.norm(np.diff(v, axis=0), axis=1)
    step = path.length / (steps - 1)
    assert d.max() <= 1.001 * step and np.median(d) > 0.98 * step   # evenly spaced on the path, no jump
    # each control point moves a bounded distance per frame (leaf lengths)
    per_point = np.linalg.norm(np.diff(v.reshape(steps, -1, 2), axis=0), axis=2)
    assert per_point.max() < 0.15
    # smoother than linear key-framing through the same reference, which turns its whole corner
    # (150 degrees here: reniform lies back towards lanceolate) in one frame
    k = path.keys.reshape(3, -1)
    key = np.concatenate([np.linspace(k[0], k[1], 9)[:-1], np.linspace(k[1], k[2], 9)])
    mine, theirs = smoothness(v), smoothness(key)
    assert theirs["max_turn"] > 2.0
    assert mine["max_turn"] < 0.5 * theirs["max_turn"] and mine["max_accel"] < 0.5 * theirs["max_accel"]
    assert mine["step_ratio"] < 1.01 < theirs["step_ratio"]


def test_sizes_interpolate_monotonically(star5):
    frames = lobe_morph("ovate", star5, 12, references=["cordate"], weights=[3.0], sizes=[0.3, 0.45, 1.2])
    s = np.array([f.transform.scale for f in frames])
    assert s[0] == pytest.approx(0.3) and s[-1] == pytest.approx(1.2)
    assert np.all(np.diff(s) > 0.0)
    shrink = lobe_morph(star5, "ovate", 8, sizes=[2.0, 0.5])
    assert np.all(np.diff([f.transform.scale for f in shrink]) < 0.0)
    # default: each key's own transform.scale (1 for a catalogue name)
    big = star5.replace(transform=star5.transform.__class__(scale=2.0))
    s = [f.transform.scale for f in lobe_morph("ovate", big, 5)]
    assert s[0] == pytest.approx(1.0) and s[-1] == pytest.approx(2.0) and np.all(np.diff(s) > 0)


def test_references_pull_the_path(star5):
    ref = star(lobes=3, depth=0.25, name="three")
    target = closed_margin(ref, 96).ravel()
    dist = [lobe_morph_path("elliptic", star5, references=[ref], weights=[w]).distance_to(target)
            for w in (0.0, 0.5, 2.0, 8.0)]
    assert all(a > b for a, b in zip(dist, dist[1:])), dist
    assert dist[-1] < 0.5 * dist[0]


def test_template_comes_from_the_lobed_key(star5):
    coloured = star5.replace(material=star5.material.__class__(front=(0.3, 0.1, 0.05)))
    frames = lobe_morph("ovate", coloured, 3)
    assert all(f.material == coloured.material for f in frames)
    assert frames[1].lobes.prune == coloured.lobes.prune


def test_a_frame_that_would_collapse_is_named():
    """Keys whose control points correspond half a turn apart meet in a point half way."""
    th = 2 * np.pi * np.arange(32) / 32
    circle = np.stack([0.4 * np.sin(-th), 0.5 - 0.4 * np.cos(th)], axis=1)
    keys = np.stack([circle, np.roll(circle, 16, axis=0)])
    path = LobeMorphPath(keys, np.ones(2), np.ones(2))
    with pytest.raises(ParamError) as err:
        path.frames(5)
    assert err.value.path == "frames[2].lobes.outline"


@pytest.mark.parametrize("kwargs, field", [
    ({"sizes": [1.0]}, "sizes"),
    ({"sizes": [1.0, 0.0]}, "sizes[1]"),
    ({"sizes": [1.0, float("nan")]}, "sizes[1]"),
    ({"references": ["cordate"], "sizes": [1.0, 2.0]}, "sizes"),
    ({"references": ["cordate"], "weights": [1.0, 2.0]}, "weights"),
    ({"references": ["cordate"], "weights": [-1.0]}, "weights[0]"),
    ({"references": ["nosuchshape"]}, "references[0]"),
    ({"steps": 1}, "steps"),
    ({"controls": 3}, "controls"),
])
def test_bad_input_names_the_field(star5, kwargs, field):
    steps = kwargs.pop("steps", 4)
    with pytest.raises(ParamError) as err:
        lobe_morph("ovate", star5, steps, **kwargs)
    assert err.value.path == field
    with pytest.raises(ParamError) as err:
        lobe_morph("ovate", "nosuchshape", 4)
    assert err.value.path == "target"


def test_zero_weight_reference_is_dropped_with_its_size(star5):
    a = lobe_morph("ovate", star5, 5, references=["cordate"], weights=[0.0], sizes=[1.0, 5.0, 2.0])
    b = lobe_morph("ovate", star5, 5, sizes=[1.0, 2.0])
    for fa, fb in zip(a, b):
        assert fa.lobes.outline == fb.lobes.outline and fa.transform.scale == pytest.approx(fb.transform.scale)


LOBED_PRESETS = ["maple", "oak", "bilobed"]


@pytest.mark.parametrize("name", LOBED_PRESETS)
def test_unilobed_to_each_lobed_preset(name):
    target = load_key_shape(name)
    assert is_lobed(target)
    frames = lobe_morph("ovate", name, 8, sizes=[0.4, 1.0])
    assert all(parse_outline(f.lobes.outline) for f in frames)
    m = len(frames[-1].lobes.outline)
    assert hausdorff(sample_closed(_ctrl(frames[-1]), 4096), sample_closed(_ctrl(target), 4096)) < 0.01
    np.testing.assert_allclose(_ctrl(frames[-1]), closed_margin(target, m), atol=1e-6)
