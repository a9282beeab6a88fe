"""The package's shape: imports run one way through the layers (the import-linter contracts in
pyproject.toml), no import cycle between files, imports at module top, ruff and mypy clean, and
the public API the README shows works after a plain ``import leafview``.
"""

from __future__ import annotations

import ast
import importlib
import re
import subprocess
import sys
from pathlib import Path

import grimp
import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "leafview"

# function-level imports of third-party packages that are optional or heavy, and only needed by
# one command or writer: USD (usd-core), the matplotlib baseline of the thumbnail benchmark
OPTIONAL_LAZY = {"pxr", "matplotlib", "mpl_toolkits"}
# the lazy sub-command dispatch is done with importlib, not import statements; these few
# function-level leafview imports remain, each for a reason written beside it in the code
MAX_FUNCTION_LEVEL_LEAFVIEW_IMPORTS = 5


def _run(args: list[str], **kwargs: object) -> subprocess.CompletedProcess[str]:
    return subprocess.run(args, cwd=ROOT, capture_output=True, text=True, **kwargs)  # type: ignore[call-overload]


def test_import_contracts_hold() -> None:
    """``lint-imports`` with the contracts of pyproject.toml: the layers, GL-free lower layers,
    the numpy-only core, the public alias modules, exporters apart from the viewer."""
    code = ("import sys; from importlinter.cli import lint_imports; "
            "sys.exit(lint_imports(config_filename='pyproject.toml', no_cache=True, no_logo=True))")
    result = _run([sys.executable, "-c", code])
    assert result.returncode == 0, result.stdout[-6000:] + result.stderr[-2000:]
    assert "BROKEN" not in result.stdout
    assert result.stdout.count("KEPT") >= 5, result.stdout


def test_layers_contract_names_every_subpackage() -> None:
    """A new subpackage must be placed in a layer, or the layers contract would not see it."""
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    subpackages = {p.parent.name for p in PACKAGE.glob("*/__init__.py")}
    for name in sorted(subpackages):
        assert f'"leafview.{name}' in text or f"| leafview.{name}" in text, f"leafview.{name} is in no layer"


def _strongly_connected(graph: grimp.ImportGraph) -> list[list[str]]:
    """Tarjan's strongly connected components of the leafview module graph (size > 1 only)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph.find_modules_directly_imported_by(v):
            if not w.startswith("leafview"):
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))
    for module in sorted(graph.modules):
        if module.startswith("leafview") and module not in index:
            visit(module)
    return found


def test_no_import_cycle_between_files() -> None:
    """Every import counts, also those inside functions (only ``if TYPE_CHECKING`` blocks are left
    out: they never run)."""
    graph = grimp.build_graph("leafview", exclude_type_checking_imports=True)
    cycles = _strongly_connected(graph)
    assert cycles == [], "import cycles between files:\n" + "\n".join(" -> ".join(c) for c in cycles)


def _function_level_imports() -> list[tuple[str, int, str]]:
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for fn in ast.walk(tree):
            if not isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            for node in ast.walk(fn):
                if isinstance(node, ast.ImportFrom):
                    name = "." * node.level + (node.module or "")
                elif isinstance(node, ast.Import):
                    name = node.names[0].name
                else:
                    continue
                out.append((str(path.relative_to(ROOT)), node.lineno, name))
    return sorted(set(out))


def test_imports_sit_at_module_top() -> None:
    """Imports inside functions only for optional heavy dependencies, and at most
    MAX_FUNCTION_LEVEL_LEAFVIEW_IMPORTS of leafview itself (sub-commands load with importlib)."""
    lazy = _function_level_imports()
    ours = [x for x in lazy if x[2].startswith((".", "leafview"))]
    others = [x for x in lazy if x not in ours and x[2].split(".")[0] not in OPTIONAL_LAZY]
    assert others == [], f"function-level imports of non-optional packages: {others}"
    assert len(ours) <= MAX_FUNCTION_LEVEL_LEAFVIEW_IMPORTS, f"function-level leafview imports: {ours}"


def test_ruff_is_clean() -> None:
    """pyflakes, isort, bugbear and pyupgrade rules as configured in pyproject.toml."""
    targets = [t for t in ("leafview", "tests", "tools", "bench", "examples") if (ROOT / t).exists()]
    result = _run([sys.executable, "-m", "ruff", "check", *targets])
    assert result.returncode == 0, result.stdout[-6000:] + result.stderr[-2000:]


@pytest.mark.slow
def test_mypy_is_clean() -> None:
    """mypy on the package with the configuration of pyproject.toml."""
    result = _run([sys.executable, "-m", "mypy", "--no-incremental"], timeout=900)
    assert result.returncode == 0, result.stdout[-8000:] + result.stderr[-2000:]


# -- the public API after `import leafview` -----------------------------------------------------
_REF = re.compile(r"(?<![\w.])leafview(?:\.[A-Za-z_][A-Za-z0-9_]*)+")
_CALLED = re.compile(r"(?<![\w.])(leafview(?:\.[A-Za-z_][A-Za-z0-9_]*)+)\s*\(")


def _readme_code() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    inline = re.findall(r"`([^`\n]+)`", text)
    return "\n".join(blocks + inline)


def _resolve_by_import(dotted: str) -> object:
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj: object = importlib.import_module(".".join(parts[:k]))
        except ModuleNotFoundError:
            continue
        for attr in parts[k:]:
            obj = getattr(obj, attr)
        return obj
    raise ModuleNotFoundError(dotted)


def test_every_leafview_name_in_the_readme_exists() -> None:
    code = _readme_code()
    refs = sorted(set(_REF.findall(code)))
    assert len(refs) > 10
    missing = []
    for ref in refs:
        try:
            _resolve_by_import(ref)
        except (ModuleNotFoundError, AttributeError) as exc:
            missing.append(f"{ref}: {exc}")
    assert missing == [], "README names that do not exist:\n" + "\n".join(missing)


def test_public_api_works_after_import_leafview() -> None:
    """Every name the README calls as ``leafview.x.y(...)``, and everything in ``leafview.__all__``,
    resolves by attribute access after a plain ``import leafview`` in a fresh interpreter, and
    the GL-free part of it loads no OpenGL."""
    called = sorted(set(_CALLED.findall(_readme_code())) | {"leafview.landmarks.fit_margin",
                                                              "leafview.shapes.catalogue",
                                                              "leafview.shapes.shapes_params"})
    gl_names = {"leafview.render", "leafview.gpu.evaluate", "leafview.gpu.LeafRenderer"}
    gl_free = [c for c in called if c not in gl_names and not c.startswith("leafview.gpu")]
    code = f"""
import functools, sys
import leafview
def walk(dotted):
    return functools.reduce(getattr, dotted.split(".")[1:], leafview)
for dotted in {gl_free!r}:
    walk(dotted)
for name in leafview.__all__:
    if name not in ("gpu", "render"):
        getattr(leafview, name)
gl = [m for m in ("moderngl", "glcontext", "glfw", "imgui_bundle") if m in sys.modules]
assert not gl, f"GL loaded by the GL-free API: {{gl}}"
for dotted in {sorted(gl_names & set(called)) + ["leafview.gpu", "leafview.render"]!r}:
    walk(dotted)
print("ok", len({gl_free!r}))
"""
    result = _run([sys.executable, "-c", code])
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.startswith("ok")
