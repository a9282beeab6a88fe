"""Synthetic leaf datasets with exact labels: pictures, instance ids, depth, normals, (u, v),
COCO annotations, cameras and each image's leaf set; deterministic, resumable, on local worker
processes or Ray actors.

:func:`make_dataset` is the API (``leafview dataset`` is a thin command over it):

1. everything is checked before any work (:class:`~leafview.dataset.recipe.Recipe`: arguments;
   the output folder; an earlier dataset in it made with other arguments; Ray and its address);
2. shards already complete in the folder (their manifest and every file it lists present) are
   skipped; the others are rendered by the engine (:mod:`leafview.dataset.engines`), each image's
   files written by :mod:`leafview.dataset.writer`;
3. the COCO files, split lists and ``dataset.json`` are assembled from the shard manifests and
   committed together, ``dataset.json`` last.

Every byte depends on the recipe alone: image ``i``'s randomness comes from
``np.random.default_rng([seed, i, part])`` (:mod:`leafview.dataset.layouts`), and nothing written
holds a time, a host name, the engine or the number of workers. See ``docs/dataset.md``.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tqdm import tqdm

from leafview._version import __version__
from leafview.atomic import check_folder, outputs, sweep_stale, write_text
from leafview.core.params import LeafParams
from leafview.dataset.engines import ENGINES, DatasetError, EngineResult, ShardFailed, start_engine
from leafview.dataset.labels import coco_document
from leafview.dataset.recipe import DATASET_FORMAT, DEFAULT_RANGES, LAYOUTS, Recipe, load_species
from leafview.dataset.writer import FOLDERS, shard_is_complete, shard_manifest_path
from leafview.errors import UsageError

__all__ = ["make_dataset", "DatasetReport", "Recipe", "DatasetError", "ShardFailed", "LAYOUTS", "ENGINES",
           "MAX_WORKERS"]

MAX_WORKERS = 1024


@dataclass
class DatasetReport:
    """What :func:`make_dataset` did.

    ``images``/``annotations``: totals of the dataset; ``splits``: images per split;
    ``rendered_shards``/``skipped_shards``: shards rendered in this run and shards found complete;
    ``images_rendered``: images rendered in this run; ``retried_shards``: shards given to a worker
    again after one died; ``seconds``: wall time of the whole call.
    """

    out: Path
    images: int
    annotations: int
    splits: dict[str, int]
    shards: int
    rendered_shards: list[int] = field(default_factory=list)
    skipped_shards: list[int] = field(default_factory=list)
    images_rendered: int = 0
    retried_shards: list[int] = field(default_factory=list)
    seconds: float = 0.0
    gl_renderer: str = ""
    engine: str = "local"
    workers: int = 1

    @property
    def images_per_s(self) -> float:
        return self.images_rendered / self.seconds if self.seconds > 0 else 0.0


def _check_engine(engine: str, workers: int, address: str | None, gpus_per_worker: float) -> None:
    if engine not in ENGINES:
        raise UsageError(f"--engine: unknown engine {engine!r} (use {', '.join(ENGINES)})")
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= MAX_WORKERS:
        raise UsageError(f"--workers: must be a whole number in 1..{MAX_WORKERS}, got {workers!r}")
    if engine != "ray" and address is not None:
        raise UsageError("--address goes with --engine ray (the local engine runs on this machine)")
    if engine != "ray" and gpus_per_worker:
        raise UsageError("--gpus-per-worker goes with --engine ray")
    if not (0.0 <= float(gpus_per_worker) <= 64.0):
        raise UsageError(f"--gpus-per-worker: must be in 0..64, got {gpus_per_worker!r}")


def _check_existing(out: Path, recipe: Recipe) -> None:
    """UsageError when ``out`` holds a dataset (or shards of one) made with other arguments."""
    manifest = out / "dataset.json"
    if manifest.is_file():
        try:
            args = json.loads(manifest.read_text(encoding="utf-8")).get("arguments")
        except (OSError, ValueError, AttributeError):
            args = None
        if args != recipe.to_dict():
            raise UsageError(f"{out} holds a dataset made with other arguments ({manifest}); "
                             "choose another folder or remove it")
    shards = out / "shards"
    if shards.is_dir():
        for path in sorted(shards.glob("*.json")):
            try:
                digest = json.loads(path.read_text(encoding="utf-8")).get("recipe")
            except (OSError, ValueError, AttributeError):
                continue          # unreadable: that shard is simply rendered again
            if digest != recipe.digest:
                raise UsageError(f"{out} holds shards of a dataset made with other arguments ({path}); "
                                 "choose another folder or remove it")


def _assemble(out: Path, recipe: Recipe) -> tuple[int, dict[str, int]]:
    """Write the COCO files, split lists and ``dataset.json`` (last) from the shard manifests, all
    in one transaction; returns (annotations, images per split)."""
    records: list[dict[str, Any]] = []
    for shard in range(recipe.shards):
        doc = json.loads(shard_manifest_path(out, shard).read_text(encoding="utf-8"))
        records.extend({k: v for k, v in rec.items() if k != "files"} for rec in doc["images"])
    names = recipe.category_names
    split_names = [name for name, _ in recipe.split]
    per_split = {name: [r for r in records if r["split"] == name] for name in split_names}
    n_ann = sum(len(r["annotations"]) for r in records)
    per_category = {name: 0 for name in names}
    for r in records:
        for a in r["annotations"]:
            per_category[names[a["category_id"] - 1]] += 1

    def dump(doc: dict[str, Any]) -> str:
        return json.dumps(doc, separators=(",", ":"), allow_nan=False) + "\n"

    with outputs():
        write_text(out / "annotations.json", dump(coco_document(records, names)))
        for name in split_names:
            write_text(out / f"annotations_{name}.json", dump(coco_document(records, names, name)))
            stems = [Path(r["file_name"]).stem for r in per_split[name]]
            write_text(out / "splits" / f"{name}.txt", "".join(f"{s}\n" for s in stems) or "\n")
        manifest = {"leafview": __version__, "format": DATASET_FORMAT, "arguments": recipe.to_dict(),
                    "counts": {"images": len(records), "annotations": n_ann,
                               "splits": {k: len(v) for k, v in per_split.items()}, "categories": per_category},
                    "annotations": {"all": "annotations.json",
                                    **{name: f"annotations_{name}.json" for name in split_names}}}
        write_text(out / "dataset.json", json.dumps(manifest, indent=2) + "\n")
    return n_ann, {k: len(v) for k, v in per_split.items()}


def make_dataset(out: str | os.PathLike[str], count: int, *, leaves: int = 100, layout: str = "plant",
                 species: str | Sequence[str] | Sequence[LeafParams] | None = None,
                 size: tuple[int, int] = (640, 480), seed: int = 0,
                 elevation: tuple[float, float] | None = None,
                 azimuth: tuple[float, float] = DEFAULT_RANGES["azimuth"],
                 distance: tuple[float, float] = DEFAULT_RANGES["distance"],
                 sun_elevation: tuple[float, float] = DEFAULT_RANGES["sun_elevation"],
                 light_intensity: tuple[float, float] = DEFAULT_RANGES["light_intensity"],
                 split: dict[str, float] | Sequence[tuple[str, float]] = (("train", 0.8), ("val", 0.2)),
                 shard_size: int = 16, engine: str = "local", workers: int = 1, address: str | None = None,
                 gpus_per_worker: float = 0.0, threads: int | None = None, progress: bool = False,
                 on_image: Callable[[], None] | None = None) -> DatasetReport:
    """Make (or finish) a dataset of ``count`` images in the folder ``out``.

    ``species``: preset names or files (a comma-separated string or a list), or
    :class:`~leafview.core.params.LeafParams` (each named: one COCO category per species);
    default :data:`~leafview.dataset.recipe.DEFAULT_SPECIES`. The other content arguments are
    those of :class:`~leafview.dataset.recipe.Recipe`. ``engine``, ``workers``, ``address``,
    ``gpus_per_worker`` (Ray actors' ``num_gpus``) and ``threads`` (``LP_NUM_THREADS`` per worker;
    default CPUs // workers) decide only how the work is done. ``progress``: a tqdm bar on stderr
    (images/s); ``on_image()`` is called after each image rendered in this run.

    Raises UsageError (bad arguments, an output folder that cannot be one, a folder holding a
    dataset made with other arguments, Ray missing) before anything is written,
    :class:`~leafview.errors.OutputError` for an unwritable folder, :class:`DatasetError` for an
    unreachable Ray cluster or a failed worker (:class:`ShardFailed`: a shard whose worker died
    twice, after the other shards are done).
    """
    t0 = time.perf_counter()
    if species is not None and not isinstance(species, str) and all(isinstance(s, LeafParams) for s in species):
        kinds = tuple(s for s in species if isinstance(s, LeafParams))
        if any(not s.name for s in kinds):
            raise UsageError("species: every LeafParams needs a name (it names the COCO category)")
        species_params = kinds
    else:
        species_params = load_species(None if species is None else
                                      species if isinstance(species, str) else [str(s) for s in species])
    recipe = Recipe(count=count, species=species_params, leaves=leaves, layout=layout, size=size, seed=seed,
                    elevation=elevation, azimuth=azimuth, distance=distance, sun_elevation=sun_elevation,
                    light_intensity=light_intensity,
                    split=tuple(split.items()) if isinstance(split, dict) else tuple(split), shard_size=shard_size)
    _check_engine(engine, workers, address, gpus_per_worker)
    folder = check_folder(Path(out), "-o")
    if folder.is_dir():
        _check_existing(folder, recipe)
    runner = start_engine(engine, folder, recipe, workers, address=address, gpus_per_worker=gpus_per_worker,
                          threads=threads)
    try:
        for name in (*FOLDERS, "shards"):
            if (folder / name).is_dir():
                sweep_stale(folder / name)
        todo = [s for s in range(recipe.shards) if not shard_is_complete(folder, recipe, s)]
        skipped = [s for s in range(recipe.shards) if s not in set(todo)]
        pending = sum(len(recipe.shard_images(s)) for s in todo)
        result = EngineResult()
        bar = _progress_bar(progress, recipe.count, recipe.count - pending)
        try:
            def tick() -> None:
                bar.update(1)
                if on_image is not None:
                    on_image()

            if todo:
                result = runner.run(todo, on_image=tick)
        finally:
            bar.close()
        n_ann, splits = _assemble(folder, recipe)
    finally:
        runner.close()
    return DatasetReport(folder, recipe.count, n_ann, splits, recipe.shards, sorted(result.done), skipped,
                         result.images, result.retried, time.perf_counter() - t0, result.gl_renderer, engine, workers)


def _progress_bar(enabled: bool, total: int, initial: int) -> Any:
    """A tqdm bar in images (its rate is images/s) on stderr, shown when ``enabled`` and stderr is a terminal."""
    return tqdm(total=total, initial=initial, unit="img", desc="dataset", disable=None if enabled else True, leave=False,
                dynamic_ncols=True)
