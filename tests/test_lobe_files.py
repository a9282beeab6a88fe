"""Compound lobed-leaf files (Garg & Leow 2011, eqs 7-9) load wherever leaf files do: the reader
leafview.botany.lobe_outline registers with leafview.core.io."""

from __future__ import annotations

import numpy as np
import pytest

from leafview.botany.lobe_outline import compound_document
from leafview.core.io import load_leaves, load_params, read_document
from leafview.core.params import LeafParams, ParamError
from leafview.resources import asset_dir, builtin_presets

COMPOUND = asset_dir() / "compound"


def test_a_compound_file_loads_as_its_lobed_leaf():
    leaf = load_params(COMPOUND / "maple.toml")
    preset = LeafParams.load(builtin_presets()["maple"])
    assert leaf.lobes.enabled and leaf.name == "maple"
    np.testing.assert_allclose(np.asarray(leaf.lobes.outline), np.asarray(preset.lobes.outline), atol=1e-9)
    assert load_leaves(COMPOUND / "oak.toml")[0].lobes.enabled
    assert compound_document(read_document(builtin_presets()["ovate"])) is None   # other files pass through


def test_a_bad_compound_file_names_the_field_and_the_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text((COMPOUND / "maple.toml").read_text().replace("half = 2", "half = 2\nwings = 3"))
    with pytest.raises(ParamError, match=r"wings.*|bad\.toml") as exc:
        load_params(bad)
    assert "bad.toml" in str(exc.value) and "wings" in str(exc.value)
