"""Synthetic clouds with a known truth: what the tests and ``leafview bench capture`` fit.

No capture can be downloaded here, so the single-leaf benchmark builds its own, as hard as the
issue's case: a built-in preset made curved (a bowed axis, a cupped and creased blade), placed
with a random rotation and translation, sampled uniformly by area
(:func:`leafview.fit.cloud.sample_leaf`), with about 30 % of one side removed as an occluder
would, and Gaussian noise.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from leafview.core.params import LeafParams, Transform
from leafview.fit.cloud import sample_leaf

__all__ = ["OccludedCloud", "without_texture", "placed", "curled", "flattened", "occluded_cloud"]

Arr = NDArray[np.float64]


def without_texture(p: LeafParams) -> LeafParams:
    """``p`` with jitter and ripples off: the 21-number blade of the paper's model."""
    return p.replace(jitter=replace(p.jitter, enabled=False), ripple=replace(p.ripple, enabled=False))


def placed(p: LeafParams, seed: int, length: float) -> LeafParams:
    """``p`` at a random rotation, a translation in [-1, 1]³ and ``length`` (seeded)."""
    rng = np.random.default_rng(seed)
    angles = Rotation.random(random_state=seed).as_euler("xyz", degrees=True)
    return p.replace(transform=Transform(translation=tuple(rng.uniform(-1.0, 1.0, 3)), rotation=tuple(angles),
                                         scale=length))


def curled(p: LeafParams, seed: int, length: float) -> LeafParams:
    """``p`` (no jitter or ripples) with a bowed axis and a cupped, creased blade (z̄s, z̄f and z̄g all
    non-zero), placed by :func:`placed`."""
    p = without_texture(p)
    shape = replace(p.shape, a1=(0.0, 0.33, 0.05), a2=(0.0, 0.67, 0.08), zf=(0.04, 0.06, 0.03),
                    zg=(0.08, 0.1, 0.05), silhouette=tuple((r[0], r[1], 0.12) for r in p.shape.silhouette))
    return placed(p.replace(shape=shape), seed, length)


def flattened(p: LeafParams, seed: int, length: float) -> LeafParams:
    """``p`` (no jitter or ripples) with every out-of-plane number zero, placed by :func:`placed`."""
    p = without_texture(p)
    shape = replace(p.shape, zf=(0.0,) * p.shape.rows, zg=(0.0,) * p.shape.rows,
                    silhouette=tuple((r[0], r[1], 0.0) for r in p.shape.silhouette))
    return placed(p.replace(shape=shape), seed, length)


@dataclass(frozen=True)
class OccludedCloud:
    """A cloud of ``truth`` with part of it hidden: ``cloud`` (visible points plus noise),
    ``visible`` and ``hidden`` (the exact surface points)."""

    truth: LeafParams
    cloud: Arr
    visible: Arr
    hidden: Arr


def occluded_cloud(truth: LeafParams, n: int, *, hide_u: float = 0.4, noise: float = 0.005,
                   seed: int = 0) -> OccludedCloud:
    """``n`` area-uniform samples of ``truth``; those with u > ``hide_u`` (one half's outer part,
    about 30 % of the leaf at 0.4) are hidden; the rest get Gaussian noise of ``noise`` × the leaf
    length per coordinate."""
    points, uv = sample_leaf(truth, n, seed)
    hidden = uv[:, 0] > hide_u
    rng = np.random.default_rng(seed + 10)
    sigma = noise * truth.transform.scale
    cloud = points[~hidden] + rng.normal(0.0, sigma, (int((~hidden).sum()), 3))
    return OccludedCloud(truth, cloud, points[~hidden], points[hidden])
