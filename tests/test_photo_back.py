"""A back texture from a second photo of the same leaf turned over (:mod:`leafview.fit.photo_back`):
the texel the renderer's back face reads at (u, v) shows the back photo at that place of the leaf,
the mirror puts one side's mark on that side, another leaf's back is refused, and ``leafview fit
FRONT --back BACK`` writes and renders it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from leafview.cli import main
from leafview.core.params import LeafParams
from leafview.core.texture import bilinear, texture_st
from leafview.deform.surface import evaluate
from leafview.errors import ParamError
from leafview.export.images import read_image
from leafview.fit.photo import canonical_frame, fit_image
from leafview.fit.photo_back import BACK_MIN_IOU, back_fit, back_texture
from leafview.fit.photo_texture import flat_top_view, texel_uv
from leafview.fit.synthetic_back import SPOT_RGB, back_colour, synthetic_back
from leafview.fit.synthetic_photos import synthetic_photo, write_photo

SIZE = (500, 500)
TEX = 128


def _point(p: np.ndarray) -> str:
    return f"{p[0]:.3f},{p[1]:.3f}"


@pytest.fixture(scope="module")
def pair():
    front = synthetic_photo(3, size=SIZE, kind="preset", petiole=False)
    fit = fit_image(front.image, base=front.base, apex=front.apex, texture_size=TEX, face="up")  # its frame unmirrored
    return front, fit, synthetic_back(front, 1)


def _leaf_points(fit, u, v):
    """Front leaf frame (x, y) of the fitted flat blade at the parameters (u, v)."""
    return evaluate(flat_top_view(fit.parts[0]), u, v)[:, :2]


def test_the_back_texture_shows_the_back_photo_at_each_place_of_the_leaf(pair):
    front, fit, back = pair
    found = back_fit(fit, back.image)
    assert found.iou > BACK_MIN_IOU + 0.05
    assert found.texture.shape == (TEX, TEX, 4) and found.texture.dtype == np.float32
    # the fit was made with the true landmarks: its leaf frame is the generator's
    assert np.allclose(fit.leaf_from_pixel, canonical_frame(front.base, front.apex))
    uu, vv = np.meshgrid(np.linspace(-0.6, 0.6, 13), np.linspace(0.2, 0.8, 13))
    u, v = uu.ravel(), vv.ravel()
    xy = _leaf_points(fit, u, v)
    s, t = texture_st(u, v)
    texel = bilinear(found.texture, s, t)
    assert texel[:, 3].min() > 0.99                                   # inside the leaf
    # where the generator put each leaf point in the back photo (its own truth, not the fit's map)
    m = np.asarray(back.truth["back_pixel_from_front_leaf"])
    px = xy @ m[:2, :2].T + m[:2, 2]
    photo = bilinear(back.image / 255.0, (px[:, 0] + 0.5) / SIZE[0], (px[:, 1] + 0.5) / SIZE[1])
    r, (sx, sy) = back.truth["spot_radius"], back.truth["spot_leaf"]
    clear = np.abs(np.hypot(xy[:, 0] - sx, xy[:, 1] - sy) - r) > 0.02   # away from the spot's rim
    err = np.abs(texel[:, :3] - photo)[clear]
    assert err.mean() < 0.008 and err.max() < 0.04, (err.mean(), err.max())
    # and the colour the generator gave that place (before its light, blur and noise)
    err = np.abs(texel[:, :3] - back_colour(xy[:, 0], xy[:, 1], back.truth))[clear]
    assert err.mean() < 0.01 and err.max() < 0.04, (err.mean(), err.max())
    assert np.array_equal(back_texture(fit, back.image), found.texture)


def test_the_mark_on_one_side_lands_on_that_side(pair):
    """The spot lies on the front's x > 0 side; turned over it shows on the photo's other side, and
    the mirror brings it back to x > 0 (u < 0) in the texture."""
    _, fit, back = pair
    texture = back_fit(fit, back.image).texture
    dark = (np.abs(texture[..., :3] - SPOT_RGB).max(axis=-1) < 0.06) & (texture[..., 3] > 0.99)
    assert dark.sum() > 20
    rows, cols = np.nonzero(dark)
    u, v = texel_uv(TEX)
    centre = _leaf_points(fit, np.array([u[cols].mean()]), np.array([v[rows].mean()]))[0]
    assert u[cols].max() < 0.0                                         # every spot texel on the u < 0 side
    assert np.hypot(*(centre - back.truth["spot_leaf"])) < 0.3 * back.truth["spot_radius"]


def test_a_back_photo_of_another_leaf_is_refused_naming_it(pair, tmp_path):
    _, fit, _ = pair
    other = synthetic_photo(2, size=SIZE, kind="asymmetric", petiole=False)
    path = write_photo(synthetic_back(other, 1), tmp_path / "other_back.png")
    with pytest.raises(ParamError, match=r"other_back\.png: .*IoU of 0\.[0-8]\d ") as info:
        back_texture(fit, path)
    assert "turned over" in str(info.value)
    with pytest.raises(ParamError, match="^back_photo: "):
        back_texture(fit, read_image(path)[0])


def test_leafview_fit_with_a_back_photo_writes_and_renders_the_back(gl, pair, tmp_path, capsys):
    front, _, back = pair
    photos = tmp_path / "photos"
    front_path, back_path = write_photo(front, photos / "oak.jpg"), write_photo(back, photos / "oak_back.jpg")
    out = tmp_path / "leaves" / "oak.leaf.json"
    marks = ["--base", _point(front.base), "--apex", _point(front.apex), "--texture-size", "64"]
    # another leaf as the back: exit 2 naming the file, nothing written
    other = write_photo(synthetic_back(synthetic_photo(2, size=SIZE, kind="asymmetric", petiole=False), 1),
                        photos / "wrong.jpg")
    assert main(["fit", str(front_path), "--back", str(other), "-o", str(out), *marks]) == 2
    assert "wrong.jpg" in capsys.readouterr().err and not out.parent.exists()
    assert main(["fit", str(front_path), "-o", str(out), "--back-base", "1,1", *marks]) == 2
    assert "--back-base applies with --back" in capsys.readouterr().err
    # with --back, PHOTO is the upper side: --face down contradicts it (exit 2, nothing written)
    assert main(["fit", str(front_path), "--back", str(back_path), "--face", "down", "-o", str(out), *marks]) == 2
    assert "--face down with --back" in capsys.readouterr().err and not out.parent.exists()

    # the back's landmarks given, as the front's are (a blade without a petiole can hide its base)
    back_marks = ["--back-base", _point(back.base), "--back-apex", _point(back.apex)]
    assert main(["fit", str(front_path), "--back", str(back_path), "-o", str(out), *marks, *back_marks]) == 0
    said = capsys.readouterr().out
    assert said.startswith(f"wrote {out} and oak.front.png and oak.back.png: IoU ") and "back photo IoU 0.9" in said
    assert sorted(p.name for p in out.parent.iterdir()) == ["oak.back.png", "oak.front.png", "oak.leaf.json"]
    leaf = LeafParams.load(out)
    assert leaf.texture is not None and (leaf.texture.front, leaf.texture.back) == ("oak.front.png", "oak.back.png")
    front_px, back_px = (read_image(out.parent / f"oak.{w}.png")[0] / 255.0 for w in ("front", "back"))

    def mean(img: np.ndarray) -> np.ndarray:
        return img[..., :3][img[..., 3] > 0.99].mean(axis=0)

    # turned over about its midrib and seen from above: the underside, drawn with the back texture
    turned = leaf.replace(transform=replace(leaf.transform, rotation=(0.0, 180.0, 0.0)))
    under = gl.render(turned, (96, 96), flat=True) / 255.0
    upper = gl.render(leaf, (96, 96), flat=True) / 255.0
    assert (under[..., 3] > 0.99).sum() > 500
    seen_under, seen_upper = mean(under), mean(upper)
    assert np.abs(seen_under - mean(back_px)).max() < 0.05, (seen_under, mean(back_px))
    assert np.abs(seen_upper - mean(front_px)).max() < 0.05, (seen_upper, mean(front_px))
    assert np.abs(mean(back_px) - mean(front_px)).max() > 0.15       # the two sides are told apart
