# example: run
"""Export one leaf three ways: a glTF binary for engines, USD for DCC tools, and the compact
parametric file (Ω plus the settings that differ from their defaults).

    python examples/export_leaf.py [OUT_DIR] [PRESET]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import leafview
from leafview.export import export_leaf
from leafview.resources import resolve_preset


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", default="out", type=Path)
    parser.add_argument("preset", nargs="?", default="holly")
    args = parser.parse_args()

    leaf = leafview.LeafParams.load(resolve_preset(args.preset))
    args.out.mkdir(parents=True, exist_ok=True)
    for name in (f"{leaf.name}.glb", f"{leaf.name}.usda"):
        path = export_leaf(leaf, args.out / name)          # vertices captured from the vertex shader
        print(f"wrote {path} ({path.stat().st_size:,} bytes)")
    compact = args.out / f"{leaf.name}.leaf.json"
    leaf.save(compact)
    assert leafview.LeafParams.load(compact) == leaf       # the compact form reads back bit for bit
    print(f"wrote {compact} ({compact.stat().st_size:,} bytes)")


if __name__ == "__main__":
    main()
