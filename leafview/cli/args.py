"""What the ``leafview`` commands share: exit codes, argument types, preset expansion, output
checks and reporting.

Argument types raise :class:`argparse.ArgumentTypeError` (argparse prints the message and exits
2); the other helpers raise :class:`~leafview.errors.UsageError`, which :func:`leafview.cli.main`
reports with exit code 2 before anything is written.

Compound leaf files (``lobed = 1``, ``assets/compound/*.toml``) load wherever a leaf file does:
this module registers a reader with :mod:`leafview.core.io` that hands them to
:func:`leafview.botany.lobe_outline.compound_document`, loaded on the first such file (it brings
scipy.optimize and shapely: half a second that every command would otherwise pay at start).
Landmark leaf files (``landmarks = 1``, ``assets/landmarks/*.toml``) load the same way, as leaves
drawn with their own landmark margin (:func:`leafview.botany.landmarks.margin_params`).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from tqdm import tqdm

from leafview.atomic import UniqueNames, check_folder, check_target
from leafview.botany.vein_shape import shape_grid
from leafview.botany.venation import check_veins
from leafview.core.io import load_leaves, register_document_reader
from leafview.core.limits import MAX_GRID, MAX_IMAGE_SIDE, parse_count
from leafview.core.params import LeafParams
from leafview.core.settings import SettingsTable
from leafview.errors import ParamError, UsageError
from leafview.resources import builtin_presets, resolve_preset
from leafview.scene.camera import VIEWS, check_leaf_framable

__all__ = ["EXIT_OK", "EXIT_FAILURE", "EXIT_USAGE", "EXIT_INTERRUPTED", "VIEWS", "count", "int_in_range", "int_pair",
           "pixels", "image_size", "output_path", "window_size", "grid", "builtin_names", "expand_presets",
           "preset_file", "load_leaf_files", "load_framable_leaves", "refuse_directory", "output_directory", "output_names", "report", "progress_bar",
           "VEINS", "add_veins_argument", "veins_off", "MAX_NUMBER_TEXT", "numbers", "checked_setting", "setting_option"]

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2
EXIT_INTERRUPTED = 130   # Ctrl-C, as a shell reports SIGINT
VEINS = ("on", "off")


# -- argument types -----------------------------------------------------------------------------
def output_path(text: str) -> str:
    """An output path for argparse (``-o``, ``--save``, ``--export``): refuses the empty string,
    which would otherwise name the current folder and write there."""
    if not text:
        raise argparse.ArgumentTypeError("an empty path; give a file or folder name")
    return text


def count(text: str, *, lo: int, hi: int, what: str, name: str | None = None) -> int:
    """A count for argparse (``10_000``, ``1e6``), in lo..hi (:mod:`leafview.core.limits`); never an
    OverflowError (``1e400``) or a 5,000-digit conversion."""
    try:
        return parse_count(text, lo, hi, what, name)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def int_in_range(text: str, *, lo: int, hi: int | None, what: str, name: str) -> int:
    """Parse a whole number in lo..hi (no upper bound when ``hi`` is None) for argparse:
    ``what`` names the unit in the type error, ``name`` the option in the range error."""
    try:
        n = int(text) if len(text) <= 40 else int("x")
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of {what}, got {text[:40]!r}") from None
    if n < lo or (hi is not None and n > hi):
        bound = f"between {lo} and {hi}" if hi is not None else f"at least {lo}"
        raise argparse.ArgumentTypeError(f"{name} must be {bound} {what}, got {n}")
    return n


MAX_NUMBER_TEXT = 60


def numbers(text: str, count: int, what: str) -> tuple[float, ...]:
    """``count`` comma-separated numbers for argparse (not checked for finiteness: the setting
    they go to says what it accepts); a type error naming ``what`` otherwise."""
    parts = text[:MAX_NUMBER_TEXT + 1].split(",")
    try:
        if len(text) > MAX_NUMBER_TEXT or len(parts) != count:
            raise ValueError(text)
        return tuple(float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text[:MAX_NUMBER_TEXT]!r}") from None


def checked_setting(settings: type[SettingsTable], name: str, value: Any) -> Any:
    """``value`` as field ``name`` of a settings table (its checks, e.g. ``light.sun[1]``, as
    argparse's type error)."""
    try:
        return getattr(settings(**{name: value}), name)
    except ParamError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def setting_option(settings: type[SettingsTable], name: str, what: str) -> Callable[[str], Any]:
    """An argparse type for one number that is field ``name`` of ``settings`` (``--exposure``,
    ``--wind``): parsed, then checked by the settings table (NaN, range) before anything runs."""
    def parse(text: str) -> Any:
        return checked_setting(settings, name, numbers(text, 1, what)[0])
    parse.__name__ = name   # argparse names the type in some messages
    return parse


def int_pair(text: str, *, lo: int, hi: int, what: str, example: str) -> tuple[int, int]:
    """Parse ``AxB`` (two whole numbers, each in lo..hi) for argparse, with a clear message."""
    try:
        if len(text) > 40:
            raise ValueError(text)
        a, b = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what} such as {example}, got {text[:40]!r}") from None
    if not (lo <= a <= hi and lo <= b <= hi):
        raise argparse.ArgumentTypeError(f"{a}x{b} outside {lo}..{hi} per side")
    return a, b


