"""Coverage-guided fuzzing of the leaf set reader (``*.leaves.json``, ``load_leaves``).

    python bench/fuzz/fuzz_leaf_set.py -max_total_time=600    # with atheris (libFuzzer flags)
    python bench/fuzz/fuzz_leaf_set.py --seconds 600          # without atheris: a random loop
"""

from __future__ import annotations

from fuzz_common import ASSETS, fuzz, instrumented

with instrumented():
    from leafview.core import compact
    from leafview.core.io import load_leaves
    from leafview.core.params import LeafParams, Transform
    from leafview.errors import LeafviewError


def seeds() -> list[bytes]:
    leaves = [LeafParams.load(p) for p in sorted((ASSETS / "presets").glob("*.toml"))]
    placed = [leaf.replace(transform=Transform(translation=(i * 0.3, 0.0, 0.0), rotation=(0.0, 0.0, 10.0 * i),
                                               scale=1.0 + 0.1 * i)) for i, leaf in enumerate(leaves)]
    return [compact.dumps_leaves(placed[i:i + 3]).encode() for i in range(0, len(placed), 3)]


if __name__ == "__main__":
    fuzz("leaf_set", (".leaves.json", ".json"), seeds(), load_leaves, LeafviewError)
