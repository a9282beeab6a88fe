"""Creating OpenGL contexts: headless through EGL (tests, thumbnails, benchmarks).

The backend is chosen by the caller, never by an environment variable read at import time.
"""

from __future__ import annotations

from typing import Any

import moderngl

from leafview.errors import GLUnavailable

__all__ = ["GLUnavailable", "create_headless_context", "REQUIRED_GL", "check_error"]

REQUIRED_GL = 450

_EGL_HELP = (
    "leafview renders offscreen through EGL with OpenGL 4.5 and could not create a context.\n"
    "  Debian/Ubuntu: apt-get install libegl1 libgl1-mesa-dri   (Mesa llvmpipe works without a GPU)\n"
    "  Fedora: dnf install mesa-libEGL mesa-dri-drivers\n"
    "  With an NVIDIA GPU, the driver's libEGL_nvidia must be installed."
)


def create_headless_context(require: int = REQUIRED_GL) -> moderngl.Context:
    """A standalone EGL context (no display needed). Raises :class:`GLUnavailable`."""
    settings: dict[str, Any] = {"backend": "egl"}
    try:
        ctx = moderngl.create_standalone_context(require=require, **settings)
    except Exception as exc:  # glcontext raises plain Exceptions with loader messages
        raise GLUnavailable(f"{_EGL_HELP}\n  (reason: {exc})") from None
    return ctx


def check_error(ctx: moderngl.Context, where: str) -> None:
    """Raise if the context has a pending GL error (``ctx.error`` clears it)."""
    err = ctx.error
    if err != "GL_NO_ERROR":
        raise RuntimeError(f"OpenGL error after {where}: {err}")
