"""Regenerate docs/images/ripple_series.png: the maize preset under the parameter series of
Geng, Hu & Zhang 2014, Figs 7-9 (β = 1 vs 2; k = 0.3 vs 0.1; θ = 8/10 vs 2/5). Run from the repository root."""

from dataclasses import replace

import numpy as np

import leafview
from leafview.export.images import contact_sheet, write_image
from leafview.resources import builtin_presets

maize = leafview.LeafParams.load(builtin_presets()["maize"])
rip = maize.ripple
series = [
    ("beta 1 (k 0.3, theta 8/10)", replace(rip, beta=1.0)),
    ("beta 2 (k 0.3, theta 8/10)", replace(rip, beta=2.0)),
    ("k 0.3 (beta 1, theta 8/10)", replace(rip, interval=(0.3, 0.3))),
    ("k 0.1 (beta 1, theta 8/10)", replace(rip, interval=(0.1, 0.1))),
    ("theta 8/10 (beta 2, k 0.3)", replace(rip, beta=2.0, phase=(8.0, 10.0))),
    ("theta 2/5 (beta 2, k 0.3)", replace(rip, beta=2.0, phase=(2.0, 5.0))),
]
leaves = [maize.replace(ripple=r) for _, r in series]
images = leafview.gpu.default_renderer().render_many(leaves, (420, 150), "side")
sheet = contact_sheet(images, [label for label, _ in series], columns=2)
write_image("docs/images/ripple_series.png", sheet)
print("wrote docs/images/ripple_series.png", sheet.shape, np.count_nonzero(sheet))
