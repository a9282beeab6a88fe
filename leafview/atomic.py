"""The output layer: every file leafview writes goes through here.

A write (:func:`atomic_output`, or :func:`write_bytes` / :func:`write_text` for data in memory):

* checks the target before any work (:func:`check_target`): its folder exists or can be
  created, is a folder and is writable (a probe file), the name fits the file system, and an
  existing target is a regular file: a symbolic link, device, pipe or directory is refused,
  never replaced;
* writes a temporary file beside the target (``.NAME.lvPID-XXXXXX.part.EXT``) and verifies that
  every byte reached the disk (written size compared, ``fsync``; callers add their own checks
  through ``verify``) before it renames the file onto the target in one step;
* turns every ``OSError`` into a one-line :class:`~leafview.errors.OutputError` naming the path
  (exit 1: the environment, such as a full disk or a read-only file system) or
  :class:`~leafview.errors.OutputPathError` (exit 2: a path that cannot be written, such as a
  name too long or a folder that is a file);
* removes its temporary files on an exception, on Ctrl-C and on SIGTERM/SIGHUP (a handler is
  installed while writing and the previous one restored after; the signal then ends the process
  as :class:`Terminated`, exit status 128 + the signal number), and the next run into a folder
  removes the temporary files a killed run left there (:func:`sweep_stale`).

Several outputs of one run commit together or not at all: inside ``with outputs() as tx:``
every write is staged (written and verified into its temporary file) and the renames happen
when the block ends without an exception; on any failure no target is changed. ``tx.path(t)``
gives a temporary file for a writer of one's own.

Output names made from input (leaf, species, shape names) go through :func:`safe_component` and
:class:`UniqueNames`: one safe path component each, unique within the run.

This is a base module: the standard library and :mod:`leafview.errors` only.
"""

from __future__ import annotations

import contextlib
import contextvars
import errno as E
import os
import re
import secrets
import signal
import stat
import threading
import time
import unicodedata
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from types import FrameType
from typing import Any

from leafview.errors import LeafviewError, OutputError, OutputPathError

__all__ = ["atomic_output", "write_bytes", "write_text", "outputs", "Outputs", "check_target", "check_folder",
           "output_error", "diagnose", "sweep_stale", "is_temp_name", "safe_component", "UniqueNames",
           "Terminated", "signal_guard", "uninterruptible", "failed_write", "brief", "NAME_MAX"]

NAME_MAX = 255                    # bytes in one file name (Linux, macOS, Windows in UTF-16 units)
SAFE_NAME_BYTES = 200             # a name made from input: room for "-N", the suffix and a temp name
_CHUNK = 1 << 20                  # bytes per os.write call
_LOW_SPACE = 1 << 20              # a write that failed with less free space than this: the disk is full
_STARTED = time.time()            # files of ours older than this process are a previous run's
_STALE_AGE = 24 * 3600.0          # a temp file this old is stale even if its process id is in use again
_TEMP_RE = re.compile(r"^\..*\.lv(?P<pid>\d+)-[a-z0-9]{6}\.part")            # ours (USD adds its own tail)
_OLD_TEMP_RE = re.compile(r"^\..+\.[a-z0-9_]{8}\.part\.[A-Za-z0-9]+$")         # leafview < 0.x (mkstemp)

# errno -> (reason, bad path given by the user: exit 2)
_REASONS: dict[int, tuple[str, bool]] = {
    E.ENOSPC: ("no space left on the device", False),
    E.EDQUOT: ("disk quota exceeded", False),
    E.EACCES: ("permission denied", False),
    E.EPERM: ("operation not permitted", False),
    E.EROFS: ("read-only file system", False),
    E.EIO: ("input/output error", False),
    E.EFBIG: ("file too large for this file system", False),
    E.ENOENT: ("its folder was removed while writing", False),
    E.EBUSY: ("device or resource busy", False),
    E.ETXTBSY: ("file busy", False),
    E.ENAMETOOLONG: ("file name too long", True),
    E.ENOTDIR: ("a folder in the path is a file", True),
    E.EISDIR: ("is a directory; give a file name", True),
    E.ELOOP: ("too many symbolic links in the path", True),
    E.EINVAL: ("invalid file name for this file system", True),
    E.EEXIST: ("exists and cannot be replaced", True),
}


