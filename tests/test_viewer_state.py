"""The viewer's state, camera and handles without a window, GL or imgui: every edit is validated,
undo/redo and the unsaved-changes flag are exact, files are never half-written, handles put the
control points where they are dropped."""

from __future__ import annotations

import numpy as np
import pytest

from leafview.app.handles import (
    HANDLE_NAMES,
    V_GAP,
    LeafFrame,
    drag_handle,
    handle_parameters,
    handle_points,
    pick,
    plane_hit,
)
from leafview.app.orbit import OrbitCamera, project
from leafview.app.state import HISTORY_LIMIT, ViewerState, get_field, with_field
from leafview.core.bezier import evaluate_curve
from leafview.core.params import LeafParams, ParamError, field_specs
from leafview.deform.surface import control_polygons, evaluate
from leafview.resources import builtin_presets, preset_dir


@pytest.fixture
def state(presets) -> ViewerState:
    path = builtin_presets()["ovate"]
    return ViewerState(presets["ovate"], path, builtin_dir=preset_dir())


def test_every_field_round_trips_through_the_state_api(presets):
    """Every path of field_specs() (new groups included) can be read and written back."""
    params = presets["serrate"]
    for path in field_specs():
        value = get_field(params, path)
        assert with_field(params, path, value) == params, path


def test_set_field_validates_and_names_the_field(state):
    before, rev = state.params, state.revision
    assert state.set_field("jitter.amplitude", 0.05)
    assert state.params.jitter.amplitude == 0.05 and state.revision == rev + 1
    assert state.error is None
    assert not state.set_field("jitter.amplitude", -1.0)
    assert "jitter.amplitude" in state.error and "minimum" in state.error
    assert not state.set_field("shape.silhouette", [[0.5, 0.3, 0], [0.4, 0.3, 0], [0.8, 0.2, 0]])
    assert "shape.silhouette[1][0]" in state.error
    assert not state.set_field("jitter.amplitude", float("nan"))
    assert "NaN" in state.error
    assert not state.set_field("jitter.nonsense", 1.0)
    assert "jitter.nonsense" in state.error
    assert state.params.jitter.amplitude == 0.05 and state.params.shape == before.shape
    assert state.revision == rev + 1  # rejected edits change nothing


def test_gestures_coalesce_into_one_undo_step(state):
    original = state.params
    for x in (0.021, 0.022, 0.023):  # one slider drag
        state.set_field("jitter.amplitude", x, gesture=True)
    state.end_gesture()
    state.set_field("jitter.density", 10.0)  # a separate click
    assert state.params.jitter.amplitude == 0.023
    assert state.undo() and state.params.jitter.density == original.jitter.density
    assert state.params.jitter.amplitude == 0.023
    assert state.undo() and state.params == original
    assert not state.undo() and not state.can_undo
    assert state.redo() and state.params.jitter.amplitude == 0.023
    assert state.redo() and state.params.jitter.density == 10.0
    assert not state.redo()
    state.undo()
    state.set_field("material.translucency", 0.5)  # a new edit drops the redo branch
    assert not state.can_redo


def test_history_is_bounded(state):
    for i in range(HISTORY_LIMIT + 20):
        state.set_field("jitter.seed", i + 1)
    steps = 0
    while state.undo():
        steps += 1
    assert steps == HISTORY_LIMIT


def test_dirty_tracks_the_saved_leaf_and_reset(state):
    assert not state.dirty and state.title == "ovate.toml"
    state.set_field("jitter.enabled", True)
    assert state.dirty and state.title.endswith("*")
    state.undo()
    assert not state.dirty  # back to what is on disk
    state.set_field("shape.zf", [0.05, 0.05, 0.05])
    assert state.reset_to_preset() and state.params == state.preset and not state.dirty
    assert state.undo() and state.params.shape.zf == (0.05, 0.05, 0.05)  # reset is undoable


def test_builtin_presets_are_read_only_and_save_as_writes_toml(state, tmp_path):
    builtin = builtin_presets()["ovate"]
    original_text = builtin.read_text()
    state.set_field("jitter.enabled", True)
    assert not state.can_save and not state.save()
    assert "Save as" in state.error
    assert not state.save_as(builtin)
    assert "read-only" in state.error and builtin.read_text() == original_text
    assert state.save_as(tmp_path / "mine")  # .toml added
    out = tmp_path / "mine.toml"
    assert LeafParams.load(out) == state.params.replace(name=state.params.name or "mine")
    assert not state.dirty and state.path == out and state.can_save
    state.set_field("jitter.seed", 3)
    assert state.save() and LeafParams.load(out).jitter.seed == 3


