"""``leafview --help`` loads only the command table: no OpenGL, window or UI library, and no
command module; each command's own ``--help`` lists its options. Every command module has
``add_arguments(parser)`` and ``run(args) -> int``."""

from __future__ import annotations

import argparse
import importlib
import json
import subprocess
import sys
import time

import pytest

from leafview.cli import COMMANDS, main

GL_AND_UI = ("moderngl", "glcontext", "glfw", "imgui_bundle")

_LOADED = """
import json, sys
from leafview.cli import main
try:
    main({argv!r})
except SystemExit as exc:
    code = exc.code
print(json.dumps({{"code": code, "modules": sorted(sys.modules)}}))
"""


def _loaded_after(argv: list[str]) -> tuple[int, list[str], str]:
    """(exit code, modules loaded, stdout before the JSON line) of ``leafview ARGV`` in a fresh
    interpreter."""
    result = subprocess.run([sys.executable, "-c", _LOADED.format(argv=argv)], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    *text, last = result.stdout.rstrip("\n").split("\n")
    report = json.loads(last)
    return report["code"], report["modules"], "\n".join(text)


@pytest.mark.parametrize("argv", [["--help"], ["--version"], []])
def test_top_level_help_loads_no_gl_and_no_command(argv):
    code, modules, text = _loaded_after(argv)
    assert code == (2 if not argv else 0)
    gl = [m for m in modules if m.split(".")[0] in GL_AND_UI]
    assert gl == [], f"leafview {' '.join(argv)} imported {gl}"
    commands = [m for m in modules if m in {module for module, _ in COMMANDS.values()}]
    assert commands == [], f"leafview {' '.join(argv)} imported the command modules {commands}"
    if argv == ["--help"]:
        for name in COMMANDS:
            assert f"  {name} " in text, name


def test_help_is_fast():
    """``leafview --help`` as the console script runs it (``leafview.cli:main``). Not a benchmark:
    a generous bound (the machine may be busy) that catches a heavy import creeping in."""
    code = "import sys; from leafview.cli import main; sys.exit(main())"
    started = time.perf_counter()
    result = subprocess.run([sys.executable, "-c", code, "--help"], capture_output=True, text=True, timeout=120)
    seconds = time.perf_counter() - started
    assert result.returncode == 0, result.stderr[-3000:]
    assert "COMMAND" in result.stdout and "render" in result.stdout and "bench" in result.stdout
    assert seconds < 10.0, f"leafview --help took {seconds:.1f} s"


def test_command_help_lists_its_options(capsys):
    with pytest.raises(SystemExit) as info:
        main(["render", "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    for option in ("--output", "--size", "--view", "--format", "--sheet", "--grid", "--quiet", "PRESET"):
        assert option in out, option
    assert "three-quarter" in out


def test_render_help_loads_only_render():
    code, modules, text = _loaded_after(["render", "--help"])
    assert code == 0 and "--sheet" in text
    others = [m for name, (m, _) in COMMANDS.items() if name != "render" and m in modules]
    assert others == []


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_command_module_has_the_interface(name):
    module = importlib.import_module(COMMANDS[name][0])
    assert callable(module.add_arguments) and callable(module.run)
    parser = argparse.ArgumentParser(prog=f"leafview {name}")
    module.add_arguments(parser)
    assert parser.format_help()


def test_unknown_command_exits_2(capsys):
    with pytest.raises(SystemExit) as info:
        main(["rendr", "ovate"])
    assert info.value.code == 2
    assert "invalid choice: 'rendr'" in capsys.readouterr().err


def test_scene_command_does_not_load_the_photo_fit():
    """``leafview scene`` loads neither the photo fit (scipy, scikit-image: about a second; the
    scene viewer is imported only for ``--view``) nor the thumbnails' sheets with the lobe-outline
    fit (``scipy.optimize``, ``scipy.interpolate``: about 0.2 s), which its ``--views`` options
    (:mod:`leafview.cli.views`) do not need."""
    unwanted = ("leafview.fit", "skimage", "leafview.app.scene_view", "leafview.gpu.sheets",
                "leafview.botany.outline_fit", "scipy.optimize", "scipy.interpolate")
    code = f"import sys, leafview.cli.scene; print(sorted(m for m in {unwanted!r} if m in sys.modules))"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    assert result.stdout.strip() == "[]", result.stdout