class Terminated(SystemExit):
    """SIGTERM or SIGHUP arrived while leafview was writing: the temporary files are removed and
    the process ends with status 128 + the signal number (uncaught, it exits quietly)."""

    def __init__(self, signum: int) -> None:
        super().__init__(128 + signum)
        self.signum = signum

    def __str__(self) -> str:
        return f"terminated by {signal.Signals(self.signum).name}"


# -- errors -------------------------------------------------------------------------------------
def _where(path: str | os.PathLike[str], flag: str | None) -> str:
    parts = [part if len(part) <= 64 else f"{part[:40]}...{part[-12:]}" for part in Path(path).parts]
    shown = str(Path(*parts)) if parts else str(path)
    return f"{flag} {shown}" if flag else shown


def output_error(exc: OSError, path: str | os.PathLike[str], flag: str | None = None) -> OutputError:
    """One line naming ``path`` for an ``OSError`` met while writing it: OutputPathError (exit 2)
    for a path that cannot be written, OutputError (exit 1) for the environment."""
    if isinstance(exc, OutputError):
        return exc
    code = exc.errno or 0
    reason, bad_path = _REASONS.get(code, ((exc.strerror or str(exc)).lower(), False))
    where = _where(path, flag)
    if code == E.ENAMETOOLONG:
        longest = max((len(part.encode("utf-8", "surrogateescape")) for part in Path(path).parts), default=0)
        if longest > NAME_MAX:
            reason = f"file name too long ({longest} bytes; the limit is {NAME_MAX})"
        else:
            reason = f"path too long ({len(os.fsencode(os.fspath(path)))} bytes)"
    elif code == E.ENOTDIR:
        blocker = _first_file_ancestor(Path(path))
        if blocker is not None:
            reason = f"{blocker} is a file, not a folder"
    elif code == E.ENOENT and os.path.isdir(Path(path).parent):
        reason, bad_path = "this file system does not take new files (choose another folder)", True
    message = f"{where}: {reason}" if code in (E.EISDIR,) else f"cannot write {where}: {reason}"
    cls = OutputPathError if bad_path else OutputError
    return cls(message, str(path), code or None)


def _first_file_ancestor(path: Path) -> Path | None:
    for parent in reversed(path.parents):
        with contextlib.suppress(OSError):
            if parent.exists() and not parent.is_dir():
                return parent
    return None


def diagnose(folder: str | os.PathLike[str]) -> int | None:
    """The errno that most likely explains a failed write into ``folder`` when the writer (a C++
    library) did not say: EROFS, ENOSPC (under 1 MiB or no inode left), EACCES, or None."""
    try:
        st = os.statvfs(folder)
    except OSError:
        return None
    if st.f_flag & os.ST_RDONLY:
        return E.EROFS
    if st.f_bavail * st.f_frsize < _LOW_SPACE or (st.f_files and st.f_favail == 0):
        return E.ENOSPC
    if not os.access(folder, os.W_OK | os.X_OK):
        return E.EACCES
    return None


def brief(detail: str, limit: int = 120) -> str:
    """A C++ library's error text cut to one short line: the first quoted message of a USD (Tf)
    error, else the first ``limit`` characters."""
    text = " ".join(str(detail).split())
    quoted = re.search(r" : '([^']+)'", text)
    if quoted:
        text = quoted.group(1)
    return text if len(text) <= limit else text[:limit - 3].rstrip() + "..."


def failed_write(path: str | os.PathLike[str], detail: str) -> OutputError | None:
    """An OutputError for a writer that failed without an errno, when the file system explains it
    (``detail``, the writer's own words, is added in brief)."""
    code = diagnose(Path(path).parent)
    if code is None:
        return None
    err = output_error(OSError(code, os.strerror(code)), path)
    err.message = f"{err.message} ({brief(detail)})" if detail else err.message
    return err


