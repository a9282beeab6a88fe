"""The glTF extensions leafview writes, checked independently of the writer and of the Khronos
validator (which skips them): official JSON schemas plus the extension specifications' rules
(support.gltf_extensions), on real exports and on targeted breakages; and the instance TRS
of an EXT_mesh_gpu_instancing scene recomposed with our own quaternion formula."""

from __future__ import annotations

import copy
import json
import math
import struct
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from support.gltf_extensions import (
    CHECKED_EXTENSIONS,
    SCHEMA_DIR,
    check_extensions,
    check_file,
    read_container,
)
from test_export import gltf_validate
from test_export_scene import StandInScene

from leafview.core.params import LeafParams, Transform
from leafview.export import export_leaf, export_scene

GRID = (5, 9)
LENGTH = 0.1
INST = "EXT_mesh_gpu_instancing"
DIFF = "KHR_materials_diffuse_transmission"


SmallScene = StandInScene      # the duck-typed scene interface, filled by hand


@pytest.fixture(scope="module")
def scene(presets_module) -> SmallScene:
    """20 ovate copies (one mirrored) for EXT_mesh_gpu_instancing, 3 maize copies as plain nodes."""
    rng = np.random.default_rng(11)
    species = [presets_module[n].replace(transform=Transform()) for n in ("ovate", "maize")]
    ids = np.r_[np.zeros(20), np.ones(3)].astype(np.int32)
    mats = np.stack([Transform(translation=tuple(rng.uniform(-5, 5, 3)), rotation=tuple(rng.uniform(-180, 180, 3)),
                               scale=float(rng.uniform(0.4, 1.6))).matrix() for _ in ids])
    mats[4, :3, 0] *= -1                       # a mirror: TRS with negative scale
    return SmallScene(species, ids, mats)


@pytest.fixture(scope="module")
def presets_module() -> dict[str, LeafParams]:
    from leafview.resources import builtin_presets

    return {name: LeafParams.load(builtin_presets()[name]) for name in ("ovate", "maize")}


