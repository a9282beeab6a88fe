"""One error hierarchy for leafview.

Every error leafview raises on purpose derives from :class:`LeafviewError`, so a caller can
catch them all in one place. The command line maps them to exit codes: bad input
(:class:`ParamError`, :class:`UsageError` and its subclasses) exits 2 and writes nothing; a
runtime failure (:class:`GLUnavailable`, :class:`ShaderError`, :class:`ImageWriteError`,
:class:`OutputError`) exits 1; an output path that cannot name a file (:class:`OutputPathError`)
exits 2.

The subclasses keep the built-in base they always had (``ValueError`` for bad values,
``RuntimeError`` for failures), so ``except ValueError`` in user code keeps working.
"""

from __future__ import annotations

__all__ = ["one_line", "LeafviewError", "ParamError", "UsageError", "ExportError", "NonFiniteMesh", "SceneLimitError",
           "GpuLimitError", "GLUnavailable", "GLContextLost", "ShaderError", "ImageWriteError"]


MAX_MESSAGE_CHARS = 300   # an error repeats at most this much of what it was given
MAX_PATH_CHARS = 200


def shorten(text: str, limit: int) -> str:
    """``text`` cut to ``limit`` characters with the length of the rest, so that an error about a
    huge value or key stays one readable line (and never copies the value whole)."""
    if len(text) <= limit:
        return text
    return f"{text[:limit]}… ({len(text) - limit:,} more characters)"


def one_line(text: str) -> str:
    """``text`` with its control characters and line separators written as escapes (``\\n``,
    ``\\x00``, ``\\u2028``), so that a key or value quoted from a hostile file can never split an
    error message over several lines."""
    if text.isprintable():
        return text
    return "".join(ch if ch.isprintable() or ch == " " else ch.encode("unicode_escape").decode("ascii")
                   for ch in text)


class LeafviewError(Exception):
    """The base of every error leafview raises on purpose."""


class ParamError(LeafviewError, ValueError):
    """Invalid leaf parameters. ``path`` is the dotted field path (``shape.silhouette[1][0]``),
    ``source`` the file (and ``line:col`` for syntax errors) when known."""

    def __init__(self, path: str, message: str, source: str | None = None) -> None:
        self.path = shorten(one_line(path), MAX_PATH_CHARS)
        self.message = shorten(one_line(message), MAX_MESSAGE_CHARS)
        self.source = None if source is None else one_line(source)
        path, message, source = self.path, self.message, self.source
        where = f"{source}: " if source else ""
        what = f"{path}: " if path else ""
        super().__init__(f"{where}{what}{message}")

    def with_source(self, source: str) -> ParamError:
        return ParamError(self.path, self.message, source)


class UsageError(LeafviewError):
    """Bad command-line input (arguments, paths, files); ``leafview`` reports it with exit code 2
    and writes nothing."""


class ExportError(UsageError):
    """A leaf or scene that cannot be written in the asked-for format (too large, not finite, an
    unknown extension); nothing is written."""


class NonFiniteMesh(ExportError):
    """A baked leaf with NaN/Inf vertices or normals (or normals that cannot be repaired); the
    message names the leaf and the first bad grid sample. Nothing is written."""


class SceneLimitError(LeafviewError, ValueError):
    """A scene that cannot be drawn within this context's limits; the message names the limit."""


class GpuLimitError(ParamError):
    """A size or count beyond what the OpenGL context or this machine's memory allows (image
    size, grid, instances, leaves, bytes to allocate). ``path`` names the parameter, the message
    the limit and the value asked for; raised before any GL object is created."""


class GLUnavailable(LeafviewError, RuntimeError):
    """No usable OpenGL 4.5 context could be created; the message says what to install."""


class GLContextLost(LeafviewError, RuntimeError):
    """The OpenGL context was released or lost while leafview still used it (for example between
    the batches of a scene), or GL reported an error no check could have prevented."""


class ShaderError(LeafviewError, RuntimeError):
    """A GLSL program failed to preprocess, compile or link.

    ``stage`` is "vertex", "fragment", "compute" or "link"; ``location`` is ``file:line``
    of the first error when the log names one.
    """

    def __init__(self, stage: str, location: str | None, log: str) -> None:
        self.stage, self.location, self.log = stage, location, log
        where = f" at {location}" if location else ""
        super().__init__(f"{stage} shader{where}:\n{log}" if stage != "link"
                         else f"program link failed{where}:\n{log}")


class ImageWriteError(LeafviewError, RuntimeError):
    """OpenImageIO could not write the file (the message carries OIIO's own error text)."""


class OutputError(LeafviewError, OSError):
    """A file could not be written because of the environment: no space left, no permission, a
    read-only file system, an I/O error. The message is one line naming the file; ``path`` is
    that file and ``errno`` the error number when known. Nothing partial is left behind, and an
    older file at ``path`` is kept whole. ``leafview`` exits 1.

    It is an ``OSError`` too, so ``except OSError`` around a save keeps working."""

    def __init__(self, message: str, path: str | None = None, errno: int | None = None) -> None:
        super().__init__(message)
        self.message, self.path = message, path
        self.errno, self.filename = errno, path

    def __str__(self) -> str:
        return self.message


class OutputPathError(OutputError, UsageError):
    """An output path that cannot name a file to write: its folder is a file, a name is too long,
    or the path is a directory, a symbolic link, a device or a pipe (leafview replaces regular
    files only). Bad input: ``leafview`` exits 2 and writes nothing."""
