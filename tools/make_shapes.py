"""Precompute the shader-model fits of every catalogue shape (leafview.botany.catalogue.catalogue):
assets/shapes/<name>.toml (a leaf preset each) and assets/shapes/fits.json (their errors).

    python tools/make_shapes.py            # about a minute on 2 cores

tests/test_outline_fit.py checks that the files still match the catalogue.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from leafview.atomic import atomic_output  # noqa: E402
from leafview.botany.catalogue import catalogue, landmark_leaf  # noqa: E402
from leafview.botany.landmarks import outline  # noqa: E402
from leafview.botany.outline_fit import fit_outline  # noqa: E402

OUT = ROOT / "assets" / "shapes"
OUTLINE_POINTS = 256


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    records = []
    t0 = time.perf_counter()
    names = set()
    for entry in catalogue():
        fit = fit_outline(outline(landmark_leaf(entry.name), OUTLINE_POINTS), name=entry.name)
        fit.params.save(OUT / f"{entry.name}.toml")
        names.add(entry.name)
        records.append({"name": entry.name, "waist": entry.waist, "base": entry.base, "apex": entry.apex,
                        "rows": fit.rows, "quartic": fit.quartic, "error": round(fit.error, 6),
                        "min_jacobian": round(fit.min_jacobian, 6)})
        print(f"{entry.name:28s} N={fit.rows} error {100 * fit.error:.2f} %  {fit.seconds:.2f} s", flush=True)
    for stale in OUT.glob("*.toml"):
        if stale.stem not in names:
            stale.unlink()
    doc = {"generator": "tools/make_shapes.py", "outline_points": OUTLINE_POINTS, "shapes": records}
    with atomic_output(OUT / "fits.json") as tmp:
        tmp.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    worst = max(r["error"] for r in records)
    print(f"{len(records)} shapes in {time.perf_counter() - t0:.0f} s, largest error {100 * worst:.2f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
