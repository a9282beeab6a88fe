"""Regenerate docs/images/architecture.{dot,svg,png}: the layers of leafview and the imports between
them, taken from the real import graph.

The graph is built by grimp (the library under import-linter) with ``if TYPE_CHECKING`` imports left
out, as the import contracts in pyproject.toml see it. Every module is collapsed to its layer: a
subpackage (``leafview.core``, ``leafview.deform``, ...), the base modules (``errors | atomic |
resources | _version``), or the public API (``leafview/__init__.py`` and the alias modules
``landmarks``, ``shapes``, ``beam``). An arrow A → B says that modules of A import modules of B;
its label is the number of distinct (importing module, imported module) pairs. Imports inside one
layer are counted in the layer's box. Imports made with ``importlib`` (the lazy attributes of
``leafview/__init__.py``, the sub-command dispatch of ``leafview.cli``) are not import statements
and do not appear.

The picture is an arc diagram: the layers stacked top to bottom in contract order, an arrow between
neighbours straight down the middle, longer arrows as nested arcs on the two sides (imports of
``core`` and of the base modules on the left, the others on the right). The positions are computed
here, written into the DOT file, and Graphviz only draws them (``dot -Kneato -n2``), so the picture
stays readable however many arrows there are.

Run from the repository root::

    python tools/make_architecture.py            # writes the .dot, renders .svg and .png (Graphviz)
    python tools/make_architecture.py --check    # exit 1 if the committed .dot is stale (no Graphviz)

``tests/test_architecture_doc.py`` calls :func:`dot_source` and compares it with the committed file.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import textwrap
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import grimp

ROOT = Path(__file__).resolve().parent.parent
DOT_PATH = ROOT / "docs" / "images" / "architecture.dot"
SVG_PATH = DOT_PATH.with_suffix(".svg")
PNG_PATH = DOT_PATH.with_suffix(".png")
REGENERATE = "python tools/make_architecture.py"
PNG_DPI = 96
PNG_MAX_WIDTH_IN = 12.4                       # at 96 dpi: at most 1190 px wide

# The layers from the top down, as in [tool.importlinter] of pyproject.toml, each with one line on
# what it holds. The public API is no layer of the contract; nothing inside the package imports it
# (a forbidden contract), so it is drawn on top, dashed.
API = "public API"
BASE = "base"
LAYERS: list[tuple[str, str]] = [
    ("leafview.cli", "one module per sub-command"),
    ("leafview.bench", "one module per benchmark table"),
    ("leafview.dataset", "labelled datasets: layouts, COCO, local and Ray engines"),
    ("leafview.notebook", "Jupyter: LeafWidget, thumbnails for _repr_png_"),
    ("leafview.app", "the viewer: glfw window, imgui panel, overlays"),
    ("leafview.export", "glTF, OBJ/PLY and USD writers; images"),
    ("leafview.gpu", "moderngl: layout, shader loading, passes, renderers"),
    ("leafview.scene", "scene specs, plants, stems, cameras (no GL)"),
    ("leafview.fit", "point clouds and RGB-D views to leaves (no GL)"),
    ("leafview.botany", "landmarks, catalogue, Ω fits, lobes, morph"),
    ("leafview.deform", "fBm, cantilever beam, the whole surface (numpy)"),
    ("leafview.core", "LeafParams, Bézier maths, blade, files (numpy)"),
    ("leafview.inputs", "the one reader of input files: type, size, nesting"),
]
BASE_MODULES = ("leafview.errors", "leafview.atomic", "leafview.resources", "leafview._version")
API_MODULES = ("leafview", "leafview.landmarks", "leafview.shapes", "leafview.beam", "leafview.venation")
ORDER = [API] + [name for name, _ in LAYERS] + [BASE]
ROLES = dict(LAYERS) | {API: "for users, not a layer: nothing inside imports it",
                        BASE: "atomic imports errors; nothing else of leafview"}
TITLES = {API: "public API (leafview)", BASE: "errors | atomic | resources | _version"}
LEFT_TARGETS = ("leafview.core", "leafview.inputs", BASE)        # arcs into these run on the left, all others on the right

# one colour per importing layer, so that an arc and its count can be told from their neighbours
COLOURS = {
    API: "#6a3d9a", "leafview.cli": "#1f78b4", "leafview.bench": "#b15928", "leafview.dataset": "#7b4f9d",
    "leafview.notebook": "#5d7c1f", "leafview.app": "#e31a1c",
    "leafview.export": "#e08000", "leafview.gpu": "#2d8f2d", "leafview.scene": "#8c6d1f", "leafview.fit": "#a0522d",
    "leafview.botany": "#138a6a", "leafview.deform": "#6a5acd", "leafview.core": "#c2185b",
    "leafview.inputs": "#00838f", BASE: "#666666",
}

# geometry, in inches
COL_W = 4.3                  # width of a layer box
GAP = 0.55                   # vertical gap between two boxes (room for the count of a straight arrow)
LANE0 = 0.32                 # distance from a box to the innermost lane of arcs
LANE = 0.25                  # distance between two lanes
RADIUS = 0.1                 # rounded corners of the arcs
ARROW = 0.11                 # length of an arrowhead
MARGIN = 0.25
TITLE_H = 0.75


def layer_of(module: str) -> str:
    """The layer node a leafview module belongs to."""
    for name, _ in LAYERS:
        if module == name or module.startswith(name + "."):
            return name
    if module in BASE_MODULES:
        return BASE
    if module in API_MODULES:
        return API
    raise ValueError(f"{module} is in no layer: add it to LAYERS, BASE_MODULES or API_MODULES in {__file__}")


def build_graph() -> grimp.ImportGraph:
    """The module import graph of leafview, as the import contracts see it (no cache written)."""
    sys.path.insert(0, str(ROOT))
    try:
        return grimp.build_graph("leafview", exclude_type_checking_imports=True, cache_dir=None)
    finally:
        sys.path.remove(str(ROOT))


def collapse(graph: grimp.ImportGraph) -> tuple[dict[str, list[str]], Counter[tuple[str, str]]]:
    """Modules per layer node, and the number of (importer, imported) module pairs per pair of nodes
    (pairs inside one node are counted under (node, node))."""
    members: dict[str, list[str]] = {node: [] for node in ORDER}
    edges: Counter[tuple[str, str]] = Counter()
    for module in sorted(graph.modules):
        source = layer_of(module)
        members[source].append(module)
        for imported in graph.find_modules_directly_imported_by(module):
            edges[(source, layer_of(imported))] += 1
    return members, edges


def _short(node: str, module: str) -> str:
    """A module's name inside its box: ``blade`` for leafview.core.blade, ``__init__`` for leafview."""
    if node in (API, BASE):
        return "__init__" if module == "leafview" else module.rsplit(".", 1)[1]
    return module[len(node) + 1:] if module != node else ""


