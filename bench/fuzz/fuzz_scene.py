"""Coverage-guided fuzzing of the scene file reader (``load_scene``: TOML and JSON recipes).

Species presets named in a fuzzed scene resolve against a temporary folder holding one valid
preset (``ok.toml``), so the reader's path handling is exercised without reaching other files.

    python bench/fuzz/fuzz_scene.py -max_total_time=600       # with atheris (libFuzzer flags)
    python bench/fuzz/fuzz_scene.py --seconds 600             # without atheris: a random loop
"""

from __future__ import annotations

import json
from pathlib import Path

import tomli_w
from fuzz_common import ASSETS, fuzz, instrumented

with instrumented():
    from leafview.core.compact import compact_dict
    from leafview.core.params import LeafParams
    from leafview.errors import LeafviewError
    from leafview.scene.spec import SceneSpec, load_scene


def seeds() -> list[bytes]:
    ovate = LeafParams.load(ASSETS / "presets" / "ovate.toml")
    maize = LeafParams.load(ASSETS / "presets" / "maize.toml")
    docs = [
        {"schema": 1, "scene": {"layout": "plant", "leaves": 30, "seed": 3}, "species": [{"preset": "ovate"}]},
        {"schema": 1, "scene": {"layout": "field", "leaves": 50, "plants": 4, "variation": 0.3},
         "species": [{"leaf": compact_dict(ovate, version=False), "weight": 2}, {"preset": "ok.toml"}],
         "plant": {"phyllotaxis": "whorled", "whorl": 4, "branches": 3}},
        SceneSpec(species=(ovate, maize), weights=(1.0, 0.5), leaves=20, layout="hedge").to_dict(),
    ]
    return [tomli_w.dumps(d).encode() for d in docs] + [json.dumps(d).encode() for d in docs]


def prepare(folder: Path) -> None:
    (folder / "ok.toml").write_bytes((ASSETS / "presets" / "ovate.toml").read_bytes())


if __name__ == "__main__":
    fuzz("scene", (".toml", ".json"), seeds(), load_scene, LeafviewError, prepare)