# -- checks -------------------------------------------------------------------------------------
_probed: set[str] = set()
_swept: set[str] = set()


def _nearest_existing(folder: Path) -> Path:
    for candidate in (folder, *folder.parents):
        try:
            os.stat(candidate)
        except FileNotFoundError:
            continue
        except OSError as exc:
            raise output_error(exc, candidate) from None
        return candidate
    return Path(".")


def _check_name_lengths(path: Path, flag: str | None) -> None:
    for part in path.parts:
        n = len(part.encode("utf-8", "surrogateescape"))
        if n > NAME_MAX:
            raise OutputPathError(f"cannot write {_where(path, flag)}: file name too long ({n} bytes; "
                                  f"the limit is {NAME_MAX})", str(path), E.ENAMETOOLONG)


def _probe(folder: Path, shown: Path, flag: str | None) -> None:
    """Create and remove a file in ``folder``: the one test of writability that root, read-only
    mounts, ACLs and /proc all answer truthfully."""
    key = os.path.abspath(folder)
    if key in _probed:
        return
    name = folder / f".leafview-probe.lv{os.getpid()}-{_token()}.part"
    # A SIGTERM between the create and the unlink would leave the probe behind: the pair runs as
    # one critical step, and a signal arriving inside it is raised once the probe is gone.
    with signal_guard(), _critical():
        try:
            fd = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o600)
        except OSError as exc:
            raise output_error(exc, shown, flag) from None
        os.close(fd)
        _unlink(name)
    _probed.add(key)


def check_folder(path: str | os.PathLike[str], flag: str | None = None, *, file: Path | None = None) -> Path:
    """An output folder (``-o DIR``): it is a folder (or can be created: the nearest existing
    folder above it is a writable folder) and writable; stale temporary files in it are removed.
    Nothing is created yet. Raises OutputPathError / OutputError naming the path (``file``, the
    file to be written in it, when given)."""
    folder = Path(path)
    shown = file if file is not None else folder
    _check_name_lengths(folder, flag)
    try:
        st = os.stat(folder)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise output_error(exc, shown, flag) from None
    if st is not None and not stat.S_ISDIR(st.st_mode):
        if file is not None:
            raise OutputPathError(f"cannot write {_where(file, flag)}: {folder} is a file, not a folder",
                                  str(file), E.ENOTDIR)
        raise OutputPathError(f"{_where(folder, flag)} exists and is not a directory", str(folder), E.ENOTDIR)
    base = _nearest_existing(folder)
    if not base.is_dir():
        raise OutputPathError(f"cannot write {_where(shown, flag)}: {base} is a file, not a folder",
                              str(shown), E.ENOTDIR)
    _probe(base, shown, flag)
    if base == folder:
        sweep_stale(folder)
    return folder


def check_target(path: str | os.PathLike[str], flag: str | None = None) -> Path:
    """An output file: its folder passes :func:`check_folder`, and the target is absent or a
    regular file (a directory, symbolic link, device, pipe or socket is refused, never replaced).
    Call it before any work; the writers call it again. Returns the path."""
    target = Path(path)
    if target.name in ("", ".", ".."):
        raise OutputPathError(f"{_where(target, flag)}: give a file name", str(target), E.EISDIR)
    _check_name_lengths(target, flag)
    _refuse_special(target, flag)
    check_folder(target.parent, flag, file=target)
    return target


def _refuse_special(target: Path, flag: str | None) -> None:
    try:
        st = os.lstat(target)
    except FileNotFoundError:
        return
    except NotADirectoryError:
        return                                   # check_folder names the file in the way
    except OSError as exc:
        raise output_error(exc, target, flag) from None
    mode = st.st_mode
    if stat.S_ISREG(mode):
        return
    if stat.S_ISDIR(mode):
        raise OutputPathError(f"{_where(target, flag)} is a directory; give a file name", str(target), E.EISDIR)
    kind = ("a symbolic link" if stat.S_ISLNK(mode) else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
            else "a named pipe" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode) else "not a file")
    raise OutputPathError(f"{_where(target, flag)} is {kind}: leafview replaces regular files only "
                          "(remove it or choose another name)", str(target), E.EEXIST)


