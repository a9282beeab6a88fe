"""The built wheel carries shaders/ and assets/ and renders from outside the source tree."""

import subprocess
import sys
import venv
import zipfile
from pathlib import Path

import pytest

pytestmark = [pytest.mark.gl, pytest.mark.slow]
ROOT = Path(__file__).resolve().parent.parent


def _run(cmd, **kw):
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=900, **kw)
    assert result.returncode == 0, f"{cmd} failed:\n{result.stdout}\n{result.stderr}"
    return result


def test_wheel_installs_in_a_clean_venv_and_renders(gl, tmp_path):
    dist = tmp_path / "dist"
    _run([sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-q", "-w", str(dist)])
    wheel = next(dist.glob("leafview-*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    assert "leafview/shaders/leaf_eval.glsl" in names and "leafview/assets/presets/ovate.toml" in names
    assert "leafview/py.typed" in names

    env_dir = tmp_path / "venv"
    venv.EnvBuilder(with_pip=True, clear=True).create(env_dir)
    py = env_dir / "bin" / "python"
    _run([str(py), "-m", "pip", "install", "-q", str(wheel)])

    work = tmp_path / "elsewhere"
    work.mkdir()
    _run([str(env_dir / "bin" / "leafview"), "render", "ovate", "-o", "thumb.png", "--size", "64"], cwd=work)
    assert (work / "thumb.png").stat().st_size > 500
    where = _run([str(py), "-c", "import leafview, leafview.resources as r; print(leafview.__file__); "
                                 "print(r.shader_dir()); print(r.preset_dir())"], cwd=work).stdout.split()
    for path in where:
        assert str(env_dir) in path and str(ROOT) not in path, where
