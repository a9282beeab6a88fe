"""render_many hands its draws to the rasteriser in groups (FlushTarget): the pixels are those of
one batch drawn at once, bit for bit."""

import numpy as np
import pytest

from leafview.core.params import Jitter
from leafview.gpu import renderer as renderer_module
from tests.conftest import random_params


@pytest.mark.parametrize("view", ["three-quarter", "top", "side"])
def test_groups_draw_the_same_pixels(gl, presets, monkeypatch, view):
    rng = np.random.default_rng(11)
    leaves = list(presets.values())[:4] + [random_params(rng) for _ in range(4)]
    leaves.append(leaves[0].replace(jitter=Jitter(enabled=True, seed=5, amplitude=0.04)))
    assert len(leaves) > renderer_module.FLUSH_EVERY and len(leaves) % renderer_module.FLUSH_EVERY
    monkeypatch.setattr(renderer_module, "FLUSH_EVERY", 10_000)   # one group: no flush
    whole = gl.render_many(leaves, (40, 36), view)
    for every in (renderer_module.BATCH, 1, 3, 4):
        monkeypatch.setattr(renderer_module, "FLUSH_EVERY", every)
        for a, b in zip(whole, gl.render_many(leaves, (40, 36), view)):
            np.testing.assert_array_equal(a, b)
    assert any((img[..., 3] > 0).any() for img in whole)   # something was drawn
