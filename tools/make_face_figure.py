"""Regenerate docs/images/face_photos.png: which side of a leaf faces the camera
(leafview.fit.photo_face). The first three face-up and the first three face-down leaves among the
seeded synthetic photos from seed 10000 (700 × 700, JPEG round trip), whatever the detector says
of them: top row each whole photo, bottom row a 96 × 96 px crop of its blade at the photo's own
resolution, enlarged 2×, where a raised vein's light/dark pair (face down) or a flat vein's even
line (face up) shows. Labels: the seed, the truth, what the detector found and its score. Run from the
repository root."""

from __future__ import annotations

import numpy as np

from leafview.bench.fit_photo import photo_cell
from leafview.export.images import contact_sheet, write_image
from leafview.fit.photo import canonical_frame
from leafview.fit.photo_face import detect_face
from leafview.fit.photo_outline import as_photo, leaf_outline
from leafview.fit.synthetic_photos import synthetic_photo

CELL, CROP, FIRST_SEED, EACH = 192, 96, 10000, 3


def crop_cell(rgb: np.ndarray, blade: np.ndarray, base: np.ndarray, apex: np.ndarray) -> np.ndarray:
    """A CROP × CROP window of the photo two fifths of the way from base to apex, moved inside the
    blade's bounding box, enlarged to CELL × CELL by repeating pixels."""
    h, w = blade.shape
    cx, cy = base + 0.4 * (apex - base)
    x0 = int(np.clip(round(cx - CROP / 2), 0, w - CROP))
    y0 = int(np.clip(round(cy - CROP / 2), 0, h - CROP))
    win = np.clip(rgb[y0:y0 + CROP, x0:x0 + CROP], 0.0, 1.0)
    k = CELL // CROP
    big = np.repeat(np.repeat(win, k, axis=0), k, axis=1)
    out = np.full((CELL, CELL, 4), 255, np.uint8)
    out[:big.shape[0], :big.shape[1], :3] = np.rint(big * 255.0)
    return out


def main() -> None:
    picked: dict[bool, list[int]] = {False: [], True: []}
    seed = FIRST_SEED
    while min(len(v) for v in picked.values()) < EACH:
        sp = synthetic_photo(seed, size=(700, 700))
        if len(picked[sp.face_down]) < EACH:
            picked[sp.face_down].append(seed)
        seed += 1
    tops, crops, labels = [], [], []
    for down in (False, True):
        for s in picked[down]:
            sp = synthetic_photo(s, size=(700, 700))
            photo = as_photo(sp.image)
            traced = leaf_outline(photo)
            est = detect_face(photo.rgb, traced.blade, canonical_frame(traced.base, traced.apex))
            tops.append(photo_cell(photo.rgb, CELL)[0])
            crops.append(crop_cell(photo.rgb, traced.blade, traced.base, traced.apex))
            labels.append(f"{s} {'down' if down else 'up'}: {est.face} {est.score:.0f}")
    sheet = contact_sheet(tops + crops, labels + [""] * len(crops), columns=len(tops))
    write_image("docs/images/face_photos.png", sheet)
    print("wrote docs/images/face_photos.png:", "; ".join(labels))


if __name__ == "__main__":
    main()
