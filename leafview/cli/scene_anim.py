"""The wind and animation options of ``leafview scene``: ``--wind SPEED``, ``--wind-dir DEG``,
``--time T``, ``--fps FPS``, and the writer of ``--frames N -o anim.mp4|anim.gif|DIR/``.

Each wind option overrides the scene file's ``[wind]`` table
(:class:`~leafview.deform.wind.WindSettings`); values are checked while the command line is parsed,
by the settings' own rules (errors name ``wind.speed`` and so on), so argparse exits 2 before
anything is built. An animation's output is checked (:func:`check_animation_output`) before the
first frame renders: an unknown extension or a place that cannot be written is a usage error
(exit 2). Frames are encoded as they come (one frame in memory at a time):

* ``.mp4``: H.264 (yuv420p) through the ffmpeg of ``imageio-ffmpeg``;
* ``.gif``: the same ffmpeg, one palette for the whole clip (``palettegen`` / ``paletteuse``);
* a folder (a path ending in ``/``, an existing folder, or a name without an extension):
  ``frame_0000.png``, ``frame_0001.png``, ... (RGBA).

Every output is atomic (:mod:`leafview.atomic`): the video is written to a temporary file beside
its target and renamed when complete, the frames of a folder commit together; a failed or
interrupted run leaves no partial file. Transparent pixels of a video are composited on white.

Example::

    leafview scene --layout plant --leaves 3000 --wind 6 --frames 120 -o anim.mp4
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import imageio_ffmpeg
import numpy as np
from numpy.typing import NDArray

from leafview.atomic import atomic_output, check_folder, check_target, outputs
from leafview.cli.args import MAX_NUMBER_TEXT, numbers, setting_option
from leafview.deform.wind import WindSettings
from leafview.errors import OutputError, OutputPathError, UsageError
from leafview.export.images import write_image

__all__ = ["add_wind_arguments", "wind_from_args", "check_animation_output", "animation_kind", "animation_times",
           "write_animation", "frame_name", "wind_speed", "wind_direction", "wind_time", "frame_rate",
           "ANIMATION_EXTENSIONS", "DEFAULT_FPS", "MAX_FPS"]

ANIMATION_EXTENSIONS = (".mp4", ".gif")
DEFAULT_FPS = 30.0
MAX_FPS = 240.0


wind_speed = setting_option(WindSettings, "speed", "a wind speed (scene units per second)")
"""``--wind SPEED``: scene units per second, checked as ``wind.speed``."""
wind_direction = setting_option(WindSettings, "direction", "a direction in degrees")
"""``--wind-dir DEG``: the direction the wind blows towards, degrees counter-clockwise from +x."""
wind_time = setting_option(WindSettings, "time", "a time in seconds")
"""``--time T``: seconds (the first frame's time of an animation), checked as ``wind.time``."""


def frame_rate(text: str) -> float:
    """``--fps FPS``: frames per second of an animation, in (0, 240]."""
    x = numbers(text, 1, "frames per second")[0]
    if not 0.0 < x <= MAX_FPS:   # NaN fails this too
        raise argparse.ArgumentTypeError(f"--fps must lie in (0, {MAX_FPS:g}], got {text[:MAX_NUMBER_TEXT]!r}")
    return x


def add_wind_arguments(p: argparse.ArgumentParser) -> None:
    """The wind options (an argument group); each defaults to None (the scene file's or the
    default wind), except ``--fps``."""
    g = p.add_argument_group("wind", "leaves in the wind (each overrides the scene file's [wind] table)")
    default = WindSettings()
    g.add_argument("--wind", type=wind_speed, metavar="SPEED",
                   help=f"wind speed in scene units per second, 0-60 (default {default.speed:g}: still)")
    g.add_argument("--wind-dir", type=wind_direction, metavar="DEG",
                   help="direction the wind blows towards, degrees counter-clockwise from +x "
                        f"(default {default.direction:g})")
    g.add_argument("--time", type=wind_time, metavar="T",
                   help=f"time in seconds of the frame (of the first frame, with --frames) (default {default.time:g})")
    g.add_argument("--fps", type=frame_rate, default=DEFAULT_FPS, metavar="FPS",
                   help=f"frames per second of an animation (--frames N -o anim.mp4|anim.gif|DIR/) "
                        f"(default {DEFAULT_FPS:g})")


def wind_from_args(args: argparse.Namespace, base: WindSettings | None = None) -> WindSettings:
    """``base`` (the scene file's wind; None: the default wind) with the options given on the
    command line."""
    base = WindSettings() if base is None else base
    changes = {field: getattr(args, name) for name, field in (("wind", "speed"), ("wind_dir", "direction"),
                                                               ("time", "time"))
               if getattr(args, name, None) is not None}
    return base.replace(**changes) if changes else base


def animation_kind(path: str | os.PathLike[str]) -> str:
    """``"mp4"``, ``"gif"`` or ``"frames"`` (a folder of PNG frames: a path ending in a separator,
    an existing folder or a name without an extension); UsageError for another extension."""
    text = os.fspath(path)
    target = Path(text)
    if text.endswith(("/", os.sep)) or target.is_dir() or not target.suffix:
        return "frames"
    suffix = target.suffix.lower()
    if suffix in ANIMATION_EXTENSIONS:
        return suffix[1:]
    raise UsageError(f"-o {text}: unknown animation type {target.suffix!r} "
                     f"(use .mp4, .gif or a folder for PNG frames)")


def frame_name(index: int) -> str:
    return f"frame_{index:04d}.png"


def check_animation_output(path: str | os.PathLike[str], frames: int) -> str:
    """Check an animation's output before anything renders; returns :func:`animation_kind`.
    UsageError (exit 2) for an unknown extension or a frame count below 1; OutputPathError
    (exit 2) for a place that cannot be written (a folder that is a file, no permission, a
    read-only file system, an existing frame that is not a regular file)."""
    if int(frames) < 1:
        raise UsageError(f"--frames must be at least 1, got {frames}")
    kind = animation_kind(path)
    try:
        if kind == "frames":
            folder = check_folder(path, "-o")
            if folder.is_dir():
                for i in range(int(frames)):   # an existing frame must be replaceable
                    name = folder / frame_name(i)
                    if os.path.lexists(name):
                        check_target(name, "-o")
        else:
            check_target(path, "-o")
    except OutputPathError:
        raise
    except OutputError as exc:   # the place, not the environment: bad input here
        raise OutputPathError(str(exc), exc.path, exc.errno) from None
    return kind


def animation_times(start: float, frames: int, fps: float) -> list[float]:
    """The time of each frame: ``start + i / fps``."""
    return [float(start) + i / float(fps) for i in range(int(frames))]


def _rgb_on_white(image: NDArray[Any]) -> NDArray[np.uint8]:
    """(h, w, 3) uint8 of an (h, w, 4) or (h, w, 3) uint8 frame, transparent pixels on white, the
    size made even (yuv420p) by repeating the last row or column."""
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] not in (3, 4):
        raise ValueError(f"a frame must be (h, w, 3|4) uint8, got {img.shape} {img.dtype}")
    if img.shape[2] == 4:
        a = img[..., 3:4].astype(np.float32) / 255.0
        rgb = np.rint(img[..., :3].astype(np.float32) * a + 255.0 * (1.0 - a)).astype(np.uint8)
    else:
        rgb = img
    h, w = rgb.shape[:2]
    return np.ascontiguousarray(np.pad(rgb, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge"))


def _encode(tmp: Path, kind: str, fps: float, first: NDArray[np.uint8], rest: Callable[[], Any]) -> None:
    """Run ffmpeg (imageio-ffmpeg) into ``tmp``: ``first`` and then every frame ``rest()`` yields."""
    h, w = first.shape[:2]
    if kind == "mp4":
        options: dict[str, Any] = {"codec": "libx264", "pix_fmt_out": "yuv420p", "quality": 8,
                                   "output_params": ["-f", "mp4", "-movflags", "+faststart"]}
    else:
        options = {"codec": "gif", "pix_fmt_out": "pal8", "quality": None,
                   "output_params": ["-f", "gif", "-filter_complex",
                                     "split[a][b];[a]palettegen=stats_mode=diff[p];[b][p]paletteuse"]}
    writer = imageio_ffmpeg.write_frames(str(tmp), (w, h), fps=fps, macro_block_size=1,
                                         ffmpeg_log_level="error", **options)
    writer.send(None)   # start ffmpeg
    try:
        writer.send(first)
        for frame in rest():
            if frame.shape != first.shape:
                raise ValueError(f"frame size changed from {first.shape[:2]} to {frame.shape[:2]}")
            writer.send(frame)
    finally:
        writer.close()


def write_animation(path: str | os.PathLike[str], frames: int, fps: float,
                    render_frame: Callable[[float], NDArray[np.uint8]], times: Sequence[float] | None = None,
                    progress: Callable[[int], Any] | None = None) -> Path:
    """Render ``frames`` frames with ``render_frame(t)`` ((h, w, 4) uint8 RGBA, row 0 at the top)
    at ``times`` (default ``i / fps``) and write them to ``path`` (mp4, gif or a folder of PNG
    frames: :func:`animation_kind`), atomically; ``progress(1)`` after each frame. Returns the
    path. The output is checked first (:func:`check_animation_output`)."""
    kind = check_animation_output(path, frames)
    n = int(frames)
    ts = list(animation_times(0.0, n, fps) if times is None else times)
    if len(ts) != n:
        raise ValueError(f"{n} frames but {len(ts)} times")
    step = progress if progress is not None else (lambda _k: None)
    if kind == "frames":
        folder = Path(path)
        with outputs():   # every frame or none
            for i, t in enumerate(ts):
                write_image(folder / frame_name(i), np.asarray(render_frame(t)))
                step(1)
        return folder

    def rest() -> Any:
        for t in ts[1:]:
            out = _rgb_on_white(render_frame(t))
            step(1)
            yield out

    first = _rgb_on_white(render_frame(ts[0]))
    step(1)
    with atomic_output(path) as tmp:
        _encode(tmp, kind, fps, first, rest)
    return Path(path)
