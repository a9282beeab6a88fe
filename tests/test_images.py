"""Image regression: small reference PNGs in tests/images, compared with a tolerance.

A test fails when more than 0.5 % of the pixels differ by more than 3/255 in any channel
(llvmpipe varies by up to 3/255 between CPU vendors). On failure the actual image and a diff
(differences ×8) go to tests/_failures/. Regenerate with ``pytest --regen-images`` after an
intended change, look at the new images, and commit them.
"""

from pathlib import Path

import numpy as np
import pytest

from leafview.imaging import read_image, write_image

pytestmark = pytest.mark.gl

IMAGES = Path(__file__).parent / "images"
FAILURES = Path(__file__).parent / "_failures"
SIZE = 96
PIXEL_TOL = 3
MAX_BAD_FRACTION = 0.005

CASES = [(name, "top") for name in ("ovate", "lanceolate", "orbicular", "acuminate", "asymmetric", "serrate",
                                    "deltoid")] + [("curled", "three-quarter"), ("serrate", "three-quarter"),
                                                   ("elliptic", "front"), ("holly", "three-quarter"),
                                                   ("maize", "side"), ("willow", "side")]


def compare(actual: np.ndarray, reference: np.ndarray) -> tuple[float, int]:
    """(fraction of pixels off by more than PIXEL_TOL, largest difference)."""
    diff = np.abs(actual.astype(np.int16) - reference.astype(np.int16)).max(axis=-1)
    return float(np.mean(diff > PIXEL_TOL)), int(diff.max())


@pytest.mark.parametrize("name, view", CASES, ids=[f"{n}-{v}" for n, v in CASES])
def test_reference_image(gl, presets, request, name, view):
    actual = gl.render(presets[name], (SIZE, SIZE), view)
    ref_path = IMAGES / f"{name}_{view}.png"
    if request.config.getoption("--regen-images"):
        write_image(ref_path, actual)
    assert ref_path.exists(), f"missing reference {ref_path}: run pytest --regen-images and look at it"
    reference, _ = read_image(ref_path)
    assert reference.shape == actual.shape
    bad, worst = compare(actual, reference)
    if bad > MAX_BAD_FRACTION:
        FAILURES.mkdir(exist_ok=True)
        write_image(FAILURES / f"{name}_{view}_actual.png", actual)
        diff = np.abs(actual.astype(np.int16) - reference.astype(np.int16))
        diff_img = np.clip(diff * 8, 0, 255).astype(np.uint8)
        diff_img[..., 3] = 255
        write_image(FAILURES / f"{name}_{view}_diff.png", diff_img)
    assert bad <= MAX_BAD_FRACTION, (f"{name}/{view}: {bad:.2%} of pixels off by more than {PIXEL_TOL}/255 "
                                     f"(largest {worst}); see {FAILURES}")


def test_compare_detects_a_changed_leaf(gl, presets):
    """The tolerance is tight enough to catch a small shape edit (guards against a vacuous test)."""
    from leafview.model.edits import scale_width

    a = gl.render(presets["ovate"], (SIZE, SIZE), "top")
    b = gl.render(scale_width(presets["ovate"], 1.04), (SIZE, SIZE), "top")
    assert compare(a, b)[0] > MAX_BAD_FRACTION
    assert compare(a, a) == (0.0, 0)
