"""``leafview morph`` (frames, contact sheet, smoothness report), the viewer's morph controller and
panel, and the public names ``leafview.landmarks`` / ``leafview.shapes.catalogue``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from leafview.botany.catalogue import landmark_leaf, load_landmark_leaf
from leafview.botany.morph import keyframe_path, leaf_vector, morph_path, smoothness
from leafview.cli import main
from leafview.core.params import LeafParams, ParamError
from leafview.export.images import PARAMS_ATTRIBUTE, read_image
from leafview.gpu.morph import RefSpec, load_morph_leaf, morph_sequence, parse_ref, shared_camera
from leafview.resources import asset_dir


def test_public_names_from_the_issue():
    import leafview.botany.landmarks as model_lm
    import leafview.landmarks as lm
    from leafview.shapes import catalogue

    assert lm.fit_margin is model_lm.fit_margin and set(lm.__all__) == set(model_lm.__all__)
    rows = catalogue()
    assert len(rows) == 64 and sum(r.table1 for r in rows) == 50 and sum(r.named for r in rows) == 14
    assert sum(r.apex == "drip" for r in rows) == 2
    first = rows[0]
    assert (first.name, first.waist, first.base, first.apex, first.unilobed) == \
        ("elliptic-concave-concave", "elliptic", "concave", "concave", True)


def test_parse_ref():
    assert parse_ref("cordate:2.5") == RefSpec("cordate", 2.5)
    assert parse_ref("cordate") == RefSpec("cordate", 1.0)
    assert parse_ref("dir/c.toml:0") == RefSpec("dir/c.toml", 0.0)
    for bad in ("cordate:x", "cordate:-1", "cordate:nan", "cordate:inf"):
        with pytest.raises(ParamError, match="--ref"):
            parse_ref(bad)


def test_landmark_examples_load_and_an_omega_preset_is_refused_with_the_reason():
    files = sorted((asset_dir() / "landmarks").glob("*.toml"))
    assert len(files) >= 3
    for f in files:
        assert load_morph_leaf(str(f), "A").name == f.stem
    with pytest.raises(ParamError, match="shader-model preset") as err:
        load_morph_leaf(str(asset_dir() / "presets" / "ovate.toml"), "A")
    assert err.value.path == "A"


def test_sequence_ends_are_the_shapes_and_fits_are_close():
    src, tgt = landmark_leaf("lanceolate"), landmark_leaf("cordate")
    seq = morph_sequence(src, tgt, [(landmark_leaf("oblong"), 2.0)], 5, polish=False)
    assert seq.leaves[0] == src and seq.leaves[-1] == tgt
    path = morph_path(src, tgt, [("oblong", 2.0)])
    np.testing.assert_allclose(seq.vectors[[0, -1]], path.vectors[[0, -1]], atol=1e-12)
    assert len(leaf_vector(src)) < path.space.dim    # the tail was inserted into the lanceolate leaf (eq. 10)
    assert len(seq.parts) == 5 and all(len(p) == 1 and isinstance(p[0], LeafParams) for p in seq.parts)
    assert max(seq.errors) < 0.04          # linear fit only
    nurbs = smoothness(morph_path(src, tgt, [("oblong", 2.0)]).frame_vectors(5))
    assert seq.smoothness == nurbs
    key = smoothness(keyframe_path(src, tgt, [("oblong", 2.0)]).frame_vectors(5, by="parameter"))
    assert seq.keyframe_smoothness == key
    assert len(seq.reference_distances) == 1 and seq.reference_distances[0] > 0


def test_shared_camera_frames_the_union_of_all_frames():
    from leafview.scene.camera import frame_view
    from leafview.shapes import shapes_params

    small, wide = shapes_params("linear"), shapes_params("reniform")
    cam = shared_camera([small, wide], "top", (100, 100))
    assert np.allclose(cam.proj, shared_camera([wide, small], "top", (100, 100)).proj)
    own = frame_view("top", np.array([[-0.04, 0.0, 0.0], [0.04, 1.0, 0.0]]), (100, 100))
    # the wide leaf decides the scale: the linear leaf is drawn smaller than on its own
    assert cam.proj[0, 0] < own.proj[0, 0]


@pytest.mark.gl
def test_cli_writes_frames_sheet_and_report(gl, tmp_path, capsys):
    out = tmp_path / "m"
    rc = main(["morph", "lanceolate", "reniform", "--ref", "obcordate:1", "--frames", "6", "-o", str(out),
               "--size", "64", "--presets", "-q"])
    assert rc == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == [f"frame_{i}.{ext}" for i in range(6) for ext in ("png", "toml")] + ["morph.json", "sheet.png"]
    report = json.loads((out / "morph.json").read_text())
    assert report["frames"] == 6 and report["method"] == "nurbs" and report["refs"] == [{"spec": "obcordate", "weight": 1.0}]
    assert max(f["fit_error"] for f in report["frame"]) <= 0.01
    assert report["smoothness"]["max_step"] < report["keyframe_smoothness"]["max_step"]
    # frames: the leaf covers a growing share of the shared frame from lanceolate to reniform
    cover = []
    for i in range(6):
        img, meta = read_image(out / f"frame_{i}.png")
        assert img.shape == (64, 64, 4)
        cover.append((img[..., 3] > 0).mean())
        saved = LeafParams.from_dict(json.loads(meta[PARAMS_ATTRIBUTE]))
        assert saved == LeafParams.load(out / f"frame_{i}.toml")
    assert cover[0] < 0.5 * cover[-1] and cover[0] > 0.02
    sheet, _ = read_image(out / "sheet.png")
    assert sheet.shape[1] == 6 * 64 and (sheet[..., 3] == 255).all()
    text = capsys.readouterr().out
    assert "NURBS path" in text and "linear key-framing" in text and "20 dimensions" in text


@pytest.mark.parametrize("args, message", [
    (["lanceolate", "nosuchshape"], "nosuchshape"),
    (["lanceolate", "cordate", "--ref", "oblong:-2"], "--ref"),
    (["lanceolate", "cordate", "--frames", "1"], "--frames"),
    (["lanceolate", "cordate", "-o", "x.png"], "directory"),
    (["PRESET", "cordate"], "shader-model preset"),
    (["lanceolate", "cordate", "--margin", "--fast"], "drop --fast"),
])
def test_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, args, message):
    args = [str(asset_dir() / "presets" / "ovate.toml") if a == "PRESET" else a for a in args]
    if "-o" not in args:
        args += ["-o", str(tmp_path / "out")]
    else:
        args[args.index("-o") + 1] = str(tmp_path / "x.png")
    assert main(["morph", *args, "-q"]) == 2
    assert message in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


# -- the viewer's morph controller and panel ------------------------------------------------------

@pytest.fixture
def state(presets):
    from leafview.app.state import ViewerState
    from leafview.resources import builtin_presets, preset_dir

    return ViewerState(presets["ovate"], builtin_presets()["ovate"], builtin_dir=preset_dir())


def test_controller_changes_only_the_shape_and_hits_the_ends(state):
    from leafview.app.morph_panel import MorphController
    from leafview.gpu.morph import fit_frame

    before = state.params
    c = MorphController(state, source="lanceolate", target="cordate")
    assert c.set_t(1.0)
    assert state.params.shape == fit_frame(landmark_leaf("cordate")).parts[0].shape
    assert state.params.material == before.material and state.params.bending == before.bending
    assert c.last_error is not None and c.last_error <= 0.01
    c.end_drag()
    assert state.undo() and state.params == before and not state.can_undo
    with pytest.raises(ValueError, match="target"):
        c.choose(target="nosuchshape")


def test_controller_exact_margins_draw_each_frame_without_a_fit(state):
    """*exact margins*: the frame's landmark margin is the leaf's silhouette (no fit), the same
    whether dragging or not; switching it off goes back to the fitted shape."""
    from leafview.app.morph_panel import MorphController
    from leafview.botany.landmarks import margins
    from leafview.gpu.morph import fit_frame

    before = state.params
    c = MorphController(state, source="lanceolate", target="cordate")
    assert c.choose(exact=True)
    assert c.set_t(0.5, dragging=True)
    path = morph_path(landmark_leaf("lanceolate"), landmark_leaf("cordate"), [])
    assert state.params.margin == margins([path.sample(0.5)])[0] and c.last_error == 0.0
    assert state.params.material == before.material and not state.params.shape.extended
    c.end_drag()
    assert state.params.margin == margins([path.sample(0.5)])[0]
    c.choose(exact=False)
    assert state.params.margin is None and state.params.shape == fit_frame(path.sample(0.5)).parts[0].shape


def test_panel_t_slider_drag_is_one_undo_step(state):
    from leafview.app.morph_panel import MorphPanel
    from tests.test_viewer_panel import UI

    ui = UI()
    try:
        panel = MorphPanel(state)
        panel.expand_all = True
        ui.frame(panel.draw)
        for key in ("morph.source", "morph.target", "morph.reference", "morph.t"):
            x0, y0, x1, y1 = panel.rects[key]
            assert x1 > x0 and y1 > y0
        before = state.params
        ui.drag(panel.draw, panel.rects["morph.t"], 0.0, 0.5)
        c = panel.controller
        assert 0.35 < c.t < 0.65
        # after release the shape is the polished fit of the frame at t
        expected = c.shape_at(c.t, polish=True)
        assert state.params.shape == expected and state.params.shape != before.shape
        assert state.undo() and state.params == before and not state.can_undo
    finally:
        ui.close()


def test_asymmetric_frames_are_two_one_sided_leaves_joined_at_the_midrib():
    from leafview.botany.asymmetric import LEFT_HALF, RIGHT_HALF
    from leafview.deform.surface import evaluate

    src = load_landmark_leaf(str(asset_dir() / "landmarks" / "asymmetric.toml"))
    seq = morph_sequence(src, landmark_leaf("elliptic"), [], 3)
    assert [len(p) for p in seq.parts] == [2, 2, 1]        # the symmetric target is one leaf
    assert max(seq.errors) <= 0.01
    right, left = seq.parts[0]
    assert (right.shape.half, left.shape.half) == (RIGHT_HALF, LEFT_HALF)
    v = np.linspace(0, 1, 11)
    np.testing.assert_allclose(evaluate(right, 0 * v, v), evaluate(left, 0 * v, v), atol=1e-12)   # no crack


@pytest.mark.gl
def test_cli_asymmetric_source_writes_both_halves(gl, tmp_path, capsys):
    out = tmp_path / "a"
    src = str(asset_dir() / "landmarks" / "asymmetric.toml")
    assert main(["morph", src, "ovate", "--frames", "3", "-o", str(out), "--size", "48", "--presets", "-q"]) == 0
    names = sorted(p.name for p in out.glob("frame_0*"))
    assert names == ["frame_0.left.toml", "frame_0.png", "frame_0.right.toml"]
    halves = [LeafParams.load(out / f"frame_0.{side}.toml").shape.half for side in ("right", "left")]
    assert halves == [-1, 1]
    assert "2 asymmetric frame(s)" in capsys.readouterr().out


def test_margin_frames_are_the_landmark_margins_themselves():
    """--margin / margin=True: each frame is one leaf drawn from its own landmark margin, the
    asymmetric ones included; its edge is that frame's B-spline (no fit, error 0)."""
    from leafview.botany.landmarks import outline_sides
    from leafview.deform.surface import evaluate

    src = load_landmark_leaf(str(asset_dir() / "landmarks" / "asymmetric.toml"))
    seq = morph_sequence(src, landmark_leaf("cordate"), [], 4, margin=True)
    assert [len(p) for p in seq.parts] == [1, 1, 1, 1] and seq.errors == [0.0] * 4
    v = np.linspace(0.0, 1.0, 21)
    for leaf, (params,) in zip(seq.leaves, seq.parts):
        right, left = outline_sides(leaf, 21, spacing="parameter")
        np.testing.assert_allclose(evaluate(params, -np.ones_like(v), v)[:, :2], right, atol=1e-12)
        np.testing.assert_allclose(evaluate(params, np.ones_like(v), v)[:, :2], left, atol=1e-12)


