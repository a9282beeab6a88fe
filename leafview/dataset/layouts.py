"""One dataset image's scene, camera and light, from (seed, index) alone.

:func:`setup_image` draws everything of image ``index`` from ``np.random.default_rng([seed,
index, PART])``, one generator per part (scene, camera, light, split), so that changing a camera
range leaves the leaves as they were, and no image depends on another or on the order in which
workers render them.

Layouts (``M`` leaves, every leaf's Ω varied by ±15 % per component and its colour by ±10 %, as
:class:`leafview.scene.spec.Scene` does; leaves only, no stems, so that the image's leaf set
``leaves/NNNNNN.leaves.json`` reproduces the picture exactly):

``plant``
    One plant (:func:`leafview.scene.plants.scatter`), a random architecture: phyllotaxis,
    height 3-8 leaf lengths, 3-8 branches; one species, drawn uniformly.
``field``
    3-6 shrubs (height 2-4, 2-5 branches) on a jittered grid, a species each.
``tray``
    Loose leaves on a plane, each of a random species: random position in a square whose side
    is chosen for about 1.4 layers of leaf cover (so they overlap like clutter), random yaw, up to
    ±12° of tilt, a third of them upside down, and a random stacking order (each leaf 0.02 leaf
    lengths above the one before it).

Camera: perspective, 40° vertical field of view, aimed at the centre of the leaves' bounding
sphere from (azimuth, elevation) drawn uniformly in the recipe's ranges, at ``distance`` × the
distance at which the sphere just fits the narrower field of view. Elevations above 89.9° are
drawn at 89.9° (a camera looking straight down has no "up" for :func:`look_at`).

Light: the key light comes from a uniform azimuth and an elevation in ``sun_elevation``, with
strength ``light_intensity``; fill and ambient are the renderer's defaults. The RGB background
is a random muted colour.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from leafview.core.compact import dumps_leaves, parse_leaves
from leafview.core.params import LeafParams
from leafview.dataset.recipe import Recipe
from leafview.gpu.frame import Lighting
from leafview.scene.camera import Camera, look_at
from leafview.scene.plants import PHYLLOTAXIS, PlantSpec, scatter
from leafview.scene.spec import VARIED, Scene, SceneSpec

__all__ = ["ImageSetup", "setup_image", "split_of", "FOV_DEG", "PART_SCENE", "PART_CAMERA", "PART_LIGHT",
           "PART_SPLIT"]

FOV_DEG = 40.0
VARIATION = 0.15
COLOUR_VARIATION = 0.1
MAX_ELEVATION = 89.9
TRAY_COVER = 1.4          # leaf area / tray area
LEAF_AREA = 0.3           # about the area of a unit-length blade
PART_SCENE, PART_CAMERA, PART_LIGHT, PART_SPLIT = 1, 2, 3, 4


@dataclass
class ImageSetup:
    """Everything image ``index`` is drawn from.

    ``leaves``: the placed leaves, exactly as ``leaves_text`` (the image's leaf set) reads back;
    ``species_id``: (M,) category index (into the recipe's species) of each leaf;
    ``lighting``: a :class:`~leafview.gpu.frame.Lighting` subclass with this image's key light;
    ``background``: sRGB (r, g, b) behind the leaves.
    """

    index: int
    leaves: list[LeafParams]
    leaves_text: str
    species_id: NDArray[np.int32]
    camera: Camera
    lighting: type[Lighting]
    background: tuple[float, float, float]
    split: str


def _rng(recipe: Recipe, index: int, part: int) -> np.random.Generator:
    return np.random.default_rng([recipe.seed, index, part])


def split_of(recipe: Recipe, index: int) -> str:
    """The split of image ``index``: a uniform draw from (seed, index) against the cumulative
    fractions (the last split takes what rounding leaves)."""
    u = float(_rng(recipe, index, PART_SPLIT).random())
    acc = 0.0
    for name, frac in recipe.split:
        acc += frac
        if u < acc:
            return name
    nonzero = [name for name, frac in recipe.split if frac > 0]
    return nonzero[-1]


def _rotation(axis: str, angle: NDArray[np.float64]) -> NDArray[np.float64]:
    c, s = np.cos(angle), np.sin(angle)
    one, zero = np.ones_like(c), np.zeros_like(c)
    if axis == "x":
        rows = [[one, zero, zero], [zero, c, -s], [zero, s, c]]
    elif axis == "y":
        rows = [[c, zero, s], [zero, one, zero], [-s, zero, c]]
    else:
        rows = [[c, -s, zero], [s, c, zero], [zero, zero, one]]
    return np.moveaxis(np.array(rows), (0, 1), (-2, -1))


def _tray(m: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """Leaf matrices of a cluttered tray of ``m`` loose leaves (see the module docstring)."""
    side = math.sqrt(m * LEAF_AREA / TRAY_COVER)
    size = rng.uniform(0.8, 1.2, m)
    xy = rng.uniform(-side / 2, side / 2, (m, 2))
    yaw = rng.uniform(0.0, 2 * math.pi, m)
    tilt = np.radians(rng.uniform(-12.0, 12.0, (m, 2)))
    flip = rng.random(m) < 1.0 / 3.0
    order = rng.permutation(m)
    rot = (_rotation("z", yaw) @ _rotation("x", tilt[:, 0]) @ _rotation("y", tilt[:, 1] + np.where(flip, np.pi, 0.0)))
    mats = np.zeros((m, 4, 4))
    mats[:, :3, :3] = rot * size[:, None, None]
    centre = np.concatenate([xy, (0.05 + 0.02 * order)[:, None]], axis=1)
    mats[:, :3, 3] = centre - np.einsum("nij,j->ni", mats[:, :3, :3], [0.0, 0.5, 0.0])   # rotate about mid-blade
    mats[:, 3, 3] = 1.0
    return mats


def _scene(recipe: Recipe, rng: np.random.Generator) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """Leaf matrices and species of one image's layout."""
    m, n_species = recipe.leaves, len(recipe.species)
    if recipe.layout == "tray":
        return _tray(m, rng), rng.integers(0, n_species, m).astype(np.int32)
    plant_seed = int(rng.integers(0, 2**62))
    if recipe.layout == "plant":
        spec = PlantSpec(phyllotaxis=str(rng.choice(PHYLLOTAXIS)), height=float(rng.uniform(3.0, 8.0)),
                         branches=int(rng.integers(3, 9)), leaf_jitter=20.0)
        plants = 1
    else:
        spec = PlantSpec(phyllotaxis=str(rng.choice(PHYLLOTAXIS)), height=float(rng.uniform(2.0, 4.0)),
                         branches=int(rng.integers(2, 6)), leaf_jitter=20.0)
        plants = min(m, int(rng.integers(3, 7)))
    placement = scatter(recipe.layout, m, plant_seed, spec, plants=plants, stems=False)
    per_plant = rng.integers(0, n_species, plants).astype(np.int32)
    return np.asarray(placement.matrices, np.float64), per_plant[placement.plant]


def _placed_leaves(recipe: Recipe, matrices: NDArray[np.float64], species_id: NDArray[np.int32],
                   rng: np.random.Generator) -> list[LeafParams]:
    """Every leaf as a stand-alone, placed, varied leaf named after its species."""
    m = len(species_id)
    factors = (1.0 + VARIATION * rng.uniform(-1.0, 1.0, (m, len(VARIED)))).astype(np.float32)
    tint = (1.0 + COLOUR_VARIATION * rng.uniform(-1.0, 1.0, m)).astype(np.float32)
    spec = SceneSpec(species=recipe.species, leaves=m, variation=VARIATION, colour_variation=COLOUR_VARIATION,
                     stems=False)
    scene = Scene(spec, recipe.species, species_id, factors, tint, matrices, None, None)
    return [scene.placed_leaf(i).replace(name=recipe.species[int(species_id[i])].name) for i in range(m)]


def _camera(recipe: Recipe, leaves: list[LeafParams], rng: np.random.Generator) -> Camera:
    """The image's camera: see the module docstring."""
    mats = np.stack([leaf.transform.matrix() for leaf in leaves])
    size = np.linalg.norm(mats[:, :3, 1], axis=1)
    centres = mats[:, :3, 3] + 0.5 * mats[:, :3, 1]          # mid-blade
    radii = 0.65 * size
    lo, hi = (centres - radii[:, None]).min(axis=0), (centres + radii[:, None]).max(axis=0)
    centre = (lo + hi) / 2
    radius = float(np.max(np.linalg.norm(centres - centre, axis=1) + radii))
    az = math.radians(rng.uniform(*recipe.azimuth))
    el = math.radians(min(rng.uniform(*recipe.camera_elevation), MAX_ELEVATION))
    factor = float(rng.uniform(*recipe.distance))
    w, h = recipe.size
    half_v = math.radians(FOV_DEG) / 2
    half_h = math.atan(math.tan(half_v) * w / h)
    dist = factor * radius / math.sin(min(half_v, half_h))
    eye = centre + dist * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    near = max(dist - 1.2 * radius, 1e-3 * dist)
    far = dist + 1.2 * radius
    return look_at(eye, centre, w / h, near, far, fov_deg=FOV_DEG)


def _lighting(recipe: Recipe, rng: np.random.Generator) -> type[Lighting]:
    az = rng.uniform(0.0, 2 * math.pi)
    el = math.radians(rng.uniform(*recipe.sun_elevation))
    strength = float(rng.uniform(*recipe.light_intensity))
    key = (math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el), strength)
    return type("ImageLighting", (Lighting,), {"key": key})


def setup_image(recipe: Recipe, index: int) -> ImageSetup:
    """Scene, camera, light and split of image ``index`` (deterministic in (seed, index))."""
    rng = _rng(recipe, index, PART_SCENE)
    matrices, species_id = _scene(recipe, rng)
    placed = _placed_leaves(recipe, matrices, species_id, rng)
    text = dumps_leaves(placed) + "\n"
    leaves = parse_leaves(json.loads(text))     # what the file holds is what is drawn, bit for bit
    camera = _camera(recipe, leaves, _rng(recipe, index, PART_CAMERA))
    light_rng = _rng(recipe, index, PART_LIGHT)
    lighting = _lighting(recipe, light_rng)
    bg = tuple(float(c) for c in light_rng.uniform(0.12, 0.55, 3))
    return ImageSetup(index, leaves, text, species_id, camera, lighting, (bg[0], bg[1], bg[2]),
                      split_of(recipe, index))
