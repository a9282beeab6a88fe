"""The ``leafview`` command end to end, and malformed input: exit 2, the field named, no output."""

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from leafview.cli import main
from leafview.core.params import LeafParams, Transform
from leafview.export.images import PARAMS_ATTRIBUTE, read_image
from leafview.resources import builtin_presets

pytestmark = pytest.mark.gl
ROOT = Path(__file__).resolve().parent.parent


def test_console_script_renders_a_thumbnail(gl, tmp_path):
    exe = shutil.which("leafview") or pytest.fail("the leafview console script is not installed")
    result = subprocess.run([exe, "render", str(ROOT / "assets/presets/ovate.toml"), "-o", "ovate.png"],
                            cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "wrote ovate.png" in result.stdout
    pixels, meta = read_image(tmp_path / "ovate.png")
    assert pixels.shape == (256, 256, 4) and pixels.dtype == np.uint8
    assert meta["oiio:ColorSpace"].lower().startswith("srgb")
    assert LeafParams.from_dict(json.loads(meta[PARAMS_ATTRIBUTE])) == LeafParams.load(ROOT / "assets/presets/ovate.toml")


@pytest.mark.parametrize("fmt, dtype, space", [("exr", np.float16, "lin"), ("tif", np.uint8, "srgb")])
def test_formats_and_embedded_parameters(gl, tmp_path, fmt, dtype, space):
    out = tmp_path / f"leaf.{fmt}"
    assert main(["render", "serrate", "-o", str(out), "--size", "64", "-q"]) == 0
    pixels, meta = read_image(out)
    assert pixels.dtype == dtype and pixels.shape == (64, 64, 4)
    assert meta["oiio:ColorSpace"].lower().startswith(space)
    assert LeafParams.from_dict(json.loads(meta[PARAMS_ATTRIBUTE])).name == "serrate"


def test_directory_of_thumbnails_and_sheet(gl, tmp_path, capsys):
    assert main(["render", str(ROOT / "assets/presets"), "-o", str(tmp_path / "thumbs"), "--size", "48"]) == 0
    written = sorted(p.stem for p in (tmp_path / "thumbs").iterdir())
    assert written == sorted(builtin_presets())
    assert f"wrote {len(builtin_presets())} png thumbnails" in capsys.readouterr().out
    assert main(["render", "ovate", "linear", "curled", "--sheet", "-o", str(tmp_path / "sheet.png"),
                 "--size", "64", "--view", "three-quarter", "-q"]) == 0
    sheet, _ = read_image(tmp_path / "sheet.png")
    assert sheet.shape[1] == 3 * 64 and sheet.shape[0] > 64 and (sheet[..., 3] == 255).all()


def _good_text() -> str:
    return (ROOT / "assets/presets/ovate.toml").read_text()


DEFECTS = {
    "syntax-error": ("leaf.toml", lambda: _good_text().replace("[shape]", "[shape"), r"leaf\.toml:\d+:\d+: TOML syntax"),
    "wrong-type": ("leaf.toml", lambda: _good_text().replace("translucency = 0.35", 'translucency = "high"'),
                   "material.translucency: expected a number"),
    "nan": ("leaf.json", lambda: json.dumps(_with(["shape", "zf", 1], math.nan)), r"shape\.zf\[1\]: is NaN"),
    "inf": ("leaf.toml", lambda: _good_text().replace("scale = 1.0", "scale = inf"), "transform.scale: is \\+Inf"),
    "unknown-key": ("leaf.toml", lambda: _good_text().replace("[jitter]", "[jitter]\ndegree = 2"),
                    "jitter.degree: unknown key"),
    "missing-field": ("leaf.json", lambda: json.dumps(_without("shape", "a2")), "shape.a2: missing field"),
    "schema-version": ("leaf.toml", lambda: _good_text().replace("schema = 1", "schema = 7"),
                       "schema: unsupported schema version 7"),
    "vbar-order": ("leaf.json", lambda: json.dumps(_with(["shape", "silhouette", 2, 0], 0.3)),
                   r"shape\.silhouette\[2\]\[0\]: v̄ must be strictly increasing"),
    "empty-file": ("leaf.toml", lambda: "", "leaf.toml: empty file"),
    "missing-path": ("absent.toml", None, "absent.toml: no such file"),
    "wrong-shape": ("leaf.json", lambda: json.dumps(_with(["shape", "a1"], [0, 1])), r"shape\.a1: expected 3 numbers"),
}


def _with(path, value):
    d = LeafParams.load(ROOT / "assets/presets/ovate.toml").to_dict()
    node = d
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return d


def _without(group, key):
    d = LeafParams.load(ROOT / "assets/presets/ovate.toml").to_dict()
    del d[group][key]
    return d


@pytest.mark.parametrize("defect", sorted(DEFECTS))
@pytest.mark.parametrize("mode", ["file", "dir", "sheet"])
def test_malformed_input_exits_2_names_the_field_and_writes_nothing(tmp_path, capsys, defect, mode):
    import re

    fname, make, expected = DEFECTS[defect]
    bad = tmp_path / "in" / fname
    bad.parent.mkdir()
    if make is not None:
        bad.write_text(make())
    out = tmp_path / "out"
    out.mkdir()
    args = {"file": [str(bad), "-o", str(out / "leaf.png")],
            "dir": ["ovate", str(bad), "-o", str(out / "thumbs")],
            "sheet": ["ovate", str(bad), "--sheet", "-o", str(out / "sheet.png")]}[mode]
    code = main(["render", *args, "--size", "32"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert re.search(expected, err), err
    assert list(out.rglob("*")) == [], "a failed run left files behind"


@pytest.mark.parametrize("args, words", [
    (["ovate", "linear", "-o", "x.png"], "need -o DIR"),
    (["ovate", "-o", "x.jpg"], "unknown image type"),
    (["ovate", "-o", "x.png", "--format", "exr"], "--format exr"),
    (["nosuchpreset", "-o", "x.png"], "no such file, directory or built-in preset"),
    (["ovate", "--sheet", "-o", "s.exr"], "--sheet writes an 8-bit"),
])
def test_bad_arguments_exit_2(tmp_path, monkeypatch, capsys, args, words):
    monkeypatch.chdir(tmp_path)
    assert main(["render", *args]) == 2
    assert words in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_argparse_errors_exit_2(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        main(["render", "ovate", "-o", "x.png", "--size", "huge"])
    assert info.value.code == 2
    with pytest.raises(SystemExit) as info:
        main(["render", "ovate", "-o", "x.png", "--view", "sideways"])
    assert info.value.code == 2
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args", [
    ["render", "ovate", "-o", ""],
    ["export", "ovate", "-o", ""],
    ["shapes", "cordate", "-o", ""],
    ["morph", "ovate", "lanceolate", "-o", ""],
    ["scene", "--leaves", "3", "-o", ""],
    ["scene", "--leaves", "3", "--save", ""],
    ["scene", "--leaves", "3", "--export", ""],
    ["scene", "--leaves", "3", "--view", "--screenshot", ""],
    ["view", "ovate", "--screenshot", ""],
    ["dataset", "--count", "1", "-o", ""],
])
def test_an_empty_output_path_is_refused_not_read_as_the_current_folder(tmp_path, monkeypatch, capsys, args):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        main(args)
    assert info.value.code == 2
    assert "an empty path" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_presets_command_lists_builtins(capsys):
    assert main(["presets"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in builtin_presets())


def test_gl_unavailable_is_a_message_not_a_traceback(tmp_path):
    """With EGL hidden the command explains what to install and exits 1 without a traceback."""
    code = ("import moderngl, sys\n"
            "def fail(*a, **k): raise Exception('libEGL.so.1: cannot open shared object file')\n"
            "moderngl.create_standalone_context = fail\n"
            "from leafview.cli import main\n"
            f"sys.exit(main(['render', 'ovate', '-o', r'{tmp_path / 'x.png'}']))\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert "apt-get install libegl1 libgl1-mesa-dri" in result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "x.png").exists()


def test_png_round_trip_keeps_straight_alpha(gl, tmp_path):
    """Partially covered edge pixels read back exactly as written (no premultiplication)."""
    from leafview.export.images import write_image

    img = gl.render(LeafParams.load(ROOT / "assets/presets/maize.toml"), (96, 96), "side")
    partial = (img[..., 3] > 0) & (img[..., 3] < 255)
    assert partial.sum() > 50
    write_image(tmp_path / "a.png", img)
    back, _ = read_image(tmp_path / "a.png")
    np.testing.assert_array_equal(back, img)


@pytest.mark.parametrize("key", ["\n", "a\rb", "\x00", "x\u2028y", "\x1b[31m"])
def test_a_control_character_in_a_key_stays_escaped_in_one_line(tmp_path, monkeypatch, capsys, key):
    """Keys and values quoted from a file are written with escapes: a key of "\\n" (found by the
    long fuzz run in a landmark file) split the error over two lines."""
    monkeypatch.chdir(tmp_path)
    doc = LeafParams.load(builtin_presets()["ovate"]).to_dict()
    doc[key] = 1
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    assert main(["render", "bad.json", "-o", "x.png"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.endswith("\n") and "\r" not in err and "\x00" not in err, repr(err)
    assert "\u2028" not in err and "\x1b" not in err
    assert key.encode("unicode_escape").decode() in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.json"]


@pytest.mark.parametrize("extra", [[], ["--sheet", "--format", "png"]])
def test_render_refuses_a_leaf_too_far_to_frame_naming_the_file(tmp_path, capsys, extra):
    """A leaf 1 long at 10⁵ from the origin cannot be resolved in 32 bits: exit 2, one line naming
    the file, the leaf and the field, and nothing written (found by the CLI fuzz run)."""
    leaf = LeafParams.load(builtin_presets()["ovate"])
    src = tmp_path / "far.toml"
    leaf.replace(name="far", transform=Transform(translation=(1e5, 0.0, 0.0))).save(src)
    out = tmp_path / "out" / "far.png"
    assert main(["render", str(src), "-o", str(out), "--size", "8", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(src) in err and "transform" in err and "leaf far" in err, err
    assert not out.exists()
