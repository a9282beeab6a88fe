"""Textured leaves in the parameter files (leafview.core.texture): the paths are relative to the
leaf file, may not leave its folder, and survive the full and the compact form."""

from __future__ import annotations

import json
import os
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from leafview.core import compact
from leafview.core.io import load_leaves, load_params, save_leaves, save_params
from leafview.core.params import LeafParams, ParamError
from leafview.core.texture import LeafTexture, parse_texture, texture_st, uv_of_st
from leafview.scene.schema import SCHEMAS


def _textured(front: str = "ovate.front.png", back: str = "") -> LeafParams:
    return LeafParams(name="ovate", texture=LeafTexture(front, back))


@pytest.mark.parametrize("suffix", [".leaf.json", ".json", ".toml"])
def test_texture_round_trips_and_resolves_beside_the_leaf_file(tmp_path: Path, suffix: str) -> None:
    leaf = _textured(back="sub/ovate.back.jpg")
    path = tmp_path / f"ovate{suffix}"
    save_params(leaf, path)
    back = load_params(path)
    assert back == leaf
    assert back.texture is not None
    front, rear = back.texture.paths()
    assert front == (tmp_path / "ovate.front.png").resolve()
    assert rear == (tmp_path / "sub" / "ovate.back.jpg").resolve()


def test_a_leaf_set_keeps_each_leafs_texture(tmp_path: Path) -> None:
    leaves = [_textured("a.png"), LeafParams(name="plain"), _textured("b.tif")]
    save_leaves(leaves, tmp_path / "set.leaves.json")
    back = load_leaves(tmp_path / "set.leaves.json")
    assert [leaf.texture.front if leaf.texture else None for leaf in back] == ["a.png", None, "b.tif"]
    assert all(leaf.texture is None or leaf.texture.folder == str(tmp_path.resolve()) for leaf in back)


def test_the_folder_is_not_part_of_the_leaf() -> None:
    assert LeafTexture("a.png", folder="/x") == LeafTexture("a.png", folder="/y")
    assert "folder" not in _textured().to_dict()["texture"]


@pytest.mark.parametrize("bad, why", [
    ("/etc/leaf.png", "absolute"), ("../leaf.png", "leaves"), ("a/../../leaf.png", "leaves"),
    ("C:/leaf.png", "drive"), ("a\\leaf.png", "drive"), ("leaf.txt", "image file"), ("", "empty"),
    ("a//leaf.png", "empty segment"), ("./leaf.png", "leaves"), ("leaf\n.png", "control"),
])
def test_unsafe_or_unusable_paths_are_refused_naming_the_field(tmp_path: Path, bad: str, why: str) -> None:
    doc = compact.compact_dict(LeafParams(name="x"))
    doc["texture"] = {"front": "ok.png", "back": bad}
    path = tmp_path / "x.leaf.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(ParamError) as info:
        load_params(path)
    assert info.value.path == "texture.back" and why in info.value.message
    assert str(path) in str(info.value)


def test_a_symbolic_link_out_of_the_folder_is_refused(tmp_path: Path) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "secret.png").write_bytes(b"x")
    folder = tmp_path / "leaves"
    folder.mkdir()
    os.symlink(outside / "secret.png", folder / "link.png")
    save_params(_textured("link.png"), folder / "x.leaf.json")
    with pytest.raises(ParamError) as info:
        load_params(folder / "x.leaf.json")
    assert info.value.path == "texture.front" and "outside" in info.value.message


@pytest.mark.parametrize("doc, field", [
    ({"back": "a.png"}, "texture.front"), ({"front": "a.png", "side": "b.png"}, "texture.side"),
    ({"front": 3}, "texture.front"), ("a.png", "texture"),
])
def test_malformed_texture_tables(doc: object, field: str) -> None:
    with pytest.raises(ParamError) as info:
        parse_texture(doc)
    assert info.value.path == field


def test_the_published_schemas_accept_and_refuse_what_the_parser_does() -> None:
    full = SCHEMAS["leaf.schema.json"]()
    good = _textured(back="b/c.tiff").to_dict()
    jsonschema.validate(good, full)
    for bad in ("../a.png", "/a.png", "a.gif", "a/./b.png"):
        doc = {**good, "texture": {"front": bad}}
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(doc, full)
        with pytest.raises(ParamError):
            LeafParams.from_dict(doc)
    jsonschema.validate(compact.compact_dict(_textured()), SCHEMAS["leaf-compact.schema.json"]())


def test_texture_coordinates_are_an_involution_and_show_the_leaf_from_above() -> None:
    u = np.linspace(-1, 1, 7)
    v = np.linspace(0, 1, 7)
    s, t = texture_st(u, v)
    assert s[0] == 1.0 and s[-1] == 0.0      # u = -1 (leaf x > 0, the right side) on the right
    assert t[0] == 1.0 and t[-1] == 0.0      # base at the bottom row, apex at the top
    uu, vv = uv_of_st(s, t)
    np.testing.assert_allclose(uu, u)
    np.testing.assert_allclose(vv, v)