def test_failed_save_leaves_no_file_and_keeps_the_edits(state, tmp_path):
    state.set_field("jitter.enabled", True)
    target = tmp_path / "missing-dir-is-a-file"
    target.write_text("x")
    assert not state.save_as(target / "leaf.toml")
    assert "cannot write" in state.error and state.dirty
    assert not state.save_as(tmp_path / "leaf.png")
    assert "unknown preset format" in state.error
    assert not state.save_as("   ")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["missing-dir-is-a-file"]


def test_open_invalid_preset_changes_nothing(state, tmp_path):
    state.set_field("jitter.seed", 5)
    before, history = state.params, state.can_undo
    bad = tmp_path / "bad.toml"
    bad.write_text("schema = 1\n[shape]\na1 = [0, 0.3, 0]\n")
    assert not state.open(bad)
    assert str(bad) in state.error and "shape.a2" in state.error
    (tmp_path / "syntax.toml").write_text("schema = = 1\n")
    assert not state.open(tmp_path / "syntax.toml") and "syntax.toml:1:" in state.error
    assert not state.open(tmp_path / "nope.toml") and "no such file" in state.error
    assert state.params == before and state.can_undo == history and state.path.name == "ovate.toml"
    good = builtin_presets()["lanceolate"]
    loads = state.loads
    assert state.open(good) and state.params.name == "lanceolate" and not state.dirty
    assert state.loads == loads + 1 and not state.can_undo


def test_recovery_file_keeps_unsaved_edits(state, tmp_path):
    assert state.write_recovery(tmp_path) is None  # nothing unsaved: nothing written
    state.set_field("jitter.seed", 42)
    first = state.write_recovery(tmp_path)
    second = state.write_recovery(tmp_path)
    assert first.name == "ovate.recovered.toml" and second.name == "ovate.recovered-1.toml"
    assert LeafParams.load(first).jitter.seed == 42
    assert state.dirty and state.path.name == "ovate.toml"  # still unsaved, same file


# -- handles and camera -----------------------------------------------------------------------
@pytest.mark.parametrize("name", HANDLE_NAMES)
def test_dragged_handle_lands_where_it_is_dropped(presets, name):
    params = presets["asymmetric"]
    target = handle_points(params)[name] + np.array([0.03, -0.02, 0.0])
    moved = drag_handle(params, name, target)
    np.testing.assert_allclose(handle_points(moved)[name][:2], target[:2], atol=2e-3)
    if name.startswith("s"):  # the silhouette curve goes through the new outline
        k, side = int(name[1]) - 1, name[2]
        ctrl = control_polygons(moved)["S" + side][k + 1]
        np.testing.assert_allclose(ctrl[:2], target[:2], atol=2e-3)
        # the blade's edge (u = ±1) is the silhouette S (eqs 5-6): it passes S(v̄_k)
        u = 1.0 if side == "+" else -1.0
        edge = evaluate(moved, [u], [moved.shape.vbar[k]])[0]
        s_curve = evaluate_curve(control_polygons(moved)["S" + side], moved.shape.vbar[k])
        np.testing.assert_allclose(edge, s_curve, atol=1e-9)