@pytest.mark.gl
def test_cli_margin_frames(gl, tmp_path, capsys):
    out = tmp_path / "m"
    src = str(asset_dir() / "landmarks" / "asymmetric.toml")
    assert main(["morph", src, "cordate", "--frames", "3", "--margin", "-o", str(out), "--size", "48", "--presets",
                 "-q"]) == 0
    assert sorted(p.name for p in out.glob("frame_0*")) == ["frame_0.png", "frame_0.toml"]
    assert LeafParams.load(out / "frame_0.toml").margin is not None
    _, meta = read_image(out / "frame_2.png")
    assert LeafParams.from_dict(json.loads(meta[PARAMS_ATTRIBUTE])).margin is not None
    assert "drawn from their landmark margins" in capsys.readouterr().out


# -- lobed targets and growth with size (Garg & Leow 2011, Figs 12-13) ----------------------------

def _star_preset(path):
    """A five-lobed leaf preset (``[lobes]`` outline, clockwise from the base) written to ``path``."""
    from leafview.core.bspline import fit_closed
    from leafview.core.lobes import Lobes, parse_outline

    th = -np.pi / 2 - np.linspace(0.0, 2.0 * np.pi, 2000, endpoint=False)
    r = 0.5 * (1.0 - 0.35 * (0.5 - 0.5 * np.cos(5 * (th + np.pi / 2))))
    ring = np.stack([r * np.cos(th), 0.5 + r * np.sin(th)], axis=1)
    LeafParams(lobes=Lobes(outline=parse_outline(fit_closed(ring, 64).tolist())), name="star").save(path)
    return str(path)