@dataclass
class Box:
    node: str
    lines: list[tuple[str, int, str]]        # (text, point size, style) per line of the label
    top: float = 0.0
    height: float = 0.0

    @property
    def bottom(self) -> float:
        return self.top + self.height


def _box(node: str, modules: list[str], inner: int) -> Box:
    names = [n for n in (_short(node, m) for m in modules) if n]
    listing = textwrap.wrap(", ".join(names), width=52) or ["(the package only)"]
    count = f"{len(modules)} module{'s' if len(modules) != 1 else ''}, {inner} import{'s' if inner != 1 else ''} inside"
    lines = [(TITLES.get(node, node), 14, "b"), (ROLES[node], 10, "i")]
    lines += [(line, 11, "") for line in listing]
    lines.append((count, 9, "grey"))
    height = sum(size for _, size, _ in lines) * 1.22 / 72 + 0.2
    return Box(node, lines, height=round(height, 3))


def _html(box: Box) -> str:
    rows = []
    for text, size, style in box.lines:
        text = text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
        text = {"b": f"<b>{text}</b>", "i": f"<i>{text}</i>"}.get(style, text)
        colour = ' color="#555555"' if style == "grey" else ""
        rows.append(f'<font point-size="{size}"{colour}>{text}</font>')
    return "<" + "<br/>".join(rows) + ">"


