"""The one input reader (leafview.inputs): non-regular files, size, nesting, long integers and bad
encodings are refused promptly with one line naming the file, through every loader and the CLI."""

import json
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from leafview import inputs
from leafview.botany.catalogue import load_landmark_leaf
from leafview.botany.lobes import load_lobed_leaf
from leafview.cli import main
from leafview.core import compact
from leafview.core.io import load_leaves, load_params, read_document
from leafview.core.params import LeafParams
from leafview.errors import ParamError
from leafview.resources import builtin_presets
from leafview.scene.spec import load_scene

ROOT = Path(__file__).resolve().parent.parent
OVATE = ROOT / "assets/presets/ovate.toml"
needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")


def _fifo(tmp_path: Path, name: str) -> Path:
    path = tmp_path / name
    os.mkfifo(path)
    return path


def _returns_promptly(fn, seconds: float = 10.0):
    """Run ``fn`` in a thread; fail (instead of hanging the suite) if it blocks."""
    out: dict = {}

    def target():
        try:
            out["value"] = fn()
        except BaseException as exc:  # handed back to the test
            out["error"] = exc

    t = threading.Thread(target=target, daemon=True)
    t0 = time.perf_counter()
    t.start()
    t.join(seconds)
    if t.is_alive():
        # unblock a reader stuck on the FIFO so the thread can end
        pytest.fail(f"{fn} blocked for {seconds} s")
    assert time.perf_counter() - t0 < seconds
    if "error" in out:
        raise out["error"]
    return out.get("value")


# -- the reader ---------------------------------------------------------------------------------
@needs_fifo
@pytest.mark.parametrize("loader", [read_document, load_params, load_leaves, load_scene, load_lobed_leaf,
                                    load_landmark_leaf])
def test_a_fifo_is_refused_without_blocking(tmp_path, loader):
    fifo = _fifo(tmp_path, "pipe.toml")
    with pytest.raises(ParamError, match=r"pipe\.toml: is a FIFO"):
        _returns_promptly(lambda: loader(fifo))


def test_devices_and_directories_are_refused(tmp_path):
    with pytest.raises(ParamError, match="is a character device"):
        inputs.read_bytes("/dev/zero")
    link = tmp_path / "zero.toml"
    link.symlink_to("/dev/zero")
    with pytest.raises(ParamError, match=r"zero\.toml: is a character device"):
        _returns_promptly(lambda: load_params(link))
    (tmp_path / "dir.toml").mkdir()
    with pytest.raises(ParamError, match=r"dir\.toml: is a directory"):
        load_params(tmp_path / "dir.toml")
    with pytest.raises(ParamError, match="no such file"):
        load_params(tmp_path / "absent.toml")


def test_size_limit_from_argument_and_environment(tmp_path, monkeypatch):
    path = tmp_path / "big.toml"
    path.write_text(OVATE.read_text() + "#" + "x" * 5000 + "\n")
    with pytest.raises(ParamError, match=r"big\.toml: is \d,\d+ bytes, above the 4,096 bytes size limit"):
        inputs.read_text(path, max_bytes=4096)
    monkeypatch.setenv(inputs.MAX_BYTES_ENV, "4096")
    with pytest.raises(ParamError, match="LEAFVIEW_MAX_INPUT_BYTES"):
        load_params(path)
    monkeypatch.setenv(inputs.MAX_BYTES_ENV, "lots")
    with pytest.raises(ParamError, match="LEAFVIEW_MAX_INPUT_BYTES: expected a whole number"):
        load_params(path)
    monkeypatch.delenv(inputs.MAX_BYTES_ENV)
    assert load_params(path).name == "ovate"
    assert inputs.max_input_bytes() == inputs.DEFAULT_MAX_BYTES == 256 * 2**20


@pytest.mark.parametrize("suffix, deep", [(".json", "[" * 100_000 + "]" * 100_000),
                                          (".json", '{"a":' * 100_000 + "1" + "}" * 100_000),
                                          (".toml", "x = " + "[" * 100_000 + "]" * 100_000),
                                          (".toml", "x = " + "{a = " * 100_000 + "1" + "}" * 100_000)])
def test_deep_nesting_is_refused_before_the_parser_recurses(tmp_path, suffix, deep):
    path = tmp_path / f"deep{suffix}"
    path.write_text(deep)
    with pytest.raises(ParamError, match=rf"deep\{suffix}:1:\d+: nested more than 64 levels deep"):
        read_document(path)


def test_deep_dotted_toml_tables_are_refused_after_parsing(tmp_path):
    path = tmp_path / "dotted.toml"
    path.write_text("[" + ".".join(["a"] * 200) + "]\nx = 1\n")
    with pytest.raises(ParamError, match="nested more than 64 levels deep"):
        read_document(path)
    ok = tmp_path / "ok.json"
    ok.write_text("[" * 60 + "]" * 60)
    expected: list = []
    for _ in range(59):
        expected = [expected]
    assert read_document(ok) == expected


@pytest.mark.parametrize("suffix, text", [(".json", '{"schema": 1, "x": ' + "9" * 5000 + "}"),
                                          (".toml", "schema = " + "9" * 5000 + "\n"),
                                          (".toml", "schema = " + "1_" * 2000 + "1\n")])