# -- temporary files ----------------------------------------------------------------------------
def _token() -> str:
    alphabet = "abcdefghijklmnopqrstuvwxyz0123456789"
    return "".join(secrets.choice(alphabet) for _ in range(6))


def _temp_name(target: Path) -> Path:
    suffix = target.suffix if len(target.suffix.encode("utf-8", "surrogateescape")) <= 32 else ""
    tail = f".lv{os.getpid()}-{_token()}.part{suffix}"
    stem = target.name[:len(target.name) - len(suffix)] if suffix else target.name
    room = NAME_MAX - 1 - len(tail.encode("utf-8", "surrogateescape"))
    stem = stem.encode("utf-8", "surrogateescape")[:room].decode("utf-8", "ignore")
    return target.with_name(f".{stem}{tail}")


def is_temp_name(name: str) -> bool:
    """Whether ``name`` is one of leafview's temporary files (this version's or an older one's)."""
    return bool(_TEMP_RE.match(name) or _OLD_TEMP_RE.match(name))


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return False                 # ours, yet older than this process: a previous owner of the id
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True                  # exists, owned by someone else
    return True


def sweep_stale(folder: str | os.PathLike[str]) -> list[Path]:
    """Remove the temporary files a killed leafview run left in ``folder``: names of our pattern,
    last modified before this process started, whose process is gone (or a day old). Each folder
    is swept once per process; returns what was removed."""
    key = os.path.abspath(folder)
    if key in _swept:
        return []
    _swept.add(key)
    removed: list[Path] = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    now = time.time()
    for entry in entries:
        name = entry.name
        if not name.startswith(".") or ".part" not in name:
            continue
        ours = _TEMP_RE.match(name)
        if not ours and not _OLD_TEMP_RE.match(name):
            continue
        try:
            st = entry.stat(follow_symlinks=False)
        except OSError:
            continue
        if not stat.S_ISREG(st.st_mode) or st.st_mtime >= _STARTED:
            continue
        if ours and _pid_alive(int(ours["pid"])) and now - st.st_mtime < _STALE_AGE:
            continue                 # another run writing now
        with contextlib.suppress(OSError):
            os.unlink(entry.path)
            removed.append(Path(entry.path))
    return removed


def _make_folders(folder: Path) -> list[Path]:
    """Create ``folder`` and missing parents; returns those created, the deepest last."""
    missing: list[Path] = []
    for candidate in (folder, *folder.parents):
        if os.path.lexists(candidate):
            break
        missing.append(candidate)
    created: list[Path] = []
    for d in reversed(missing):
        try:
            os.mkdir(d)
        except FileExistsError:
            continue
        except OSError as exc:
            _remove_folders(created)
            raise output_error(exc, d) from None
        created.append(d)
    return created