@pytest.fixture(scope="module")
def scene_glb(scene, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("ext") / "scene.glb"
    return export_scene(scene, path, resolution=GRID, backend="numpy", length_m=LENGTH)


@pytest.fixture(scope="module")
def scene_file(scene_glb) -> tuple[dict, bytes]:
    doc, blob = read_container(scene_glb)
    assert blob is not None
    return doc, blob


def _instanced(doc: dict) -> tuple[int, dict[str, int]]:
    (n, node), = [(i, nd) for i, nd in enumerate(doc["nodes"]) if INST in nd.get("extensions", {})]
    return n, node["extensions"][INST]["attributes"]


def _to_glb(doc: dict, blob: bytes) -> bytes:
    """A GLB container written here, not by leafview's writer (JSON chunk, BIN chunk)."""
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    total = 12 + 8 + len(text) + 8 + len(blob)
    return (struct.pack("<4sII", b"glTF", 2, total) + struct.pack("<II", len(text), 0x4E4F534A) + text
            + struct.pack("<II", len(blob), 0x004E4942) + blob)


# -- real exports are clean -------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_single_leaf_exports_pass(presets_module, tmp_path, suffix):
    path = export_leaf(presets_module["ovate"], tmp_path / f"leaf{suffix}", resolution=GRID, backend="numpy")
    doc, blob = read_container(path)
    assert blob is not None and len(blob) == doc["buffers"][0]["byteLength"]
    ext = doc["materials"][0]["extensions"][DIFF]
    assert ext["diffuseTransmissionFactor"] == pytest.approx(presets_module["ovate"].material.translucency)
    assert check_file(path) == []


def test_instanced_scene_passes(scene_glb, scene_file):
    doc, _ = scene_file
    _n, attrs = _instanced(doc)
    assert set(attrs) == {"TRANSLATION", "ROTATION", "SCALE"}
    assert doc["accessors"][attrs["ROTATION"]]["count"] == 20
    assert INST in doc["extensionsRequired"] and DIFF in doc["extensionsUsed"]
    assert check_file(scene_glb) == []


def test_schemas_are_the_stored_official_files():
    readme = (SCHEMA_DIR / "README.md").read_text()
    for name in sorted(p.name for p in SCHEMA_DIR.glob("*.schema.json")):
        assert f"`{name}`" in readme, f"{name} has no source line in the README"
        schema = json.loads((SCHEMA_DIR / name).read_text())
        assert schema["$schema"] == "http://json-schema.org/draft-04/schema"
    for filename, _ in CHECKED_EXTENSIONS.values():
        assert (SCHEMA_DIR / filename).is_file()


# -- targeted breakages ------------------------------------------------------------------------------
Mutation = Callable[[dict, bytearray], tuple[str, str]]


def _wrong_rotation_type(doc, blob):
    n, a = _instanced(doc)
    doc["accessors"][a["ROTATION"]]["type"] = "VEC3"
    return f"/nodes/{n}/extensions/{INST}/attributes/ROTATION", "must be VEC4"


def _count_mismatch(doc, blob):
    n, a = _instanced(doc)
    doc["accessors"][a["SCALE"]]["count"] -= 1
    return f"/nodes/{n}/extensions/{INST}/attributes", "counts differ"


def _non_unit_quaternion(doc, blob):
    n, a = _instanced(doc)
    acc = doc["accessors"][a["ROTATION"]]
    at = doc["bufferViews"][acc["bufferView"]]["byteOffset"] + acc.get("byteOffset", 0) + 3 * 16
    q = np.frombuffer(bytes(blob[at:at + 16]), "<f4") * np.float32(1.01)
    blob[at:at + 16] = q.astype("<f4").tobytes()
    return f"/nodes/{n}/extensions/{INST}/attributes/ROTATION", "element 3 is not a unit quaternion"


def _factor_above_one(doc, blob):
    doc["materials"][0]["extensions"][DIFF]["diffuseTransmissionFactor"] = 1.5
    return f"/materials/0/extensions/{DIFF}/diffuseTransmissionFactor", "1.5 is greater than the maximum of 1"


def _factor_nan(doc, blob):
    doc["materials"][1]["extensions"][DIFF]["diffuseTransmissionFactor"] = math.nan
    return f"/materials/1/extensions/{DIFF}/diffuseTransmissionFactor", "not a finite number"


def _colour_too_short(doc, blob):
    doc["materials"][0]["extensions"][DIFF]["diffuseTransmissionColorFactor"] = [0.1, 0.2]
    return f"/materials/0/extensions/{DIFF}/diffuseTransmissionColorFactor", "is too short"


def _not_in_extensions_used(doc, blob):
    doc["extensionsUsed"].remove(DIFF)
    return f"/materials/0/extensions/{DIFF}", "not listed in extensionsUsed"


def _not_required(doc, blob):
    del doc["extensionsRequired"]
    return "/extensionsRequired", f"lacks {INST}"


def _bad_texture_index(doc, blob):
    doc["materials"][0]["extensions"][DIFF]["diffuseTransmissionTexture"] = {"index": 3}
    return f"/materials/0/extensions/{DIFF}/diffuseTransmissionTexture/index", "texture 3 does not exist"


def _missing_texcoord(doc, blob):
    doc["textures"] = [{}]
    doc["materials"][0]["extensions"][DIFF]["diffuseTransmissionColorTexture"] = {"index": 0, "texCoord": 1}
    return f"/materials/0/extensions/{DIFF}/diffuseTransmissionColorTexture/texCoord", "has no TEXCOORD_1"


def _node_without_mesh(doc, blob):
    n, _ = _instanced(doc)
    del doc["nodes"][n]["mesh"]
    return f"/nodes/{n}", "no mesh"


def _stride_too_small(doc, blob):
    _n, a = _instanced(doc)
    doc["bufferViews"][doc["accessors"][a["TRANSLATION"]]["bufferView"]]["byteStride"] = 8
    view = doc["accessors"][a["TRANSLATION"]]["bufferView"]
    return f"/bufferViews/{view}/byteStride", "must be ≥ the element size"


def _past_the_view(doc, blob):
    _n, a = _instanced(doc)
    for index in a.values():
        doc["accessors"][index]["count"] += 1
    return f"/accessors/{a['TRANSLATION']}", "elements end at byte"


def _missing_accessor(doc, blob):
    n, _a = _instanced(doc)
    doc["nodes"][n]["extensions"][INST]["attributes"]["SCALE"] = 999
    return f"/nodes/{n}/extensions/{INST}/attributes/SCALE", "accessor 999 does not exist"


def _unknown_attribute(doc, blob):
    n, a = _instanced(doc)
    doc["nodes"][n]["extensions"][INST]["attributes"]["COLOR"] = a["SCALE"]
    return f"/nodes/{n}/extensions/{INST}/attributes/COLOR", "unknown instance attribute"


def _on_a_material(doc, blob):
    _n, a = _instanced(doc)
    doc["materials"][0]["extensions"][INST] = {"attributes": dict(a)}
    return f"/materials/0/extensions/{INST}", "belongs on nodes"


def _with_unlit(doc, blob):
    doc["materials"][0]["extensions"]["KHR_materials_unlit"] = {}
    doc["extensionsUsed"].append("KHR_materials_unlit")
    return "/materials/0/extensions/KHR_materials_unlit", f"must not be used together with {DIFF}"


MUTATIONS: list[Mutation] = [
    _wrong_rotation_type, _count_mismatch, _non_unit_quaternion, _factor_above_one, _factor_nan, _colour_too_short,
    _not_in_extensions_used, _not_required, _bad_texture_index, _missing_texcoord, _node_without_mesh,
    _stride_too_small, _past_the_view, _missing_accessor, _unknown_attribute, _on_a_material, _with_unlit,
]


@pytest.mark.parametrize("mutate", MUTATIONS, ids=lambda f: f.__name__.strip("_"))
def test_breakage_is_reported_at_its_path(scene_file, mutate):
    doc, blob = copy.deepcopy(scene_file[0]), bytearray(scene_file[1])
    pointer, words = mutate(doc, blob)
    problems = check_extensions(doc, bytes(blob))
    hits = [p for p in problems if p.startswith(pointer + ":") and words in p]
    assert hits, f"expected '{pointer}: ...{words}...' in {problems}"


def test_valid_variants_are_not_reported(scene_file):
    """Normalized SHORT rotations (allowed by the attribute table), a strided TRANSLATION view and
    a texture with its TEXCOORD_0: legal files the checker must accept."""
    doc, blob = copy.deepcopy(scene_file[0]), bytearray(scene_file[1])
    n, a = _instanced(doc)
    rot = doc["accessors"][a["ROTATION"]]
    at = doc["bufferViews"][rot["bufferView"]]["byteOffset"]
    q = np.frombuffer(bytes(blob[at:at + 16 * rot["count"]]), "<f4").reshape(-1, 4)
    q16 = np.round(q * 32767).astype("<i2")
    blob += q16.tobytes()
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(blob) - q16.nbytes, "byteLength": q16.nbytes})
    doc["accessors"].append({"bufferView": len(doc["bufferViews"]) - 1, "componentType": 5122, "normalized": True,
                             "count": rot["count"], "type": "VEC4"})
    doc["nodes"][n]["extensions"][INST]["attributes"]["ROTATION"] = len(doc["accessors"]) - 1
    # TRANSLATION as every other 12-byte element of a 24-byte-strided view over T and S interleaved
    t_acc, s_acc = doc["accessors"][a["TRANSLATION"]], doc["accessors"][a["SCALE"]]
    t = np.frombuffer(bytes(blob), "<f4", 3 * t_acc["count"], doc["bufferViews"][t_acc["bufferView"]]["byteOffset"])
    s = np.frombuffer(bytes(blob), "<f4", 3 * s_acc["count"], doc["bufferViews"][s_acc["bufferView"]]["byteOffset"])
    both = np.hstack([t.reshape(-1, 3), s.reshape(-1, 3)]).astype("<f4")
    blob += both.tobytes()
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(blob) - both.nbytes, "byteLength": both.nbytes,
                               "byteStride": 24})
    doc["accessors"].append({"bufferView": len(doc["bufferViews"]) - 1, "componentType": 5126,
                             "count": t_acc["count"], "type": "VEC3"})
    doc["nodes"][n]["extensions"][INST]["attributes"]["TRANSLATION"] = len(doc["accessors"]) - 1
    doc["buffers"][0]["byteLength"] = len(blob)
    doc["textures"] = [{}]
    doc["materials"][0]["extensions"][DIFF]["diffuseTransmissionTexture"] = {"index": 0, "texCoord": 0}
    assert check_extensions(doc, bytes(blob)) == []
    # ... and the checker reads these variants' data: a quantised quaternion pushed off unit length
    q16[5] = (q16[5] * 0.9).astype("<i2")
    blob[len(blob) - both.nbytes - q16.nbytes:len(blob) - both.nbytes] = q16.tobytes()
    assert any("element 5 is not a unit quaternion" in p for p in check_extensions(doc, bytes(blob)))


