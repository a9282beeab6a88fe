# example: run (needs a display: the test starts Xvfb)
"""The viewer with a panel of your own: two buttons that edit the leaf through the viewer's state,
so each click is one undoable step (Ctrl+Z) like any slider.

    python examples/viewer_panel.py [PRESET] [--frames N --screenshot FILE]

Without ``--frames`` the window stays open until you close it.
"""

from __future__ import annotations

import argparse

from imgui_bundle import imgui

import leafview
from leafview.app.state import ViewerState
from leafview.app.viewer import Viewer
from leafview.app.window import ViewerWindow
from leafview.core.edits import scale_width
from leafview.resources import resolve_preset


def leaf_tools(state: ViewerState) -> None:
    """Drawn every frame inside the settings panel, below the parameter groups."""
    if imgui.collapsing_header("My tools", imgui.TreeNodeFlags_.default_open):
        if imgui.button("Wider ×1.1"):
            state.apply(lambda leaf: scale_width(leaf, 1.1))
        imgui.same_line()
        if imgui.button("Serrate"):
            state.set_field("jitter.enabled", True)
        imgui.text(f"Ω: {len(state.params.to_vector())} numbers, {state.params.shape.rows} silhouette rows")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("preset", nargs="?", default="beech")
    parser.add_argument("--frames", type=int, default=None)
    parser.add_argument("--screenshot", default=None)
    args = parser.parse_args()

    path = resolve_preset(args.preset)
    state = ViewerState(leafview.LeafParams.load(path), path)

    def make_view(ctx):  # the window's GL context -> the view it shows
        viewer = Viewer(ctx, state)
        viewer.add_panel(leaf_tools)
        return viewer

    with ViewerWindow(state, (1024, 640), title="leafview: custom panel", make_view=make_view) as window:
        raise SystemExit(window.run(frames=args.frames, screenshot=args.screenshot))


if __name__ == "__main__":
    main()
