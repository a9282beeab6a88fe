"""What the viewer edits: the current leaf, the file it came from, undo/redo and view toggles.

No GL and no imgui here: the panel, the viewport handles, keyboard shortcuts and the tests all
change the leaf through the same :class:`ViewerState` methods (:meth:`ViewerState.set_field`,
:meth:`ViewerState.apply`, :meth:`ViewerState.undo`, ...). Every change is validated by
:func:`leafview.core.params.parse_params`; an invalid value sets :attr:`ViewerState.error` (which
names the field) and leaves the leaf as it was.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview.botany.lobe_outline import compound_document
from leafview.core.defaults import DEFAULT_GRID
from leafview.core.io import read_document
from leafview.core.params import FieldSpec, LeafParams, ParamError, field_specs, parse_params
from leafview.deform.wind import WindSettings

__all__ = ["ViewerState", "ViewSettings", "ReferencePhoto", "get_field", "with_field", "HISTORY_LIMIT"]

HISTORY_LIMIT = 500


@dataclass
class ViewSettings:
    """Viewport toggles and scene settings that are not part of the leaf (not saved in presets)."""

    wireframe: bool = False
    show_controls: bool = True      # control polygons of A, S, F, G and the drag handles (C)
    show_ground: bool = True        # ground grid (G)
    show_help: bool = False         # key table overlay (H / F1)
    grid: tuple[int, int] = DEFAULT_GRID  # (u, v) samples of the drawn surface
    light_azimuth: float = 37.9     # key light, degrees (0 = from -y, towards +x positive)
    light_elevation: float = 55.2   # degrees above the leaf plane
    show_veins: bool = True         # leaves with venation show their veins (--veins on|off)
    wind: WindSettings = field(default_factory=WindSettings)   # the leaf in the wind (speed 0: still)
    wind_playing: bool = True       # the wind's time follows the wall clock (play/pause)

    def light_direction(self) -> tuple[float, float, float]:
        """Unit vector towards the key light (world space, z up)."""
        az, el = math.radians(self.light_azimuth), math.radians(self.light_elevation)
        return (math.sin(az) * math.cos(el), -math.cos(az) * math.cos(el), math.sin(el))


@dataclass
class ReferencePhoto:
    """The photo shown behind the leaf (``leafview.app.photo_reference``): not part of the leaf,
    not saved, not undone. Pixel coordinates are the full photo's (x right, y down).

    ``image`` is the display copy (RGBA uint8, reduced by ``factor``); ``size`` the photo's
    (width, height); ``base_px`` / ``apex_px`` the landmarks handed to the fit; ``leaf_from_pixel``
    the 3 × 3 placement in leaf space; ``report`` the last fit's measures
    (:func:`leafview.fit.photo.fit_image`); ``revision`` changes whenever ``image`` does; ``fits``
    counts the fits made (the viewer frames the leaf after each)."""

    path: Path | None = None
    image: NDArray[np.uint8] | None = None
    factor: int = 1
    size: tuple[int, int] = (0, 0)
    dpi: float | None = None
    opacity: float = 0.6
    visible: bool = True
    base_px: tuple[float, float] | None = None
    apex_px: tuple[float, float] | None = None
    leaf_from_pixel: NDArray[np.float64] | None = None
    fitted: bool = False
    report: dict[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = field(default_factory=tuple)
    revision: int = 0
    fits: int = 0


def _plain(value: Any) -> Any:
    """Tuples and arrays to nested lists (the form :func:`parse_params` reads)."""
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist"):
        return _plain(value.tolist())
    return value


def get_field(params: LeafParams, path: str) -> Any:
    """Value of the dotted field ``path`` (``"jitter.amplitude"``) of ``params``."""
    obj: Any = params
    for part in path.split("."):
        obj = getattr(obj, part)
    return obj


def with_field(params: LeafParams, path: str, value: Any) -> LeafParams:
    """New, validated parameters with ``path`` set to ``value``; raises :class:`ParamError`."""
    group, _, name = path.partition(".")
    if not name or "." in name:
        raise ParamError(path, "expected a field path of the form group.field")
    data = params.to_dict()
    if group not in data:  # a group the file form leaves out: start from its current values
        obj = getattr(params, group, None)
        if obj is None or not is_dataclass(obj):
            raise ParamError(path, f"unknown parameter group {group!r}")
        data[group] = {f.name: _plain(getattr(obj, f.name)) for f in fields(obj)}
    if name not in data[group]:
        raise ParamError(path, "unknown field")
    data[group][name] = _plain(value)
    return parse_params(data)


class ViewerState:
    """The leaf being edited and everything needed to never lose it.

    Parameters
    ----------
    params:
        The leaf to start from.
    path:
        The file it was loaded from (``None`` for a new, unsaved leaf). Save writes there unless
        it is a built-in preset, which is never overwritten (save as instead).

    Attributes
    ----------
    params : LeafParams
        The current leaf. Replaced (never mutated) by every edit.
    revision : int
        Incremented on every change of :attr:`params`; the renderer uploads the uniform block
        only when it differs from the revision it last uploaded.
    error : str or None
        The last user-facing error (invalid value, unreadable preset, failed save).
    message : str
        The last status message (saved, opened, screenshot written, ...).
    view : ViewSettings
        Viewport toggles.
    reference : ReferencePhoto
        The photo shown behind the leaf, if any.
    """

    def __init__(self, params: LeafParams | None = None, path: str | Path | None = None, *,
                 builtin_dir: Path | None = None) -> None:
        self.params = params if params is not None else LeafParams()
        self.path = Path(path) if path is not None else None
        self.preset = self.params          # what "reset to preset" returns to
        self.saved = self.params           # what is on disk (for the unsaved-changes check)
        self.builtin_dir = builtin_dir
        self.revision = 0
        self.loads = 0                     # incremented by every successful open()
        self.error: str | None = None
        self.message = ""
        self.view = ViewSettings()
        self.reference = ReferencePhoto()
        self._undo: list[LeafParams] = []
        self._redo: list[LeafParams] = []
        self._gesture: str | None = None

    # -- queries ------------------------------------------------------------------------------
    @property
    def dirty(self) -> bool:
        """True when the leaf differs from what was last loaded or saved."""
        return self.params != self.saved

    @property
    def can_undo(self) -> bool:
        return bool(self._undo)

    @property
    def can_redo(self) -> bool:
        return bool(self._redo)

    @property
    def title(self) -> str:
        name = self.path.name if self.path else (self.params.name or "untitled")
        return f"{name}{' *' if self.dirty else ''}"

    def get(self, path: str) -> Any:
        """Current value of a dotted field path."""
        return get_field(self.params, path)

    @staticmethod
    def specs() -> dict[str, FieldSpec]:
        """The field metadata the panel is generated from (new groups appear here)."""
        return field_specs()

    # -- edits --------------------------------------------------------------------------------
    def set_field(self, path: str, value: Any, *, gesture: bool = False) -> bool:
        """Set one field; returns whether the leaf changed.

        ``gesture=True`` marks a continuous interaction (a slider being dragged): consecutive
        edits of the same field become one undo step until :meth:`end_gesture`.
        """
        return self.apply(lambda p: with_field(p, path, value), gesture=path if gesture else None)

    def apply(self, edit: Callable[[LeafParams], LeafParams], *, gesture: str | None = None) -> bool:
        """Replace the leaf by ``edit(params)``; a :class:`ParamError` (or ``ValueError``) from
        ``edit`` sets :attr:`error` and changes nothing. ``gesture`` names a continuous
        interaction whose edits coalesce into one undo step."""
        try:
            new = edit(self.params)
        except (ParamError, ValueError) as exc:
            self.error = str(exc)
            return False
        self.error = None
        if new == self.params:
            return False
        if gesture is None or gesture != self._gesture:
            self._push_undo(self.params)
        self._gesture = gesture
        self._set(new)
        return True

    @property
    def in_gesture(self) -> bool:
        """True while a continuous interaction (a slider being dragged) is under way."""
        return self._gesture is not None

    def end_gesture(self) -> None:
        """Close the current continuous interaction: the next edit starts a new undo step."""
        self._gesture = None

    def _push_undo(self, params: LeafParams) -> None:
        self._undo.append(params)
        del self._undo[:-HISTORY_LIMIT]
        self._redo.clear()

    def _set(self, params: LeafParams) -> None:
        self.params = params
        self.revision += 1

    def undo(self) -> bool:
        """Step back one edit (Ctrl+Z); returns False when there is nothing to undo."""
        return self._step(self._undo, self._redo)

    def redo(self) -> bool:
        """Re-apply the last undone edit (Ctrl+Shift+Z)."""
        return self._step(self._redo, self._undo)

    def _step(self, source: list, target: list) -> bool:
        """Move one state from ``source`` to the current leaf, keeping the current on ``target``."""
        self._gesture = None
        if not source:
            return False
        target.append(self.params)
        self._set(source.pop())
        return True

    def reset_to_preset(self) -> bool:
        """Return to the leaf as it was loaded (itself an undoable edit)."""
        self._gesture = None
        return self.apply(lambda _: self.preset)

    # -- files --------------------------------------------------------------------------------
    def open(self, path: str | Path) -> bool:
        """Load a preset. On any error the message goes to :attr:`error` and nothing changes.

        Opening replaces the history (the caller asks about unsaved edits first). A compound
        (multilobed) leaf file (``lobed = 1``, :mod:`leafview.botany.lobes`) is opened as one
        lobed margin (:func:`leafview.botany.lobe_outline.lobed_outline_params`, a few seconds);
        it has no leaf file of its own then (save as writes one, never over the compound file).
        """
        p = Path(path).expanduser()
        try:
            # a compound file reads as its lobed leaf (the reader leafview.botany.lobe_outline
            # registers with leafview.core.io), with its errors naming the field
            leaf = compound_document(read_document(p))
            compound = leaf is not None
            params = leaf if leaf is not None else LeafParams.load(p)
        except ParamError as exc:
            if not exc.source:
                exc = exc.with_source(str(p))
            self.error = str(exc)
            return False
        except OSError as exc:
            self.error = f"{p}: cannot read: {exc.strerror or exc}"
            return False
        self.path, self.preset, self.saved = (None if compound else p), params, params
        self._undo.clear()
        self._redo.clear()
        self._gesture = None
        self._set(params)
        self.loads += 1
        self.error = None
        self.message = f"opened {p}" + (" as one lobed margin (save as to keep it)" if compound else "")
        return True

    def is_builtin(self, path: Path | None = None) -> bool:
        """Whether ``path`` (default: the current file) is one of the shipped presets."""
        p = path if path is not None else self.path
        if p is None or self.builtin_dir is None:
            return False
        try:
            return p.resolve().parent == self.builtin_dir.resolve()
        except OSError:
            return False

    @property
    def can_save(self) -> bool:
        """Whether :meth:`save` has a file to write to (not new, not a built-in preset)."""
        return self.path is not None and not self.is_builtin()

    def save(self) -> bool:
        """Write the leaf to its file (TOML or JSON by suffix). Needs :attr:`can_save`."""
        if not self.can_save:
            self.error = "this leaf has no file of its own yet (a built-in preset or new): use Save as"
            return False
        assert self.path is not None
        return self.save_as(self.path)

    def save_as(self, path: str | Path) -> bool:
        """Write the leaf to ``path`` (``.toml`` added when there is no suffix) and make it the
        current file. Errors go to :attr:`error`; nothing is half-written (atomic output)."""
        p = Path(path).expanduser()
        if not str(path).strip():
            self.error = "save as: give a file name"
            return False
        if not p.suffix:
            p = p.with_suffix(".toml")
        if self.is_builtin(p):
            self.error = f"{p}: built-in presets are read-only; choose another name"
            return False
        try:
            self.params.save(p)
        except ParamError as exc:
            self.error = str(exc)
            return False
        except OSError as exc:
            self.error = f"{p}: cannot write: {exc.strerror or exc}"
            return False
        self.path, self.saved = p, self.params
        self.error = None
        self.message = f"saved {p}"
        return True

    def write_recovery(self, directory: str | Path | None = None) -> Path | None:
        """If there are unsaved edits, write them to ``<name>.recovered.toml`` (never over an
        existing file) and return its path. For when the viewer is stopped without asking
        (Ctrl+C in the terminal, a crash); the current file is left untouched."""
        if not self.dirty:
            return None
        folder = Path(directory) if directory is not None else Path.cwd()
        stem = self.path.stem if self.path else (self.params.name or "leaf")
        target, n = folder / f"{stem}.recovered.toml", 1
        while target.exists():
            target, n = folder / f"{stem}.recovered-{n}.toml", n + 1
        try:
            self.params.save(target)
        except (OSError, ParamError):
            return None
        return target