@pytest.mark.usefixtures("gltf_validator")   # installs the Khronos validator on first use
def test_khronos_validator_misses_what_the_checker_finds(scene_file, tmp_path):
    """The reason for this module: three breakages inside the extensions pass the Khronos
    glTF-Validator with no error, and the checker reports each."""
    doc, blob = copy.deepcopy(scene_file[0]), bytearray(scene_file[1])
    expected = [m(doc, blob) for m in (_count_mismatch, _non_unit_quaternion, _factor_above_one)]
    path = tmp_path / "broken.glb"
    path.write_bytes(_to_glb(doc, bytes(blob)))
    report = gltf_validate(path)
    assert report["issues"]["numErrors"] == 0, report["issues"]["messages"]
    problems = check_file(path)
    for pointer, words in expected:
        assert any(p.startswith(pointer + ":") and words in p for p in problems), (pointer, problems)


# -- the instances re-imported ------------------------------------------------------------------
def _quat_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices of unit quaternions (x, y, z, w), written out here (not leafview's)."""
    x, y, z, w = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def _trs(t: np.ndarray, q: np.ndarray, s: np.ndarray) -> np.ndarray:
    m = np.zeros((len(t), 4, 4))
    m[:, :3, :3] = _quat_matrix(q) * s[:, None, :]
    m[:, :3, 3] = t
    m[:, 3, 3] = 1.0
    return m


def test_instances_recompose_to_the_scene_matrices(scene, scene_file):
    doc, blob = scene_file
    n, attrs = _instanced(doc)

    def data(index: int) -> np.ndarray:
        acc = doc["accessors"][index]
        view = doc["bufferViews"][acc["bufferView"]]
        assert acc["componentType"] == 5126 and "byteStride" not in view
        width = {"VEC3": 3, "VEC4": 4}[acc["type"]]
        start = view["byteOffset"] + acc.get("byteOffset", 0)
        return np.frombuffer(blob, "<f4", acc["count"] * width, start).reshape(-1, width).astype(np.float64)

    inst = _trs(data(attrs["TRANSLATION"]), data(attrs["ROTATION"]), data(attrs["SCALE"]))
    expect = scene.matrices[scene.shape_ids == 0]
    assert len(inst) == len(expect) == 20
    # each instance equals exactly one scene matrix (order is the writer's business)
    dist = np.abs(inst[:, None] - expect[None]).max(axis=(2, 3))
    match = dist.argmin(axis=1)
    assert sorted(match) == list(range(20))
    assert dist[np.arange(20), match].max() <= 1e-6
    # the node chain above the instances: leafview z-up leaf lengths -> glTF y-up metres
    parent = {c: i for i, nd in enumerate(doc["nodes"]) for c in nd.get("children", [])}
    chain, k = np.eye(4), n
    while True:
        nd = doc["nodes"][k]
        local = _trs(np.array([nd.get("translation", [0, 0, 0])], float), np.array([nd.get("rotation", [0, 0, 0, 1])], float),
                     np.array([nd.get("scale", [1, 1, 1])], float))[0]
        chain = local @ chain
        if k not in parent:
            break
        k = parent[k]
    to_file = np.array([[LENGTH, 0, 0, 0], [0, 0, LENGTH, 0], [0, -LENGTH, 0, 0], [0, 0, 0, 1]])  # (x, z, -y)·L
    assert np.abs(chain - to_file).max() <= 1e-6


def test_command_line_exit_codes(scene_glb, scene_file, tmp_path, capsys):
    from support.gltf_extensions import main

    doc, blob = copy.deepcopy(scene_file[0]), bytearray(scene_file[1])
    pointer, words = _wrong_rotation_type(doc, blob)
    broken = tmp_path / "broken.glb"
    broken.write_bytes(_to_glb(doc, bytes(blob)))
    assert main([str(scene_glb)]) == 0
    assert main([str(broken)]) == 1
    out = capsys.readouterr().out
    assert f"{scene_glb}: 0 problems in {INST}, {DIFF}" in out
    assert f"{broken}: 1 problems" in out and f"  {pointer}: " in out and words in out
