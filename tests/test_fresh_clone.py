"""What a fresh clone needs is what the README says (issue 14).

* ``git clone`` of this repository (its committed HEAD) with a fresh venv: the README's Install and
  Render a leaf commands, read from the README itself and run as written, write the PNG and the
  line the README shows.
* ``.ci/run`` installs no system package the README does not name, and runs the README's test
  command with nothing in between (no ``npm ci``: the ``gltf_validator`` fixture installs the
  glTF validator's npm package itself).
* That fixture's setup (``support.validate.ensure_gltf_validator``): what it says without node or
  npm and when the registry cannot be reached, and two processes installing at once.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
from support import validate
from support.validate import ValidatorMissing, ensure_gltf_validator

from leafview.export.images import read_image
from tests.conftest import require_or_skip

ROOT = Path(__file__).resolve().parent.parent
APT = re.compile(r"^\s*(sudo\s+)?apt-get\s")


# -- the README's code blocks -------------------------------------------------------------------
def readme_blocks(text: str, title: str) -> list[tuple[str, list[str]]]:
    """(language, lines) of each fenced code block in the README section ``## title``."""
    section = re.search(rf"^## {re.escape(title)}[ \t]*\n(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert section, f"README.md has no '## {title}' section"
    return [(lang, body.splitlines())
            for lang, body in re.findall(r"^```(\w*)[ \t]*\n(.*?)^```", section.group(1), re.M | re.S)]


def readme_steps(text: str, titles: tuple[str, ...] = ("Install", "Render a leaf")) -> list[tuple[str, list[str]]]:
    """(command, the output lines the README shows for it), in README order: every line of a
    ``bash`` block (comments are left to bash) but the ``apt-get`` ones, and every ``$`` line of
    a ``console`` block with the lines below it."""
    steps: list[tuple[str, list[str]]] = []
    for title in titles:
        for lang, lines in readme_blocks(text, title):
            if lang == "console":
                for line in lines:
                    if line.startswith("$ "):
                        steps.append((line[2:].strip(), []))
                    elif steps and line.strip():
                        steps[-1][1].append(line.rstrip())
            elif lang in ("bash", "sh", "shell"):
                steps += [(line.strip(), []) for line in lines
                          if line.strip() and not line.lstrip().startswith("#") and not APT.match(line)]
    return steps


def apt_packages(text: str) -> set[str]:
    """Package names on the ``apt-get install`` lines of ``text`` (options and comments dropped)."""
    names: set[str] = set()
    for line in text.splitlines():
        found = re.search(r"apt-get\s+install\s+([^#\n]*)", line)
        if found:
            names |= {w for w in found.group(1).split() if not w.startswith(("-", "$", ">"))}
    return names


def test_readme_shows_install_and_render_commands():
    steps = readme_steps((ROOT / "README.md").read_text(encoding="utf-8"))
    commands = [cmd for cmd, _ in steps]
    assert any(re.match(r"pip install (-e )?\.", c) for c in commands), commands
    renders = [(cmd, out) for cmd, out in steps if cmd.startswith("leafview render")]
    assert renders and re.fullmatch(r"wrote \S+\.png \(\d+×\d+, .*\)", renders[0][1][0]), steps


def test_ci_runs_the_readme_test_command_after_only_the_packages_the_readme_names():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    named = apt_packages("\n".join("\n".join(lines) for title in ("Install", "Run the tests")
                                   for _, lines in readme_blocks(readme, title)))
    listed = re.search(r'^\s*packages="([^"]+)"', ci, re.M)
    installed = set(listed.group(1).split()) if listed else apt_packages(ci)
    assert installed >= {"libegl1", "libgl1-mesa-dri", "xvfb", "nodejs", "npm"}, installed
    assert installed <= named, f".ci/run installs packages README.md does not name: {installed - named}"
    assert not re.search(r"^[^#]*\bnpm\s+(ci|install)\b", ci, re.M), ".ci/run sets up npm packages itself"
    test_block = [line for line in readme_blocks(readme, "Run the tests")[0][1]
                  if line.strip() and not APT.match(line)]
    ci_lines = [line.strip() for line in ci.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    assert test_block == ['pip install -e ".[test]"', "LEAFVIEW_REQUIRE_GL=1 python -m pytest"], test_block
    assert ci_lines[-1] == test_block[-1], "the README's test command is not the last thing .ci/run does"
    assert any(line.endswith('pip install -q -e ".[test]"') or line == test_block[0] for line in ci_lines)


# -- a fresh clone ------------------------------------------------------------------------------
def png_size(path: Path) -> tuple[int, int]:
    """(width, height) of a PNG after checking its structure with the standard library alone:
    signature, every chunk's CRC, IHDR first, IEND last, and IDAT inflating to exactly the
    filtered scanlines IHDR promises."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    pos, chunks = 8, []
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        (crc,) = struct.unpack(">I", data[pos + 8 + length:pos + 12 + length])
        assert zlib.crc32(kind + body) == crc, f"{path}: bad CRC in {kind!r}"
        chunks.append((kind, body))
        pos += 12 + length
    assert chunks[0][0] == b"IHDR" and chunks[-1] == (b"IEND", b""), [k for k, _ in chunks]
    width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", chunks[0][1])
    channels = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}[colour]
    assert interlace == 0
    pixels = zlib.decompress(b"".join(body for kind, body in chunks if kind == b"IDAT"))
    assert len(pixels) == height * (1 + (width * channels * depth + 7) // 8)
    return width, height


def _fresh_env(venv: Path) -> dict[str, str]:
    """The environment of a shell with ``venv`` activated and nothing of this test run leaking in."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP", "PYTHONUSERBASE", "VIRTUAL_ENV",
                        "PYTEST_CURRENT_TEST", "PYTEST_ADDOPTS")}
    env["VIRTUAL_ENV"] = str(venv)
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    return env


