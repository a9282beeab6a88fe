"""docs/architecture.md stays true: the layer picture is regenerated from the import graph and
compared with the committed DOT file, and the tool that draws it knows the layers of the contract.

Needs grimp (a test dependency), not Graphviz: only the DOT text is compared.
"""

from __future__ import annotations

import difflib
import importlib.util
import struct
import sys
import tomllib
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parent.parent
TOOL = ROOT / "tools" / "make_architecture.py"
DOT = ROOT / "docs" / "images" / "architecture.dot"
PNG = ROOT / "docs" / "images" / "architecture.png"


def _tool() -> ModuleType:
    """tools/make_architecture.py, loaded from its path (tools/ is not a package)."""
    spec = importlib.util.spec_from_file_location("make_architecture", TOOL)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["make_architecture"] = module          # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_committed_layer_picture_matches_the_import_graph() -> None:
    tool = _tool()
    expected = tool.dot_source()
    committed = DOT.read_text(encoding="utf-8") if DOT.exists() else ""
    if committed != expected:
        diff = difflib.unified_diff(committed.splitlines(), expected.splitlines(), "committed", "import graph",
                                    n=0, lineterm="")
        changed = [line[:160] for line in diff][:30]
        pytest.fail(f"docs/images/architecture.dot is stale (the imports between layers changed): run "
                    f"`{tool.REGENERATE}` (needs Graphviz for the .svg/.png) and commit the three files\n"
                    + "\n".join(changed), pytrace=False)


def test_tool_layers_follow_the_layers_contract() -> None:
    """The picture's layer order is the order of the layers contract in pyproject.toml."""
    tool = _tool()
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    contracts = config["tool"]["importlinter"]["contracts"]
    layers = next(c["layers"] for c in contracts if c.get("type") == "layers")
    # the base modules close the list: one layer or a few (errors under atomic, which raises them)
    split = next(i for i in range(len(layers)) if all(
        m.strip() in tool.BASE_MODULES for layer in layers[i:] for m in layer.split("|")))
    packages, base = layers[:split], layers[split:]
    # sibling layers ("a | b": neither imports the other) are drawn as boxes side by side, in order
    assert [name for name, _ in tool.LAYERS] == [m.strip() for layer in packages for m in layer.split("|")]
    assert sorted(m.strip() for layer in base for m in layer.split("|")) == sorted(tool.BASE_MODULES)


def test_png_is_at_most_1200_px_wide() -> None:
    with PNG.open("rb") as f:
        header = f.read(24)
    assert header[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", header[16:24])
    assert width <= 1200, f"{PNG.name} is {width} px wide"


def test_architecture_page_shows_the_picture() -> None:
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    assert "images/architecture.png" in text or "images/architecture.svg" in text
    assert "tools/make_architecture.py" in text
