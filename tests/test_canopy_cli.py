"""``leafview scene``'s canopy options end to end: bad light, wind and animation input is refused
with exit 2, the field (and the file) named and nothing written; an animation to a folder writes
its frames; a saved scene keeps its ``[light]`` and ``[wind]``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from leafview.cli import main
from leafview.cli.scene_anim import frame_name
from leafview.deform.wind import WindSettings
from leafview.export.images import read_image
from leafview.scene.lighting import LightSettings
from leafview.scene.spec import load_scene

SCENE = "schema = 1\n[scene]\nlayout = 'plant'\nleaves = 40\nseed = 1\n[[species]]\npreset = 'ovate'\n"


def _run(argv: list[str]) -> int:
    """The exit code of ``leafview ARGV`` (argparse's own refusals exit through SystemExit)."""
    try:
        return main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)


def _refused(tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], *words: str) -> str:
    """Run ``leafview scene ARGV`` in ``tmp_path`` (which holds only scene files); assert exit 2,
    every word in the message, and that no new file appeared."""
    before = sorted(tmp_path.rglob("*"))
    code = _run(["scene", *argv])
    err = capsys.readouterr().err
    assert code == 2, err
    for word in words:
        assert word in err, err
    assert sorted(tmp_path.rglob("*")) == before, "a refused run left files behind"
    return err


@pytest.mark.parametrize("table, words", [
    ("[light]\nsun = [10, 95]\n", ("light.sun[1]",)),
    ("[light]\nsun = [400, 30]\n", ("light.sun[0]",)),
    ("[wind]\nspeed = -1\n", ("wind.speed",)),
    ("[light]\nshadows = \"yes\"\n", ("light.shadows",)),
    ("[light]\nsunshine = 1.0\n", ("light.sunshine", "unknown")),
    ("[wind]\ngusts = 2\n", ("wind.gusts", "unknown")),
    ("[light]\nexposure = nan\n", ("light.exposure",)),
    ("[light]\nshadow_filter = \"pcf\"\n", ("light.shadow_filter",)),
])
def test_a_bad_light_or_wind_table_exits_2_naming_the_field_and_the_file(tmp_path, capsys, table, words):
    bad = tmp_path / "bad.toml"
    bad.write_text(SCENE + table)
    _refused(tmp_path, capsys, [str(bad), "-o", str(tmp_path / "x.png")], "bad.toml", *words)


def test_a_bad_variety_or_edit_exits_2_naming_it(tmp_path, capsys):
    bad = tmp_path / "variety.toml"
    bad.write_text(SCENE + "variety = { bend_load = [1.5, 0.5] }\n")
    _refused(tmp_path, capsys, [str(bad), "-o", str(tmp_path / "x.png")], "variety.toml", "variety.bend_load")
    bad.unlink()
    edits = tmp_path / "edits.toml"
    edits.write_text(SCENE + "[[edits]]\nop = 'width'\nvalue = 50.0\n")
    _refused(tmp_path, capsys, [str(edits), "-o", str(tmp_path / "x.png")], "edits.toml", "edits[0].value")


@pytest.mark.parametrize("argv, words", [
    (["--exposure", "nan"], ("light.exposure",)),
    (["--exposure", "11"], ("light.exposure",)),
    (["--sun", "135,91"], ("light.sun[1]",)),
    (["--sun", "135"], ("AZ,EL",)),
    (["--wind", "1e9"], ("wind.speed",)),
    (["--wind", "-1"], ("wind.speed",)),
    (["--wind", "inf"], ("finite",)),
    (["--time", "-1"], ("wind.time",)),
    (["--shadows", "yes"], ("--shadows",)),
])
def test_bad_light_and_wind_options_exit_2_before_anything_renders(tmp_path, capsys, argv, words):
    _refused(tmp_path, capsys, ["--leaves", "20", "--layout", "plant", *argv, "-o", str(tmp_path / "x.png")], *words)


@pytest.mark.parametrize("output, words", [
    ("anim.avi", ("unknown animation type", ".avi")),
    ("/proc/x.mp4", ("/proc/x.mp4",)),
    ("/proc/frames/", ("/proc/frames",)),
])
def test_an_animation_of_unknown_type_or_in_an_unwritable_place_exits_2(tmp_path, capsys, monkeypatch, output,
                                                                         words):
    monkeypatch.chdir(tmp_path)
    _refused(tmp_path, capsys, ["--leaves", "20", "--layout", "plant", "--wind", "8", "--frames", "3",
                                "-o", output], *words)
    assert not Path(output).exists()


def test_frames_of_the_wind_to_a_folder_differ(gl, tmp_path, capsys):
    out = tmp_path / "frames"
    code = main(["scene", "--leaves", "300", "--layout", "plant", "--seed", "2", "--size", "96x96", "--wind", "8",
                 "--frames", "3", "--fps", "4", "-o", f"{out}/"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "3 frames at 4 fps, wind 8" in captured.out
    assert sorted(p.name for p in out.iterdir()) == [frame_name(i) for i in range(3)]
    frames = [read_image(out / frame_name(i))[0] for i in range(3)]
    assert all(f.shape == (96, 96, 4) and f.dtype == np.uint8 for f in frames)
    for a, b in zip(frames, frames[1:]):
        changed = np.abs(a.astype(np.int16) - b.astype(np.int16)).max(axis=-1) > 8
        assert changed.mean() > 0.01, "the leaves did not move between frames"


def test_a_saved_scene_keeps_its_light_and_wind(gl, tmp_path, capsys):
    saved = tmp_path / "windy.toml"
    code = main(["scene", "--leaves", "60", "--layout", "plant", "--seed", "5", "--sun", "200,20", "--wind", "3",
                 "--shadows", "off", "--exposure", "0.5", "--save", str(saved)])
    assert code == 0, capsys.readouterr().err
    spec = load_scene(saved)
    assert spec.light == LightSettings(sun=(200.0, 20.0), shadows=False, exposure=0.5)
    assert spec.wind == WindSettings(speed=3.0)
    text = saved.read_text()
    assert "[light]" in text and "[wind]" in text
    again = tmp_path / "again.toml"   # saved again from the file: the same recipe
    assert main(["scene", str(saved), "--save", str(again), "-q"]) == 0
    assert load_scene(again) == spec
    # options on the command line override the file's table, the rest of it stays
    assert main(["scene", str(saved), "--sun", "90,45", "--save", str(tmp_path / "third.toml"), "-q"]) == 0
    third = load_scene(tmp_path / "third.toml")
    assert third.light == spec.light.replace(sun=(90.0, 45.0)) and third.wind == spec.wind


def test_the_settings_tables_of_docs_canopy_match_the_code():
    """docs/canopy.md's [light]/[wind]/variety/[[edits]] tables are written from the field specs
    (tools/canopy_settings_table.py); a changed default or range must be written again."""
    root = Path(__file__).resolve().parent.parent
    result = subprocess.run([sys.executable, "tools/canopy_settings_table.py", "--check"], cwd=root,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stdout + result.stderr


def test_a_negative_azimuth_is_a_value_not_an_option(tmp_path):
    """``--sun -180,90``: a comma list starting with '-' is the option's value (argparse alone
    would take it for an unknown option)."""
    out = tmp_path / "s.toml"
    assert main(["scene", "--leaves", "3", "--sun", "-180,90", "--save", str(out), "-q"]) == 0
    assert "-180" in out.read_text()
