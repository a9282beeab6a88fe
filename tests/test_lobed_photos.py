"""Photos of lobed leaves fitted as lobed leaves (issue 21): detection, the closed margin against
the true outline, the texture addressed by the flat position, the CLI's ``--lobed``."""

from __future__ import annotations

import numpy as np
import pytest

from leafview.botany.lobe_sweep import sweep_table
from leafview.cli import main
from leafview.core.bspline import sample_closed
from leafview.core.params import LeafParams
from leafview.core.texture import texture_st
from leafview.deform.sweep import flat_of_uv
from leafview.errors import ParamError
from leafview.export.images import read_image
from leafview.fit.photo import fit_image, polygon_mask, top_view_iou
from leafview.fit.photo_lobed import LOBED_SOLIDITY, fit_lobed_margin, lobe_measures, looks_lobed
from leafview.fit.photo_outline import as_photo, leaf_outline
from leafview.fit.synthetic_photos import SyntheticPhoto, synthetic_photo, write_photo

SIZE = (600, 600)
# the unilobed photos of tests/test_photo_fit.py and tests/test_fit_photo_cli.py
UNILOBED = [(3, "preset", True), (2, "asymmetric", False), (5, "serrated", False), (3, "preset", False),
            (2, "landmark", False)]


@pytest.fixture(scope="module")
def maple() -> SyntheticPhoto:
    return synthetic_photo(906, size=SIZE, lobed_preset="maple")


@pytest.fixture(scope="module")
def maple_fit(maple):
    return fit_image(maple.image, dpi=maple.dpi, texture_size=128)


def _truth_iou(fit, sp: SyntheticPhoto) -> float:
    return top_view_iou(fit.margin_pixels(), polygon_mask(sp.outline, sp.blade.shape))


def test_a_maple_photo_fits_a_lobed_leaf_close_to_the_truth(maple, maple_fit):
    fit = maple_fit
    assert fit.report["lobed"] and len(fit.parts) == 1
    leaf = fit.parts[0]
    assert leaf.lobes.enabled and len(leaf.lobes.outline) == fit.report["controls"]
    assert LeafParams.from_dict(leaf.to_dict()).lobes.outline == leaf.lobes.outline      # a valid leaf file
    assert _truth_iou(fit, maple) >= 0.95
    for found, true in ((fit.outline.base, maple.base), (fit.outline.apex, maple.apex)):
        assert np.hypot(*(found - true)) <= 0.03 * maple.length_px
    c = np.asarray(leaf.lobes.outline)
    assert np.hypot(*sample_closed(c, 4 * len(c))[0]) < 0.02          # C(0) at the base
    assert fit.report["hausdorff_pct"] <= 1.5
    assert leaf.transform.scale == pytest.approx(
        maple.length_px / maple.dpi * 0.0254, rel=0.05)


def test_the_lobed_texture_shows_the_photo_at_the_flat_position(maple_fit):
    fit = maple_fit
    tex = fit.texture
    inside = tex[..., 3] > 0.999
    assert 0.2 < inside.mean() < 0.9
    # texel (i, j) holds the photo's colour at the leaf point (x, y) = uv_of_st of its centre
    rng = np.random.default_rng(0)
    rows, cols = np.nonzero(inside)
    pick = rng.choice(len(rows), 40, replace=False)
    size = tex.shape[0]
    u = 1.0 - 2.0 * (cols[pick] + 0.5) / size
    v = 1.0 - (rows[pick] + 0.5) / size
    s, t = texture_st(u, v)
    assert np.allclose(s * size - 0.5, cols[pick]) and np.allclose(t * size - 0.5, rows[pick])
    # (u, v) is the flat position in the sweep's texture window
    x, y = flat_of_uv(u, v, sweep_table(fit.parts[0].lobes).window)
    px = np.stack([x, y, np.ones_like(x)], 1) @ fit.pixel_from_leaf.T
    photo = fit.photo.rgb[np.rint(px[:, 1]).astype(int), np.rint(px[:, 0]).astype(int)]
    assert np.median(np.abs(tex[rows[pick], cols[pick], :3] - photo)) < 0.05


