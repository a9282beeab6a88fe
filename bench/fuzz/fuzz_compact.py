"""Coverage-guided fuzzing of the compact leaf reader (``*.leaf.json``, ``load_leaves``).

    python bench/fuzz/fuzz_compact.py -max_total_time=600     # with atheris (libFuzzer flags)
    python bench/fuzz/fuzz_compact.py --seconds 600           # without atheris: a random loop
"""

from __future__ import annotations

from fuzz_common import ASSETS, fuzz, instrumented

with instrumented():
    from leafview.core import compact
    from leafview.core.io import load_leaves
    from leafview.core.params import LeafParams
    from leafview.errors import LeafviewError


def seeds() -> list[bytes]:
    paths = sorted((ASSETS / "presets").glob("*.toml")) + sorted((ASSETS / "shapes").glob("*.toml"))
    return [compact.dumps(LeafParams.load(p)).encode() for p in paths]


if __name__ == "__main__":
    fuzz("compact", (".leaf.json", ".json"), seeds(), load_leaves, LeafviewError)