def test_long_integers_are_refused(tmp_path, suffix, text):
    path = tmp_path / f"long{suffix}"
    path.write_text(text)
    with pytest.raises(ParamError, match=r"long\.\w+:1:\d+: a number of \d+ digits; at most 100"):
        read_document(path)


def test_long_digits_inside_strings_are_text(tmp_path):
    path = tmp_path / "name.toml"
    path.write_text(OVATE.read_text().replace('name = "ovate"', 'name = "' + "7" * 200 + '"'))
    assert load_params(path).name == "7" * 200


def test_bad_utf8_names_the_byte_offset(tmp_path):
    text = OVATE.read_bytes()
    at = text.index(b"[shape]")
    path = tmp_path / "latin1.toml"
    path.write_bytes(text[:at] + b"# caf\xe9\n" + text[at:])
    with pytest.raises(ParamError, match=rf"latin1\.toml: not UTF-8 text: invalid continuation byte at byte {at + 5} "
                                         r"\(line \d+\)"):
        load_params(path)
    lobed = tmp_path / "lobed.toml"
    lobed.write_bytes(b"lobed = 1\nname = \"\xff\"\n")
    with pytest.raises(ParamError, match=r"lobed\.toml: not UTF-8 text: invalid start byte at byte 18 \(line 2\)"):
        load_lobed_leaf(lobed)


def test_compact_text_goes_through_the_same_limits():
    with pytest.raises(ParamError, match="nested more than 64"):
        compact.loads("[" * 1000 + "]" * 1000)
    with pytest.raises(ParamError, match="at most 100"):
        compact.loads('{"leafview": 1, "omega": [' + "1" * 300 + "]}")


# -- names ----------------------------------------------------------------------------------------
def test_names_are_bounded_and_printable(tmp_path):
    good = json.loads(json.dumps(LeafParams.load(OVATE).to_dict()))
    for name, words in (("x" * 257, "257 characters; at most 256"), ("a\x00b", "control character U+0000"),
                        ("line\nbreak", "control character U+000A"), ("esc\x1b[2J", "U+001B")):
        path = tmp_path / "named.json"
        path.write_text(json.dumps({**good, "name": name}))
        with pytest.raises(ParamError, match=rf"named\.json: name: .*{re.escape(words)}"):
            load_params(path)
    path.write_text(json.dumps({**good, "name": "Fagus sylvatica – é"}))
    assert load_params(path).name == "Fagus sylvatica – é"


def test_a_200_mb_name_never_reaches_the_image(tmp_path, capsys):
    path = tmp_path / "huge.leaf.json"
    path.write_text('{"leafview": 1, "name": "' + "n" * 300_000 + '", "omega": '
                    + json.dumps(LeafParams.load(OVATE).to_vector().tolist()) + "}")
    assert main(["render", str(path), "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "300,000 characters" in err and "huge.leaf.json" in err
    assert not (tmp_path / "x.png").exists()


# -- the command line ---------------------------------------------------------------------------
@needs_fifo
@pytest.mark.parametrize("argv", [["render", "{fifo}", "-o", "{out}/x.png"],
                                  ["scene", "{fifo}", "-o", "{out}/x.png"],
                                  ["export", "{fifo}", "-o", "{out}/x.glb"],
                                  ["shapes", "--lobed", "{fifo}", "-o", "{out}/x.png"],
                                  ["morph", "{fifo}", "ovate", "-o", "{out}/m"]])
def test_cli_fifo_inputs_exit_2_promptly(tmp_path, capsys, argv):
    fifo = _fifo(tmp_path, "pipe.toml")
    out = tmp_path / "out"
    args = [a.format(fifo=fifo, out=out) for a in argv]
    code = _returns_promptly(lambda: main(args))
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "pipe.toml" in err and ("FIFO" in err or "not a" in err), err
    assert not out.exists()


def test_cli_dev_zero_and_deep_nesting_exit_2(tmp_path, capsys):
    link = tmp_path / "zero.toml"
    link.symlink_to("/dev/zero")
    assert main(["render", str(link), "-o", str(tmp_path / "x.png")]) == 2
    assert main(["render", "/dev/zero", "-o", str(tmp_path / "x.png")]) == 2
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    assert main(["scene", str(deep), "-o", str(tmp_path / "x.png")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 3 and all("error:" in line for line in lines), lines
    assert "character device" in lines[0] and "deep.json:1:" in lines[2]
    assert not (tmp_path / "x.png").exists()


def _run(args, cwd):
    return subprocess.run([sys.executable, "-c", "import sys; from leafview.cli import main; sys.exit(main())", *args],
                          cwd=cwd, capture_output=True, text=True,
                          timeout=60, stdin=subprocess.DEVNULL)


@needs_fifo
def test_subprocess_fifo_and_long_int_give_one_line_and_no_traceback(tmp_path):
    _fifo(tmp_path, "pipe.toml")
    (tmp_path / "long.toml").write_text("schema = " + "9" * 5000 + "\n")
    for name in ("pipe.toml", "long.toml"):
        result = _run(["render", name, "-o", "x.png"], tmp_path)
        assert result.returncode == 2, result.stderr
        assert "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr
        assert name in result.stderr
    assert not (tmp_path / "x.png").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.toml", "pipe.toml"]


def test_builtin_presets_still_read():
    for path in builtin_presets().values():
        assert load_params(path).name
