"""The output layer under faults (leafview/atomic.py, docs/reliability.md "Outputs").

After every fault the target is either the old complete file or a new complete one, no temporary
file is left (after SIGKILL the next run into the folder removes it), and ``leafview`` printed
one line and exited 1 (environment) or 2 (bad path), never a traceback.

How each fault is made:

* full disk: ``os.write`` patched to write up to a limit and then raise ENOSPC for leafview's
  temporary files only (every byte writer goes through it); OpenImageIO's libpng writes with
  its own stdio, so its silent truncation is made by a wrapped ``ImageOutput`` that truncates
  the file and reports success; and, where ``mount`` is permitted (root), a real 64 KiB tmpfs;
* read-only folder: root ignores permission bits, so a real tmpfs remounted read-only (EROFS)
  where mount is permitted, and a patched ``os.open`` that answers EACCES inside one folder;
* SIGTERM / SIGKILL: ``leafview export`` of a scene in a subprocess whose ``os.write`` is slowed,
  signalled as soon as its temporary file appears;
* two writers: two such subprocesses writing one target at once.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from leafview.atomic import (
    NAME_MAX,
    UniqueNames,
    atomic_output,
    check_target,
    is_temp_name,
    outputs,
    safe_component,
    sweep_stale,
    write_bytes,
    write_text,
)
from leafview.cli import main
from leafview.core import compact
from leafview.core.io import save_leaves
from leafview.core.params import LeafParams
from leafview.errors import ImageWriteError, OutputError, OutputPathError
from leafview.export import images as images_mod
from leafview.export.images import write_image
from leafview.resources import builtin_presets
from leafview.scene.spec import SceneSpec, save_scene
from tests.conftest import require_or_skip

ROOT = Path(__file__).resolve().parent.parent
DRIVER = r"""
import os, signal, sys, time
# a parent started with nohup passes SIGHUP on as ignored, and one started in the background by a
# shell without job control SIGINT (Python then installs no KeyboardInterrupt handler); leafview
# leaves a disposition it did not set alone: start from what a command typed in a terminal has
signal.signal(signal.SIGHUP, signal.SIG_DFL)
signal.signal(signal.SIGINT, signal.default_int_handler)
delay = float(os.environ.get("LV_SLOW_WRITE", "0"))
if delay:
    real = os.write
    def slow(fd, data):
        time.sleep(delay)
        return real(fd, data)
    os.write = slow