@pytest.mark.gl
def test_cli_unilobed_to_lobed_with_growth(gl, tmp_path, capsys):
    star = _star_preset(tmp_path / "star.toml")
    out = tmp_path / "lobed"
    assert main(["morph", "ovate", star, "--steps", "5", "--sizes", "0.4,1", "-o", str(out), "--size", "48",
                 "--presets", "-q"]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == [f"frame_{i}.{ext}" for i in range(5) for ext in ("png", "toml")] + ["morph.json", "sheet.png"]
    frames = [LeafParams.load(out / f"frame_{i}.toml") for i in range(5)]
    assert all(f.lobes.enabled for f in frames)
    scales = [f.transform.scale for f in frames]
    assert scales[0] == pytest.approx(0.4) and scales[-1] == pytest.approx(1.0) and np.all(np.diff(scales) > 0)
    report = json.loads((out / "morph.json").read_text())
    assert report["space"] == "margin" and report["sizes"] == [0.4, 1.0] and report["controls"] == 96
    assert [f["size"] for f in report["frame"]] == pytest.approx(scales)
    img, meta = read_image(out / "frame_2.png")
    assert LeafParams.from_dict(json.loads(meta[PARAMS_ATTRIBUTE])) == frames[2]
    # growth: the last frame covers more of the shared camera than the first
    cover = [(read_image(out / f"frame_{i}.png")[0][..., 3] > 0).mean() for i in (0, 4)]
    assert cover[0] < cover[1]
    assert "lobed frames" in capsys.readouterr().out


@pytest.mark.gl
def test_cli_sizes_scale_unilobed_frames(gl, tmp_path):
    out = tmp_path / "grow"
    assert main(["morph", "lanceolate", "cordate", "--ref", "oblong:2", "--sizes", "0.3,0.5,1", "--frames", "6",
                 "--fast", "-o", str(out), "--size", "32", "--presets", "-q"]) == 0
    report = json.loads((out / "morph.json").read_text())
    sizes = [f["size"] for f in report["frame"]]
    assert sizes[0] == pytest.approx(0.3) and sizes[-1] == pytest.approx(1.0) and np.all(np.diff(sizes) > 0)
    assert LeafParams.load(out / "frame_3.toml").transform.scale == pytest.approx(sizes[3])


@pytest.mark.parametrize("args, message", [
    (["ovate", "STAR", "--sizes", "1,2,3"], "--sizes: expected 2 sizes"),
    (["ovate", "STAR", "--sizes", "1,0"], "--sizes[1]"),
    (["ovate", "STAR", "--sizes", "1,x"], "--sizes[1]"),
    (["lanceolate", "cordate", "--ref", "oblong", "--sizes", "1,2"], "--sizes: expected 3 sizes"),
    (["lanceolate", "cordate", "--sizes=-1,2"], "--sizes[0]"),
    (["nosuchshape", "STAR"], "A"),
    (["ovate", "STAR", "--ref", "nosuchshape:2"], "--ref nosuchshape:2"),
    (["ovate", "STAR", "--method", "keyframe"], "keyframe"),
    (["ovate", "STAR", "--margin"], "drop --margin"),
])
def test_lobed_and_sizes_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, args, message):
    star = _star_preset(tmp_path.parent / f"{tmp_path.name}-star.toml")
    args = [star if a == "STAR" else a for a in args]
    assert main(["morph", *args, "-o", str(tmp_path / "out"), "-q"]) == 2
    assert message in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_controller_grows_and_morphs_to_a_lobed_target(state, tmp_path, monkeypatch):
    import leafview.app.morph_panel as mp

    c = mp.MorphController(state, source="lanceolate", target="cordate", grow=True)
    c.set_t(0.0)
    assert state.params.transform.scale == pytest.approx(mp.GROWTH_SIZES[0])
    c.set_t(1.0)
    assert state.params.transform.scale == pytest.approx(mp.GROWTH_SIZES[-1])
    assert not state.params.lobes.enabled
    star = _star_preset(tmp_path / "star.toml")
    monkeypatch.setattr(mp, "_lobed_names", lambda: (star,))
    assert star in c.targets() and "cordate" in c.targets()
    c.choose(target=star)
    assert c.lobed and state.params.lobes.enabled and c.last_error is None
    np.testing.assert_allclose(np.asarray(state.params.lobes.outline),
                               mp._lobe_path("lanceolate", star, mp.NO_REFERENCE, 1.0, True).controls_at(1.0))
    c.choose(target="cordate")                    # back to a unilobed target: the leaf is unlobed again
    assert not state.params.lobes.enabled and not c.lobed
    c.choose(grow=False)
    with pytest.raises(ValueError, match="target"):
        c.choose(target="nosuchshape")
