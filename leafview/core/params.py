"""Leaf parameters: the 21-number shape vector Ω of Chaurasia & Beardsley 2017, sec. 3 plus jitter, material and
world transform, with validation that names the offending field.

Layout of Ω (``to_vector`` / ``from_vector``)::

    [a1(3), a2(3), v̄1, x̄s1, z̄s1, v̄2, x̄s2, z̄s2, v̄3, x̄s3, z̄s3, z̄f1, z̄f2, z̄f3, z̄g1, z̄g2, z̄g3]

The axis A is cubic with fixed base (0,0,0) and apex (0,1,0); S, F and G are quartic and share
base and apex with it (eqs 3-4).

Extended silhouettes. Chaurasia & Beardsley 2017, sec. 3, define S, F and G for any degree n (n - 1 inner control points;
the paper picks n = 4, giving 21 numbers). ``shape.silhouette`` may hold N = 3 ..
:data:`MAX_SILHOUETTE_ROWS` rows, making S, F and G of degree N + 1, with one z̄f and one z̄g
per row. Each row may also be *tilted* (``shape.tilt``, degrees): its control point is displaced
from the foot ``A(v̄_i)`` along the normal turned by φ_i towards the base (φ > 0) or the apex
(φ < 0), so cordate lobes below the base and emarginate shoulders above the apex are reachable
with the feet still on the midrib (see :mod:`leafview.deform.surface`). The default (N = 3, no tilt)
is exactly the paper's model; such a leaf's Ω is the 21 numbers above. An extended leaf's Ω is
``[a1, a2, rows (3N), z̄f (N), z̄g (N), tilt (N)]``, 6 + 6N numbers.

Parameters are immutable: edits return new objects, which makes
undo and comparison trivial.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from leafview.core.bezier import derivative_points, evaluate_curve
from leafview.core.display import png_of
from leafview.core.fieldspec import FieldSpec, check_choice, check_range, number, spec_field
from leafview.core.limits import MAX_SILHOUETTE_ROWS, check_name
from leafview.core.lobes import BranchTurtle, Lobes, lobes_dict, parse_lobes_field
from leafview.core.margin import Margin
from leafview.core.texture import LeafTexture, parse_texture
from leafview.core.venation import VeinEdit, Venation, parse_edits, venation_dict
from leafview.errors import ParamError

__all__ = [
    "SCHEMA_VERSION",
    "OMEGA_SIZE",
    "MAX_SILHOUETTE_ROWS",
    "ParamError",
    "FieldSpec",
    "Shape",
    "Jitter",
    "Material",
    "Transform",
    "Ripple",
    "Bending",
    "Venation",
    "Lobes",
    "BranchTurtle",
    "VeinEdit",
    "LeafParams",
    "field_specs",
    "transform_matrices",
    "omega_sizes",
    "split_omega",
]

SCHEMA_VERSION = 1
OMEGA_SIZE = 21             # Ω of the paper's quartic model (3 silhouette rows, no tilt)
# MAX_SILHOUETTE_ROWS (7, degree up to 8) lives with the other limits in leafview.core.limits

# The physical ranges every accepted value lies in (the hard ranges of the FieldSpecs below, and
# what the JSON Schemas publish). They are chosen so that any accepted leaf evaluates, bends
# (Geng, Hu & Zhang 2014, eq. 4) and renders to finite numbers in float64 and float32:
OMEGA_LIMIT = 10.0          # |Ω control coordinate| in leaf lengths (the leaf itself is 1 long)
TRANSLATION_LIMIT = 1e9     # |translation| in leaf lengths
ROTATION_LIMIT = 720.0      # |rotation| in degrees
SCALE_RANGE = (1e-6, 1e6)   # uniform scale
STIFFNESS_RANGE = (1e-4, 1e4)   # flexural rigidity EI of midrib and petiole
DIRECTION_LIMIT = 1e3       # |load direction component| (only the direction matters)
MIN_DIRECTION = 1e-6        # the load direction's length must be at least this
PHASE_LIMIT = 1e4           # |ripple phase θ|
MIN_AXIS_TANGENT = 1e-6     # |A'(v̄_i)| in the leaf plane, per unit of v, at each silhouette row

Vec3 = tuple[float, float, float]


# FieldSpec (the metadata of one field) and the shared checks live in leafview.core.fieldspec, so
# that groups defined in their own modules (leafview.core.venation) can use them too
_spec = spec_field
_number = number
_check_range = check_range


@dataclass(frozen=True)
class Shape:
    """Ω: the Bézier control data of eqs 3-4 (leaf length normalised to 1 along +y)."""

    a1: Vec3 = _spec("axis a1", "axis", -0.5, 0.5, 0.005, hard=(-OMEGA_LIMIT, OMEGA_LIMIT), kind="vec3", default=(0.0, 1 / 3, 0.0))
    a2: Vec3 = _spec("axis a2", "axis", -0.5, 1.0, 0.005, hard=(-OMEGA_LIMIT, OMEGA_LIMIT), kind="vec3", default=(0.0, 2 / 3, 0.0))
    silhouette: tuple[Vec3, ...] = _spec(
        "silhouette rows (v̄, x̄s, z̄s)", "silhouette", -0.5, 1.0, 0.005, hard=(-OMEGA_LIMIT, OMEGA_LIMIT), kind="rows",
        default=((0.25, 0.35, 0.0), (0.5, 0.4, 0.0), (0.75, 0.25, 0.0)))
    zf: tuple[float, ...] = _spec("z̄f (F at 1/3 width)", "curvature", -0.3, 0.3, 0.002, hard=(-OMEGA_LIMIT, OMEGA_LIMIT), kind="per_row",
                                  default=(0.0, 0.0, 0.0))
    zg: tuple[float, ...] = _spec("z̄g (G at 2/3 width)", "curvature", -0.3, 0.3, 0.002, hard=(-OMEGA_LIMIT, OMEGA_LIMIT), kind="per_row",
                                  default=(0.0, 0.0, 0.0))
    tilt: tuple[float, ...] = _spec("row tilt φ (degrees, + towards the base)", "silhouette", -90.0, 90.0, 0.5,
                                    hard=(-90.0, 90.0), kind="per_row", default=(0.0, 0.0, 0.0))
    half: int = _spec("drawn half (0 both, +1 u ≥ 0, -1 u < 0)", "silhouette", -1, 1, 1, hard=(-1, 1),
                      kind="int", default=0)

    def __post_init__(self) -> None:
        # an untilted shape built with more rows than the default tilt gets one zero per row
        n = len(self.silhouette)
        if len(self.tilt) != n and not any(self.tilt):
            object.__setattr__(self, "tilt", (0.0,) * n)

    @property
    def rows(self) -> int:
        """N, the number of silhouette rows (S, F and G have degree N + 1)."""
        return len(self.silhouette)

    @property
    def extended(self) -> bool:
        """True unless this is the paper's quartic (3 rows, no tilt): such leaves take the
        extended evaluation path on the GPU."""
        return self.rows != 3 or any(float(t) != 0.0 for t in self.tilt)

    @property
    def phi(self) -> NDArray[np.float64]:
        """The row tilts φ_i in radians."""
        return np.radians(np.asarray(self.tilt, dtype=np.float64))

    @property
    def vbar(self) -> NDArray[np.float64]:
        return np.array([r[0] for r in self.silhouette])

    @property
    def xs(self) -> NDArray[np.float64]:
        return np.array([r[1] for r in self.silhouette])

    @property
    def zs(self) -> NDArray[np.float64]:
        return np.array([r[2] for r in self.silhouette])

    def axis_points(self) -> NDArray[np.float64]:
        """The four control points of the cubic axis A: base, a1, a2, apex."""
        return np.array([(0.0, 0.0, 0.0), self.a1, self.a2, (0.0, 1.0, 0.0)], dtype=np.float64)


@dataclass(frozen=True)
class Jitter:
    """Serrated margin (Chaurasia & Beardsley 2017, sec. 6): a periodic table of ``table_size`` values in [0, 1]
    drawn from ``seed``, read at ``v · density``; ``amplitude`` is the largest outward offset in
    leaf lengths (the paper's "degree")."""

    enabled: bool = _spec("jitter on", "jitter", 0, 1, 1, kind="bool", default=False)
    amplitude: float = _spec("degree", "jitter", 0.0, 0.08, 0.001, hard=(0.0, 1.0), default=0.02)
    density: float = _spec("density (teeth per leaf)", "jitter", 1.0, 120.0, 1.0, hard=(1e-3, 4096.0),
                           default=36.0)
    seed: int = _spec("seed", "jitter", 0, 9999, 1, hard=(0, 2**31 - 1), kind="int", default=0)


@dataclass(frozen=True)
class Material:
    """Two-sided leaf material: linear-ish RGB in [0, 1] and a translucency weight in [0, 1]."""

    front: Vec3 = _spec("front colour", "material", 0, 1, 0.01, hard=(0.0, 1.0), kind="color",
                        default=(0.045, 0.15, 0.025))
    back: Vec3 = _spec("back colour", "material", 0, 1, 0.01, hard=(0.0, 1.0), kind="color",
                       default=(0.13, 0.25, 0.06))
    translucency: float = _spec("translucency", "material", 0.0, 1.0, 0.01, hard=(0.0, 1.0),
                                default=0.35)


@dataclass(frozen=True)
class Transform:
    """World placement, kept apart from the shape (Chaurasia & Beardsley 2017, sec. 3, "coordinate frames")."""

    translation: Vec3 = _spec("translation", "transform", -5, 5, 0.01, kind="vec3",
                              hard=(-TRANSLATION_LIMIT, TRANSLATION_LIMIT),
                              default=(0.0, 0.0, 0.0))
    rotation: Vec3 = _spec("rotation XYZ (degrees)", "transform", -180, 180, 1, kind="vec3",
                           hard=(-ROTATION_LIMIT, ROTATION_LIMIT),
                           default=(0.0, 0.0, 0.0))
    scale: float = _spec("scale", "transform", 0.05, 10, 0.01, hard=SCALE_RANGE, default=1.0)

    def matrix(self) -> NDArray[np.float64]:
        """4×4 column-vector matrix ``T · Rz · Ry · Rx · s`` (rotations in degrees)."""
        rx, ry, rz = np.radians(self.rotation)
        cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
        r_x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
        r_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
        r_z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
        m = np.eye(4)
        m[:3, :3] = r_z @ r_y @ r_x * self.scale
        m[:3, 3] = self.translation
        return m

    @classmethod
    def from_matrix(cls, m: ArrayLike, *, tol: float = 1e-6) -> Transform:
        """The transform whose :meth:`matrix` is ``m`` (a rotation times a uniform positive scale,
        then a translation). Angles come back in (-180, 180]; the middle one (about y) in
        [-90, 90]. Raises :class:`ParamError` for shear, non-uniform scale or a mirror."""
        a = np.asarray(m, dtype=np.float64)
        if a.shape != (4, 4) or not np.all(np.isfinite(a)):
            raise ParamError("transform", f"expected a finite 4×4 matrix, got shape {a.shape}")
        lin = a[:3, :3]
        scale = float(np.cbrt(np.linalg.det(lin)))
        if not scale > 0.0:
            raise ParamError("transform", "the matrix mirrors or collapses space (determinant ≤ 0)")
        r = lin / scale
        if np.abs(r.T @ r - np.eye(3)).max() > tol:
            raise ParamError("transform", "the matrix is not a rotation times a uniform scale")
        # r = Rz(c) Ry(b) Rx(a): r[2,0] = -sin b, r[2,1] = cos b sin a, r[1,0] = sin c cos b
        b = math.asin(float(np.clip(-r[2, 0], -1.0, 1.0)))
        if abs(r[2, 0]) < 1.0 - 1e-12:
            a_ = math.atan2(r[2, 1], r[2, 2])
            c = math.atan2(r[1, 0], r[0, 0])
        else:  # gimbal lock: only a - c (or a + c) is defined; put it all in a
            a_ = math.atan2(-r[1, 2], r[1, 1])
            c = 0.0
        angles = (math.degrees(a_), math.degrees(b), math.degrees(c))
        translation = (float(a[0, 3]), float(a[1, 3]), float(a[2, 3]))
        return cls(translation=translation, rotation=angles, scale=scale)


Pair = tuple[float, float]


@dataclass(frozen=True)
class Ripple:
    """Rippled margins (Geng, Hu & Zhang 2014, sec. 5.2.3, eq. 5). Each cross-section is a secondary vein, a
    cantilever from the midrib, under the turbulent load ``P [λ + (1 - λ) N(k i + θ)]`` with
    ``N`` the fBm signal of ``beta`` and ``seed`` and ``i = veins · v``. Pairs are
    ``[left, right]`` as seen in the top view (left: the u >= 0 half, -x)."""

    enabled: bool = _spec("ripples on", "ripple", 0, 1, 1, kind="bool", default=False)
    beta: float = _spec("β (spectral slope)", "ripple", 0.5, 3.0, 0.05, hard=(None, 8.0), positive=True,
                        default=1.0)
    seed: int = _spec("seed", "ripple", 0, 9999, 1, hard=(0, 2**31 - 1), kind="int", default=0)
    veins: float = _spec("secondary veins along the blade", "ripple", 5, 200, 1, hard=(None, 4096.0),
                         positive=True, default=60.0)
    amplitude: Pair = _spec("load amplitude P [left, right]", "ripple", 0.0, 0.1, 0.001, hard=(0.0, 1.0),
                            kind="pair", default=(0.02, 0.02))
    fluctuation: Pair = _spec("λ [left, right]", "ripple", 0.0, 1.0, 0.01, hard=(0.0, 1.0), kind="pair",
                              default=(0.2, 0.2))
    interval: Pair = _spec("sampling interval k [left, right]", "ripple", 0.01, 1.0, 0.01, hard=(0.0, 64.0),
                           kind="pair", default=(0.3, 0.3))
    phase: Pair = _spec("phase θ [left, right]", "ripple", 0.0, 64.0, 0.1, hard=(-PHASE_LIMIT, PHASE_LIMIT),
                        kind="pair", default=(8.0, 10.0))


@dataclass(frozen=True)
class Bending:
    """Cantilever bending of the midrib and petiole (Geng, Hu & Zhang 2014, sec. 4, eq. 4, and sec. 5.2.2) under
    a load along ``direction`` (world space, default gravity), and a twist about the midrib that
    grows linearly to ``twist`` degrees at the apex. ``load`` is per unit blade area; only
    ``load / stiffness`` matters for the shape."""

    load: float = _spec("load", "bending", 0.0, 40.0, 0.1, hard=(0.0, 1e4), default=0.0)
    direction: Vec3 = _spec("load direction (world)", "bending", -1, 1, 0.01, kind="vec3",
                            hard=(-DIRECTION_LIMIT, DIRECTION_LIMIT),
                            default=(0.0, 0.0, -1.0))
    stiffness: float = _spec("midrib EI", "bending", 0.05, 10.0, 0.01, hard=STIFFNESS_RANGE, positive=True,
                         default=1.0)
    twist: float = _spec("twist at the apex (degrees)", "bending", -180, 180, 1, hard=(-720.0, 720.0),
                         default=0.0)
    petiole_length: float = _spec("petiole length", "bending", 0.0, 0.5, 0.005, hard=(0.0, 10.0), default=0.0)
    petiole_stiffness: float = _spec("petiole EI", "bending", 0.05, 10.0, 0.01, hard=STIFFNESS_RANGE,
                                    positive=True, default=1.0)

    @property
    def active(self) -> bool:
        return self.load > 0.0 or self.twist != 0.0 or self.petiole_length > 0.0


@dataclass(frozen=True)
class LeafParams:
    """Everything that describes one leaf. ``shape`` is Ω; the rest are independent groups."""

    shape: Shape = field(default_factory=Shape)
    jitter: Jitter = field(default_factory=Jitter)
    material: Material = field(default_factory=Material)
    transform: Transform = field(default_factory=Transform)
    ripple: Ripple = field(default_factory=Ripple)
    bending: Bending = field(default_factory=Bending)
    venation: Venation = field(default_factory=Venation)   # leafview.core.venation; off by default
    lobes: Lobes = field(default_factory=Lobes)            # leafview.core.lobes; unlobed by default
    name: str = ""
    texture: LeafTexture | None = None   # front/back images addressed by (u, v) (leafview.core.texture)
    margin: Margin | None = None         # a landmark margin in place of Ω's silhouette (leafview.core.margin)

    def __post_init__(self) -> None:
        if self.margin is None:
            return
        if not isinstance(self.margin, Margin):
            raise ParamError("margin", f"expected a Margin, got {type(self.margin).__name__}")
        if self.shape.extended:
            raise ParamError("margin", "a leaf with a landmark margin takes its heights from the paper's three "
                                       "silhouette rows: its shape may not be extended (rows or tilts)")
        if self.lobes.enabled:
            raise ParamError("margin", "a lobed leaf has its own margin: give either [lobes] or margin")

    # -- Ω as a flat vector -------------------------------------------------------------------
    def to_vector(self) -> NDArray[np.float64]:
        """Ω in the paper's order (see the module docstring): shape (21,) for the paper's quartic,
        (6 + 6N,) with the tilts appended for an extended silhouette of N rows."""
        s = self.shape
        rows = [c for row in s.silhouette for c in row]
        tail = list(s.tilt) if s.extended else []
        return np.array([*s.a1, *s.a2, *rows, *s.zf, *s.zg, *tail], dtype=np.float64)

    @classmethod
    def from_vector(cls, omega: ArrayLike) -> LeafParams:
        """Build parameters from Ω: 21 numbers (the paper's quartic) or 6 + 6N numbers (an
        extended silhouette of N rows with tilts, as :meth:`to_vector` writes it); jitter off,
        everything else at its default."""
        w = np.asarray(omega, dtype=np.float64)
        if w.ndim != 1:
            raise ParamError("omega", f"expected a flat list of numbers, got shape {w.shape}")
        shape = _parse_group(Shape, split_omega(w.tolist()), "shape", required=True)
        return cls(shape=shape)

    # -- dicts ----------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (lists, floats, ints, bools), the on-disk form with ``schema``."""
        out: dict[str, Any] = {"schema": SCHEMA_VERSION}
        if self.name:
            out["name"] = self.name
        for group in _GROUPS:
            obj = getattr(self, group)
            if group == "venation":   # written only when set, so older files read and write back unchanged
                if obj != Venation():
                    out[group] = venation_dict(obj, keep_empty_edits=True)
                continue
            if group == "lobes":      # the same: only lobed leaves write a [lobes] table
                if obj.enabled:
                    out[group] = lobes_dict(obj)
                continue
            out[group] = {f.name: _plain(getattr(obj, f.name)) for f in fields(obj)}
        if self.texture is not None:
            out["texture"] = self.texture.to_dict()
        if self.margin is not None:
            out["margin"] = self.margin.to_dict()
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> LeafParams:
        """Validate a nested dict (as read from TOML/JSON); raises :class:`ParamError`."""
        return parse_params(data)

    # -- files ----------------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> LeafParams:
        """Read a ``.toml`` or ``.json`` preset, full or compact (:func:`leafview.core.io.load_params`)."""
        return _file_io().load(path)

    def save(self, path: str | os.PathLike[str], *, digits: int | None = None) -> None:
        """Write a ``.toml``, ``.json`` or compact ``.leaf.json`` preset atomically (``digits``:
        significant digits of the compact form, default exact; :func:`leafview.core.io.save_params`)."""
        _file_io().save(self, path, digits=digits)

    def replace(self, **groups: Any) -> LeafParams:
        return replace(self, **groups)

    def _repr_png_(self) -> bytes | None:
        """A 256×256 PNG thumbnail for Jupyter (:func:`leafview.core.display.png_of`), or None
        where no renderer is registered or OpenGL is unavailable (Jupyter shows the text repr)."""
        return png_of("leaf", self)


class FileIO(Protocol):
    """How leaf files are read and written: :mod:`leafview.core.io` registers the implementation
    when ``leafview.core`` is imported, so that this module need not import the file formats
    (which import it)."""

    def load(self, path: str | os.PathLike[str]) -> LeafParams: ...

    def save(self, params: LeafParams, path: str | os.PathLike[str], *, digits: int | None = None) -> None: ...


_FILE_IO: list[FileIO] = []


def register_file_io(codec: FileIO) -> None:
    """Install the reader and writer behind :meth:`LeafParams.load` and :meth:`LeafParams.save`."""
    _FILE_IO[:] = [codec]


def _file_io() -> FileIO:
    if not _FILE_IO:
        raise RuntimeError("leafview.core.io is not loaded: import leafview (or leafview.core) first")
    return _FILE_IO[0]


def transform_matrices(transforms: Sequence[Transform]) -> NDArray[np.float64]:
    """(N, 4, 4) :meth:`~leafview.core.params.Transform.matrix` of every transform, vectorised:
    ``T · Rz · Ry · Rx · s`` (rotations in degrees, column vectors)."""
    n = len(transforms)
    rot = np.radians(np.array([t.rotation for t in transforms], np.float64).reshape(n, 3))
    c, s = np.cos(rot), np.sin(rot)
    one, zero = np.ones(n), np.zeros(n)
    r_x = np.stack([one, zero, zero, zero, c[:, 0], -s[:, 0], zero, s[:, 0], c[:, 0]], axis=1).reshape(n, 3, 3)
    r_y = np.stack([c[:, 1], zero, s[:, 1], zero, one, zero, -s[:, 1], zero, c[:, 1]], axis=1).reshape(n, 3, 3)
    r_z = np.stack([c[:, 2], -s[:, 2], zero, s[:, 2], c[:, 2], zero, zero, zero, one], axis=1).reshape(n, 3, 3)
    m = np.zeros((n, 4, 4))
    m[:, :3, :3] = r_z @ r_y @ r_x * np.array([t.scale for t in transforms], np.float64)[:, None, None]
    m[:, :3, 3] = np.array([t.translation for t in transforms], np.float64).reshape(n, 3)
    m[:, 3, 3] = 1.0
    return m


def omega_sizes() -> dict[int, int]:
    """Accepted lengths of Ω -> silhouette rows N: 21 (the paper's quartic, N = 3, no tilts) and
    6 + 6N for an extended silhouette of N = 3..MAX_SILHOUETTE_ROWS rows with tilts."""
    return {OMEGA_SIZE: 3, **{6 + 6 * n: n for n in range(3, MAX_SILHOUETTE_ROWS + 1)}}


def split_omega(w: list[float]) -> dict[str, Any]:
    """Ω (see the module docstring) as the fields of a ``shape`` table: ``a1``, ``a2``,
    ``silhouette`` rows, ``zf``, ``zg`` and, for an extended silhouette, ``tilt``. Raises
    :class:`ParamError` ("omega") for a length that is not in :func:`omega_sizes`."""
    sizes = omega_sizes()
    if len(w) not in sizes:
        raise ParamError("omega", f"expected {OMEGA_SIZE} numbers (or 6 + 6N for N = 3..{MAX_SILHOUETTE_ROWS} "
                                  f"silhouette rows with tilts), got {len(w)}")
    n = sizes[len(w)]
    e = 6 + 3 * n
    table: dict[str, Any] = {"a1": w[0:3], "a2": w[3:6], "silhouette": [w[6 + 3 * i:9 + 3 * i] for i in range(n)],
                             "zf": w[e:e + n], "zg": w[e + n:e + 2 * n]}
    if len(w) != OMEGA_SIZE:
        table["tilt"] = w[e + 2 * n:e + 3 * n]
    return table


def field_specs() -> dict[str, FieldSpec]:
    """Metadata of every editable field keyed by dotted path, e.g. ``"jitter.amplitude"``."""
    out: dict[str, FieldSpec] = {}
    for group, cls in _GROUPS.items():
        for f in fields(cls):
            out[f"{group}.{f.name}"] = f.metadata["spec"]
    return out


# ---------------------------------------------------------------------------------------------
# validation
_GROUPS: dict[str, type] = {"shape": Shape, "jitter": Jitter, "material": Material, "transform": Transform,
                             "ripple": Ripple, "bending": Bending, "venation": Venation,
                             "lobes": Lobes}
_TOP_KEYS = {"schema", "name", "texture", "margin", *_GROUPS}


def _plain(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value


def _vector(value: Any, n: int, path: str) -> tuple[float, ...]:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, (list, tuple)):
        raise ParamError(path, f"expected a list of {n} numbers, got {type(value).__name__} {value!r}")
    if len(value) != n:
        raise ParamError(path, f"expected {n} numbers, got {len(value)}")
    return tuple(_number(v, f"{path}[{i}]") for i, v in enumerate(value))


def parse_field(value: Any, spec: FieldSpec, path: str, rows: int = 3) -> Any:
    """``value`` checked against ``spec`` (by its kind: number, int, bool, choice, vectors, rows,
    edits) and normalised; a :class:`ParamError` naming ``path`` otherwise."""
    if spec.kind == "choice":
        return check_choice(value, spec, path)
    if spec.kind == "edits":
        return parse_edits(value, path)
    if spec.kind == "bool":
        if not isinstance(value, bool):
            raise ParamError(path, f"expected true or false, got {type(value).__name__} {value!r}")
        return value
    if spec.kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParamError(path, f"expected an integer, got {type(value).__name__} {value!r}")
        _check_range(float(value), spec, path)
        return int(value)
    if spec.kind in ("vec3", "color", "pair"):
        vec = _vector(value, 2 if spec.kind == "pair" else 3, path)
        for i, x in enumerate(vec):
            _check_range(x, spec, f"{path}[{i}]")
        return vec
    if spec.kind == "rows":
        if isinstance(value, np.ndarray):
            value = value.tolist()
        if not isinstance(value, (list, tuple)) or not 3 <= len(value) <= MAX_SILHOUETTE_ROWS:
            raise ParamError(path, f"expected 3 to {MAX_SILHOUETTE_ROWS} rows [v̄, x̄s, z̄s]")
        rows_out = tuple(_vector(row, 3, f"{path}[{i}]") for i, row in enumerate(value))
        for i, row in enumerate(rows_out):
            for j, x in enumerate(row):
                _check_range(x, spec, f"{path}[{i}][{j}]")
        return rows_out
    if spec.kind == "per_row":
        if isinstance(value, np.ndarray):
            value = value.tolist()
        if not isinstance(value, (list, tuple)) or len(value) != rows:
            got = len(value) if isinstance(value, (list, tuple)) else f"{type(value).__name__} {value!r}"
            raise ParamError(path, f"expected {rows} numbers (one per silhouette row), got {got}")
        vec = _vector(value, rows, path)
        for i, x in enumerate(vec):
            _check_range(x, spec, f"{path}[{i}]")
        return vec
    x = _number(value, path)
    _check_range(x, spec, path)
    return x


def _parse_group(cls: type, data: Any, group: str, *, required: bool) -> Any:
    if not isinstance(data, Mapping):
        raise ParamError(group, f"expected a table of fields, got {type(data).__name__}")
    known = {f.name: f for f in fields(cls)}
    for key in data:
        if key not in known:
            raise ParamError(f"{group}.{key}", f"unknown key (known: {', '.join(known)})")
    values: dict[str, Any] = {}
    rows = 3
    for name, f in known.items():  # silhouette comes before the per-row fields
        path = f"{group}.{name}"
        if name not in data:
            if required and not (cls is Shape and name in _OPTIONAL_SHAPE):  # optional in schema 1 files
                raise ParamError(path, "missing field")
            continue
        spec = f.metadata["spec"]
        if spec.kind in ("outline", "points", "turtle"):   # leafview.core.lobes
            values[name] = parse_lobes_field(name, data[name], path, values.get("outline", ()))
            continue
        values[name] = parse_field(data[name], spec, path, rows)
        if name == "silhouette":
            rows = len(values[name])
    obj = cls(**values)
    if cls is Shape:
        _check_shape(obj)
    if cls is Bending and not math.hypot(*obj.direction) >= MIN_DIRECTION:
        raise ParamError(f"{group}.direction", f"the load direction must not be the zero vector "
                                               f"(length at least {MIN_DIRECTION:g})")
    return obj


_OPTIONAL_SHAPE = ("tilt", "half")   # added to schema 1 later; files without them stay valid


def _check_shape(shape: Shape) -> None:
    v = [float(row[0]) for row in shape.silhouette]
    for i, x in enumerate(v):
        if not 0.0 < x < 1.0:
            raise ParamError(f"shape.silhouette[{i}][0]", f"v̄ = {x!r} must lie strictly inside (0, 1)")
    for name in ("zf", "zg", "tilt"):
        if len(getattr(shape, name)) != len(v):
            raise ParamError(f"shape.{name}", f"expected {len(v)} numbers (one per silhouette row), "
                             f"got {len(getattr(shape, name))}")
    for i in range(1, len(v)):
        if not v[i] > v[i - 1]:
            raise ParamError(f"shape.silhouette[{i}][0]",
                             f"v̄ must be strictly increasing: {v[i - 1]!r} then {v[i]!r}")
    # eq. 2 needs the axis' in-plane direction at each row's foot: where A'(v̄) (nearly) vanishes,
    # the normal n(v̄) is 0/0 and the whole blade NaN (a1 = a0 and v̄ = 5e-324: A' = 3 v̄² ĵ = 0)
    tangents = evaluate_curve(derivative_points(shape.axis_points()), np.asarray(v))[:, :2]
    for i, t in enumerate(tangents):
        if not math.hypot(float(t[0]), float(t[1])) >= MIN_AXIS_TANGENT:
            raise ParamError(f"shape.silhouette[{i}][0]",
                             f"the axis has no in-plane direction at v̄ = {v[i]!r} (|A'(v̄)| below "
                             f"{MIN_AXIS_TANGENT:g}), so the silhouette's normal there is undefined (eq. 2): "
                             "move the row or the axis control points a1, a2")


def parse_params(data: Any) -> LeafParams:
    """Validate a nested dict into :class:`LeafParams` (``schema`` and ``shape`` required)."""
    if not isinstance(data, Mapping):
        raise ParamError("", f"expected a table at the top level, got {type(data).__name__}")
    if not data:
        raise ParamError("", "empty document: expected 'schema' and a [shape] table")
    for key in data:
        if key not in _TOP_KEYS:
            raise ParamError(str(key), f"unknown key (known: {', '.join(sorted(_TOP_KEYS))})")
    if "schema" not in data:
        raise ParamError("schema", f"missing field (this version writes schema = {SCHEMA_VERSION})")
    schema = data["schema"]
    if isinstance(schema, bool) or not isinstance(schema, int):
        raise ParamError("schema", f"expected an integer, got {type(schema).__name__} {schema!r}")
    if schema != SCHEMA_VERSION:
        raise ParamError("schema", f"unsupported schema version {schema} (this leafview reads {SCHEMA_VERSION})")
    name = check_name(data.get("name", ""), "name")
    if "shape" not in data:
        raise ParamError("shape", "missing table")
    groups = {g: _parse_group(cls, data[g], g, required=(g == "shape"))
              for g, cls in _GROUPS.items() if g in data}
    texture = parse_texture(data["texture"]) if "texture" in data else None
    margin = Margin.from_dict(data["margin"]) if "margin" in data else None
    return LeafParams(name=name, texture=texture, margin=margin, **groups)
