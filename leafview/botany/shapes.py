"""Botanical leaf shapes (Garg & Leow 2011, Table 1 and Fig. 5) as shader-model leaves.

The landmark model (:mod:`leafview.botany.catalogue`) describes a margin; :mod:`leafview.botany.outline_fit`
fits the shader model Ω to it. The fits of the 62 catalogue entries are precomputed into
``assets/shapes/<name>.toml`` (plain leaf presets) with their errors in ``assets/shapes/fits.json``
by ``tools/make_shapes.py`` (about a minute; a test checks the files still match the catalogue).
Random instances (Fig. 8) are fitted when asked for, to within :data:`INSTANCE_TARGET`: about
0.25 s each with the least-squares polish on llvmpipe's machine (2 cores), 0.025 s with the
linear fit only (``polish=False``; then up to about 3.5 % off).

``leafview shapes`` (:mod:`leafview.cli.shapes`) lists and renders them; ``leafview bench shapes``
(:mod:`leafview.bench.shapes`) measures generation and rendering rates.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from difflib import get_close_matches
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from leafview.botany.batch_fit import BatchFit, fit_outlines
from leafview.botany.catalogue import ShapeEntry, landmark_leaf, random_instance
from leafview.botany.catalogue import catalogue as _catalogue
from leafview.botany.landmarks import LandmarkLeaf, margin_params, outline, outlines
from leafview.botany.outline_fit import OutlineFit, fit_outline
from leafview.botany.quick_fit import quick_fit_outlines
from leafview.core.defaults import INSTANCE_FIT_TARGET
from leafview.core.params import LeafParams, ParamError
from leafview.resources import asset_dir

INSTANCE_TARGET = INSTANCE_FIT_TARGET
_HAUSDORFF_SLACK = 5e-4     # half the 1e-3 densification step of outline_fit.hausdorff

__all__ = ["INSTANCE_TARGET", "ShapeEntry", "ShapeFitInfo", "catalogue", "landmark_leaf", "omega_of_margin", "shapes_dir",
           "shape_names", "shapes_params", "fit_info", "fit_landmark_leaf", "fit_instances", "InstanceFit", "instances"]


def catalogue() -> list[ShapeEntry]:
    """The 62 catalogue shapes (Garg & Leow 2011, Table 1 and Fig. 5) as :class:`ShapeEntry` rows:
    ``name``, ``waist``, ``base``, ``apex``, ``unilobed``, ``table1``, ``named`` and the recipe.
    Same list as :func:`leafview.botany.catalogue.catalogue`; :func:`fit_info` gives each one's fit."""
    return _catalogue()


@dataclass(frozen=True)
class ShapeFitInfo:
    """What ``tools/make_shapes.py`` recorded for one catalogue shape."""

    name: str
    waist: str
    base: str
    apex: str
    rows: int
    quartic: bool
    error: float          # Hausdorff ÷ leaf length, both sides
    min_jacobian: float   # > 0: the blade does not fold


def shapes_dir() -> Path:
    """``assets/shapes`` (in the wheel or the source tree)."""

    return asset_dir() / "shapes"


@lru_cache(maxsize=1)
def _index() -> dict[str, ShapeFitInfo]:
    path = shapes_dir() / "fits.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileNotFoundError(f"{path} is missing: run tools/make_shapes.py") from None
    return {d["name"]: ShapeFitInfo(**d) for d in data["shapes"]}


def shape_names() -> list[str]:
    """The catalogue names with a precomputed fit, in catalogue order."""
    return list(_index())


def fit_info(name: str) -> ShapeFitInfo:
    """The recorded fit of catalogue shape ``name``; :class:`ParamError` for unknown names."""
    index = _index()
    if name not in index:

        near = get_close_matches(name, list(index), n=3)
        hint = f" (did you mean {', '.join(near)}?)" if near else " (`leafview shapes` lists them)"
        raise ParamError("shape", f"unknown catalogue shape {name!r}{hint}")
    return index[name]


def fit_landmark_leaf(leaf: LandmarkLeaf, *, polish: bool = True, n: int = 256, **kwargs: Any) -> OutlineFit:
    """Fit Ω to a :class:`~leafview.botany.landmarks.LandmarkLeaf`; returns the
    :class:`~leafview.botany.outline_fit.OutlineFit`."""

    return fit_outline(outline(leaf, n), polish=polish, name=getattr(leaf, "name", "") or "", **kwargs)


def shapes_params(name: str, seed: int | None = None, *, amount: float = 0.2, polish: bool = True) -> LeafParams:
    """The shader-model leaf of catalogue shape ``name``.

    Parameters
    ----------
    name
        A catalogue name (``leafview shapes`` lists them), e.g. ``"cordate"`` or
        ``"ovate-extended-convex"``.
    seed
        None: the precomputed fit of the shape itself. An integer: a random instance of the shape
        (Garg & Leow 2011, Fig. 8, landmark parameters perturbed by up to ``amount``), fitted now.
    polish
        For random instances: run the least-squares polish (slower, closer; see
        :func:`~leafview.botany.outline_fit.fit_outline`).
    """
    fit_info(name)  # clear error for unknown names
    if seed is None:
        return _load(name)

    leaf = random_instance(landmark_leaf(name), int(seed), amount)
    params = fit_landmark_leaf(leaf, polish=polish, target=INSTANCE_TARGET).params
    return params.replace(name=f"{name}#{seed}")


@lru_cache(maxsize=128)
def _load(name: str) -> LeafParams:
    return LeafParams.load(shapes_dir() / f"{name}.toml")


LeafOrName = str | LandmarkLeaf
Seed = int | np.integer[Any]


