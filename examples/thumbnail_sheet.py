# example: compare
"""A labelled contact sheet of every built-in preset, rendered offscreen by the vertex shader.

    python examples/thumbnail_sheet.py [OUT_DIR] [--size N]

Writes ``OUT_DIR/presets_sheet.png`` (default ``OUT_DIR`` = ``out``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import leafview
from leafview.export.images import contact_sheet, write_image
from leafview.resources import builtin_presets


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", default="out", type=Path)
    parser.add_argument("--size", type=int, default=96, help="thumbnail size in pixels")
    args = parser.parse_args()

    presets = builtin_presets()                                    # name -> assets/presets/<name>.toml
    leaves = [leafview.LeafParams.load(path) for path in presets.values()]
    thumbs = [leafview.render(leaf, size=(args.size, args.size), view="top") for leaf in leaves]
    sheet = contact_sheet(thumbs, [leaf.name for leaf in leaves], columns=6)
    args.out.mkdir(parents=True, exist_ok=True)
    path = write_image(args.out / "presets_sheet.png", sheet)
    print(f"wrote {path}: {len(leaves)} presets, {sheet.shape[1]}×{sheet.shape[0]} px")


if __name__ == "__main__":
    main()
