"""Coverage-guided fuzzing of the landmark leaf reader (``load_landmark_leaf``, ``landmarks = 1``;
what ``leafview morph`` reads).

    python bench/fuzz/fuzz_landmark.py -max_total_time=600    # with atheris (libFuzzer flags)
    python bench/fuzz/fuzz_landmark.py --seconds 600          # without atheris: a random loop
"""

from __future__ import annotations

from fuzz_common import files, fuzz, instrumented

with instrumented():
    from leafview.botany.catalogue import load_landmark_leaf
    from leafview.errors import LeafviewError


if __name__ == "__main__":
    fuzz("landmark", (".toml", ".json"), files("assets/landmarks/*.toml"), load_landmark_leaf, LeafviewError)