from leafview.cli import main
sys.exit(main(sys.argv[1:]))
"""


# -- helpers ------------------------------------------------------------------------------------
def temps(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.rglob("*") if ".part" in p.name)


def one_line(err: str) -> str:
    lines = [line for line in err.strip().splitlines() if line.strip() and not line.startswith("note:")]
    assert "Traceback" not in err, err
    assert len(lines) == 1, err
    return lines[0]


def ovate() -> LeafParams:
    return LeafParams.load(builtin_presets()["ovate"])


def enospc_after(monkeypatch: pytest.MonkeyPatch, limit: int) -> None:
    """``os.write`` into leafview temporary files writes ``limit`` bytes in all, then ENOSPC."""
    real = os.write
    written = [0]

    def fake(fd: int, data: bytes) -> int:
        try:
            name = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            name = ""
        if ".part" not in name:
            return real(fd, data)
        room = limit - written[0]
        if room <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        n = real(fd, bytes(memoryview(data)[:room]))
        written[0] += n
        return n

    monkeypatch.setattr(os, "write", fake)


def mount_tmpfs(where: Path, options: str) -> None:
    if os.geteuid() != 0:
        require_or_skip("a real tmpfs needs root to mount; the patched-write tests cover the same fault")
    where.mkdir(exist_ok=True)
    result = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(where)],
                            capture_output=True, text=True)
    if result.returncode:
        require_or_skip(f"mount -t tmpfs is not permitted here ({result.stderr.strip()}); "
                    "the patched-write tests cover the same fault")


@pytest.fixture
def small_fs(tmp_path):
    mnt = tmp_path / "small"
    mount_tmpfs(mnt, "size=64k")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


@pytest.fixture
def ro_fs(tmp_path):
    mnt = tmp_path / "ro"
    mount_tmpfs(mnt, "size=1m")
    (mnt / "old.glb").write_bytes(b"old")
    (mnt / "s.toml").write_text("old")
    result = subprocess.run(["mount", "-o", "remount,ro", str(mnt)], capture_output=True, text=True)
    if result.returncode:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)
        require_or_skip(f"remounting read-only is not permitted here: {result.stderr.strip()}")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def cli(args: list[str], cwd: Path, delay: float = 0.0) -> subprocess.Popen[str]:
    env = {**os.environ, "LV_SLOW_WRITE": str(delay)}
    return subprocess.Popen([sys.executable, "-c", DRIVER, *args], cwd=cwd, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def wait_for_temp(folder: Path, proc: subprocess.Popen[str], timeout: float = 120.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if any(is_temp_name(p.name) and "probe" not in p.name for p in folder.iterdir()):
            return
        if proc.poll() is not None:
            pytest.fail(f"the export ended before writing: {proc.communicate()}")
        time.sleep(0.005)
    proc.kill()
    pytest.fail("no temporary file appeared")


def glb_complete(path: Path) -> bool:
    data = path.read_bytes()
    return data[:4] == b"glTF" and int.from_bytes(data[8:12], "little") == len(data)


@pytest.fixture(scope="module")
def big_scene(tmp_path_factory):
    """A scene file of 600 varied leaves: a GLB of several MB at 9x17."""
    folder = tmp_path_factory.mktemp("scene")
    save_scene(SceneSpec(species=(ovate(),), name="big", leaves=600, seed=1), folder / "big.toml")
    return folder / "big.toml"


# -- the layer itself -----------------------------------------------------------------------------
def test_enospc_mid_file_keeps_the_old_file_and_leaves_no_temp(tmp_path, monkeypatch):
    target = tmp_path / "a.bin"
    target.write_bytes(b"old")
    enospc_after(monkeypatch, 3000)
    with pytest.raises(OutputError, match="no space left on the device") as info:
        write_bytes(target, b"x" * 10_000)
    assert info.value.errno == errno.ENOSPC and not isinstance(info.value, OutputPathError)
    assert str(target) in str(info.value) and "\n" not in str(info.value)
    assert target.read_bytes() == b"old" and temps(tmp_path) == []


def test_enospc_through_the_cli_exits_1_with_one_line(tmp_path, monkeypatch, capsys):
    out = tmp_path / "leaf.glb"
    out.write_bytes(b"old")
    enospc_after(monkeypatch, 10_000)
    assert main(["export", "ovate", "-o", str(out), "--backend", "numpy", "-q"]) == 1
    line = one_line(capsys.readouterr().err)
    assert line.startswith("leafview export: cannot write") and "no space left" in line and str(out) in line
    assert out.read_bytes() == b"old" and temps(tmp_path) == []


def test_enospc_in_one_output_of_a_transaction_writes_none(tmp_path, monkeypatch):
    (tmp_path / "b.txt").write_text("old b")
    with pytest.raises(OutputError):
        with outputs():
            write_text(tmp_path / "a.txt", "new a")
            write_text(tmp_path / "sub" / "c.txt", "new c")
            enospc_after(monkeypatch, 10)
            write_text(tmp_path / "b.txt", "new b" * 10)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.txt"]          # no a.txt, no sub/
    assert (tmp_path / "b.txt").read_text() == "old b"


def test_transaction_commits_all_on_success(tmp_path):
    with outputs() as tx:
        write_text(tmp_path / "a.txt", "a")
        own = tx.path(tmp_path / "b.bin")
        own.write_bytes(b"b")
        assert not (tmp_path / "a.txt").exists()        # staged, not yet renamed
    assert (tmp_path / "a.txt").read_text() == "a" and (tmp_path / "b.bin").read_bytes() == b"b"
    assert temps(tmp_path) == [] and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


def test_truncating_image_writer_is_detected(tmp_path, monkeypatch):
    """libpng on a full disk: OpenImageIO reports success for a truncated file."""
    real = images_mod.oiio

    class Truncating:
        def __init__(self, out):
            self.out, self.path = out, None

        def open(self, path, spec):
            self.path = path
            return self.out.open(path, spec)

        def close(self):
            ok = self.out.close()
            size = os.path.getsize(self.path)
            os.truncate(self.path, size // 2)
            return ok

        def __getattr__(self, name):
            return getattr(self.out, name)

    class FakeOutput:
        @staticmethod
        def create(path):
            return Truncating(real.ImageOutput.create(path))

    class FakeOIIO:
        ImageOutput = FakeOutput

        def __getattr__(self, name):
            return getattr(real, name)

    monkeypatch.setattr(images_mod, "oiio", FakeOIIO())
    pixels = np.random.default_rng(0).integers(0, 255, (64, 64, 4), dtype=np.uint8)
    for suffix in ("png", "tif", "exr"):
        target = tmp_path / f"img.{suffix}"
        data = pixels.astype(np.float32) / 255 if suffix == "exr" else pixels
        with pytest.raises((ImageWriteError, OutputError), match="incomplete|read back"):
            write_image(target, data)
        assert not target.exists() and temps(tmp_path) == []


def test_read_only_folder_simulated_with_eacces(tmp_path, monkeypatch, capsys):
    """Root ignores chmod, so os.open answers EACCES for anything created in the folder."""
    locked = tmp_path / "locked"
    locked.mkdir()
    real = os.open

    def fake(path, flags, *args, **kwargs):
        if flags & os.O_CREAT and Path(path).parent == locked:
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
        return real(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", fake)
    code = main(["scene", "--leaves", "20", "--save", str(tmp_path / "s.toml"),
                 "--export", str(locked / "x.glb")])
    assert code == 1
    line = one_line(capsys.readouterr().err)
    assert "permission denied" in line and "x.glb" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["locked"]       # s.toml not written either
    assert list(locked.iterdir()) == []


@pytest.mark.parametrize("make, words", [
    (lambda d: os.symlink(d / "real.glb", d / "out.glb"), "symbolic link"),
    (lambda d: os.mkfifo(d / "out.glb"), "named pipe"),
    (lambda d: (d / "out.glb").mkdir(), "is a directory"),
])
def test_only_regular_files_are_replaced(tmp_path, capsys, make, words):
    (tmp_path / "real.glb").write_bytes(b"old")
    make(tmp_path)
    before = os.lstat(tmp_path / "out.glb")
    assert main(["export", "ovate", "-o", str(tmp_path / "out.glb"), "--backend", "numpy"]) == 2
    assert words in one_line(capsys.readouterr().err)
    after = os.lstat(tmp_path / "out.glb")
    assert stat.S_IFMT(after.st_mode) == stat.S_IFMT(before.st_mode) and after.st_ino == before.st_ino
    assert (tmp_path / "real.glb").read_bytes() == b"old" and temps(tmp_path) == []


def test_device_is_refused():
    with pytest.raises(OutputPathError, match="is a device"):
        check_target("/dev/null")


@pytest.mark.parametrize("path, code, words", [
    ("file.txt/out.glb", 2, "is a file, not a folder"),
    ("x" * 300 + ".glb", 2, f"the limit is {NAME_MAX}"),
    ("/proc/out.glb", 2, "does not take new files"),
    ("/sys/out.glb", 1, "permission denied"),
])
def test_bad_output_paths_are_one_line(tmp_path, monkeypatch, capsys, path, code, words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "file.txt").write_text("x")
    assert main(["export", "ovate", "-o", path, "--backend", "numpy"]) == code
    line = one_line(capsys.readouterr().err)
    assert words in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.txt"]


def test_stale_temp_files_are_swept_but_live_ones_kept(tmp_path):
    old = time.time() - 3600
    dead = tmp_path / ".leaf.lv999999999-abcdef.part.glb"        # no such process
    legacy = tmp_path / ".leaf.k2j4_x9q.part.png"                  # mkstemp name of older versions
    alive = tmp_path / f".leaf.lv{os.getppid()}-abcdef.part.glb"   # a running process: kept
    fresh = tmp_path / ".leaf.lv999999999-zzzzzz.part.glb"         # newer than this process: kept
    user = tmp_path / ".notes.part.txt"                             # not ours
    for p in (dead, legacy, alive, fresh, user):
        p.write_bytes(b"x")
    for p in (dead, legacy, alive, user):
        os.utime(p, (old, old))
    assert sorted(p.name for p in sweep_stale(tmp_path)) == sorted([dead.name, legacy.name])
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([alive.name, fresh.name, user.name])


def test_sigterm_during_the_writability_probe_leaves_no_probe_file(tmp_path, monkeypatch):
    """The hostile rerun sends SIGTERM the moment it sees a temporary name, which can be the
    writability probe: the signal waits until the probe is removed, then ends the run."""
    import leafview.atomic as atomic_mod
    monkeypatch.setattr(atomic_mod, "_probed", set())
    real_close = os.close

    def close_and_signal(fd):
        real_close(fd)
        os.kill(os.getpid(), signal.SIGTERM)     # arrives between the probe's create and unlink

    monkeypatch.setattr(atomic_mod.os, "close", close_and_signal)
    with pytest.raises(atomic_mod.Terminated):
        check_target(tmp_path / "leaf.glb")
    monkeypatch.setattr(atomic_mod.os, "close", real_close)
    assert list(tmp_path.iterdir()) == []
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


# -- real small and read-only file systems ---------------------------------------------------------
def test_real_full_tmpfs_export_and_save(small_fs, capsys):
    (small_fs / "keep.glb").write_bytes(b"old")
    assert main(["export", "ovate", "-o", str(small_fs / "keep.glb"), "--backend", "numpy",
                 "--resolution", "129x257", "-q"]) == 1
    assert "no space left" in one_line(capsys.readouterr().err)
    assert (small_fs / "keep.glb").read_bytes() == b"old" and temps(small_fs) == []
    assert main(["export", "ovate", "-o", str(small_fs / "x.usdc"), "--backend", "numpy",
                 "--resolution", "129x257", "-q"]) == 1
    assert "no space left" in one_line(capsys.readouterr().err)
    assert sorted(p.name for p in small_fs.iterdir()) == ["keep.glb"]


def test_real_full_tmpfs_png_is_not_reported_written(gl, small_fs, capsys):
    out = small_fs / "tiny" / "out.png"
    assert main(["render", "ovate", "-o", str(out), "--size", "2048"]) == 1
    captured = capsys.readouterr()
    assert "wrote" not in captured.out
    assert "no space left" in one_line(captured.err)
    assert list(small_fs.iterdir()) == []                  # nor the tiny/ folder made for it


def test_real_read_only_tmpfs(ro_fs, tmp_path, capsys):
    assert main(["export", "ovate", "-o", str(ro_fs / "old.glb"), "--backend", "numpy"]) == 1
    assert "read-only file system" in one_line(capsys.readouterr().err)
    assert main(["scene", "--leaves", "20", "--save", str(tmp_path / "s.toml"), "--export",
                 str(ro_fs / "x.glb")]) == 1
    assert "read-only file system" in one_line(capsys.readouterr().err)
    assert not (tmp_path / "s.toml").exists()
    assert (ro_fs / "old.glb").read_bytes() == b"old" and sorted(p.name for p in ro_fs.iterdir()) == [
        "old.glb", "s.toml"]


# -- signals and concurrent writers ---------------------------------------------------------------
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_mid_export_removes_the_temp_file(tmp_path, big_scene, sig):
    out = tmp_path / "big.glb"
    out.write_bytes(b"old")
    proc = cli(["export", str(big_scene), "-o", str(out), "--backend", "numpy", "--resolution", "9x17", "-q"],
               tmp_path, delay=1.0)
    wait_for_temp(tmp_path, proc)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + sig, err
    assert f"terminated by {signal.Signals(sig).name}" in one_line(err)
    assert out.read_bytes() == b"old" and temps(tmp_path) == []


@pytest.mark.parametrize("after", [0.0, 0.05, 0.3])
def test_sigterm_mid_png_is_one_line_and_leaves_nothing(gl, tmp_path, after):
    """The PNG encoder (libpng under OpenImageIO) runs as one uninterruptible step: a SIGTERM that
    lands while it has the file open waits for the close, so libpng never finishes a half-written
    PNG and prints nothing of its own; the temporary file is removed and the old target kept."""
    out = tmp_path / "big.png"
    out.write_bytes(b"old")
    proc = cli(["render", "ovate", "-o", str(out), "--size", "3000", "-q"], tmp_path)
    wait_for_temp(tmp_path, proc)
    time.sleep(after)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    if proc.returncode == 0:      # the render finished before the signal: a complete new file
        assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and temps(tmp_path) == []
        return
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "terminated by SIGTERM" in one_line(err)
    assert "IDAT" not in err and "libpng" not in err
    assert out.read_bytes() == b"old" and temps(tmp_path) == []


def test_sigint_mid_export_removes_the_temp_file(tmp_path, big_scene):
    out = tmp_path / "big.glb"
    proc = cli(["export", str(big_scene), "-o", str(out), "--backend", "numpy", "--resolution", "9x17", "-q"],
               tmp_path, delay=1.0)
    wait_for_temp(tmp_path, proc)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "interrupted" in one_line(err)
    assert not out.exists() and temps(tmp_path) == []


def test_sigkill_leaves_a_temp_file_that_the_next_run_removes(tmp_path, big_scene):
    out = tmp_path / "big.glb"
    out.write_bytes(b"old")
    args = ["export", str(big_scene), "-o", str(out), "--backend", "numpy", "--resolution", "9x17", "-q"]
    proc = cli(args, tmp_path, delay=0.3)
    wait_for_temp(tmp_path, proc)
    proc.kill()
    proc.communicate(timeout=60)
    assert out.read_bytes() == b"old" and len(temps(tmp_path)) == 1
    again = cli(args, tmp_path)
    _, err = again.communicate(timeout=300)
    assert again.returncode == 0, err
    assert glb_complete(out) and temps(tmp_path) == []


def test_two_processes_writing_one_target(tmp_path, big_scene):
    out = tmp_path / "same.glb"
    runs = [cli(["export", str(big_scene), "-o", str(out), "--backend", "numpy", "--resolution", res, "-q"],
                tmp_path, delay=0.05) for res in ("9x17", "5x9")]
    for proc in runs:
        _, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err
    assert glb_complete(out) and temps(tmp_path) == []
    final = out.read_bytes()
    singles = []
    for res in ("9x17", "5x9"):
        one = tmp_path / res / "same.glb"            # the same file name: the root node is named after it
        assert main(["export", str(big_scene), "-o", str(one), "--backend", "numpy", "--resolution", res,
                     "-q"]) == 0
        singles.append(one.read_bytes())
    assert final in singles


# -- names from input -----------------------------------------------------------------------------
HOSTILE = ["../escaped", "/abs/path", "a/../../b", "..", ".", ".hidden", "dup", "dup", "DUP", "con", "LPT1.x",
           "x" * 256, "back\\slash", "é" * 200, "*?<>|:", " lead and trail. "]


def test_safe_component_and_unique_names():
    unique = UniqueNames()
    names = [unique(n) for n in HOSTILE]
    assert len({n.casefold() for n in names}) == len(HOSTILE)
    for name in names:
        assert "/" not in name and "\\" not in name and name not in (".", "..") and not name.startswith(".")
        assert len(name.encode()) <= 200 and name == name.strip()
        assert name.split(".")[0].lower() not in {"con", "lpt1"}
    assert names[6:9] == ["dup", "dup-2", "DUP-3"]
    assert safe_component("a\x00b\x1fc") == "a_b_c"


def hostile_leaf_set(path: Path) -> Path:
    leaves = [ovate().replace(name=f"leaf{i}") for i in range(len(HOSTILE))]
    save_leaves(leaves, path)
    doc = json.loads(path.read_text())
    for entry, name in zip(doc["leaves"], HOSTILE):
        entry["name"] = name
    path.write_text(json.dumps(doc))
    assert [leaf.name for leaf in compact.parse_leaves(doc)] == HOSTILE
    return path


def files_under(folder: Path) -> set[Path]:
    return {p for p in folder.rglob("*") if p.is_file()}


@pytest.mark.parametrize("command", ["export", "render"])
def test_hostile_leaf_names_never_leave_the_output_folder(request, tmp_path, monkeypatch, command):
    if command == "render":
        request.getfixturevalue("gl")
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    leaf_set = hostile_leaf_set(tmp_path / "hostile.leaves.json")
    before = files_under(tmp_path)
    extra = ["--backend", "numpy", "--format", "obj", "--resolution", "5x9"] if command == "export" else ["--size", "16"]
    assert main([command, str(leaf_set), "-o", "out", "-q", *extra]) == 0
    new = files_under(tmp_path) - before
    out = (work / "out").resolve()
    assert all(p.resolve().parent == out for p in new), sorted(map(str, new))
    # one mesh or image per leaf (an export also writes each leaf's .mtl and baked vein maps, named after it)
    drawn = [p for p in new if p.suffix == (".obj" if command == "export" else ".png")]
    assert len(drawn) == len(HOSTILE) and temps(tmp_path) == []
    if command == "export":
        assert len(new) > 2 * len(HOSTILE)
    assert not Path("/abs").exists() and not (tmp_path / "escaped.obj").exists()


def test_hostile_shape_names_write_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["shapes", "--names", "../../escaped", "-o", "out"]) == 2
    assert list(tmp_path.iterdir()) == []


def test_atomic_output_failure_removes_the_folders_it_made(tmp_path):
    with pytest.raises(RuntimeError):
        with atomic_output(tmp_path / "a" / "b" / "c.txt") as tmp:
            tmp.write_text("x")
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []
