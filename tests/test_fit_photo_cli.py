"""``leafview fit PHOTO`` and ``leafview fit DIR`` end to end: the leaf and its texture written
together and loading back, a folder's report and contact sheet, refusals that write nothing."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from leafview.bench import fit_photo
from leafview.cli import main
from leafview.cli.bench import SUITES
from leafview.core.io import load_leaves, save_leaves
from leafview.core.params import LeafParams
from leafview.export.images import read_image, write_image
from leafview.fit.photo_batch import fit_photos
from leafview.fit.synthetic_photos import SyntheticPhoto, synthetic_photo, write_photo

SIZE = (600, 600)


@pytest.fixture(scope="module")
def photos(tmp_path_factory) -> dict[str, tuple[Path, SyntheticPhoto]]:
    folder = tmp_path_factory.mktemp("photos")
    out = {}
    for name, seed, kind in (("oak", 3, "preset"), ("odd", 2, "asymmetric")):
        sp = synthetic_photo(seed, size=SIZE, kind=kind, petiole=False)
        out[name] = (write_photo(sp, folder / f"{name}.jpg"), sp)
    return out


def _point(p: np.ndarray) -> str:
    return f"{p[0]:.3f},{p[1]:.3f}"


def test_a_photo_becomes_a_leaf_with_its_texture_beside_it(photos, tmp_path, capsys):
    path, sp = photos["oak"]
    out = tmp_path / "leaves" / "oak.leaf.json"
    code = main(["fit", str(path), "-o", str(out), "--base", _point(sp.base), "--apex", _point(sp.apex),
                 "--texture-size", "128"])
    assert code == 0
    assert capsys.readouterr().out.startswith(f"wrote {out} and oak.front.png: IoU ")
    assert sorted(p.name for p in out.parent.iterdir()) == ["oak.front.png", "oak.leaf.json"]
    leaf = LeafParams.load(out)
    assert leaf.name == "oak" and leaf.texture is not None and leaf.texture.front == "oak.front.png"
    assert leaf.texture.resolve() == (out.parent / "oak.front.png").resolve()
    assert leaf.transform.scale == pytest.approx(sp.length_px / sp.dpi * 0.0254, rel=1e-6)
    pixels, _ = read_image(out.parent / "oak.front.png")
    assert pixels.shape == (128, 128, 4) and pixels.dtype == np.uint8
    alpha = pixels[..., 3]
    assert (alpha == 255).mean() > 0.5 and (alpha == 0).any()     # the leaf, and margins cut out by the mask


def test_an_asymmetric_leaf_keeps_both_halves_only_in_a_leaf_set(photos, tmp_path, capsys):
    path, sp = photos["odd"]
    marks = ["--base", _point(sp.base), "--apex", _point(sp.apex), "--texture-size", "64"]
    assert main(["fit", str(path), "-o", str(tmp_path / "odd.leaf.json"), *marks]) == 0
    err = capsys.readouterr().err
    assert "odd.leaves.json keeps both" in err and "sides differ" in err
    assert LeafParams.load(tmp_path / "odd.leaf.json").shape.half == 0
    assert main(["fit", str(path), "-o", str(tmp_path / "odd.leaves.json"), *marks, "-q"]) == 0
    assert capsys.readouterr().out == ""
    halves = load_leaves(tmp_path / "odd.leaves.json")
    assert [h.shape.half for h in halves] == [-1, 1]
    assert all(h.texture is not None and h.texture.front == "odd.front.png" for h in halves)


def test_options_that_do_not_apply_are_refused(photos, tmp_path, capsys):
    path, _ = photos["oak"]
    np.save(tmp_path / "cloud.npy", np.random.default_rng(0).random((50, 3)))
    for argv, flag in (([str(path), "--scanlines", "8"], "--scanlines"),
                       ([str(tmp_path / "cloud.npy"), "--dpi", "300"], "--dpi"),
                       ([str(path.parent), "--base", "1,2"], "--base"),
                       ([str(path), "--keep-unexplained"], "--keep-unexplained"),
                       ([str(path), "--jobs", "2"], "--jobs")):
        assert main(["fit", *argv, "-o", str(tmp_path / "x" / "a.leaf.json")]) == 2
        assert flag in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


@pytest.fixture(scope="module")
def bad_photos(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("bad")
    paths = {"empty": write_photo(synthetic_photo(1, size=SIZE, empty=True), folder / "empty.jpg"),
             "touching": write_photo(synthetic_photo(3, size=SIZE, touching=True), folder / "touching.jpg"),
             "tiny": write_image(folder / "tiny.png", np.full((8, 8, 4), 200, np.uint8))}
    whole = write_photo(synthetic_photo(3, size=(300, 300), kind="preset"), folder / "whole.jpg").read_bytes()
    (folder / "truncated.jpg").write_bytes(whole[: len(whole) // 3])
    paths["truncated"] = folder / "truncated.jpg"
    return paths


@pytest.mark.parametrize("which", ["empty", "touching", "tiny", "truncated"])
def test_bad_photos_exit_2_naming_the_file_and_write_nothing(bad_photos, tmp_path, capsys, which):
    path = bad_photos[which]
    out = tmp_path / "out"
    assert main(["fit", str(path), "-o", str(out / "leaf.leaf.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("leafview fit: error: ") and str(path) in err, err
    assert not out.exists()


def test_a_folder_of_photos_writes_leaves_a_report_and_a_contact_sheet(photos, tmp_path, capsys):
    folder = tmp_path / "in"
    folder.mkdir()
    for path, _ in photos.values():
        (folder / path.name).write_bytes(path.read_bytes())
    whole = photos["oak"][0].read_bytes()
    (folder / "broken.jpg").write_bytes(whole[: len(whole) // 3])
    (folder / "notes.txt").write_text("not a photo")
    out = tmp_path / "out"
    assert main(["fit", str(folder), "-o", str(out), "--texture-size", "64"]) == 1     # one photo failed
    captured = capsys.readouterr()
    assert "fitted 2 of 3 photos" in captured.out and "broken.jpg" in captured.err
    report = json.loads((out / "report.json").read_text())
    assert report["photos"] == 3 and report["fitted"] == 2 and report["failed"] == 1
    entries = {e["photo"]: e for e in report["leaves"]}
    assert set(entries) == {"broken.jpg", "oak.jpg", "odd.jpg"}
    assert "broken.jpg" in entries["broken.jpg"]["error"]
    for name in ("oak", "odd"):
        e = entries[f"{name}.jpg"]
        assert 0.5 < e["iou"] <= 1.0 and e["hausdorff_pct"] > 0.0
        assert [len(r) for r in e["row_residuals"]] == e["rows"]
        leaves = load_leaves(out / e["leaf"])
        assert len(leaves) == (2 if e["asymmetric"] else 1) and e["leaf"].startswith(name)
        assert all(leaf.texture is not None and leaf.texture.resolve() == (out / e["texture"]).resolve()
                   for leaf in leaves)
    sheet, _ = read_image(out / "contact.png")
    assert sheet.shape[1] <= 2048 and sheet.shape[1] % 3 == 0
    assert sheet.shape[0] > 224                                   # two photos' rows of photo | overlay | render


def test_an_empty_folder_is_refused(tmp_path, capsys):
    (tmp_path / "in").mkdir()
    assert main(["fit", str(tmp_path / "in"), "-o", str(tmp_path / "out")]) == 2
    assert "no photos" in capsys.readouterr().err and not (tmp_path / "out").exists()


def test_the_fit_bench_fills_its_table(gl):
    """``leafview bench fit --quick`` measures against the truth and prints the goals beside it."""
    assert SUITES["fit"] == "leafview.bench.fit_photo"
    res = fit_photo.run(quick=True, ctx=gl.ctx)
    assert res["photos"] == len(res["rows"]) == fit_photo.QUICK_PHOTOS and res["gl_renderer"]
    ok = [r for r in res["rows"] if "error" not in r]
    assert ok and all(0.5 < r["iou"] <= 1.0 for r in ok) and res["iou_worst"] <= res["iou_median"]
    assert res["photos_per_s"] > 0.0 and set(res["stage_ms"]) == {"read", "outline", "fit", "texture", "veins", "measures"}
    assert res["photos_per_s_pooled"] > 0.0 and res["pooled_failed"] == res["failed"] and "processes" in fit_photo.format_table(res)
    json.dumps(res, allow_nan=False)
    table = fit_photo.format_table(res)
    assert "goal ≥ 0.97" in table and "photos per second" in table


def test_worker_processes_give_the_fits_of_one_process_in_order(tmp_path):
    """fit_photos with 2 workers: the same leaves and error lines as in this process, in order."""
    paths = [write_photo(synthetic_photo(seed, size=(320, 320)), tmp_path / f"p{seed}.jpg") for seed in (11, 12)]
    whole = paths[0].read_bytes()
    (tmp_path / "cut.jpg").write_bytes(whole[: len(whole) // 3])
    paths.insert(1, tmp_path / "cut.jpg")
    names = ["a", "b", "c"]
    alone = list(fit_photos(paths, names, jobs=1, texture_size=32))
    pooled = list(fit_photos(paths, names, jobs=2, texture_size=32))
    assert isinstance(alone[1], str) and alone[1] == pooled[1] and "cut.jpg" in alone[1]
    for a, b in ((alone[0], pooled[0]), (alone[2], pooled[2])):
        assert not isinstance(a, str) and not isinstance(b, str)
        assert a.parts == b.parts and np.array_equal(a.texture, b.texture)


def test_the_two_halves_render_as_one_leaf(gl, photos, tmp_path, capsys):
    """``leafview render NAME.leaves.json -o NAME.png``: the halves of an asymmetric leaf (a pair
    alone) come out as one picture, textured, each half on its side of the midrib."""
    path, sp = photos["odd"]
    marks = ["--base", _point(sp.base), "--apex", _point(sp.apex), "--texture-size", "64"]
    assert main(["fit", str(path), "-o", str(tmp_path / "odd.leaves.json"), *marks, "-q"]) == 0
    assert main(["render", str(tmp_path / "odd.leaves.json"), "-o", str(tmp_path / "odd.png"), "--size", "96"]) == 0
    assert "2 leaves together" in capsys.readouterr().out
    alpha = read_image(tmp_path / "odd.png")[0][..., 3] > 127
    cols = np.flatnonzero(alpha.any(axis=0))
    middle = (cols.min() + cols.max()) / 2
    assert alpha.sum() > 800 and alpha[:, : int(middle) - 5].any() and alpha[:, int(middle) + 5:].any()
    # a set of unrelated leaves still needs a folder, a sheet or --together
    halves = load_leaves(tmp_path / "odd.leaves.json")
    save_leaves([h.replace(shape=replace(h.shape, half=0)) for h in halves], tmp_path / "two.leaves.json")
    assert main(["render", str(tmp_path / "two.leaves.json"), "-o", str(tmp_path / "two.png")]) == 2
    assert "--together" in capsys.readouterr().err
    assert main(["render", str(tmp_path / "two.leaves.json"), "-o", str(tmp_path / "two.png"), "--together",
                 "-q"]) == 0 and (tmp_path / "two.png").exists()
    assert main(["render", str(tmp_path / "two.leaves.json"), "-o", str(tmp_path / "two.exr"), "--together"]) == 2
