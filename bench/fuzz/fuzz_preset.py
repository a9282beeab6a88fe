"""Coverage-guided fuzzing of the preset reader (full TOML and JSON presets, ``load_leaves``).

    python bench/fuzz/fuzz_preset.py -max_total_time=600      # with atheris (libFuzzer flags)
    python bench/fuzz/fuzz_preset.py --seconds 600            # without atheris: a random loop
"""

from __future__ import annotations

import json
import tomllib

from fuzz_common import files, fuzz, instrumented

with instrumented():
    from leafview.core.io import load_leaves
    from leafview.errors import LeafviewError


def seeds() -> list[bytes]:
    tomls = files("assets/presets/*.toml", "assets/shapes/*.toml")
    return tomls + [json.dumps(tomllib.loads(t.decode())).encode() for t in tomls[:20]]


if __name__ == "__main__":
    fuzz("preset", (".toml", ".json"), seeds(), load_leaves, LeafviewError)