@dataclass
class Arc:
    source: str
    target: str
    count: int
    side: int = 0              # -1 left, +1 right, 0 straight down the middle
    lane: int = 0
    y_out: float = 0.0
    y_in: float = 0.0


def _assign_lanes(arcs: list[Arc]) -> None:
    """Nested lanes on one side: shorter arcs inside; an arc takes the innermost lane whose arcs
    span no rank it spans (arcs that only meet at a box share a lane: their ends sit at different
    heights of that box)."""
    taken: list[list[tuple[int, int]]] = []
    for arc in sorted(arcs, key=lambda a: (ORDER.index(a.target) - ORDER.index(a.source),
                                           ORDER.index(a.source), ORDER.index(a.target))):
        lo, hi = ORDER.index(arc.source), ORDER.index(arc.target)
        for lane, spans in enumerate(taken):
            if all(hi <= a or lo >= b for a, b in spans):
                spans.append((lo, hi))
                arc.lane = lane
                break
        else:
            taken.append([(lo, hi)])
            arc.lane = len(taken) - 1


def _assign_ports(boxes: dict[str, Box], arcs: list[Arc]) -> None:
    """Where each arc meets the side of its boxes: arriving arcs above leaving ones; arriving arcs
    from the inner lanes outwards, leaving arcs from the outer lanes inwards, so nested arcs do not
    cross at a box."""
    for node, box in boxes.items():
        for side in (-1, 1):
            arriving = sorted((a for a in arcs if a.side == side and a.target == node), key=lambda a: a.lane)
            leaving = sorted((a for a in arcs if a.side == side and a.source == node), key=lambda a: -a.lane)
            ends = [(a, "in") for a in arriving] + [(a, "out") for a in leaving]
            pad = min(0.12, box.height / 6)
            step = (box.height - 2 * pad) / max(len(ends), 1)
            for k, (arc, end) in enumerate(ends):
                y = round(box.top + pad + (k + 0.5) * step, 3)
                if end == "in":
                    arc.y_in = y
                else:
                    arc.y_out = y


def layout(members: dict[str, list[str]], edges: Counter[tuple[str, str]]) -> tuple[list[Box], list[Arc], float]:
    """Boxes stacked in ORDER, arcs with sides, lanes and ports; returns them and the width of the
    left lane area (the column's left edge, measured from the margin)."""
    boxes = [_box(node, members[node], edges.get((node, node), 0)) for node in ORDER]
    y = MARGIN + TITLE_H
    for box in boxes:
        box.top = round(y, 3)
        y += box.height + GAP
    arcs = []
    for (source, target), count in edges.items():
        if source == target:
            continue
        if ORDER.index(target) < ORDER.index(source):
            raise ValueError(f"{source} imports {target}, which sits above it: the layers contract is broken")
        arc = Arc(source, target, count)
        if ORDER.index(target) - ORDER.index(source) > 1:
            arc.side = -1 if target in LEFT_TARGETS else 1
        arcs.append(arc)
    for side in (-1, 1):
        _assign_lanes([a for a in arcs if a.side == side])
    _assign_ports({b.node: b for b in boxes}, arcs)
    lanes_left = max((a.lane + 1 for a in arcs if a.side == -1), default=0)
    return boxes, arcs, LANE0 + lanes_left * LANE


def _fmt(x: float) -> str:
    return f"{x:.2f}".rstrip("0").rstrip(".")


