"""Regenerate docs/images/lobed.png: the built-in lobed leaves as the shader sweeps them
(Mündermann et al. 2003): top row maple, oak and bilobed seen from above and maple's skeleton
(red) with its railroad ties (green); bottom row the same leaves in three-quarter view with
turtle edits per branch (sec. 4: bend, twist, turn), cupped ties and rippled margins (Geng, Hu &
Zhang 2014, eq. 5), and oak's flat ties. Run from the repository root."""

from dataclasses import replace

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import leafview  # noqa: E402
from leafview.botany.lobe_skeleton import skeleton  # noqa: E402
from leafview.botany.lobe_sweep import sweep_table  # noqa: E402
from leafview.core.lobes import BranchTurtle, outline_samples  # noqa: E402
from leafview.export.images import contact_sheet, write_image  # noqa: E402
from leafview.resources import builtin_presets  # noqa: E402

SIZE = (256, 256)


def load(name: str) -> leafview.LeafParams:
    return leafview.LeafParams.load(builtin_presets()[name]).replace(name=name)


def diagram(leaf: leafview.LeafParams) -> np.ndarray:
    """The flat leaf's margin (black), skeleton (red) and railroad ties (green), as an RGBA image."""
    table = sweep_table(leaf.lobes)
    sk = skeleton(leaf.lobes)
    ring = outline_samples(leaf.lobes.outline)
    fig = plt.figure(figsize=(SIZE[0] / 100, SIZE[1] / 100), dpi=100)
    ax = fig.add_axes((0.02, 0.02, 0.96, 0.96))
    for k, s in zip(table.flat[::2, :2], table.flat[::2, 2:]):
        ax.plot([k[0], s[0]], [k[1], s[1]], color=(0.3, 0.6, 0.3), lw=0.5)
    ax.plot(*np.vstack([ring, ring[:1]]).T, color="k", lw=0.8)
    for edge in sk.edges:
        ax.plot(*edge.points.T, color=(0.8, 0.1, 0.1), lw=1.4)
    ax.set_aspect("equal")
    ax.axis("off")
    fig.patch.set_facecolor((1, 1, 1, 0))
    fig.canvas.draw()
    img = np.asarray(fig.canvas.buffer_rgba()).copy()
    plt.close(fig)
    return img


def edited(leaf: leafview.LeafParams, branches: tuple[BranchTurtle, ...], cup: float, ripple: bool
           ) -> leafview.LeafParams:
    out = leaf.replace(lobes=replace(leaf.lobes, branches=branches, cup=cup))
    if ripple:
        out = out.replace(ripple=replace(out.ripple, enabled=True))
    return out


def main() -> None:
    maple, oak, bilobed = load("maple"), load("oak"), load("bilobed")
    lift = (40.0, 60.0, 80.0, 100.0)   # degrees per leaf length, rising towards the tip
    maple3 = edited(maple, tuple(BranchTurtle(branch=b, bend=lift) for b in range(1, 5)), 0.15, False)
    oak3 = edited(oak, (BranchTurtle(branch=0, bend=(0.0, 20.0, 40.0, 60.0)),), 0.1, True)
    bilobed3 = edited(bilobed, tuple(BranchTurtle(branch=b, twist=(0.0, 30.0, 60.0, 60.0)) for b in (1, 2)),
                      0.2, False)
    images = [leafview.render(leaf, SIZE, "top") for leaf in (maple, oak, bilobed)] + [diagram(maple)]
    images += [leafview.render(leaf, SIZE, "three-quarter") for leaf in (maple3, oak3, bilobed3)]
    images += [leafview.render(maple, SIZE, "three-quarter")]
    labels = ["maple", "oak", "bilobed", "maple: skeleton and ties",
              "maple, lobes bent, cupped", "oak, midrib bent, rippled", "bilobed, lobes twisted", "maple, flat"]
    sheet = contact_sheet(images, labels, columns=4)
    write_image("docs/images/lobed.png", sheet)
    print("wrote docs/images/lobed.png", sheet.shape)


if __name__ == "__main__":
    main()
