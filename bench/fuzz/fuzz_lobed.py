"""Coverage-guided fuzzing of the multilobed leaf reader (``load_lobed_leaf``, ``lobed = 1`` TOML).

    python bench/fuzz/fuzz_lobed.py -max_total_time=600       # with atheris (libFuzzer flags)
    python bench/fuzz/fuzz_lobed.py --seconds 600             # without atheris: a random loop
"""

from __future__ import annotations

from fuzz_common import files, fuzz, instrumented

with instrumented():
    from leafview.botany.lobes import load_lobed_leaf
    from leafview.errors import LeafviewError


if __name__ == "__main__":
    fuzz("lobed", (".toml",), files("assets/compound/*.toml"), load_lobed_leaf, LeafviewError)