def _remove_folders(created: Iterable[Path]) -> None:
    for d in reversed(list(created)):
        with contextlib.suppress(OSError):
            os.rmdir(d)              # only when empty


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _finish(tmp: Path, target: Path, expected_size: int | None) -> None:
    """Make sure every byte of ``tmp`` is on the disk: fsync, size (and non-empty)."""
    try:
        fd = os.open(tmp, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise OutputError(f"cannot write {target}: nothing was written", str(target)) from None
    try:
        os.fsync(fd)
        size = os.fstat(fd).st_size
    finally:
        os.close(fd)
    if size == 0:
        raise OutputError(f"{target}: nothing was written", str(target))
    if expected_size is not None and size != expected_size:
        err = failed_write(target, f"{size:,} of {expected_size:,} bytes written")
        raise err or OutputError(f"cannot write {target}: only {size:,} of {expected_size:,} bytes were written",
                                 str(target), E.EIO)
    os.chmod(tmp, 0o666 & ~_umask())            # temp files are 0600; give the usual file mode


def _fsync_folder(folder: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _unlink(path: Path) -> None:
    with contextlib.suppress(OSError):
        os.unlink(path)


# -- signals ------------------------------------------------------------------------------------
_guard_depth = 0
_masked = 0
_pending: int | None = None
_raised = False
_saved: dict[int, Any] = {}


def _on_signal(signum: int, frame: FrameType | None) -> None:
    global _pending, _raised
    if _pending is None:
        _pending = signum
    if _masked or _raised:
        return                        # inside a cleanup, or already unwinding: finish it first
    _raised = True
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise Terminated(signum)


@contextlib.contextmanager
def signal_guard() -> Iterator[None]:
    """While writing: SIGTERM and SIGHUP (and SIGINT where it would kill the process) become
    exceptions, so every ``finally`` removes its temporary files; the handlers in place before are
    restored when the outermost guard ends. Only signals left at their default are taken (a
    program's own handlers and ignored signals stay as they are). Main thread only."""
    global _guard_depth, _pending, _raised
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    if _guard_depth == 0:
        _pending, _raised = None, False
        for sig in (signal.SIGTERM, getattr(signal, "SIGHUP", None), signal.SIGINT):
            if sig is None:
                continue
            with contextlib.suppress(ValueError, OSError):
                if signal.getsignal(sig) is signal.SIG_DFL:
                    _saved[sig] = signal.signal(sig, _on_signal)
    _guard_depth += 1
    try:
        yield
    finally:
        _guard_depth -= 1
        if _guard_depth == 0:
            for sig, old in _saved.items():
                with contextlib.suppress(ValueError, OSError):
                    signal.signal(sig, old)
            _saved.clear()
            pending, raised = _pending, _raised
            _pending, _raised = None, False
            if pending is not None and not raised:   # arrived during a cleanup: honour it now
                if pending == signal.SIGINT:
                    raise KeyboardInterrupt
                raise Terminated(pending)


@contextlib.contextmanager
def _critical() -> Iterator[None]:
    """A cleanup or a commit that a signal must not cut in half: the signal waits until the end."""
    global _masked, _raised
    _masked += 1
    try:
        yield
    finally:
        _masked -= 1
        if not _masked and _pending is not None and not _raised and _guard_depth:
            _raised = True
            if _pending == signal.SIGINT:
                raise KeyboardInterrupt
            raise Terminated(_pending)


def uninterruptible() -> contextlib.AbstractContextManager[None]:
    """A step a signal must not cut in half, for writers that call into C libraries: SIGINT,
    SIGTERM or SIGHUP arriving inside it is raised when it ends (the temporary file is then removed
    as usual). ``write_image`` encodes each image inside one, so libpng never finishes a PNG
    it was interrupted in (and never prints its own "No IDATs written")."""
    return _critical()


# -- transactions -------------------------------------------------------------------------------
_ACTIVE: contextvars.ContextVar[Outputs | None] = contextvars.ContextVar("leafview_outputs", default=None)


class Outputs:
    """The files of one run, committed together: see :func:`outputs`."""

    def __init__(self) -> None:
        self._staged: dict[str, tuple[Path, Path]] = {}     # target key -> (target, verified temp)
        self._open: list[Path] = []                          # temp files handed out, not yet verified
        self._folders: list[Path] = []
        self.committed: list[Path] = []

    def path(self, target: str | os.PathLike[str]) -> Path:
        """A temporary file for ``target`` to write into; it is verified (non-empty, on disk) and
        renamed onto ``target`` when the transaction commits."""
        t = check_target(target)
        with _critical():                # created and registered as one step, so a rollback finds it
            tmp = self._new_temp(t)
            self._open.append(tmp)
            self._stage(t, tmp)
        return tmp

    def staged(self, target: str | os.PathLike[str]) -> Path | None:
        """The temporary file that will become ``target`` (None when nothing is staged for it)."""
        entry = self._staged.get(os.path.abspath(target))
        return entry[1] if entry else None

    def __len__(self) -> int:
        return len(self._staged)

    def _new_temp(self, target: Path) -> Path:
        self._folders += _make_folders(target.parent)
        return _create_temp(target)

    def _stage(self, target: Path, tmp: Path) -> None:
        key = os.path.abspath(target)
        old = self._staged.pop(key, None)
        if old is not None and old[1] != tmp:
            _unlink(old[1])                  # written twice in one run: the last one counts
        self._staged[key] = (target, tmp)

    def _commit(self) -> None:
        targets = {tmp: t for t, tmp in self._staged.values()}
        for tmp in self._open:
            if tmp in targets:                 # (not replaced by a later write of the same target)
                try:
                    _finish(tmp, targets[tmp], None)
                except OSError as exc:
                    raise output_error(exc, targets[tmp]) from None
        self._open.clear()
        with _critical():
            # (target, hard link to the file it replaced, whether there was one)
            done: list[tuple[Path, Path | None, bool]] = []
            target = Path()
            try:
                for target, tmp in self._staged.values():
                    _refuse_special(target, None)
                    existed = os.path.lexists(target)
                    backup = None
                    if existed:
                        backup = _temp_name(target)
                        try:
                            os.link(target, backup)
                        except OSError:
                            backup = None            # no hard links here: that file cannot be put back
                    try:
                        os.replace(tmp, target)
                    except BaseException:
                        if backup is not None:
                            _unlink(backup)
                        raise
                    done.append((target, backup, existed))
            except BaseException as exc:
                for replaced, backup, existed in reversed(done):    # put every replaced file back
                    if backup is not None:
                        with contextlib.suppress(OSError):
                            os.replace(backup, replaced)
                    elif not existed:
                        _unlink(replaced)
                if isinstance(exc, OSError):
                    raise output_error(exc, target) from None
                raise
            for _, backup, _ in done:
                if backup is not None:
                    _unlink(backup)
            for folder in {t.parent for t, _, _ in done}:
                _fsync_folder(folder)
            self.committed = [t for t, _, _ in done]
            self._staged.clear()

    def _rollback(self) -> None:
        with _critical():
            for _, tmp in self._staged.values():
                _unlink(tmp)
            for tmp in self._open:
                _unlink(tmp)
            self._staged.clear()
            self._open.clear()
            _remove_folders(self._folders)


@contextlib.contextmanager
def outputs() -> Iterator[Outputs]:
    """Commit several outputs together: every write inside the block is staged into a verified
    temporary file, and when the block ends cleanly they are all renamed onto their targets
    (a rename that fails puts the files already replaced back). On an exception, Ctrl-C or
    SIGTERM nothing is changed and no temporary file is left. Transactions nest: an inner
    block joins the outer one."""
    outer = _ACTIVE.get()
    if outer is not None:
        yield outer
        return
    tx = Outputs()
    with signal_guard():
        token = _ACTIVE.set(tx)
        try:
            yield tx
        except BaseException:
            _ACTIVE.reset(token)
            tx._rollback()
            raise
        _ACTIVE.reset(token)
        try:
            tx._commit()
        except BaseException:
            tx._rollback()
            raise


def _create_temp(target: Path) -> Path:
    for _ in range(100):
        tmp = _temp_name(target)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o600)
        except FileExistsError:
            continue
        except OSError as exc:
            raise output_error(exc, target) from None
        os.close(fd)
        return tmp
    raise OutputError(f"cannot write {target}: no free temporary name", str(target), E.EEXIST)


# -- single outputs -----------------------------------------------------------------------------
@contextlib.contextmanager
def atomic_output(path: str | os.PathLike[str], *, expected_size: int | None = None,
                  verify: Callable[[Path], None] | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` (same suffix) for a writer; when the block ends
    cleanly the file is verified (non-empty, ``expected_size`` bytes if given, ``verify(tmp)``,
    fsync) and renamed onto ``path``, or staged when a transaction (:func:`outputs`) is open.

    On an exception the temporary file (and any folder made for it) is removed and ``path`` is
    left as it was; an ``OSError`` comes out as an :class:`~leafview.errors.OutputError` naming
    ``path``.
    """
    target = check_target(path)
    tx = _ACTIVE.get()
    with signal_guard():
        folders: list[Path] = []
        tmp: Path | None = None
        try:
            with _critical():            # a signal here waits until the temp file is known
                if tx is not None:
                    tmp = tx._new_temp(target)
                else:
                    folders = _make_folders(target.parent)
                    tmp = _create_temp(target)
            assert tmp is not None
            yield tmp
            _finish(tmp, target, expected_size)
            if verify is not None:
                verify(tmp)
            if tx is not None:
                tx._stage(target, tmp)
                return
            with _critical():
                _refuse_special(target, None)
                os.replace(tmp, target)
                _fsync_folder(target.parent)
        except BaseException as exc:
            with _critical():
                if tmp is not None:
                    _unlink(tmp)
                _remove_folders(folders)
            if isinstance(exc, OSError) and not isinstance(exc, LeafviewError):
                raise output_error(exc, target) from exc
            raise


def write_bytes(path: str | os.PathLike[str], *chunks: bytes | bytearray | memoryview) -> Path:
    """Write ``chunks`` one after another to ``path`` atomically (see :func:`atomic_output`),
    every byte accounted for; returns the path."""
    total = sum(memoryview(c).nbytes for c in chunks)
    with atomic_output(path, expected_size=total) as tmp:
        fd = os.open(tmp, os.O_WRONLY | os.O_TRUNC | getattr(os, "O_CLOEXEC", 0))
        try:
            for chunk in chunks:
                view = memoryview(chunk).cast("B")
                while view:
                    n = os.write(fd, view[:_CHUNK])
                    if n <= 0:
                        raise OSError(E.EIO, "write returned no progress")
                    view = view[n:]
        finally:
            os.close(fd)
    return Path(path)


def write_text(path: str | os.PathLike[str], text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`write_bytes`); returns the path."""
    return write_bytes(path, text.encode(encoding))


# -- names from input ---------------------------------------------------------------------------
_WINDOWS_RESERVED = {"con", "prn", "aux", "nul", *(f"com{i}" for i in range(10)), *(f"lpt{i}" for i in range(10))}
_UNSAFE = set('/\\:*?"<>|')


def safe_component(name: str, *, fallback: str = "leaf", max_bytes: int = SAFE_NAME_BYTES) -> str:
    """``name`` as one safe file name component: separators, ``: * ? " < > |``, NUL and control
    characters become ``_``; no leading dot or space, no trailing dot or space, not ``.``/``..``,
    not a Windows device name (``CON``, ``NUL``, ``COM1`` ... get a ``_``), at most ``max_bytes``
    in UTF-8; ``fallback`` when nothing is left."""
    text = unicodedata.normalize("NFC", str(name))
    out = "".join("_" if c in _UNSAFE or unicodedata.category(c) in ("Cc", "Cf", "Cs", "Zl", "Zp") else c
                  for c in text)
    out = out.lstrip(". ").rstrip(". ")
    if not out.strip("_"):
        out = fallback
    if out.split(".")[0].lower() in _WINDOWS_RESERVED:
        out = out.split(".")[0] + "_" + out[len(out.split(".")[0]):]
    raw = out.encode("utf-8")
    if len(raw) > max_bytes:
        out = raw[:max_bytes].decode("utf-8", "ignore").rstrip(". ") or fallback
    return out


class UniqueNames:
    """Safe, unique file names for one folder: ``name``, ``name-2``, ``name-3`` ... (compared
    without case, as case-insensitive file systems do)."""

    def __init__(self, *, fallback: str = "leaf") -> None:
        self.fallback = fallback
        self._taken: set[str] = set()

    def __call__(self, name: str) -> str:
        base = safe_component(name, fallback=self.fallback)
        out, k = base, 1
        while out.casefold() in self._taken:
            k += 1
            out = f"{base}-{k}"
        self._taken.add(out.casefold())
        return out