def dot_source(graph: grimp.ImportGraph | None = None) -> str:
    """The DOT text of the layer picture (positions included), deterministic for one import graph."""
    members, edges = collapse(graph if graph is not None else build_graph())
    boxes, arcs, left_area = layout(members, edges)
    by_node = {b.node: b for b in boxes}
    lanes_right = max((a.lane + 1 for a in arcs if a.side == 1), default=0)
    x_left = MARGIN + left_area                          # the column's left edge
    x_mid = x_left + COL_W / 2
    width = x_left + COL_W + LANE0 + lanes_right * LANE + MARGIN
    height = boxes[-1].bottom + MARGIN

    def pt(x: float, y: float) -> str:                   # inches, y down -> points, y up
        return f"{_fmt(x * 72)},{_fmt((height - y) * 72)}"

    out = [
        "// Generated by tools/make_architecture.py from the import graph of leafview (grimp); do not edit.",
        f"// Regenerate: {REGENERATE}. Positions are computed there; render with dot -Kneato -n2.",
        "digraph leafview_layers {",
        f'    graph [layout=neato, splines=true, outputorder=edgesfirst, bb="0,0,{_fmt(width * 72)},'
        f'{_fmt(height * 72)}", pad=0.1, bgcolor=white];',
        '    node [shape=box, style="rounded,filled", fixedsize=true, fontname="Helvetica", fillcolor="#f3f7ee",'
        ' color="#7a9a5a", penwidth=1.2];',
        '    edge [fontname="Helvetica", fontsize=11, arrowsize=0.8, penwidth=1.4];',
        "",
        f'    title [shape=plaintext, style="", width={_fmt(width - 2 * MARGIN)}, height={_fmt(TITLE_H)}, '
        f'pos="{pt(width / 2, MARGIN + TITLE_H / 2 - 0.05)}", label=<<font point-size="17"><b>leafview: the layers '
        'and the imports between them</b></font><br/><font point-size="11">arrow A → B: modules of A import '
        'modules of B; number: (importing module, imported module) pairs, from the import graph</font><br/>'
        '<font point-size="11">arcs into core and the base modules run on the left, the others on the right; '
        'colour: the importing layer</font>>];',
        "",
        "    // the layers, top to bottom in the order of the layers contract in pyproject.toml",
    ]
    for box in boxes:
        attrs = (f'pos="{pt(x_mid, box.top + box.height / 2)}", width={_fmt(COL_W)}, height={_fmt(box.height)}, '
                 f"label={_html(box)}")
        if box.node == API:
            attrs += ', style="rounded,filled,dashed", fillcolor="#f1ecf7", color="#6a3d9a"'
        elif box.node == BASE:
            attrs += ', fillcolor="#eeeeee", color="#888888"'
        out.append(f'    "{box.node}" [{attrs}];')
    out += ["", "    // imports between layers; each count is also drawn as a small box over its arrow"]
    placed: list[tuple[float, float]] = []
    gaps = [round((a.bottom + b.top) / 2, 3) for a, b in zip(boxes, boxes[1:])]
    for arc in sorted(arcs, key=lambda a: (ORDER.index(a.source), ORDER.index(a.target))):
        src, dst = by_node[arc.source], by_node[arc.target]
        colour = COLOURS[arc.source]
        if arc.side == 0:
            points = [(x_mid, src.bottom), (x_mid, src.bottom + 0.1), (x_mid, dst.top - ARROW - 0.1),
                      (x_mid, dst.top - ARROW)]
            tip = (x_mid, dst.top)
            label = (x_mid, (src.bottom + dst.top - ARROW) / 2)
        else:
            edge_x = x_left if arc.side < 0 else x_left + COL_W
            lane_x = edge_x + arc.side * (LANE0 + arc.lane * LANE)
            r, s = RADIUS, arc.side
            y0, y1 = arc.y_out, arc.y_in
            points = [(edge_x, y0), (edge_x + s * 0.05, y0), (lane_x - s * (r + 0.05), y0), (lane_x - s * r, y0),
                      (lane_x - s * r * 0.45, y0), (lane_x, y0 + r * 0.45), (lane_x, y0 + r),
                      (lane_x, y0 + r + 0.05), (lane_x, y1 - r - 0.05), (lane_x, y1 - r),
                      (lane_x, y1 - r * 0.45), (lane_x - s * r * 0.45, y1), (lane_x - s * r, y1),
                      (lane_x - s * (r + 0.05), y1), (edge_x + s * (ARROW + 0.05), y1), (edge_x + s * ARROW, y1)]
            tip = (edge_x, y1)
            crossings = [y for a in arcs if a.side == s and a is not arc and a.lane > arc.lane
                         for y in (a.y_out, a.y_in)]
            label = (lane_x, _label_y(lane_x, y0 + r + 0.15, y1 - r - 0.15, placed, gaps, crossings))
        placed.append(label)
        spline = "e," + pt(*tip) + " " + " ".join(pt(x, y) for x, y in points)
        out.append(f'    "{arc.source}" -> "{arc.target}" [label="{arc.count}", lp="{pt(*label)}", color="{colour}", '
                   f'fontcolor="{colour}", pos="{spline}"];')
        out.append(f'    "count {arc.source} -> {arc.target}" [label="{arc.count}", pos="{pt(*label)}", '
                   f'width={_fmt(0.14 + 0.08 * len(str(arc.count)))}, height=0.2, style="rounded,filled", '
                   f'fillcolor=white, color="{colour}", fontcolor="{colour}", fontsize=11, penwidth=1];')
    out.append("}")
    return "\n".join(out) + "\n"


