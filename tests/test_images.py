"""Image regression: small reference PNGs in tests/images, compared with a tolerance.

A test fails when more than 0.5 % of the pixels differ by more than 3/255 in any channel
(llvmpipe varies by up to 3/255 between CPU vendors). On failure the actual image and a diff
(differences ×8) go to tests/_failures/. Regenerate with ``pytest --regen-images`` after an
intended change, look at the new images, and commit them.
"""

import pytest

pytestmark = pytest.mark.gl

from tests.conftest import MAX_BAD_FRACTION, assert_matches_reference, compare  # noqa: E402

SIZE = 96
CASES = [(name, "top") for name in ("ovate", "lanceolate", "orbicular", "acuminate", "asymmetric", "serrate",
                                    "deltoid")] + [("curled", "three-quarter"), ("serrate", "three-quarter"),
                                                   ("elliptic", "front"), ("holly", "three-quarter"),
                                                   ("maize", "side"), ("willow", "side")]


@pytest.mark.parametrize("name, view", CASES, ids=[f"{n}-{v}" for n, v in CASES])
def test_reference_image(gl, presets, request, name, view):
    assert_matches_reference(gl.render(presets[name], (SIZE, SIZE), view), f"{name}_{view}", request)


def test_compare_detects_a_changed_leaf(gl, presets):
    """The tolerance is tight enough to catch a small shape edit (guards against a vacuous test)."""
    from leafview.core.edits import scale_width

    a = gl.render(presets["ovate"], (SIZE, SIZE), "top")
    b = gl.render(scale_width(presets["ovate"], 1.04), (SIZE, SIZE), "top")
    assert compare(a, b)[0] > MAX_BAD_FRACTION
    assert compare(a, a) == (0.0, 0)
