"""A private Xvfb display for the tests that open real glfw windows."""

from __future__ import annotations

import os
import shutil
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


class DisplayUnavailable(RuntimeError):
    """Xvfb is missing or did not start; the message says why."""


@contextmanager
def xvfb(log: Path, screen: str = "1280x800x24") -> Iterator[str]:
    """Start Xvfb on a free display number (it picks one itself: -displayfd) and yield ``":N"``;
    stop it afterwards."""
    exe = shutil.which("Xvfb")
    if exe is None:
        raise DisplayUnavailable("Xvfb is not installed (apt-get install xvfb)")
    read_fd, write_fd = os.pipe()
    with open(log, "wb") as err:
        proc = subprocess.Popen([exe, "-displayfd", str(write_fd), "-screen", "0", screen, "-nolisten", "tcp",
                                 "-noreset"],   # no server reset (refusing connections) when the last client leaves
                                pass_fds=(write_fd,), stdout=subprocess.DEVNULL, stderr=err)
    os.close(write_fd)
    try:
        with os.fdopen(read_fd) as pipe:
            number = pipe.readline().strip()  # written once the server accepts connections
        if not number:
            raise DisplayUnavailable(f"Xvfb did not start: {log.read_text(errors='replace').strip()[-300:]}")
        yield f":{number}"
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def display_env(display: str) -> dict[str, str]:
    """The environment of a child process that should open its windows on ``display``."""
    env = dict(os.environ, DISPLAY=display)
    env.pop("WAYLAND_DISPLAY", None)
    return env