def pixels(text: str) -> int:
    """``--size N`` of square images: 8..8192 pixels."""
    return int_in_range(text, lo=8, hi=MAX_IMAGE_SIDE, what="pixels", name="size")


def image_size(text: str) -> tuple[int, int]:
    """``--size WxH`` of an offscreen image: each side 16..8192."""
    return int_pair(text, lo=16, hi=MAX_IMAGE_SIDE, what="WxH", example="1280x720")


def window_size(text: str) -> tuple[int, int]:
    """``--size WxH`` of a window: each side 64..8192."""
    return int_pair(text, lo=64, hi=MAX_IMAGE_SIDE, what="WIDTHxHEIGHT", example="1280x800")


def grid(text: str) -> tuple[int, int]:
    """``NUxNV`` samples across and along the blade: each 2..1025."""
    return int_pair(text, lo=2, hi=MAX_GRID, what="NUxNV", example="33x65")


# -- presets ------------------------------------------------------------------------------------
def builtin_names() -> str:
    """The built-in preset names, comma-separated (for error messages)."""
    return ", ".join(builtin_presets())


def expand_presets(specs: Sequence[str]) -> list[Path]:
    """Preset files for ``specs`` (files, directories of presets, built-in names), in order;
    raises UsageError naming the first that is missing or an empty directory."""
    paths: list[Path] = []
    for spec in specs:
        path = resolve_preset(spec)
        if not path.exists() and not path.suffix:
            raise UsageError(f"{spec}: no such file, directory or built-in preset (built-in: {builtin_names()})")
        if path.is_dir():
            found = sorted([*path.glob("*.toml"), *path.glob("*.json")])
            if not found:
                raise UsageError(f"{path}: directory holds no .toml or .json presets")
            paths.extend(found)
        else:
            paths.append(path)
    return paths


def preset_file(spec: str) -> Path:
    """One preset file or built-in name (not a directory); raises UsageError."""
    path = resolve_preset(spec)
    if not path.exists() and not path.suffix:
        raise UsageError(f"{spec}: no such file or built-in preset (built-in: {builtin_names()})")
    if path.is_dir():
        raise UsageError(f"{path} is a directory: give one preset file or a built-in name")
    return path


def load_leaf_files(paths: Sequence[Path]) -> list[LeafParams]:
    """Every leaf of the given files, in order: a leaf set (``*.leaves.json``) gives all of its
    leaves, any other preset file (a compound ``lobed = 1`` file too) one. Each leaf is named
    (its file's stem when unnamed)."""
    return [_checked_veins(leaf, path) for path in paths for leaf in load_leaves(path)]


def _checked_veins(leaf: LeafParams, path: Path) -> LeafParams:
    """``leaf``'s vein edits checked now (the vein each names, :func:`check_veins`; the blade's
    folding, :func:`shape_grid`, cached for the drawing that follows), so that a refusal names the
    file before anything is drawn or written. Leaves without edits cost nothing here."""
    if leaf.venation.edits:
        try:
            check_veins(leaf)
            shape_grid(leaf)
        except ParamError as exc:
            raise exc.with_source(str(path)) from None
    return leaf


