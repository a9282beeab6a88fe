"""Every script in examples/ runs as a user would run it, in its own process.

Each example starts with a header line ``# example: run``, ``# example: compare`` or
``# example: off`` (as pygfx marks its examples): ``run`` must exit 0 and write what it says,
``compare`` also matches a small reference image in tests/images (``--regen-images`` rewrites
it), ``off`` is not run. A new example without a header fails here.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from support.display import DisplayUnavailable, display_env, xvfb

from leafview.app.viewer import Viewer, open_state
from leafview.core.edits import scale_width
from leafview.core.params import LeafParams
from leafview.export.images import read_image
from leafview.resources import resolve_preset
from tests.conftest import assert_matches_reference, require_or_skip

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
HEADER = re.compile(r"^# example: (run|compare|off)\b")

pytestmark = pytest.mark.gl


def _mode(path: Path) -> str:
    first = path.read_text(encoding="utf-8").splitlines()[0]
    m = HEADER.match(first)
    assert m, f"{path.name}: first line must be '# example: run|compare|off', got {first!r}"
    return m.group(1)


def _run(args: list[str], *, env: dict[str, str] | None = None, timeout: int = 300) -> subprocess.CompletedProcess[str]:
    result = subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True, env=env,
                            timeout=timeout)
    assert result.returncode == 0, f"{args}: exit {result.returncode}\n{result.stdout}\n{result.stderr}"
    assert "Traceback" not in result.stderr, result.stderr
    return result


def test_every_example_has_a_header_and_a_test() -> None:
    names = {p.stem for p in EXAMPLES}
    assert {"thumbnail_sheet", "viewer_panel", "big_scene", "export_leaf"} <= names
    tested = {name[len("test_example_"):] for name in globals() if name.startswith("test_example_")}
    for path in EXAMPLES:
        if _mode(path) != "off":
            assert path.stem in tested, f"examples/{path.name} has no test_example_{path.stem} here"


def test_example_thumbnail_sheet(gl, tmp_path, request) -> None:
    result = _run(["examples/thumbnail_sheet.py", str(tmp_path), "--size", "40"])
    sheet, _ = read_image(tmp_path / "presets_sheet.png")
    assert "presets" in result.stdout
    assert sheet.shape[1] == 6 * 40 and sheet.shape[0] <= 256
    assert_matches_reference(sheet, "example_thumbnail_sheet", request)


def test_example_big_scene(gl, tmp_path) -> None:
    result = _run(["examples/big_scene.py", str(tmp_path), "--size", "320x180"])
    m = re.search(r"([\d,]+) leaves, ([\d,]+) drawn", result.stdout)
    assert m, result.stdout
    total, drawn = (int(x.replace(",", "")) for x in m.groups())
    assert total == 100_000 and 0 < drawn <= total
    image, _ = read_image(tmp_path / "field.png")
    assert image.shape == (180, 320, 4)
    assert (image[..., 3] > 0).mean() > 0.2          # the field covers the lower part of the frame


def test_example_canopy_edits(gl, tmp_path) -> None:
    from leafview.scene.spec import load_scene

    result = _run(["examples/canopy_edits.py", str(tmp_path), "--leaves", "600", "--size", "160x120"])
    assert "edits ['width']" in result.stdout and "1 buffer write(s)" in result.stdout, result.stdout
    noon, _ = read_image(tmp_path / "plant_noon.png")
    evening, _ = read_image(tmp_path / "plant_evening_wind.png")
    assert noon.shape == evening.shape == (120, 160, 4)
    assert (noon[..., 3] == 255).all()                 # sky and ground behind the plant
    assert np.abs(noon.astype(int) - evening.astype(int)).mean() > 3   # another sun, another instant
    spec = load_scene(tmp_path / "plant.toml")
    assert [e.op for e in spec.edits] == ["width"] and spec.light.sun == (200.0, 18.0)
    assert spec.wind.speed == 6.0 and spec.varieties[0].bend_load == (0.7, 1.3)


def test_example_export_leaf(gl, tmp_path) -> None:
    result = _run(["examples/export_leaf.py", str(tmp_path), "holly"])
    glb, usda, compact = (tmp_path / name for name in ("holly.glb", "holly.usda", "holly.leaf.json"))
    assert glb.read_bytes()[:4] == b"glTF"
    assert usda.read_text(encoding="utf-8").startswith("#usda 1.0")
    assert compact.read_text(encoding="utf-8").startswith('{"leafview":1')
    assert result.stdout.count("wrote ") == 3


def test_example_viewer_panel(gl, tmp_path) -> None:
    try:
        with xvfb(tmp_path / "xvfb.log") as display:
            shot = tmp_path / "window.png"
            result = _run(["examples/viewer_panel.py", "beech", "--frames", "6", "--screenshot", str(shot)],
                          env=display_env(display))
    except DisplayUnavailable as exc:
        require_or_skip(str(exc))
        return
    assert f"wrote {shot}" in result.stdout
    window, _ = read_image(shot)
    assert window.shape[:2] == (640, 1024)
    assert np.ptp(window[..., :3].astype(np.int16)) > 50   # a drawn leaf and panel, not a blank window


def test_custom_panels_are_drawn_every_frame_and_edit_through_the_state(gl) -> None:
    """What viewer_panel.py relies on: ``Viewer.add_panel`` draws the function in the panel each
    frame with the viewer's state, and an edit made there is one undoable step."""
    path = resolve_preset("ovate")
    viewer = Viewer(gl.ctx, open_state(LeafParams.load(path), path), samples=0)
    calls = []

    def panel(state):
        calls.append(state)
        if len(calls) == 2:
            state.apply(lambda leaf: scale_width(leaf, 1.5))

    try:
        viewer.add_panel(panel)
        before = viewer.state.params
        for _ in range(3):
            viewer.frame((640, 400), None, 1 / 60)
        assert len(calls) == 3 and all(s is viewer.state for s in calls)
        assert viewer.state.params.shape.silhouette[1][1] == pytest.approx(1.5 * before.shape.silhouette[1][1])
        assert viewer.state.undo() and viewer.state.params == before
    finally:
        viewer.release()
