#!/usr/bin/env python3
"""Run the leafview benchmark (the same as ``leafview bench``).

Usage, from the repository root with leafview installed (``pip install -e .[bench]``)::

    python bench/run_bench.py            # readable table (full run, well under a minute)
    python bench/run_bench.py --json     # the results as JSON
    python bench/run_bench.py --quick    # small counts: a smoke run of a few seconds
    python bench/run_bench.py all        # every suite (core, scene, shapes, export, dataset)
    python bench/run_bench.py dataset    # dataset images/s, 1 worker against 2 (local engine)

Needs OpenGL 4.5 through EGL (Mesa llvmpipe works without a GPU) and matplotlib for the
baseline. Numbers are timings on *this* machine; the GL renderer is printed with them.
"""

import sys

from leafview.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", *sys.argv[1:]]))