@pytest.mark.gl
@pytest.mark.slow
def test_readme_install_and_render_work_in_a_fresh_clone(gl, tmp_path):
    """``git clone``, ``python -m venv`` (no system site packages), then the README's Install and
    Render a leaf commands as the README writes them (``sudo apt-get`` lines left out)."""
    git = shutil.which("git")
    if git is None or not (ROOT / ".git").exists():
        pytest.skip(f"needs git and a git checkout ({ROOT} is not one)")
    timings: list[tuple[str, float]] = []

    def run(label: str, cmd: list[str], **kw) -> subprocess.CompletedProcess:
        start = time.perf_counter()
        result = subprocess.run(cmd, capture_output=True, text=True, encoding="utf-8", errors="replace",
                                timeout=900, check=False, **kw)
        timings.append((label, time.perf_counter() - start))
        print(f"{timings[-1][1]:7.1f} s  {label}")
        assert result.returncode == 0, (f"`{label}` exited with {result.returncode}:\n"
                                        f"{result.stdout[-3000:]}\n{result.stderr[-3000:]}")
        return result

    clone = tmp_path / "leafview"
    run("git clone", [git, "clone", "-q", "--no-hardlinks", str(ROOT), str(clone)])
    steps = readme_steps((clone / "README.md").read_text(encoding="utf-8"))   # the committed README
    assert [c for c, _ in steps if c.startswith("pip")] and [c for c, _ in steps if c.startswith("leafview")], steps

    venv = clone / ".venv"
    run("python -m venv .venv", [sys.executable, "-m", "venv", str(venv)], cwd=clone)
    config = (venv / "pyvenv.cfg").read_text(encoding="utf-8")
    assert re.search(r"include-system-site-packages\s*=\s*false", config), config
    env = _fresh_env(venv)

    outputs = []
    for cmd, expected in steps:
        result = run(cmd, ["bash", "-c", cmd], cwd=clone, env=env)
        outputs.append((cmd, result.stdout.splitlines(), expected))
    where = run("command -v leafview", ["bash", "-c", "command -v leafview"], cwd=clone, env=env).stdout.strip()
    assert Path(where).parent == venv / "bin", where
    print(f"{sum(t for _, t in timings):7.1f} s  in all")

    for cmd, printed, expected in outputs:
        if expected:
            assert printed == expected, f"`{cmd}` printed {printed}, the README shows {expected}"
    (cmd, printed, expected), = [o for o in outputs if o[0].startswith("leafview render")]
    name, w, h = re.fullmatch(r"wrote (\S+) \((\d+)×(\d+), .*\)", expected[0]).groups()
    image = clone / name
    assert png_size(image) == (int(w), int(h))
    pixels, _ = read_image(image)
    assert pixels.shape == (int(h), int(w), 4)
    assert np.any(pixels[..., 3] == 255) and np.any(pixels[..., 3] == 0), "the leaf is not drawn"


