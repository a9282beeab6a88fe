"""COCO instance labels from an instance-id image, and the COCO documents of a dataset.

Per image (:func:`image_annotations`), every leaf id ``k > 0`` present in the instance image gives
one annotation: its mask ``instance == k`` run-length encoded with pycocotools
(``mask.encode`` on the Fortran-ordered uint8 mask, ``counts`` decoded to ``str``), ``area`` the
number of its pixels, ``bbox`` ``[x, y, width, height]`` of the mask in pixels (integers: the
columns ``x .. x + width - 1`` and rows ``y .. y + height - 1`` hold it), ``iscrowd`` 0,
``instance_id`` ``k`` (the leaf's index in the image's leaf set + 1, the value of its pixels
in ``instances/NNNNNN.png``) and ``visible_fraction``: the mask's pixels over the pixels the leaf
covers in the same image when drawn alone (see :mod:`leafview.dataset.writer` for how that is
measured). Leaves with no visible pixel get no annotation.

Ids are given when the whole dataset is assembled (:func:`coco_document`): image ``id`` =
index + 1, annotation ids 1, 2, ... in (image, instance) order, category ``id`` = species
position + 1, the same ids in the per-split files.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pycocotools import mask as mask_utils

from leafview._version import __version__

__all__ = ["image_annotations", "coco_document", "categories", "encode_mask", "mask_bbox"]


def encode_mask(mask: NDArray[np.bool_]) -> dict[str, Any]:
    """The COCO RLE of a (h, w) boolean mask: ``{"size": [h, w], "counts": str}``."""
    rle = mask_utils.encode(np.asfortranarray(mask.astype(np.uint8)))
    counts = rle["counts"]
    return {"size": [int(rle["size"][0]), int(rle["size"][1])],
            "counts": counts.decode("ascii") if isinstance(counts, bytes) else str(counts)}


def mask_bbox(mask: NDArray[np.bool_]) -> list[int]:
    """``[x, y, width, height]`` of the pixels of ``mask`` (integers; all zero for an empty mask)."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return [0, 0, 0, 0]
    return [int(cols[0]), int(rows[0]), int(cols[-1] - cols[0] + 1), int(rows[-1] - rows[0] + 1)]


def image_annotations(instance: NDArray[np.integer], species_id: NDArray[np.integer],
                      alone: NDArray[np.integer]) -> list[dict[str, Any]]:
    """Annotations (without ``id`` and ``image_id``) of one image: one per leaf id present in
    ``instance`` ((h, w), 0 background), its category from ``species_id`` (per leaf, 0-based) and
    its visible fraction from ``alone`` (per leaf, pixels covered when drawn alone)."""
    ids, areas = np.unique(instance[instance > 0], return_counts=True)
    out = []
    for k, area in zip(ids.tolist(), areas.tolist()):
        mask = instance == k
        leaf = k - 1
        covered = int(alone[leaf])
        out.append({"category_id": int(species_id[leaf]) + 1, "segmentation": encode_mask(mask),
                    "area": int(area), "bbox": mask_bbox(mask), "iscrowd": 0, "instance_id": int(k),
                    "visible_fraction": float(area / covered) if covered else 1.0})
    return out


def categories(names: Sequence[str]) -> list[dict[str, Any]]:
    """One COCO category per species, ids from 1 in the recipe's order."""
    return [{"id": i + 1, "name": name, "supercategory": "leaf"} for i, name in enumerate(names)]


def coco_document(images: Sequence[dict[str, Any]], names: Sequence[str], split: str | None = None
                  ) -> dict[str, Any]:
    """A COCO instances document of ``images`` (records as the shard manifests hold them: ``index``,
    ``file_name``, ``width``, ``height``, ``split``, ``annotations``), only those of ``split`` when
    given. Annotation ids count over every image (so they are the same in every document)."""
    out_images: list[dict[str, Any]] = []
    out_anns: list[dict[str, Any]] = []
    next_id = 1
    for rec in images:
        anns = rec["annotations"]
        if split is None or rec["split"] == split:
            image_id = int(rec["index"]) + 1
            out_images.append({"id": image_id, "file_name": rec["file_name"], "width": rec["width"],
                               "height": rec["height"], "split": rec["split"]})
            out_anns.extend({"id": next_id + j, "image_id": image_id, **a} for j, a in enumerate(anns))
        next_id += len(anns)
    info = {"description": "leafview synthetic leaves" + (f", split {split}" if split else ""),
            "version": __version__, "contributor": "leafview"}
    return {"info": info, "images": out_images, "annotations": out_anns, "categories": categories(names)}