def load_framable_leaves(paths: Sequence[Path]) -> list[LeafParams]:
    """:func:`load_leaf_files`, each leaf checked by
    :func:`~leafview.scene.camera.check_leaf_framable` (finite, and within what 32-bit rendering
    can frame); a refusal names the file as well as the leaf and the field."""
    leaves: list[LeafParams] = []
    for path in paths:
        for leaf in load_leaves(path):
            _checked_veins(leaf, path)
            try:
                check_leaf_framable(leaf)
            except ParamError as exc:
                raise exc.with_source(str(path)) from None
            leaves.append(leaf)
    return leaves


def _compound_document(data: Any) -> LeafParams | None:
    """The lobed leaf of a compound document, None for any other (see the module docstring)."""
    if not (isinstance(data, Mapping) and "lobed" in data):
        return None
    leaf: LeafParams = importlib.import_module("leafview.botany.lobe_outline").compound_document(data)
    return leaf


register_document_reader(_compound_document)


def _landmark_document(data: Any) -> LeafParams | None:
    """A landmark leaf file (``landmarks = 1``, ``assets/landmarks/*.toml``; Garg & Leow 2011,
    eq. 1) as a leaf drawn with its own margin (:mod:`leafview.core.margin`), None for any other."""
    if not (isinstance(data, Mapping) and "landmarks" in data):
        return None
    landmarks = importlib.import_module("leafview.botany.landmarks")
    leaf: LeafParams = landmarks.margin_params([landmarks.LandmarkLeaf.from_dict(data)])[0]
    return leaf


register_document_reader(_landmark_document)


# -- outputs ------------------------------------------------------------------------------------
def refuse_directory(flag: str, path: str | Path) -> Path:
    """Check the output file ``path`` given with ``flag`` before any work (see
    :func:`leafview.atomic.check_target`): UsageError when it is a directory, a symbolic link, a
    device or pipe, when a folder above it is a file or a name is too long; OutputError (exit 1)
    when its folder is not writable. Returns the path."""
    return check_target(path, flag)   # "-o PATH is a directory; give a file name", links, devices, ...


def output_directory(path: Path, flag: str = "-o") -> Path:
    """``-o DIR``: UsageError when ``path`` exists and is not a directory (or a folder above it
    is a file), OutputError when it cannot be written; stale temporary files in it are removed."""
    return check_folder(path, flag)


def output_names(names: Sequence[str], *, fallback: str = "leaf", quiet: bool = False) -> list[str]:
    """File names (without suffix) for outputs named from input (leaf, species, shape names):
    each one safe path component (no separators, ``..``, leading dots, control characters,
    Windows device names; length capped) and unique in the run (``name``, ``name-2``, ...), so
    nothing is written outside the output folder and nothing overwrites another output. A note
    on stderr lists the names that changed (unless ``quiet``)."""
    unique = UniqueNames(fallback=fallback)
    out = [unique(n) for n in names]
    changed = [(n, o) for n, o in zip(names, out) if n != o]
    if changed and not quiet:
        shown = ", ".join(f"{n!r} -> {o}" for n, o in changed[:5]) + (" ..." if len(changed) > 5 else "")
        print(f"note: {len(changed)} name(s) changed to safe, unique file names: {shown}", file=sys.stderr)
    return out


# -- reporting ----------------------------------------------------------------------------------
def report(args: argparse.Namespace, text: str) -> None:
    """Print ``text`` unless ``-q``/``--quiet`` was given."""
    if not args.quiet:
        print(text)


def progress_bar(iterable: Iterable[Any] | None = None, *, quiet: bool, **options: Any) -> Any:
    """A tqdm progress bar on stderr: hidden with ``quiet``, and (tqdm's rule) when stderr is not
    a terminal. ``options`` go to tqdm (``total``, ``unit``, ``desc``, ``leave``, ...)."""
    return tqdm(iterable, disable=True if quiet else None, file=sys.stderr, **options)


def add_veins_argument(parser: argparse.ArgumentParser) -> None:
    """``--veins on|off`` (``render``, ``scene``, ``view``; argparse refuses other values, exit 2)."""
    parser.add_argument("--veins", choices=VEINS, default="on",
                        help="on (default): leaves whose venation is enabled show their veins; off: no leaf "
                             "does (drawn as if its venation were disabled)")


def veins_off(args: argparse.Namespace) -> bool:
    """Whether ``--veins off`` was given."""
    return getattr(args, "veins", "on") == "off"