# -- the gltf_validator fixture's setup ---------------------------------------------------------
def _validator_copy(folder: Path) -> Path:
    """tools/gltf_validator without node_modules, at ``folder``."""
    folder.mkdir()
    for name in ("package.json", "package-lock.json", "validate.mjs"):
        shutil.copy2(validate.VALIDATOR_DIR / name, folder / name)
    return folder


@pytest.mark.parametrize("tool", ["node", "npm"])
def test_validator_setup_names_what_is_missing(tmp_path, monkeypatch, tool):
    folder = _validator_copy(tmp_path / "gltf_validator")
    real_which = shutil.which
    monkeypatch.setattr(validate.shutil, "which", lambda name, *a, **k: None if name == tool else real_which(name))
    with pytest.raises(ValidatorMissing) as caught:
        ensure_gltf_validator(folder)
    message = str(caught.value)
    assert f"no `{tool}` on PATH" in message and "apt-get install nodejs npm" in message, message
    assert sorted(p.name for p in folder.iterdir()) == ["package-lock.json", "package.json", "validate.mjs"]


def test_validator_setup_offline_says_the_registry_is_unreachable(tmp_path, monkeypatch):
    if shutil.which("node") is None or shutil.which("npm") is None:
        require_or_skip("needs node and npm (apt-get install nodejs npm)")
    folder = _validator_copy(tmp_path / "gltf_validator")
    monkeypatch.setenv("npm_config_registry", "http://127.0.0.1:9/")     # nothing listens on port 9
    monkeypatch.setenv("npm_config_cache", str(tmp_path / "empty_npm_cache"))
    monkeypatch.setenv("npm_config_fetch_retries", "0")
    start = time.perf_counter()
    with pytest.raises(ValidatorMissing) as caught:
        ensure_gltf_validator(folder, timeout=120)
    message = str(caught.value)
    print(f"npm gave up after {time.perf_counter() - start:.1f} s:\n{message}")
    assert "could not reach the npm registry" in message and "ECONNREFUSED" in message, message
    assert f"npm ci --prefix {folder}" in message
    assert not (folder / "node_modules").exists()
    assert not list(folder.glob(".install-*")), "the failed install left its folder behind"


@pytest.mark.slow
@pytest.mark.usefixtures("gltf_validator")   # the registry (or npm's cache) is reachable
def test_two_processes_install_once_and_both_get_it(tmp_path):
    folder = _validator_copy(tmp_path / "gltf_validator")
    code = ("import sys; sys.path.insert(0, sys.argv[1]); from pathlib import Path; "
            "from support.validate import ensure_gltf_validator; print(ensure_gltf_validator(Path(sys.argv[2]))[1])")
    procs = [subprocess.Popen([sys.executable, "-c", code, str(ROOT / "tests"), str(folder)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = [(p.wait(timeout=600), *p.communicate()) for p in procs]
    assert [rc for rc, _, _ in results] == [0, 0], results
    assert [out.strip() for _, out, _ in results] == [str(folder / "validate.mjs")] * 2
    assert sum("installed gltf-validator" in err for _, _, err in results) == 1, results
    assert not list(folder.glob(".install-*"))
    version = subprocess.run(["node", "--input-type=module", "-e",
                              "import v from 'gltf-validator'; console.log(v.version())"],
                             cwd=folder, capture_output=True, text=True, timeout=60, check=True).stdout
    assert version.strip() == json.loads((folder / "package-lock.json").read_text())["packages"][
        "node_modules/gltf-validator"]["version"]
