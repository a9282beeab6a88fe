"""``leafview dataset``: files and formats, COCO masks against the instance images pixel for pixel,
byte-identical output whatever the engine and the number of workers, resuming, a dying worker,
and bad input (exit 2 or 1, one line, nothing written)."""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import io
import json
import os
import shutil
import signal
import sys
import time
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO

from leafview.cli import main
from leafview.core.io import load_leaves
from leafview.dataset import DatasetReport, ShardFailed, engines, make_dataset
from leafview.dataset.engines import CRASH_ENV, RayShardWorker
from leafview.dataset.labels import mask_bbox
from leafview.dataset.layouts import setup_image, split_of
from leafview.dataset.recipe import Recipe, load_species
from leafview.dataset.writer import FOLDERS, disjoint_groups, image_files
from leafview.errors import GLUnavailable
from tests.conftest import require_or_skip

pytestmark = [pytest.mark.gl, pytest.mark.filterwarnings("ignore:__array__ implementation:DeprecationWarning")]

SPECIES = ("ovate", "lanceolate", "serrate")
ARGS = dict(count=4, leaves=8, layout="tray", species=",".join(SPECIES), size=(64, 48), seed=5, shard_size=2,
            split={"train": 0.5, "val": 0.5})


def digests(folder: Path) -> dict[str, str]:
    """SHA-256 of every file under ``folder`` (relative paths)."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def read(path: Path) -> tuple[np.ndarray, str]:
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    try:
        spec = inp.spec()
        return inp.read_image(spec.format), str(spec.format)
    finally:
        inp.close()


def one_line(err: str) -> str:
    lines = [line for line in err.strip().splitlines() if line.strip()]
    assert len(lines) == 1, err
    return lines[0]


@pytest.fixture(scope="module")
def base(tmp_path_factory, _session_renderer) -> tuple[Path, DatasetReport]:
    if isinstance(_session_renderer, str):
        require_or_skip(f"OpenGL 4.5 through EGL is unavailable: {_session_renderer}")
    out = tmp_path_factory.mktemp("dataset") / "ds"
    report = make_dataset(out, workers=1, **ARGS)
    return out, report


def test_files_formats_and_coco_masks_match_the_instance_images(base):
    out, report = base
    assert report.images == 4 and report.images_rendered == 4 and report.rendered_shards == [0, 1]
    assert "llvmpipe" in report.gl_renderer or report.gl_renderer
    for i in range(4):
        for rel in image_files(i).values():
            assert (out / rel).is_file(), rel
    with contextlib.redirect_stdout(io.StringIO()):      # COCO prints its progress
        coco = COCO(str(out / "annotations.json"))
    assert [c["name"] for c in coco.loadCats(coco.getCatIds())] == list(SPECIES)
    assert sorted(coco.getImgIds()) == [1, 2, 3, 4]
    n_checked = 0
    for i in range(4):
        rgb, fmt = read(out / f"images/{i:06d}.png")
        assert rgb.shape == (48, 64, 3) and fmt == "uint8"
        inst, fmt = read(out / f"instances/{i:06d}.png")
        assert inst.shape == (48, 64, 1) and fmt == "uint16"
        inst = inst[..., 0].astype(np.int64)
        depth, fmt = read(out / f"depth/{i:06d}.exr")
        assert depth.shape == (48, 64, 1) and fmt == "float"
        normals, fmt = read(out / f"normals/{i:06d}.exr")
        assert normals.shape == (48, 64, 3) and fmt == "float"
        uv, fmt = read(out / f"uv/{i:06d}.exr")
        assert uv.shape == (48, 64, 2) and fmt == "float"
        # leaves only: every drawn pixel belongs to a leaf, and has a depth and a unit normal
        assert np.array_equal(depth[..., 0] > 0, inst > 0)
        assert np.allclose(np.linalg.norm(normals[inst > 0], axis=1), 1.0, atol=1e-3)
        leaves = load_leaves(out / f"leaves/{i:06d}.leaves.json")
        assert len(leaves) == ARGS["leaves"] and inst.max() <= len(leaves)
        assert {leaf.name for leaf in leaves} <= set(SPECIES)
        cam = json.loads((out / f"cameras/{i:06d}.json").read_text())
        assert (cam["width"], cam["height"]) == (64, 48) and np.asarray(cam["K"]).shape == (3, 3)
        assert np.asarray(cam["world_from_camera"]).shape == (4, 4)
        anns = coco.loadAnns(coco.getAnnIds(imgIds=[i + 1]))
        assert sorted(a["instance_id"] for a in anns) == sorted(set(np.unique(inst)) - {0})
        for a in anns:
            mask = inst == a["instance_id"]
            decoded = mask_utils.decode(a["segmentation"]).astype(bool)    # counts are str
            assert isinstance(a["segmentation"]["counts"], str)
            assert np.array_equal(decoded, mask), f"image {i}, leaf {a['instance_id']}"
            assert a["area"] == int(mask.sum()) == int(mask_utils.area(a["segmentation"]))
            assert a["bbox"] == mask_bbox(mask) == [int(x) for x in mask_utils.toBbox(a["segmentation"])]
            assert 0.0 < a["visible_fraction"] <= 1.0
            assert coco.cats[a["category_id"]]["name"] == leaves[a["instance_id"] - 1].name
            n_checked += 1
    assert n_checked == report.annotations > 0
    # some leaf of the tray is partly hidden: the visible fraction measures something
    assert min(a["visible_fraction"] for a in coco.anns.values()) < 1.0
    # the splits: each image in exactly one, decided by (seed, index)
    recipe = Recipe(count=4, species=load_species(",".join(SPECIES)), leaves=8, layout="tray", size=(64, 48),
                    seed=5, shard_size=2, split=(("train", 0.5), ("val", 0.5)))
    listed = {name: (out / "splits" / f"{name}.txt").read_text().split() for name in ("train", "val")}
    assert sorted(listed["train"] + listed["val"]) == [f"{i:06d}" for i in range(4)]
    for name, stems in listed.items():
        assert all(split_of(recipe, int(s)) == name for s in stems)
        doc = json.loads((out / f"annotations_{name}.json").read_text())
        assert sorted(img["file_name"] for img in doc["images"]) == [f"images/{s}.png" for s in sorted(stems)]
    manifest = json.loads((out / "dataset.json").read_text())
    assert manifest["counts"]["images"] == 4 and manifest["counts"]["annotations"] == report.annotations
    assert manifest["arguments"] == recipe.to_dict()
    text = "".join(p.read_text(errors="replace") for p in out.rglob("*.json"))
    assert os.uname().nodename not in text
    assert setup_image(recipe, 2).leaves == load_leaves(out / "leaves/000002.leaves.json")


def test_an_images_leaf_set_renders_with_leafview_scene(base, tmp_path):
    out, _ = base
    png = tmp_path / "again.png"
    assert main(["scene", str(out / "leaves/000001.leaves.json"), "-o", str(png), "--size", "64x48", "-q"]) == 0
    assert png.is_file()


def test_one_and_two_workers_write_identical_bytes(base, tmp_path):
    out, _ = base
    report = make_dataset(tmp_path / "two", workers=2, **ARGS)
    assert report.images_rendered == 4
    assert digests(tmp_path / "two") == digests(out)


@pytest.mark.slow
def test_ray_engine_writes_identical_bytes(base, tmp_path):
    assert importlib.util.find_spec("ray") is not None, 'Ray is part of the [test] extra: pip install -e ".[test]"'
    out, _ = base
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    report = make_dataset(tmp_path / "ray", engine="ray", workers=2, **ARGS)
    assert report.images_rendered == 4 and report.engine == "ray"
    assert digests(tmp_path / "ray") == digests(out)
    # the local Ray is shut down and its signal handlers are gone again
    assert {sig: signal.getsignal(sig) for sig in handlers} == handlers


def test_resume_renders_only_the_missing_shard(base, tmp_path):
    out, _ = base
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    # a run killed in shard 1: its marker never written, one image file lost, a temporary file left
    (copy / "shards/000001.json").unlink()
    (copy / "dataset.json").unlink()
    (copy / "depth/000003.exr").unlink()
    stale = copy / "images/.000003.lv999999999-abcdef.part.png"
    stale.write_bytes(b"x")
    old = time.time() - 3600
    os.utime(stale, (old, old))
    report = make_dataset(copy, workers=1, **ARGS)
    assert report.rendered_shards == [1] and report.skipped_shards == [0] and report.images_rendered == 2
    assert not stale.exists()
    assert digests(copy) == digests(out)
    # a complete dataset: nothing to render, the same bytes
    again = make_dataset(copy, workers=2, **ARGS)
    assert again.rendered_shards == [] and again.images_rendered == 0
    assert digests(copy) == digests(out)


def test_a_dying_worker_is_retried_once_then_reported(gl, tmp_path, monkeypatch, capsys):
    args = dict(count=4, leaves=3, layout="plant", species="ovate", size=(32, 24), shard_size=2)
    monkeypatch.setenv(CRASH_ENV, "1@1")                 # dies on the first attempt at shard 1 only
    report = make_dataset(tmp_path / "once", **args)
    assert report.retried_shards == [1] and report.rendered_shards == [0, 1]
    assert (tmp_path / "once/dataset.json").is_file()
    monkeypatch.setenv(CRASH_ENV, "0")                   # dies on every attempt at shard 0
    with pytest.raises(ShardFailed, match="shard 0 .*died") as info:
        make_dataset(tmp_path / "twice", **args)
    assert info.value.shards == [0]
    assert (tmp_path / "twice/shards/000001.json").is_file()          # the other shard is done
    assert not (tmp_path / "twice/shards/000000.json").exists()
    assert not (tmp_path / "twice/dataset.json").exists()
    code = main(["dataset", "-o", str(tmp_path / "twice"), "--count", "4", "--leaves", "3", "--species", "ovate",
                 "--size", "32x24", "--shard-size", "2", "-q"])
    assert code == 1
    assert "shard 0 (images 000000-000001)" in one_line(capsys.readouterr().err)


def _ray_present() -> None:
    assert importlib.util.find_spec("ray") is not None, 'Ray is part of the [test] extra: pip install -e ".[test]"'



@pytest.mark.parametrize("extra, code, words", [
    (["--split", "train=0.5,val=0.4"], 2, "sum to 0.9"),
    (["--split", "train=0.8,train=0.2"], 2, "named twice"),
    (["--address", "127.0.0.1:1"], 2, "--address goes with --engine ray"),
    (["--gpus-per-worker", "1"], 2, "goes with --engine ray"),
    (["--elevation", "60,10"], 2, "LO must not exceed HI"),
    (["--distance", "one,two"], 2, "expected LO,HI"),
    (["--species", "ovate,nosuchleaf"], 2, "not a preset file or built-in name"),
    (["--engine", "ray", "--address", "127.0.0.1:1"], 1, "no Ray cluster can be reached"),
])
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, extra, code, words):
    if "--engine" in extra:
        _ray_present()
    out = tmp_path / "ds"
    t0 = time.perf_counter()
    assert main(["dataset", "-o", str(out), "--count", "2", "--size", "32x24", *extra]) == code
    assert time.perf_counter() - t0 < 60
    assert words in one_line(capsys.readouterr().err)
    assert not out.exists()


@pytest.mark.parametrize("target, code, words", [
    ("file.txt/ds", 2, "is a file, not a folder"),
    ("/sys/leafview-dataset", 1, "permission denied"),
])
def test_unwritable_output_folder(tmp_path, monkeypatch, capsys, target, code, words):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "file.txt").write_text("x")
    assert main(["dataset", "-o", target, "--count", "2", "--size", "32x24"]) == code
    assert words in one_line(capsys.readouterr().err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.txt"]


def test_a_folder_made_with_other_arguments_is_refused(base, capsys):
    out, _ = base
    before = digests(out)
    assert main(["dataset", "-o", str(out), "--count", "4", "--leaves", "8", "--layout", "tray", "--species",
                 ",".join(SPECIES), "--size", "64x48", "--seed", "6", "--shard-size", "2",
                 "--split", "train=0.5,val=0.5"]) == 2
    assert "made with other arguments" in one_line(capsys.readouterr().err)
    assert digests(out) == before


def test_missing_ray_names_the_extra(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)        # import ray -> ImportError
    assert main(["dataset", "-o", str(tmp_path / "ds"), "--count", "2", "--engine", "ray"]) == 2
    assert 'pip install "leafview[ray]"' in one_line(capsys.readouterr().err)
    assert not (tmp_path / "ds").exists()


# -- pieces without GL ------------------------------------------------------------------------------
def test_disjoint_groups_never_hold_overlapping_boxes():
    rng = np.random.default_rng(0)
    xy = rng.integers(0, 60, (80, 2))
    boxes = np.concatenate([xy, xy + rng.integers(1, 20, (80, 2))], axis=1)
    boxes[3] = (5, 5, 5, 9)                               # empty: off screen
    groups = disjoint_groups(boxes)
    assert sorted(i for g in groups for i in g) == [i for i in range(80) if i != 3]
    for g in groups:
        for a in g:
            for b in g:
                if a < b:
                    x = boxes[a][0] < boxes[b][2] and boxes[b][0] < boxes[a][2]
                    y = boxes[a][1] < boxes[b][3] and boxes[b][1] < boxes[a][3]
                    assert not (x and y)


def test_randomness_comes_from_seed_and_index_alone():
    species = load_species("ovate,lanceolate")
    a = Recipe(count=50, species=species, leaves=5, layout="field", seed=3)
    b = Recipe(count=7, species=species, leaves=5, layout="field", seed=3, azimuth=(10.0, 20.0), shard_size=3)
    assert setup_image(a, 4).leaves == setup_image(b, 4).leaves              # camera ranges leave the scene alone
    assert setup_image(a, 4).leaves_text != setup_image(a, 5).leaves_text
    splits = [split_of(a, i) for i in range(50)]
    assert splits == [split_of(b, i) for i in range(50)] and set(splits) == {"train", "val"}
    assert FOLDERS == ("images", "instances", "depth", "normals", "uv", "cameras", "leaves")


@pytest.mark.slow
def test_bench_dataset_quick_run_fills_the_table(gl):
    from leafview.bench.dataset import format_table, run

    res = run(quick=True, ctx=gl.ctx)
    assert res["gl_renderer"] == gl.ctx.info["GL_RENDERER"]
    assert res["images_per_s"]["1"] > 0 and res["images_per_s"]["2"] > 0 and res["ratio"] > 0
    assert res["threads"]["1"] >= res["threads"]["2"] >= 1
    assert "ratio 2 ÷ 1 workers" in format_table(res)
    json.dumps(res, allow_nan=False)


def test_a_ray_actor_given_a_gpu_draws_on_that_egl_device(gl, base, tmp_path, monkeypatch):
    """An actor with num_gpus takes the EGL device of the GPU id Ray assigned it (EGL lists every
    GPU of the node whatever CUDA_VISIBLE_DEVICES says). Here Ray is faked: id 0 is llvmpipe's one
    EGL device; id 7 does not exist and is named in the error."""
    class FakeRay:
        ids: list[str] = ["0"]

        def get_gpu_ids(self) -> list[str]:
            return self.ids

    fake = FakeRay()
    monkeypatch.setattr(engines, "import_ray", lambda: fake)
    recipe = Recipe(count=1, species=load_species("ovate"), leaves=2, layout="tray", size=(32, 24))
    try:
        worker = RayShardWorker(str(tmp_path), recipe, None, gpu_device=True)   # its own context, made current
        try:
            assert worker.gl_renderer() == base[1].gl_renderer
        finally:
            worker.renderer.release()
        fake.ids = ["7"]
        with pytest.raises(GLUnavailable, match="EGL device 7"):
            RayShardWorker(str(tmp_path), recipe, None, gpu_device=True)
    finally:
        gl.ctx.__enter__()   # the shared test context current again for the tests that follow
