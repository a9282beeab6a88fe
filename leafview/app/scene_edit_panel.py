"""The scene viewer's edit panel: scene-wide edits (Chaurasia & Beardsley 2017, sec. 6, applied to
every leaf, one species or the selection; :mod:`leafview.scene.scene_edits`) with undo, redo and
save.

The sliders hold a pending edit: a width factor, an asymmetry shift, a curvature lift (of the axis
or of S, F or G) and a move of one silhouette row's point. **Apply** turns every slider that is
off its neutral value into one edit (each its own undo step), hands the changed leaves to
``update`` (the viewer's :func:`leafview.gpu.scene_edits.update_rows`) and puts the sliders back.
**Save** writes the scene file with the edits (and, given ``spec``, the viewer's current
``[light]`` and ``[wind]``).
:class:`SceneEditPanel` keeps its logic out of imgui (:meth:`apply`, :meth:`undo`, :meth:`redo`,
:meth:`save`), so tests call it directly.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from imgui_bundle import imgui
from numpy.typing import NDArray

from leafview.errors import LeafviewError
from leafview.scene.scene_edits import CURVES, SceneEditor
from leafview.scene.spec import SceneSpec, save_scene

__all__ = ["SceneEditPanel", "TARGET_LABELS"]

TARGET_LABELS = ("all", "species", "selection")
_TARGETS = ("all", "species", "leaves")


@dataclass
class SceneEditPanel:
    """Widgets over a :class:`~leafview.scene.scene_edits.SceneEditor`.

    ``update``: called with the leaves whose rows changed after every apply, undo and redo.
    ``path``: where **Save** writes the scene file (None: the button asks for nothing and says so).
    ``spec``: the scene's spec to save, e.g. with the viewer's light and wind (None: the editor's
    scene's own); its ``edits`` are replaced by the editor's.
    """

    editor: SceneEditor
    update: Callable[[NDArray[np.int64]], Any]
    path: Path | None = None
    spec: Callable[[], SceneSpec] | None = None
    target: int = 0              # index into _TARGETS
    species: int = 0
    width: float = 1.0
    asymmetry: float = 0.0
    curvature: float = 0.0
    curve: int = 0               # index into CURVES
    row: int = 0
    row_x: float = 0.0
    row_v: float = 0.0
    message: str = ""

    # -- logic ---------------------------------------------------------------------------------
    def _select(self) -> None:
        kind = _TARGETS[self.target]
        if kind == "all":
            self.editor.select()
        elif kind == "species":
            self.editor.select(species=self.species)
        else:
            self.editor.select(self.editor.selection)

    def pending(self) -> list[tuple[str, float, dict[str, Any]]]:
        """The edits Apply would make: (op, value, keyword arguments)."""
        out: list[tuple[str, float, dict[str, Any]]] = []
        if self.width != 1.0:
            out.append(("width", self.width, {}))
        if self.asymmetry:
            out.append(("asymmetry", self.asymmetry, {}))
        if self.curvature:
            out.append(("curvature", self.curvature, {"curve": CURVES[self.curve]}))
        if self.row_x or self.row_v:
            out.append(("silhouette", self.row_x, {"row": self.row, "v": self.row_v}))
        return out

    def apply(self) -> NDArray[np.int64]:
        """Apply the pending edits to the target; returns the leaves changed (also given to ``update``)."""
        changed = [np.zeros(0, np.int64)]
        try:
            self._select()
            for op, value, kwargs in self.pending():
                changed.append(self.editor.apply(op, value, **kwargs))
        except LeafviewError as exc:
            self.message = str(exc)
        else:
            self.message = f"{len(self.pending())} edit(s) applied"
            self.width, self.asymmetry, self.curvature, self.row_x, self.row_v = 1.0, 0.0, 0.0, 0.0, 0.0
        ids = np.unique(np.concatenate(changed))
        if ids.size:
            self.update(ids)
        return ids

    def undo(self) -> NDArray[np.int64] | None:
        ids = self.editor.undo()
        if ids is not None:
            self.update(ids)
        return ids

    def redo(self) -> NDArray[np.int64] | None:
        ids = self.editor.redo()
        if ids is not None:
            self.update(ids)
        return ids

    def save(self, path: str | os.PathLike[str] | None = None) -> bool:
        """Write the scene file with its edits to ``path`` (default :attr:`path`); False when
        there is nowhere to write or writing failed (:attr:`message` says why)."""
        target = Path(path) if path is not None else self.path
        if target is None:
            self.message = "no scene file to save to (open the viewer with one)"
            return False
        try:
            if self.spec is None:
                self.editor.save(target)
            else:
                save_scene(self.spec().replace(edits=self.editor.edits), target)
        except (LeafviewError, OSError) as exc:
            self.message = str(exc)
            return False
        self.message = f"saved {target.name} ({len(self.editor.edits)} edit(s))"
        return True

    # -- widgets -------------------------------------------------------------------------------
    def draw(self) -> None:
        """The panel's widgets, inside the caller's imgui window."""
        ed = self.editor
        imgui.text("Scene-wide edits")
        imgui.push_item_width(150)
        for k, label in enumerate(TARGET_LABELS):
            if k:
                imgui.same_line()
            if imgui.radio_button(f"{label}##edit-target", self.target == k):
                self.target = k
        if _TARGETS[self.target] == "species" and len(ed.scene.species) > 1:
            _, self.species = imgui.slider_int("species##edit", self.species, 0, len(ed.scene.species) - 1)
        imgui.text(f"selected: {ed.selection.size:,} leaves")
        imgui.text_disabled("click, shift+click, right or shift drag")
        _, self.width = imgui.slider_float("width x##edit", self.width, 0.25, 3.0)
        _, self.asymmetry = imgui.slider_float("asymmetry##edit", self.asymmetry, -0.3, 0.3)
        _, self.curvature = imgui.slider_float("curvature##edit", self.curvature, -0.3, 0.3)
        _, self.curve = imgui.combo("curve##edit", self.curve, list(CURVES))
        _, self.row = imgui.slider_int("row##edit", self.row, 0, 2)
        _, self.row_x = imgui.slider_float("row x shift##edit", self.row_x, -0.3, 0.3)
        _, self.row_v = imgui.slider_float("row v shift##edit", self.row_v, -0.2, 0.2)
        if imgui.button("Apply##edit"):
            self.apply()
        imgui.same_line()
        if imgui.button("Undo##edit"):
            self.undo()
        imgui.same_line()
        if imgui.button("Redo##edit"):
            self.redo()
        imgui.same_line()
        if imgui.button("Save##edit"):
            self.save()
        imgui.text(f"{len(ed.history)} edit(s) this session")
        if self.message:
            imgui.text_wrapped(self.message)
        imgui.pop_item_width()