def _label_y(x: float, lo: float, hi: float, placed: list[tuple[float, float]], gaps: list[float],
             crossings: list[float]) -> float:
    """A height for a count on the vertical part of an arc (between lo and hi): in a gap between two
    boxes if one is free (no arc turns there), else near the middle; never on another arc's
    horizontal run (``crossings``) nor on a count already placed on a neighbouring lane."""
    mid = (lo + hi) / 2
    sweep = [mid + k * 0.09 * sign for k in range(0, 60) for sign in (1, -1)]
    for y in sorted((g for g in gaps if lo <= g <= hi), key=lambda g: abs(g - mid)) + sweep:
        if (lo <= y <= hi and all(abs(x - px) > 0.3 or abs(y - py) > 0.26 for px, py in placed)
                and all(abs(y - c) > 0.13 for c in crossings)):
            return round(y, 3)
    return round(mid, 3)


def render(dot_path: Path = DOT_PATH) -> None:
    """An SVG and a PNG at most about 1200 px wide from the DOT file, with Graphviz."""
    dot = shutil.which("dot")
    if dot is None:
        raise SystemExit("Graphviz 'dot' is not installed (Debian: apt-get install graphviz); the .dot file is written")
    common = [dot, "-Kneato", "-n2", str(dot_path)]
    subprocess.run(common + ["-Tsvg", "-o", str(SVG_PATH)], check=True)
    subprocess.run(common + ["-Tpng", f"-Gdpi={PNG_DPI}", f"-Gsize={PNG_MAX_WIDTH_IN},60", "-o", str(PNG_PATH)],
                   check=True)
    try:                                                  # a palette PNG is a third of the size
        from PIL import Image
    except ImportError:
        return
    with Image.open(PNG_PATH) as image:
        small = image.convert("RGB").quantize(colors=128, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    small.save(PNG_PATH, optimize=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if the committed .dot file is stale")
    args = parser.parse_args(argv)
    text = dot_source()
    rel = DOT_PATH.relative_to(ROOT)
    if args.check:
        if not DOT_PATH.exists() or DOT_PATH.read_text(encoding="utf-8") != text:
            print(f"{rel} is stale: run {REGENERATE}", file=sys.stderr)
            return 1
        print(f"{rel} is up to date")
        return 0
    DOT_PATH.write_text(text, encoding="utf-8")
    render()
    print(f"wrote {rel}, {SVG_PATH.relative_to(ROOT)}, {PNG_PATH.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