@pytest.mark.parametrize("seed,kind,petiole", UNILOBED)
def test_unilobed_photos_are_not_taken_for_lobed(seed, kind, petiole):
    sp = synthetic_photo(seed, size=SIZE, kind=kind, petiole=petiole)
    m = lobe_measures(leaf_outline(as_photo(sp.image)).outline)
    assert not looks_lobed(m) and m.solidity > LOBED_SOLIDITY


def test_auto_keeps_a_unilobed_photo_unilobed_and_on_forces_a_valid_lobed_leaf():
    sp = synthetic_photo(3, size=SIZE, kind="preset", petiole=True)
    auto = fit_image(sp.image, dpi=sp.dpi, texture_size=64)
    assert not auto.report["lobed"] and not auto.parts[0].lobes.enabled and auto.report["rows"]
    on = fit_image(sp.image, dpi=sp.dpi, texture_size=64, lobed="on")
    leaf = on.parts[0]
    assert on.report["lobed"] and leaf.lobes.enabled
    assert LeafParams.from_dict(leaf.to_dict()).lobes.enabled
    assert on.report["iou"] >= 0.97 and _truth_iou(on, sp) >= 0.95


def test_off_gives_the_unilobed_fit_of_a_maple(maple, maple_fit):
    off = fit_image(maple.image, dpi=maple.dpi, texture_size=64, lobed="off")
    assert not off.report["lobed"] and not off.parts[0].lobes.enabled and off.report["rows"]
    assert _truth_iou(off, maple) < _truth_iou(maple_fit, maple) - 0.05     # Ω cannot follow the lobes


def test_bad_lobed_values_are_refused(maple):
    with pytest.raises(ParamError, match="lobed"):
        fit_image(maple.image, lobed="maybe")


def test_the_margin_fit_grows_until_within_the_target():
    theta = np.linspace(0.0, 2.0 * np.pi, 800, endpoint=False)
    r = 0.5 + 0.25 * np.cos(5 * theta)                   # five lobes
    ring = np.stack([r * np.cos(theta), 0.5 + r * np.sin(theta)], 1)
    coarse = fit_lobed_margin(ring, 0.05, start=8)
    fine = fit_lobed_margin(ring, 0.002, start=8)
    assert coarse.hausdorff <= 0.05 and fine.hausdorff <= 0.002
    assert len(fine.outline) > len(coarse.outline)
    assert len(fine.valleys) == 5


def test_the_cli_writes_a_lobed_leaf_and_its_texture(maple, tmp_path, capsys):
    path = write_photo(maple, tmp_path / "maple.jpg")
    out = tmp_path / "out" / "maple.leaf.json"
    assert main(["fit", str(path), "-o", str(out), "--texture-size", "64", "--lobed", "auto"]) == 0
    assert "lobed margin" in capsys.readouterr().out
    assert sorted(p.name for p in out.parent.iterdir()) == ["maple.front.png", "maple.leaf.json"]
    leaf = LeafParams.load(out)
    assert leaf.lobes.enabled and leaf.texture is not None and leaf.texture.front == "maple.front.png"
    pixels, _ = read_image(out.parent / "maple.front.png")
    assert pixels.shape == (64, 64, 4) and (pixels[..., 3] == 255).any() and (pixels[..., 3] == 0).any()


def test_the_cli_refuses_a_bad_lobed_value(maple, tmp_path, capsys):
    path = write_photo(maple, tmp_path / "maple.jpg")
    out = tmp_path / "bad.leaf.json"
    with pytest.raises(SystemExit) as exc:
        main(["fit", str(path), "-o", str(out), "--lobed", "sometimes"])
    assert exc.value.code == 2 and not out.exists()