def instances(names_or_leaves: LeafOrName | list[LeafOrName] | tuple[LeafOrName, ...],
              seeds: Seed | list[Seed] | tuple[Seed, ...] | range, amount: float = 0.2, *,
              target: float = INSTANCE_TARGET, n: int = 128, margin: bool = False) -> list[LeafParams]:
    """Random instances (Garg & Leow 2011, Fig. 8) of catalogue shapes, fitted together (or, with
    ``margin=True``, drawn with their own landmark margins: no fit).

    The batched counterpart of ``shapes_params(name, seed)``: every leaf's landmarks are perturbed
    by up to ``amount`` (:func:`~leafview.botany.catalogue.random_instance`), then all margins are
    fitted at once to within ``target`` by :func:`fit_instances` (the quick batch fit, and the full
    one for the few leaves it misses), well over 100× faster per leaf than ``shapes_params`` with a
    seed.

    Parameters
    ----------
    names_or_leaves
        A catalogue name or :class:`~leafview.botany.landmarks.LandmarkLeaf`, or a sequence of them.
    seeds
        An integer or a sequence of integers; a single name or seed is repeated to match the other.
    amount
        Relative perturbation of the landmark parameters, in [0, 1).
    margin
        Give each leaf its landmark margin as its silhouette (:mod:`leafview.core.margin`, the
        B-spline of eqs 2-6 evaluated in the shader) instead of fitting Ω to it: exact, and
        20-25× faster end to end (``leafview bench shapes``). ``target`` and ``n`` are then unused.

    Returns
    -------
    list of LeafParams
        Named ``"<name>#<seed>"``, in input order.
    """


    many = list(names_or_leaves) if isinstance(names_or_leaves, (list, tuple)) else [names_or_leaves]
    seed_list = list(seeds) if isinstance(seeds, (list, tuple, range)) else [seeds]
    if not many or not seed_list:
        raise ParamError("names_or_leaves" if not many else "seeds", "expected at least one")
    if len(many) == 1:
        many = many * len(seed_list)
    elif len(seed_list) == 1:
        seed_list = seed_list * len(many)
    if len(many) != len(seed_list):
        raise ParamError("seeds", f"expected {len(many)} seeds (one per leaf) or one, got {len(seed_list)}")
    leaves, names = [], []
    for k, (item, seed) in enumerate(zip(many, seed_list)):
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise ParamError(f"seeds[{k}]", f"expected an integer, got {seed!r}")
        if isinstance(item, str):
            fit_info(item)  # clear error for unknown names
            base, label = landmark_leaf(item), item
        elif isinstance(item, LandmarkLeaf):
            base, label = item, item.name or "leaf"
        else:
            raise ParamError(f"names_or_leaves[{k}]", f"expected a catalogue name or a LandmarkLeaf, got {type(item).__name__}")
        leaves.append(random_instance(base, int(seed), amount))
        names.append(f"{label}#{int(seed)}")
    if margin:
        return [p.replace(name=name) for p, name in zip(margin_params(leaves), names)]
    return fit_instances(outlines(leaves, n), target, names).params


def omega_of_margin(params: LeafParams, *, polish: bool = True, n: int = 128) -> OutlineFit:
    """Ω fitted to the landmark margin of ``params`` (:mod:`leafview.core.margin`), for a leaf
    whose silhouette rows are to be edited: the fit's ``params`` is ``params`` with the fitted
    shape and no margin (its material, transform, jitter, ripples and bending kept)."""
    if params.margin is None:
        raise ParamError("margin", "this leaf has no landmark margin to fit")
    v = np.linspace(0.0, 1.0, n)
    right = params.margin.right.evaluate(v)[0][0]
    left = params.margin.left.evaluate(v)[0][0] * np.array([-1.0, 1.0])
    fit = fit_outline(right=right, left=left, polish=polish, name=params.name)
    return replace(fit, params=replace(params, shape=fit.params.shape, margin=None))


@dataclass(frozen=True)
class InstanceFit:
    """What :func:`fit_instances` did: the fitted leaves, the quick pass over all of them (its
    own errors and fold measure, aimed at ``target`` less the Hausdorff slack) and the leaves the
    full batch fit refitted."""

    params: list[LeafParams]
    quick: BatchFit
    refitted: NDArray[np.int64]

    @property
    def refit_share(self) -> float:
        """The share of leaves the quick fit missed (refitted by the full batch fit)."""
        return float(self.refitted.size / max(len(self.params), 1))


def fit_instances(rings: NDArray[np.float64], target: float, names: list[str]) -> InstanceFit:
    """Ω fitted to the closed outlines ``rings`` (B, 2n - 2, 2) to within ``target``: the quick
    batch fit (:func:`~leafview.botany.quick_fit.quick_fit_outlines`) for all, aiming half a
    :func:`~leafview.botany.outline_fit.hausdorff` step below ``target`` (that measure's
    vertex-to-vertex distances may exceed the quick fit's bound by that much), then the full batch
    fit (:func:`~leafview.botany.batch_fit.fit_outlines`, per-leaf fallback included) for the
    leaves it misses, keeping the better of the two."""
    quick = quick_fit_outlines(rings, target=max(target - _HAUSDORFF_SLACK, 0.5 * target), names=names)
    params = list(quick.params)
    missed = np.flatnonzero((quick.errors > target - _HAUSDORFF_SLACK) | (quick.min_jacobian <= 0.0))
    if missed.size:
        full = fit_outlines(rings[missed], target=target, names=[names[i] for i in missed])
        for k, i in enumerate(missed):
            if (full.min_jacobian[k] > 0.0, -full.errors[k]) >= (quick.min_jacobian[i] > 0.0, -quick.errors[i]):
                params[i] = full.params[k]
    return InstanceFit(params, quick, missed.astype(np.int64))

