"""Scene-wide edits: the artist edits of Chaurasia & Beardsley 2017, sec. 6 (width, asymmetry,
silhouette, curvature; :mod:`leafview.core.edits` for one leaf) applied to every leaf of a scene, to
one species or to a selection of leaves, as the paper applies them to whole datasets.

A scene leaf's Ω is its species' Ω times its factors plus its offsets (:attr:`Scene.factors
<leafview.scene.spec.Scene.factors>`, :attr:`Scene.offsets <leafview.scene.spec.Scene.offsets>`,
columns in :data:`~leafview.scene.spec.VARIED` order), so every edit is a change of those two
arrays and nothing else (the GPU rows follow with one buffer update,
:func:`leafview.gpu.scene_edits.update_rows`):

``width`` (value f > 0, Fig. 7a, :func:`~leafview.core.edits.scale_width`)
    x̄s of each silhouette row multiplied by f: factors and offsets of ``xs1..3`` times f.
``asymmetry`` (value dx, Fig. 7b, :func:`~leafview.core.edits.skew_axis`)
    a1.x and a2.x moved by dx: offsets of ``a1.x``, ``a2.x`` plus dx.
``silhouette`` (row k, value dx, ``v`` dv, Fig. 7c-d, :func:`~leafview.core.edits.set_silhouette_point`)
    silhouette control point k moved by (dv, dx): offsets of ``vbar{k+1}``, ``xs{k+1}``.
``curvature`` (curve, value dz, Fig. 7e-f, :func:`~leafview.core.edits.curve_axis`,
:func:`~leafview.core.edits.curve_longitudinal`)
    ``axis``: a1.z, a2.z lifted by dz; ``S``, ``F``, ``G``: z̄s, z̄f or z̄g of every row lifted by dz.

Edits are relative (a factor or a displacement), so a leaf keeps its own variation. Lobed leaves
are skipped (their shape is their sweep table, not Ω), and the rows of an extended silhouette
beyond the paper's three keep their species' values (they are not among the varied columns).
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from leafview.core.fieldspec import number
from leafview.core.params import OMEGA_LIMIT, ParamError

if TYPE_CHECKING:
    from leafview.scene.spec import Scene

__all__ = ["EDIT_OPS", "EDIT_TARGETS", "CURVES", "SceneEdit", "parse_edits", "apply_edits", "edit_columns",
           "species_omega", "leaf_omega", "SceneEditor"]

EDIT_OPS = ("width", "asymmetry", "silhouette", "curvature")
EDIT_TARGETS = ("all", "species", "leaves")
CURVES = ("axis", "S", "F", "G")
SIL_ROWS = 3            # silhouette rows among the varied columns
# columns of Scene.factors / Scene.offsets (leafview.scene.spec.VARIED order; a test checks it)
_COL: dict[str, tuple[int, ...]] = {"a1.x": (0,), "a1.z": (2,), "a2.x": (3,), "a2.z": (5,), "vbar": (6, 9, 12),
                                     "xs": (7, 10, 13), "zs": (8, 11, 14), "zf": (15, 16, 17), "zg": (18, 19, 20)}
_LIMITS = {"width": (1e-3, 10.0), "asymmetry": (-1.0, 1.0), "silhouette": (-1.0, 1.0), "curvature": (-1.0, 1.0)}
_V_LIMIT = 0.5


@dataclass(frozen=True)
class SceneEdit:
    """One scene-wide edit (the module docstring says what each ``op`` does).

    ``target``: ``all`` leaves, one ``species`` (its index in the scene's species) or the
    ``leaves`` given (indices). ``row``: the silhouette row (0-2) of a ``silhouette`` edit, ``v``
    its foot's shift dv; ``curve``: ``axis``, ``S``, ``F`` or ``G`` of a ``curvature`` edit."""

    op: str
    value: float
    target: str = "all"
    species: int = 0
    leaves: tuple[int, ...] = ()
    row: int = 0
    v: float = 0.0
    curve: str = "axis"

    def __post_init__(self) -> None:
        if self.op not in EDIT_OPS:
            raise ParamError("op", f"unknown edit {self.op!r} (use {', '.join(EDIT_OPS)})")
        value = number(self.value, "value")
        lo, hi = _LIMITS[self.op]
        if not lo <= value <= hi:
            raise ParamError("value", f"a {self.op} edit takes a value in [{lo:g}, {hi:g}], got {value!r}")
        object.__setattr__(self, "value", value)
        if self.target not in EDIT_TARGETS:
            raise ParamError("target", f"unknown target {self.target!r} (use {', '.join(EDIT_TARGETS)})")
        if isinstance(self.species, bool) or not isinstance(self.species, (int, np.integer)) or self.species < 0:
            raise ParamError("species", f"must be a species index (0, 1, ...), got {self.species!r}")
        object.__setattr__(self, "species", int(self.species))
        leaves = tuple(self.leaves)
        for k, i in enumerate(leaves):
            if isinstance(i, bool) or not isinstance(i, (int, np.integer)) or i < 0:
                raise ParamError(f"leaves[{k}]", f"must be a leaf index (0, 1, ...), got {i!r}")
        if self.target == "leaves" and not leaves:
            raise ParamError("leaves", "a 'leaves' target needs at least one leaf index")
        object.__setattr__(self, "leaves", tuple(sorted({int(i) for i in leaves})))
        if isinstance(self.row, bool) or not isinstance(self.row, (int, np.integer)) or not 0 <= self.row < SIL_ROWS:
            raise ParamError("row", f"must be a silhouette row 0..{SIL_ROWS - 1}, got {self.row!r}")
        object.__setattr__(self, "row", int(self.row))
        v = number(self.v, "v")
        if abs(v) > _V_LIMIT:
            raise ParamError("v", f"must be in [-{_V_LIMIT}, {_V_LIMIT}], got {v!r}")
        object.__setattr__(self, "v", v)
        if self.curve not in CURVES:
            raise ParamError("curve", f"unknown curve {self.curve!r} (use {', '.join(CURVES)})")

    def to_dict(self) -> dict[str, Any]:
        """The ``[[edits]]`` table of a scene file (only the keys that mean something for ``op``)."""
        out: dict[str, Any] = {"op": self.op, "value": self.value, "target": self.target}
        if self.target == "species":
            out["species"] = self.species
        elif self.target == "leaves":
            out["leaves"] = list(self.leaves)
        if self.op == "silhouette":
            out["row"] = self.row
            if self.v:
                out["v"] = self.v
        if self.op == "curvature":
            out["curve"] = self.curve
        return out


_KEYS = ("op", "value", "target", "species", "leaves", "row", "v", "curve")


def parse_edits(value: Any, path: str = "edits") -> tuple[SceneEdit, ...]:
    """A scene file's ``[[edits]]`` list as :class:`SceneEdit` s; a bad entry raises
    :class:`~leafview.errors.ParamError` naming it (``edits[2].value``)."""
    if not isinstance(value, (list, tuple)):
        raise ParamError(path, "expected a list of [[edits]] tables")
    out = []
    for i, item in enumerate(value):
        where = f"{path}[{i}]"
        if not isinstance(item, Mapping):
            raise ParamError(where, "must be a table")
        for key in item:
            if key not in _KEYS:
                raise ParamError(f"{where}.{key}", f"unknown key (known: {', '.join(_KEYS)})")
        if "op" not in item:
            raise ParamError(f"{where}.op", f"missing (one of {', '.join(EDIT_OPS)})")
        if "value" not in item:
            raise ParamError(f"{where}.value", "missing")
        leaves = item.get("leaves", ())
        if not isinstance(leaves, (list, tuple)):
            raise ParamError(f"{where}.leaves", "must be a list of leaf indices")
        kwargs = {k: item[k] for k in _KEYS if k in item}
        kwargs["leaves"] = tuple(leaves)
        try:
            out.append(SceneEdit(**kwargs))
        except ParamError as exc:
            raise ParamError(f"{where}.{exc.path}", exc.message) from None
    return tuple(out)


def edit_columns(edit: SceneEdit) -> tuple[tuple[int, ...], str]:
    """(columns of Scene.factors/offsets the edit changes, ``"scale"`` or ``"add"``)."""
    if edit.op == "width":
        return _COL["xs"], "scale"
    if edit.op == "asymmetry":
        return _COL["a1.x"] + _COL["a2.x"], "add"
    if edit.op == "silhouette":
        return (_COL["vbar"][edit.row], _COL["xs"][edit.row]), "add"
    if edit.curve == "axis":
        return _COL["a1.z"] + _COL["a2.z"], "add"
    return _COL[{"S": "zs", "F": "zf", "G": "zg"}[edit.curve]], "add"


def species_omega(scene: Scene) -> NDArray[np.float32]:
    """(S, 21) float32: each species' Ω in VARIED order (the first three silhouette rows)."""
    rows = []
    for sp in scene.species:
        s = sp.shape
        sil = [c for r in s.silhouette[:SIL_ROWS] for c in r]
        rows.append([*s.a1, *s.a2, *sil, *s.zf[:SIL_ROWS], *s.zg[:SIL_ROWS]])
    return np.asarray(rows, np.float64).astype(np.float32)


def leaf_omega(scene: Scene, leaves: Any, table: NDArray[np.float32] | None = None) -> NDArray[np.float32]:
    """(n, 21) float32: Ω of ``leaves`` as the scene defines it, species × factors + offsets
    (before the v̄ clamp of :func:`~leafview.scene.spec.vary_shape`), as the GPU packs it."""
    idx = np.asarray(leaves, np.int64).reshape(-1)
    table = species_omega(scene) if table is None else table
    out: NDArray[np.float32] = table[scene.species_id[idx]] * scene.factors[idx]
    if scene.offsets is not None:
        out += scene.offsets[idx]
    return out


def _targets(scene: Scene, edit: SceneEdit, where: str) -> NDArray[np.int64]:
    """The leaves ``edit`` applies to (sorted, lobed leaves left out)."""
    n = len(scene)
    if edit.target == "all":
        idx = np.arange(n, dtype=np.int64)
    elif edit.target == "species":
        if edit.species >= len(scene.species):
            raise ParamError(f"{where}.species", f"species {edit.species} out of range 0..{len(scene.species) - 1}")
        idx = np.flatnonzero(scene.species_id == edit.species).astype(np.int64)
    else:
        idx = np.asarray(edit.leaves, np.int64)
        if idx.size and idx[-1] >= n:
            raise ParamError(f"{where}.leaves", f"leaf {int(idx[-1])} out of range 0..{n - 1}")
    lobed = np.array([bool(sp.lobes.enabled) for sp in scene.species], bool)
    if lobed.any():
        idx = idx[~lobed[scene.species_id[idx]]]
    return idx


@dataclass
class _Change:
    """What one edit did: the factors and offsets of rows ``leaves``, columns ``cols``, before and
    after (only the columns it changes, so the undo history of an edit of 10⁶ leaves stays small)."""

    edit: SceneEdit
    leaves: NDArray[np.int64]
    cols: list[int]
    before: tuple[NDArray[np.float32], NDArray[np.float32] | None]
    after: tuple[NDArray[np.float32], NDArray[np.float32]]
    created_offsets: bool

    def put(self, scene: Scene, state: tuple[NDArray[np.float32], NDArray[np.float32] | None]) -> None:
        """Write ``state`` (before or after) back into the scene's arrays."""
        rows = self.leaves[:, None]
        scene.factors[rows, self.cols] = state[0]
        if state[1] is not None and scene.offsets is not None:
            scene.offsets[rows, self.cols] = state[1]


def _apply_one(scene: Scene, edit: SceneEdit, where: str, table: NDArray[np.float32]) -> _Change:
    """Apply ``edit`` (validated first: nothing changes when it fails)."""
    idx = _targets(scene, edit, where)
    cols, kind = edit_columns(edit)
    c = list(cols)
    rows = idx[:, None]
    f_old = scene.factors[rows, c]
    o_old = None if scene.offsets is None else scene.offsets[rows, c]
    f_new = f_old.copy()
    o_new = np.zeros_like(f_old) if o_old is None else o_old.copy()
    if kind == "scale":
        f_new *= np.float32(edit.value)
        o_new *= np.float32(edit.value)
    elif edit.op == "silhouette":
        o_new[:, 0] += np.float32(edit.v)
        o_new[:, 1] += np.float32(edit.value)
    else:
        o_new += np.float32(edit.value)
    omega = table[scene.species_id[idx]][:, c] * f_new + o_new
    bad = ~np.isfinite(omega) | (np.abs(omega) > OMEGA_LIMIT)
    if bad.any():
        leaf = int(idx[np.flatnonzero(bad.any(axis=1))[0]])
        raise ParamError(f"{where}.value", f"leaf {leaf}'s Ω would leave ±{OMEGA_LIMIT:g} leaf lengths")
    created = scene.offsets is None
    if created:
        scene.offsets = np.zeros_like(scene.factors)
    change = _Change(edit, idx, c, (f_old, o_old), (f_new, o_new), created)
    change.put(scene, change.after)
    return change


def apply_edits(scene: Scene, edits: Sequence[SceneEdit], path: str = "edits") -> NDArray[np.int64]:
    """Apply ``edits`` in order to ``scene`` in place (``scene.factors``, ``scene.offsets``, the
    latter created when first needed); returns the sorted ids of the leaves changed. An edit
    that fails (a species or leaf out of range, an Ω beyond the parameters' limits) raises
    :class:`~leafview.errors.ParamError` naming ``path[i]``; the edits before it stay applied."""
    return np.unique(np.concatenate([np.zeros(0, np.int64)] + [c.leaves for c in _apply(scene, edits, path)]))


def _apply(scene: Scene, edits: Sequence[SceneEdit], path: str) -> list[_Change]:
    table = species_omega(scene)
    return [_apply_one(scene, e, f"{path}[{i}]", table) for i, e in enumerate(edits)]


@dataclass
class SceneEditor:
    """Interactive scene-wide edits with a selection, undo and redo (the scene viewer's panel and
    the Python API). Each :meth:`apply`, :meth:`undo` and :meth:`redo` returns the ids of the
    leaves whose rows changed: pass them to :func:`leafview.gpu.scene_edits.update_rows`.

    Example::

        ed = SceneEditor(scene)
        ed.select(species=0)
        update_rows(renderer, ed.apply("width", 1.2))   # leafview.gpu.scene_edits
        update_rows(renderer, ed.undo())
        ed.save("edited.toml")
    """

    scene: Scene
    selection: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    target: str = "all"          # all | species | leaves (the selection)
    species: int = 0
    _done: list[_Change] = field(default_factory=list)
    _undone: list[_Change] = field(default_factory=list)

    def select(self, leaves: Any = None, *, species: int | None = None, add: bool = False) -> None:
        """Target the given ``leaves`` (added to the selection with ``add``), one ``species``, or,
        with neither, every leaf."""
        if species is not None:
            if not 0 <= int(species) < len(self.scene.species):
                raise ParamError("species", f"species {species} out of range 0..{len(self.scene.species) - 1}")
            self.target, self.species = "species", int(species)
        elif leaves is None:
            self.target = "all"
        else:
            ids = np.asarray(leaves, np.int64).reshape(-1)
            if ids.size and (ids.min() < 0 or ids.max() >= len(self.scene)):
                raise ParamError("leaves", f"leaf index out of range 0..{len(self.scene) - 1}")
            self.selection = np.union1d(self.selection, ids) if add else np.unique(ids)
            self.target = "leaves"

    def edit(self, op: str, value: float, **kwargs: Any) -> SceneEdit:
        """The :class:`SceneEdit` of ``op`` for the current target (not applied)."""
        if self.target == "leaves":
            if not self.selection.size:
                raise ParamError("leaves", "nothing is selected")
            return SceneEdit(op, value, "leaves", leaves=tuple(int(i) for i in self.selection), **kwargs)
        return SceneEdit(op, value, self.target, species=self.species, **kwargs)

    def apply(self, op: str | SceneEdit, value: float = 0.0, **kwargs: Any) -> NDArray[np.int64]:
        """Apply an edit (``op`` and ``value``, ``row``, ``v``, ``curve``; or a :class:`SceneEdit`)
        to the current target; the redo list is cleared."""
        edit = op if isinstance(op, SceneEdit) else self.edit(op, value, **kwargs)
        change = _apply(self.scene, [edit], "edit")[0]
        self._done.append(change)
        self._undone.clear()
        return change.leaves

    def undo(self) -> NDArray[np.int64] | None:
        """Undo the last edit (factors and offsets restored bit for bit); None when none is left."""
        if not self._done:
            return None
        c = self._done.pop()
        c.put(self.scene, c.before)
        if c.created_offsets:
            self.scene.offsets = None
        self._undone.append(c)
        return c.leaves

    def redo(self) -> NDArray[np.int64] | None:
        """Redo the last undone edit; None when none is left."""
        if not self._undone:
            return None
        c = self._undone.pop()
        if self.scene.offsets is None:
            self.scene.offsets = np.zeros_like(self.scene.factors)
        c.put(self.scene, c.after)
        self._done.append(c)
        return c.leaves

    @property
    def history(self) -> list[SceneEdit]:
        """The edits applied in this session, oldest first (undone ones left out)."""
        return [c.edit for c in self._done]

    @property
    def edits(self) -> tuple[SceneEdit, ...]:
        """Every edit of the scene: its file's, then this session's (what :meth:`save` writes)."""
        return tuple(getattr(self.scene.spec, "edits", ())) + tuple(self.history)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the scene file with :attr:`edits` (:func:`leafview.scene.spec.save_scene`, atomic)."""
        spec_module = importlib.import_module("leafview.scene.spec")   # spec imports this module
        spec_module.save_scene(self.scene.spec.replace(edits=self.edits), path)