def test_every_handle_of_extended_tilted_silhouettes_follows_the_cursor():
    """Catalogue shapes with 4-7 silhouette rows and tilted rows get a handle per row; dropping a
    handle where it is changes nothing, and a moved handle lands exactly where it was dropped (its
    foot stays, its length and tilt follow), the other half mirroring it."""
    from leafview.app.handles import handle_names
    from leafview.shapes import fit_info, shape_names, shapes_params

    picks = {}
    for name in shape_names():
        info = fit_info(name)
        picks.setdefault((info.rows, not info.quartic and info.rows == 3), name)
    assert {rows for rows, _ in picks} >= {3, 4, 5, 6, 7}
    for shape in picks.values():
        params = shapes_params(shape)
        names = handle_names(params)
        assert len(names) == 2 + 2 * params.shape.rows
        assert params.shape.extended or params.shape.rows == 3
        for name in names[2:]:
            here = handle_points(params)[name]
            same = drag_handle(params, name, here)
            np.testing.assert_allclose(same.shape.silhouette, params.shape.silhouette, atol=2e-3, err_msg=shape)
            target = here + np.array([0.01, -0.004, 0.0])
            moved = drag_handle(params, name, target)
            np.testing.assert_allclose(handle_points(moved)[name][:2], target[:2], atol=1e-9,
                                       err_msg=f"{shape} {name}")
            other = name[:-1] + ("-" if name.endswith("+") else "+")
            mirror = handle_points(moved)[other] - handle_points(params)[other]
            if params.shape.extended:     # the foot stays; both halves follow the new row
                assert moved.shape.vbar.tolist() == params.shape.vbar.tolist()
                assert np.abs(mirror[:2]).max() > 1e-3


def test_silhouette_drag_keeps_v_order(presets):
    params = presets["ovate"]
    far = handle_points(params)["s3+"] + np.array([0.0, -0.9, 0.0])  # past s2 and s1
    moved = drag_handle(params, "s3+", far)
    v = moved.shape.vbar
    assert v[2] == pytest.approx(v[1] + V_GAP, abs=1e-3) and v[0] < v[1] < v[2]
    with pytest.raises(ParamError, match="unknown handle"):
        drag_handle(params, "s9+", far)
    with pytest.raises(ParamError):
        drag_handle(params, "a1", [np.nan, 0, 0])


def test_bent_leaf_handles_map_back_exactly(presets):
    bent = [p for p in presets.values() if getattr(getattr(p, "bending", None), "active", False)]
    assert bent, "the maize and willow presets bend"
    params = bent[0]
    frame = LeafFrame(params)
    hp, hv = handle_points(params), handle_parameters(params)
    pts = np.array([hp[n] for n in HANDLE_NAMES])
    v = np.array([hv[n] for n in HANDLE_NAMES])
    world = frame.to_world(pts, v)
    assert np.abs(world - LeafFrame(params.replace(bending=type(params.bending)())).to_world(pts, v)).max() > 1e-3
    np.testing.assert_allclose(frame.to_leaf(world, v), pts, atol=1e-9)
    # the bent midrib control curve A(t) is the surface's midrib L(0, t)
    t = np.linspace(0, 1, 9)
    midrib = frame.to_world(evaluate_curve(params.shape.axis_points(), t), t)
    surface = evaluate(params, np.zeros_like(t), t) @ params.transform.matrix()[:3, :3].T
    np.testing.assert_allclose(midrib, surface + params.transform.matrix()[:3, 3], atol=1e-6)


def test_pick_and_plane_hit():
    screen = np.array([[10.0, 10.0], [50.0, 50.0], [np.nan, np.nan]])
    assert pick(screen, ["a", "b", "c"], 48, 53) == "b"
    assert pick(screen, ["a", "b", "c"], 30, 30) is None
    hit = plane_hit(np.array([0, 0, 5.0]), np.array([0, 0, -1.0]), np.zeros(3), np.array([0, 0, 1.0]))
    np.testing.assert_allclose(hit, [0, 0, 0])
    assert plane_hit(np.array([0, 0, 5.0]), np.array([1.0, 0, 0]), np.zeros(3), np.array([0, 0, 1.0])) is None


def test_camera_ray_goes_through_the_projected_point():
    cam = OrbitCamera.framing(np.array([[-0.4, 0, 0], [0.4, 1, 0.1]]), aspect=1.5)
    point = np.array([0.2, 0.6, 0.05])
    for _ in range(3):
        c = cam.camera(900, 600)
        xy = project(c, point[None], 900, 600)[0]
        origin, d = cam.ray(xy[0], xy[1], 900, 600)
        closest = origin + np.dot(point - origin, d) * d
        np.testing.assert_allclose(closest, point, atol=1e-6)
        cam.orbit(40, -25)
        cam.pan(12, 7, 600)
        cam.dolly(1.5)
    assert -89.0 <= cam.elevation <= 89.0
    az = cam.azimuth
    cam.reset(np.array([[-0.4, 0, 0], [0.4, 1, 0.1]]), 1.5)
    assert cam.azimuth == 35.0 and cam.azimuth != az
