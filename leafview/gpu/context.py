"""Creating OpenGL contexts: headless through EGL (tests, thumbnails, benchmarks).

The backend is chosen by the caller, never by an environment variable read at import time.
"""

from __future__ import annotations

import atexit
from typing import Any

import moderngl

from leafview.errors import GLContextLost, GLUnavailable

__all__ = ["GLUnavailable", "create_headless_context", "acquire_headless_context", "recycle_headless_context",
           "REQUIRED_GL", "check_error", "is_software"]

REQUIRED_GL = 450

_EGL_HELP = ("install EGL and Mesa's drivers (Debian/Ubuntu: apt-get install libegl1 libgl1-mesa-dri; "
             "Fedora: dnf install mesa-libEGL mesa-dri-drivers; llvmpipe needs no GPU; with an NVIDIA GPU, "
             "the driver's libEGL_nvidia)")


def create_headless_context(require: int = REQUIRED_GL, device: int | None = None) -> moderngl.Context:
    """A standalone EGL context (no display needed). ``device``: the index of the EGL device
    (``EGL_EXT_device_enumeration`` order; on an NVIDIA node the GPUs, in the order MuJoCo and
    robosuite also assume to be CUDA's); None: EGL's default device. Raises
    :class:`GLUnavailable` with a one-line message: what failed and what to install."""
    settings: dict[str, Any] = {"backend": "egl"}
    if device is not None:
        if isinstance(device, bool) or not isinstance(device, int) or device < 0:
            raise GLUnavailable(f"EGL device must be an index ≥ 0, got {device!r}")
        settings["device_index"] = device
    try:
        ctx = moderngl.create_standalone_context(require=require, **settings)
    except Exception as exc:  # glcontext raises plain Exceptions with loader messages
        reason = " ".join(str(exc).split()) or type(exc).__name__
        where = f" on EGL device {device}" if device is not None else ""
        raise GLUnavailable(f"no OpenGL {require // 100}.{require % 100 // 10} context through EGL{where} "
                            f"({reason}); {_EGL_HELP}") from None
    return ctx


# Released renderers hand their context back here and the next one takes it: creating and
# destroying an EGL context leaks about 180 KiB each time (about 37 KiB of Python integers in
# moderngl's context set-up, the rest in the EGL/Mesa driver), so create/release loops must not.
_POOL: list[moderngl.Context] = []
_POOL_SIZE = 2


def acquire_headless_context(require: int = REQUIRED_GL) -> moderngl.Context:
    """A headless context for a renderer that owns one: a recycled one (made current again) or a
    new one (:func:`create_headless_context`). Give it back with :func:`recycle_headless_context`."""
    while _POOL:
        ctx = _POOL.pop()
        if type(ctx.mglo).__name__ != "InvalidObject" and ctx.version_code >= require:
            ctx.__enter__()   # current again (another context may have been made current since)
            ctx.error  # noqa: B018  (reading it clears a stale error flag)
            return ctx
    return create_headless_context(require)


def recycle_headless_context(ctx: moderngl.Context) -> None:
    """Take back a context from :func:`acquire_headless_context` whose owner released every object
    it made except what it left in ``ctx.extra`` for the next owner (compiled programs): kept for
    the next renderer (up to two), else released with ``ctx.extra``. A released context is ignored."""
    if type(ctx.mglo).__name__ == "InvalidObject":
        return
    if len(_POOL) < _POOL_SIZE and ctx not in _POOL:
        _POOL.append(ctx)
    else:
        _release(ctx)


def _release(ctx: moderngl.Context) -> None:
    """Release ``ctx`` and what its owner left in ``ctx.extra`` for the next one (shared resources)."""
    extra, ctx.extra = ctx.extra, None
    if hasattr(extra, "release"):
        extra.release()
    ctx.release()


def release_pool() -> None:
    """Release the recycled contexts (at exit, or to give the driver its memory back)."""
    while _POOL:
        ctx = _POOL.pop()
        if type(ctx.mglo).__name__ != "InvalidObject":
            _release(ctx)


atexit.register(release_pool)


def check_error(ctx: moderngl.Context, where: str) -> None:
    """Raise :class:`~leafview.errors.GLContextLost` (a ``RuntimeError``) if the context has a
    pending GL error (``ctx.error`` clears it) or was released."""
    if type(ctx.mglo).__name__ == "InvalidObject":
        raise GLContextLost(f"the OpenGL context was released or lost before {where}")
    err = ctx.error
    if err != "GL_NO_ERROR":
        raise GLContextLost(f"OpenGL error after {where}: {err}")


def is_software(gl_renderer: str) -> bool:
    """Whether ``GL_RENDERER`` names a CPU rasteriser (Mesa llvmpipe/softpipe, SwiftShader)."""
    name = gl_renderer.lower()
    return any(s in name for s in ("llvmpipe", "softpipe", "swiftshader", "software"))
