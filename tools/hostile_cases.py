"""The hostile-input rerun of issue 14: a fixed corpus of careless and hostile uses of ``leafview``.

Each case runs the command line (or, for the Python API, a tiny snippet) as a subprocess in a
folder of its own, with a time-out and a memory watchdog, and is classified as

* ``clean refusal``: exit 1 or 2, one line on stderr (after argparse's usage block), nothing written;
* ``success``: exit 0, every file it wrote reads back complete and finite, under the output folder;
* ``traceback``: a Python traceback, or a death by signal / an exit code other than 0, 1, 2;
* ``hang``: no answer within the case's time-out (the process group is killed);
* ``wrong outcome``: anything else the promise forbids: a file outside the output folder, a
  temporary or partial file left, a replaced link or device, a refused run that wrote something,
  exit 0 with a corrupt, non-finite or blank file, another file's content in a message, more than
  one error line, memory past the watchdog, success where a refusal is due (or the reverse);
* ``skipped``: the case needs something this machine does not allow (mounting a tmpfs, mknod).

It prints a table of counts by class (and by category), every case that is not clean as
``command -> observed``, and writes a JSON report with ``--json``. Run it from anywhere::

    python tools/hostile_cases.py --json /tmp/hostile.json          # the whole corpus (a few minutes)
    python tools/hostile_cases.py --only fifo --jobs 1              # the cases whose name has "fifo"
    python tools/hostile_cases.py --list                            # names and commands only

``tests/fuzz/test_fuzz_hostile.py`` (slow) runs it and asserts 0 tracebacks, 0 hangs, 0 wrong outcomes.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
import tomllib
from collections import Counter
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomli_w

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
from support.promise import (  # noqa: E402  (tests/support is not a package on the path)
    file_problem,
    image_coverage,
    is_temp_name,
    snapshot,
    stream_problems,
    tree_problems,
)

CLI = "import sys; from leafview.cli import main; sys.exit(main())"
SECRET = "SECRET_7f3a9c"
CLASSES = ("clean refusal", "success", "traceback", "hang", "wrong outcome", "skipped")
PRESETS = ROOT / "assets" / "presets"
GiB = 1 << 30


# -- inputs ---------------------------------------------------------------------------------------
def preset_doc(name: str = "ovate") -> dict[str, Any]:
    return tomllib.loads((PRESETS / f"{name}.toml").read_text(encoding="utf-8"))


def preset(base: str = "ovate", **groups: dict[str, Any]) -> str:
    """TOML text of a built-in preset with some fields replaced (``shape={"zf": [...]}``)."""
    doc = preset_doc(base)
    for group, values in groups.items():
        doc.setdefault(group, {}).update(values)
    return tomli_w.dumps(doc)


def omega(name: str = "ovate") -> list[float]:
    shape = preset_doc(name)["shape"]
    return [*shape["a1"], *shape["a2"], *[x for row in shape["silhouette"] for x in row], *shape["zf"], *shape["zg"]]


def leaf_set(names: list[str], **extra: Any) -> str:
    leaves = [{"name": n, "omega": omega(), **extra} for n in names]
    return json.dumps({"leafview": 1, "leaves": leaves})


def scene_text(species: list[dict[str, Any]], leaves: int = 10, fmt: str = "toml", **scene: Any) -> str:
    doc = {"schema": 1, "scene": {"leaves": leaves, **scene}, "species": species}
    return tomli_w.dumps(doc) if fmt == "toml" else json.dumps(doc)


def landmark_text() -> str:
    return (ROOT / "assets" / "landmarks" / "emarginate.toml").read_text(encoding="utf-8")


def lobed_doc() -> dict[str, Any]:
    return tomllib.loads((ROOT / "assets" / "compound" / "maple.toml").read_text(encoding="utf-8"))


# -- the case folder ------------------------------------------------------------------------------
class Skip(Exception):
    """The case needs what this machine does not allow."""


@dataclass
class Ctx:
    """A case's folder ``root``: ``in/``, ``out/``, ``trap/`` (``secret.toml``, ``target.png``)."""

    root: Path
    mounts: list[Path] = field(default_factory=list)

    def write(self, rel: str, data: str | bytes) -> Path:
        path = self.root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data.encode("utf-8", "surrogatepass") if isinstance(data, str) else data)
        return path

    def fifo(self, rel: str) -> Path:
        path = self.root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        os.mkfifo(path)
        return path

    def link(self, rel: str, target: str | Path) -> Path:
        path = self.root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.symlink_to(target)
        return path

    def mount(self, rel: str, size: str = "64k", *, readonly: bool = False, fill: bool = False) -> Path:
        """A tmpfs at ``rel`` (read-only, or filled up to the last byte)."""
        path = self.root / rel
        path.mkdir(parents=True, exist_ok=True)
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                              capture_output=True, text=True)
        if done.returncode != 0:
            raise Skip(f"cannot mount a tmpfs: {done.stderr.strip()[:120]}")
        self.mounts.append(path)
        if fill:   # write until the file system is full, to the last block
            with contextlib.suppress(OSError), open(path / "filler", "wb", buffering=0) as fh:
                while True:
                    fh.write(b"\0" * 512)
        if readonly:
            subprocess.run(["mount", "-o", "remount,ro", str(path)], check=True, capture_output=True)
        return path

    def device(self, rel: str) -> Path:
        path = self.root / rel
        try:
            os.mknod(path, 0o666 | 0o020000, os.makedev(1, 3))   # a character device like /dev/null
        except OSError as exc:
            raise Skip(f"cannot mknod: {exc}") from None
        return path


def _standard(ctx: Ctx) -> None:
    for folder in ("in", "out", "trap"):
        (ctx.root / folder).mkdir()
    ctx.write("trap/secret.toml", f'{SECRET} = "{SECRET}"\n' + (PRESETS / "ovate.toml").read_text())
    ctx.write("trap/target.png", b"ORIGINAL")


# -- cases ----------------------------------------------------------------------------------------
@dataclass
class Case:
    """One hostile use. ``argv`` runs the CLI; ``snippet`` runs Python (the API: print nothing,
    raise a LeafviewError to refuse). ``expect``: refuse, succeed or any (either, cleanly)."""

    name: str
    category: str
    argv: list[str] | None = None
    snippet: str | None = None
    setup: Callable[[Ctx], None] | None = None
    expect: str = "refuse"
    out: tuple[str, ...] = ("out",)
    timeout: float = 60.0
    not_blank: bool = False              # on success, images must show the leaf
    max_output: int | None = None        # bytes, on success
    interrupt: tuple[int, float] | None = None   # (signal, at most seconds to wait for a .part file)
    rerun: bool = False                  # after the (interrupted) run, run the same command again
    twice: bool = False                  # two processes at once, same command
    fsize: int | None = None             # RLIMIT_FSIZE of the child (a "disk" that fills up)
    mem_limit: int = 4 * GiB
    all_or_none: int | None = None       # an interrupted run leaves none or all of this many files
    label: str = ""                      # how the report shows a snippet
    forbidden: tuple[str, ...] = (SECRET, "root:x:0:0")   # text no output may contain

    def command(self) -> str:
        if self.label:
            return self.label
        if self.snippet is not None:
            return "python: " + " ".join(self.snippet.split())[:200]
        return "leafview " + " ".join(_short(a) for a in self.argv or [])


def _short(arg: str, n: int = 70) -> str:
    text = repr(arg)[1:-1] if (not arg or any(c in arg for c in " \n\t\x00")) else arg
    text = f"'{text}'" if (not arg or " " in arg) else text
    return text if len(text) <= n else f"{text[:30]}…({len(arg):,} chars)…{text[-20:]}"


def corpus() -> list[Case]:
    cases: list[Case] = []
    add = cases.append

    # 1. output names derived from input ---------------------------------------------------------
    names = {"dotdot": ["../escaped"], "absolute": ["@TRAP@/absolute"], "nested": ["a/b/c"], "dup": ["dup", "dup"],
             "empty-dot": ["", "."], "dotdot-only": [".."], "nul": ["a\x00b"], "300-bytes": ["x" * 300],
             "300-bytes-utf8": ["é" * 150], "newline": ["line\nbreak"], "dash": ["-rf"], "hidden": [".hidden"]}
    for key, ns in names.items():
        def setup(ctx: Ctx, ns: list[str] = ns) -> None:
            ctx.write("in/set.leaves.json",
                      leaf_set([n.replace("@TRAP@", str(ctx.root / "trap")) for n in ns]))
        add(Case(f"names-{key}-render", "output names from input", ["render", "in/set.leaves.json", "-o", "out",
                                                                      "--size", "16"], setup=setup, expect="any"))
        add(Case(f"names-{key}-export", "output names from input", ["export", "in/set.leaves.json", "-o", "out",
                                                                      "--backend", "numpy"], setup=setup, expect="any"))
    for key in ("dotdot", "absolute"):
        def setup2(ctx: Ctx, ns: list[str] = names[key]) -> None:
            ctx.write("in/set.leaves.json", leaf_set([n.replace("@TRAP@", str(ctx.root / "trap")) for n in ns]))
        add(Case(f"names-{key}-export-obj", "output names from input",
                 ["export", "in/set.leaves.json", "-o", "out", "--format", "obj", "--backend", "numpy"], setup=setup2,
                 expect="any"))
        add(Case(f"names-{key}-sheet", "output names from input",
                 ["render", "in/set.leaves.json", "--sheet", "-o", "out/sheet.png", "--size", "16"], setup=setup2,
                 expect="succeed"))

    # 2. a full disk --------------------------------------------------------------------------------
    for suffix in ("png", "tif", "exr"):
        add(Case(f"disk-full-render-{suffix}", "full disk", ["render", "ovate", "-o", f"tiny/out.{suffix}",
                                                              "--size", "2048"],
                 setup=lambda c: c.mount("tiny"), out=("tiny",), expect="any"))
    add(Case("disk-full-scene-png", "full disk", ["scene", "--leaves", "200", "-o", "tiny/s.png", "--size", "2048x2048"],
             setup=lambda c: c.mount("tiny"), out=("tiny",), expect="any"))
    for suffix in ("glb", "gltf", "usda", "usdc", "obj", "ply"):
        add(Case(f"disk-full-export-{suffix}", "full disk", ["export", "maize", "-o", f"tiny/m.{suffix}"],
                 setup=lambda c: c.mount("tiny"), out=("tiny",), expect="any"))
    add(Case("disk-full-leaf-json", "full disk", ["export", "ovate", "-o", "full/x.leaf.json"],
             setup=lambda c: c.mount("full", "16k", fill=True), out=("full",)))
    add(Case("disk-full-scene-save", "full disk", ["scene", "--leaves", "10", "--save", "full/s.toml"],
             setup=lambda c: c.mount("full", "16k", fill=True), out=("full",)))
    add(Case("disk-full-render-dir", "full disk", ["render", "ovate", "lanceolate", "maize", "-o", "tiny/dir",
                                                   "--size", "1024"],
             setup=lambda c: c.mount("tiny", "96k"), out=("tiny",), expect="any"))
    for name, argv in (("render-png", ["render", "ovate", "-o", "out/x.png", "--size", "1024"]),
                       ("export-glb", ["export", "maize", "-o", "out/m.glb"]),
                       ("export-usdc", ["export", "maize", "-o", "out/m.usdc"]),
                       ("export-ply", ["export", "maize", "-o", "out/m.ply"]),
                       ("scene-png", ["scene", "--leaves", "100", "-o", "out/s.png", "--size", "1024x1024"])):
        add(Case(f"file-size-limit-{name}", "full disk", argv, fsize=16 * 1024, expect="any"))
    for key, argv in (("obj", ["export", "maize", "-o", "out/m.obj"]),
                      ("ply", ["export", "maize", "-o", "out/m.ply"]),
                      ("gltf", ["export", "maize", "-o", "out/m.gltf"]),
                      ("leaf-json", ["export", "ovate", "-o", "out/x.leaf.json"]),
                      ("scene-save", ["scene", "--leaves", "5", "--save", "out/s.toml"])):
        limit = 600 if key in ("obj", "ply", "gltf") else 60
        add(Case(f"patched-writer-enospc-{key}", "full disk", snippet=_enospc(*argv, limit=limit),
                 label="leafview " + " ".join(argv) + f"  (Python writes fail with ENOSPC after {limit} bytes)"))

    # 3. non-finite output ----------------------------------------------------------------------------
    far = {"translation-1e308": {"transform": {"translation": [1e308, 0.0, 0.0]}},
           "translation-1e30": {"transform": {"translation": [1e30, 0.0, 0.0]}},
           "zf-1e308": {"shape": {"zf": [1e308, 1e308, 1e308]}},
           "scale-1e300": {"transform": {"scale": 1e300}},
           "rotation-1e308": {"transform": {"rotation": [1e308, 0.0, 0.0]}}}
    targets = {"translation-1e308": ["ply", "obj", "glb", "gltf", "usda", "png"], "translation-1e30": ["png", "ply"],
               "zf-1e308": ["png", "glb", "obj"], "scale-1e300": ["png", "ply", "usdc"], "rotation-1e308": ["png"]}
    for key, groups in far.items():
        for suffix in targets[key]:
            def setup3(ctx: Ctx, groups: dict[str, Any] = groups) -> None:
                ctx.write("in/far.toml", preset("ovate", **groups))
            argv = (["render", "in/far.toml", "-o", "out/x.png", "--size", "32"] if suffix == "png"
                    else ["export", "in/far.toml", "-o", f"out/x.{suffix}", "--backend", "numpy"])
            add(Case(f"non-finite-{key}-{suffix}", "non-finite output", argv, setup=setup3, expect="any",
                     not_blank=True))
    add(Case("non-finite-set-translation-glb", "non-finite output", ["export", "in/set.leaves.json", "-o", "out/s.glb"],
             setup=lambda c: c.write("in/set.leaves.json", leaf_set(["a", "b"], transform={"translation": [1e308, 0, 0]})),
             expect="any"))

    # 4. input paths that reach other files -------------------------------------------------------------
    for key, ref in (("dotdot", "../trap/secret.toml"), ("absolute", "@TRAP@/secret.toml"), ("etc", "/etc/passwd"),
                     ("climb", "sub/../../trap/secret.toml"), ("in-folder-bad", "sub/bad.toml"),
                     ("symlink-out", "link.toml")):
        def setup4(ctx: Ctx, ref: str = ref) -> None:
            ctx.write("in/sub/bad.toml", f"{SECRET}_BAD = 1\n" + (PRESETS / "ovate.toml").read_text())
            ctx.link("in/link.toml", ctx.root / "trap" / "secret.toml")
            ctx.write("in/s.toml", scene_text([{"preset": ref.replace("@TRAP@", str(ctx.root / "trap"))}]))
        add(Case(f"species-preset-{key}", "input paths", ["scene", "in/s.toml", "-o", "out/s.png", "--size", "32x32"],
                 setup=setup4, forbidden=(SECRET, "root:x:0:0")))
    add(Case("species-preset-in-folder-ok", "input paths", ["scene", "in/s.toml", "-o", "out/s.png", "--size", "32x32"],
             setup=lambda c: (c.write("in/sub/ok.toml", (PRESETS / "ovate.toml").read_text()),
                              c.write("in/s.toml", scene_text([{"preset": "sub/ok.toml"}]))),
             expect="succeed"))
    add(Case("species-preset-dotdot-export", "input paths", ["export", "in/s.toml", "-o", "out/s.glb"],
             setup=lambda c: c.write("in/s.toml", scene_text([{"preset": "../trap/secret.toml"}]))))

    # 5. outputs that are links, devices, FIFOs -------------------------------------------------------------
    for argv, rel in ((["render", "ovate", "-o", "out/link.png", "--size", "16"], "out/link.png"),
                      (["export", "ovate", "-o", "out/link.glb", "--backend", "numpy"], "out/link.glb"),
                      (["export", "ovate", "-o", "out/link.leaf.json"], "out/link.leaf.json"),
                      (["scene", "--leaves", "5", "--save", "out/link.toml"], "out/link.toml")):
        add(Case(f"output-symlink-{Path(rel).name}", "special outputs", argv,
                 setup=lambda c, rel=rel: c.link(rel, c.root / "trap" / "target.png")))
    add(Case("output-dangling-symlink", "special outputs", ["render", "ovate", "-o", "out/new.png", "--size", "16"],
             setup=lambda c: c.link("out/new.png", c.root / "trap" / "new.png")))
    add(Case("output-char-device", "special outputs", ["render", "ovate", "-o", "out/dev.png", "--size", "16"],
             setup=lambda c: c.device("out/dev.png")))
    add(Case("output-fifo", "special outputs", ["render", "ovate", "-o", "out/fifo.png", "--size", "16"],
             setup=lambda c: c.fifo("out/fifo.png"), timeout=20))
    add(Case("output-fifo-save", "special outputs", ["scene", "--leaves", "5", "--save", "out/fifo.toml"],
             setup=lambda c: c.fifo("out/fifo.toml"), timeout=20))

    # 6. values the validator accepts that used to crash the beam solver -----------------------------------
    bend = {"bending": {"load": 40.0, "twist": 25.0}}
    for key, groups in {"a1-y-10": {"shape": {"a1": [0.0, 10.0, 0.0]}}, "a1-x-10": {"shape": {"a1": [10.0, 0.3, 0.0]}},
                        "a2-y-minus-10": {"shape": {"a2": [0.0, -10.0, 0.0]}},
                        "xs-10": {"shape": {"silhouette": [[0.12, 10.0, 0.0], [0.4, 10.0, 0.0], [0.75, 10.0, 0.0]]}},
                        "zf-10": {"shape": {"zf": [10.0, -10.0, 10.0]}},
                        "load-1e4": {"bending": {"load": 1e4, "twist": 720.0}},
                        "stiff-min": {"bending": {"load": 1e4, "stiffness": 1e-3, "petiole_length": 10.0}},
                        "a1-1e6": {"shape": {"a1": [0.0, 1e6, 0.0]}}}.items():
        def setup6(ctx: Ctx, groups: dict[str, Any] = groups) -> None:
            ctx.write("in/bent.toml", preset("maize", **{**bend, **groups}))
        add(Case(f"beam-{key}-render", "values that crash deeper", ["render", "in/bent.toml", "-o", "out/x.png",
                                                                     "--size", "32"], setup=setup6, expect="any"))
        add(Case(f"beam-{key}-export", "values that crash deeper", ["export", "in/bent.toml", "-o", "out/x.obj",
                                                                     "--backend", "numpy"], setup=setup6, expect="any"))
    for scale in ("1e-300", "1e300", "1e30"):
        add(Case(f"beam-set-scale-{scale}", "values that crash deeper",
                 ["export", "in/set.leaves.json", "-o", "out/s.glb", "--backend", "numpy"],
                 setup=lambda c, s=float(scale): c.write("in/set.leaves.json", json.dumps(
                     {"leafview": 1, "leaves": [{"name": "a", "omega": omega("maize"), "bending": {"load": 6},
                                                 "transform": {"scale": s}}, {"name": "b", "omega": omega()}]})),
                 expect="any"))

    for key, plant in (("whorl-inf", {"whorl": float("inf")}), ("branches-nan", {"branches": float("nan")}),
                       ("branch-length-denormal", {"branch_length": 5e-324}), ("internode-denormal", {"internode": 5e-324})):
        add(Case(f"scene-plant-{key}", "values that crash deeper", ["scene", "in/s.toml", "-o", "out/s.png", "--size",
                                                                    "16x16"],
                 setup=lambda c, plant=plant: c.write("in/s.toml", tomli_w.dumps(
                     {"schema": 1, "scene": {"leaves": 10, "plants": 0}, "species": [{"preset": "ovate"}],
                      "plant": plant})), expect="any"))
    for key, doc in (("schema-list", {**preset_doc(), "schema": [0.0] * 1000}),
                     ("key-5000-chars", {**preset_doc(), "shape": {**preset_doc()["shape"], "a" + "9" * 5000: [0, 1, 0]}}),
                     ("name-list", {**preset_doc(), "name": ["x" * 100] * 100})):
        add(Case(f"message-echo-{key}", "unbounded fields", ["render", "in/x.json", "-o", "out/x.png", "--size", "16"],
                 setup=lambda c, doc=doc: c.write("in/x.json", json.dumps(doc))))

    # 7. file-system faults ----------------------------------------------------------------------------------
    for name, argv in (("render", ["render", "ovate", "-o", "ro/x.png", "--size", "16"]),
                       ("export-glb", ["export", "ovate", "-o", "ro/x.glb"]),
                       ("export-usda", ["export", "ovate", "-o", "ro/x.usda"]),
                       ("export-leaf-json", ["export", "ovate", "-o", "ro/x.leaf.json"]),
                       ("scene-save", ["scene", "--leaves", "5", "--save", "ro/s.toml"]),
                       ("shapes-lobed", ["shapes", "--lobed", "maple", "-o", "ro/m.png", "--size", "32"]),
                       ("morph", ["morph", "ovate", "cordate", "--frames", "2", "--fast", "--size", "8", "-o", "ro/m"])):
        add(Case(f"readonly-folder-{name}", "file-system faults", argv,
                 setup=lambda c: c.mount("ro", readonly=True), out=("ro",)))
    for name, argv in (("render", ["render", "ovate", "-o", "file/x.png", "--size", "16"]),
                       ("export", ["export", "ovate", "-o", "file/x.glb"]),
                       ("scene-save", ["scene", "--leaves", "5", "--save", "file/s.toml"]),
                       ("morph", ["morph", "ovate", "cordate", "--frames", "2", "--fast", "--size", "8", "-o", "file/m"])):
        add(Case(f"parent-is-a-file-{name}", "file-system faults", argv, setup=lambda c: c.write("file", "x")))
    long_name = "a" * 300
    for name, argv in (("render", ["render", "ovate", "-o", f"out/{long_name}.png", "--size", "16"]),
                       ("export", ["export", "ovate", "-o", f"out/{long_name}.glb"]),
                       ("leaf-json", ["export", "ovate", "-o", f"out/{long_name}.leaf.json"]),
                       ("scene-save", ["scene", "--leaves", "5", "--save", f"out/{long_name}.toml"])):
        add(Case(f"name-300-bytes-{name}", "file-system faults", argv))
    add(Case("lobed-is-a-directory", "file-system faults", ["shapes", "--lobed", "in", "-o", "out/x.png"]))
    add(Case("output-under-proc", "file-system faults", ["render", "ovate", "-o", "/proc/leafview-hostile.png",
                                                         "--size", "16"], out=()))
    add(Case("output-under-proc-export", "file-system faults", ["export", "ovate", "-o", "/proc/leafview-hostile.glb"],
             out=()))
    for name, argv in (("render", ["render", "ovate", "-o", "", "--size", "16"]),
                       ("export", ["export", "ovate", "-o", ""]),
                       ("scene-save", ["scene", "--leaves", "5", "--save", ""])):
        add(Case(f"output-empty-string-{name}", "file-system faults", argv, out=("out", ".")))
    add(Case("output-deep-new-folder", "file-system faults", ["render", "ovate", "-o", "out/a/b/c/x.png", "--size", "16"],
             expect="succeed"))

    # 8. parser limits --------------------------------------------------------------------------------------
    runners = {"preset.json": ["render", "in/x.json", "-o", "out/x.png", "--size", "16"],
               "preset.toml": ["render", "in/x.toml", "-o", "out/x.png", "--size", "16"],
               "compact.leaf.json": ["render", "in/x.leaf.json", "-o", "out/x.png", "--size", "16"],
               "set.leaves.json": ["render", "in/x.leaves.json", "-o", "out", "--size", "16"],
               "scene.toml": ["scene", "in/x.toml", "-o", "out/s.png", "--size", "16x16"],
               "scene.json": ["scene", "in/x.json", "-o", "out/s.png", "--size", "16x16"],
               "lobed.toml": ["shapes", "--lobed", "in/x.toml", "-o", "out/l.png", "--size", "16"],
               "landmark.toml": ["morph", "in/x.toml", "ovate", "--frames", "2", "--fast", "--size", "8", "-o", "out/m"],
               "landmark.json": ["morph", "in/x.json", "ovate", "--frames", "2", "--fast", "--size", "8", "-o", "out/m"]}
    deep = 100_000
    variants: dict[str, Callable[[str], bytes]] = {
        "deep": lambda kind: (f'{{"schema": 1, "shape": {"[" * deep}{"]" * deep}}}' if kind.endswith("json")
                              else f'schema = 1\nshape = {"[" * deep}{"]" * deep}\n').encode(),
        "deep-table": lambda kind: ('{"a":' * deep + "1" + "}" * deep if kind.endswith("json")
                                    else "x = " + "{a = " * deep + "1" + "}" * deep + "\n").encode(),
        "bigint": lambda kind: (f'{{"schema": {"9" * 5000}, "leafview": {"9" * 5000}, "landmarks": {"9" * 5000}}}'
                                if kind.endswith("json")
                                else f"schema = {'9' * 5000}\nlobed = {'9' * 5000}\nlandmarks = {'9' * 5000}\n").encode(),
        "latin1": lambda kind: ('{"schema": 1, "name": "caf\xe9"}' if kind.endswith("json")
                                else 'schema = 1\nlobed = 1\nlandmarks = 1\nname = "caf\xe9"\n').encode("latin-1"),
        "nul-bytes": lambda kind: b'schema = 1\x00\nname = "a\x00b"\n',
        "empty": lambda kind: b"",
    }
    for kind, argv in runners.items():
        path = argv[1] if argv[0] != "shapes" else argv[2]
        for variant, make in variants.items():
            add(Case(f"parser-{variant}-{kind}", "parser limits", argv,
                     setup=lambda c, p=path, m=make, k=kind: c.write(p, m(k))))
        add(Case(f"parser-dev-zero-{kind}", "parser limits", argv,
                 setup=lambda c, p=path: c.link(p, "/dev/zero"), timeout=60))
        add(Case(f"parser-dev-null-{kind}", "parser limits", argv, setup=lambda c, p=path: c.link(p, "/dev/null")))
    add(Case("parser-300MB-sparse-preset", "parser limits", ["render", "in/big.toml", "-o", "out/x.png"],
             setup=lambda c: _sparse(c.root / "in" / "big.toml", 300 << 20), timeout=90))
    for name, argv in (("render", ["render", "in/nul.json", "-o", "out", "--size", "16"]),
                       ("export", ["export", "in/nul.json", "-o", "out", "--backend", "numpy"])):
        add(Case(f"nul-in-leaf-name-{name}", "parser limits", argv, expect="any",
                 setup=lambda c: c.write("in/nul.json", preset_json(name="a\x00b"))))

    # 9. a FIFO as every kind of input --------------------------------------------------------------------
    fifo_cases = {"render-toml": (["render", "in/f.toml", "-o", "out/x.png"], "in/f.toml"),
                  "render-json": (["render", "in/f.json", "-o", "out/x.png"], "in/f.json"),
                  "render-leaf-json": (["render", "in/f.leaf.json", "-o", "out/x.png"], "in/f.leaf.json"),
                  "render-leaves-json": (["render", "in/f.leaves.json", "-o", "out"], "in/f.leaves.json"),
                  "render-folder": (["render", "in/d", "-o", "out"], "in/d/x.toml"),
                  "export": (["export", "in/f.toml", "-o", "out/x.glb"], "in/f.toml"),
                  "scene": (["scene", "in/f.toml", "-o", "out/s.png", "--size", "16x16"], "in/f.toml"),
                  "scene-save": (["scene", "in/f.json", "--save", "out/s.toml"], "in/f.json"),
                  "scene-species": (["scene", "--species", "in/f.toml", "--leaves", "5", "-o", "out/s.png",
                                     "--size", "16x16"], "in/f.toml"),
                  "shapes-lobed": (["shapes", "--lobed", "in/f.toml", "-o", "out/l.png"], "in/f.toml"),
                  "morph-a": (["morph", "in/f.toml", "ovate", "--frames", "2", "--fast", "-o", "out/m"], "in/f.toml"),
                  "morph-ref": (["morph", "ovate", "cordate", "--ref", "in/f.toml:1", "--frames", "2", "--fast",
                                 "-o", "out/m"], "in/f.toml"),
                  "view": (["view", "in/f.toml", "--frames", "1"], "in/f.toml")}
    for key, (argv, rel) in fifo_cases.items():
        add(Case(f"fifo-{key}", "special files", argv, setup=lambda c, rel=rel: c.fifo(rel), timeout=20))
    add(Case("fifo-scene-species-preset", "special files", ["scene", "in/s.toml", "-o", "out/s.png", "--size", "16x16"],
             setup=lambda c: (c.fifo("in/f.toml"), c.write("in/s.toml", scene_text([{"preset": "f.toml"}]))),
             timeout=20))

    # 10. huge counts -----------------------------------------------------------------------------------------
    for value in ("1e400", "-1e400", "inf", "nan", "10000001", "1e7.5"):
        add(Case(f"leaves-{value}", "huge counts", ["scene", "--leaves", value, "-o", "out/s.png"]))
    for flag, value in (("--plants", "1000000000000"), ("--plants", "-5"), ("--seed", "-1"),
                        ("--seed", "18446744073709551616"), ("--seed", "1" + "0" * 30)):
        add(Case(f"scene{flag}-{value[:12]}", "huge counts", ["scene", flag, value, "--leaves", "10", "-o",
                                                                "out/s.png", "--size", "16x16"], expect="any"))
    add(Case("scene-plants-1e6", "huge counts", ["scene", "--plants", "1000000", "--leaves", "1000", "-o", "out/s.png",
                                                 "--size", "64x64"], expect="any", timeout=90))
    add(Case("lobed-2000-positions", "huge counts", ["shapes", "--lobed", "in/many.toml", "-o", "out/l.png",
                                                     "--size", "32"],
             setup=lambda c: c.write("in/many.toml", tomli_w.dumps({**lobed_doc(), "positions": [[0.5, 30.0, 0.5]] * 2000})),
             expect="any", timeout=90))
    add(Case("leaf-set-1e5-as-scene", "huge counts", ["scene", "in/big.leaves.json", "-o", "out/s.png", "--size", "64x64"],
             setup=lambda c: c.write("in/big.leaves.json", _big_set(100_000)), expect="any", timeout=120))
    add(Case("morph-frames-1e9", "huge counts", ["morph", "ovate", "cordate", "--frames", "1000000000", "-o", "out/m"]))
    add(Case("render-size-16384", "huge counts", ["render", "ovate", "-o", "out/x.png", "--size", "16384"]))
    add(Case("render-grid-huge", "huge counts", ["render", "ovate", "-o", "out/x.png", "--grid", "100000x100000"]))
    add(Case("export-resolution-huge", "huge counts", ["export", "ovate", "-o", "out/x.glb", "--resolution",
                                                        "100000x100000"]))

    # 11. side effects of a failed run (outputs commit together) ----------------------------------------------
    add(Case("save-then-unwritable-image", "side effects", ["scene", "--leaves", "10", "--save", "out/s.toml", "-o",
                                                           "ro/out.png", "--size", "32x32"],
             setup=lambda c: c.mount("ro", readonly=True), out=("out", "ro")))
    add(Case("save-then-image-parent-file", "side effects", ["scene", "--leaves", "10", "--save", "out/s.toml", "-o",
                                                            "file/out.png", "--size", "32x32"],
             setup=lambda c: c.write("file", "x")))
    add(Case("save-then-export-parent-file", "side effects", ["scene", "--leaves", "10", "--save", "out/s.toml",
                                                             "--export", "file/x.glb"],
             setup=lambda c: c.write("file", "x")))
    add(Case("render-dir-second-fails", "side effects", ["render", "ovate", "lanceolate", "-o", "out/dir", "--size", "16"],
             setup=lambda c: (c.root / "out" / "dir" / "lanceolate.png").mkdir(parents=True)))

    # 12. interruption ------------------------------------------------------------------------------------
    # the 1,500 veined maize leaves take 85-107 s to export on an idle 2-core machine (the vein
    # shape and field of each distinct leaf), longer beside the other cases: a hang is well beyond
    BIG_EXPORT_TIMEOUT = 300
    def big_scene(ctx: Ctx) -> None:
        ctx.write("in/big.toml", scene_text([{"preset": "maize"}], leaves=1500, variation=0.2))
    for sig in (signal.SIGTERM, signal.SIGINT):
        add(Case(f"{sig.name}-mid-export", "interruption", ["export", "in/big.toml", "-o", "out/big.glb",
                                                             "--resolution", "17x33"],
                 setup=big_scene, interrupt=(sig, 45.0), timeout=BIG_EXPORT_TIMEOUT, expect="any"))
    add(Case("SIGTERM-mid-render-dir", "interruption", ["render", str(PRESETS), "-o", "out/dir", "--size", "512"],
             interrupt=(signal.SIGTERM, 8.0), timeout=90, expect="any", all_or_none=len(list(PRESETS.glob("*.toml")))))
    add(Case("SIGKILL-then-rerun", "interruption", ["export", "in/big.toml", "-o", "out/big.glb", "--resolution", "17x33"],
             setup=big_scene, interrupt=(signal.SIGKILL, 45.0), rerun=True, timeout=BIG_EXPORT_TIMEOUT,
             expect="succeed"))
    add(Case("two-writers-one-target", "interruption", ["export", "maize", "-o", "out/m.glb"], twice=True,
             expect="succeed"))

    # 13. unbounded fields ------------------------------------------------------------------------------------
    add(Case("name-200MB", "unbounded fields", ["render", "in/x.json", "-o", "out/x.png", "--size", "16"],
             setup=lambda c: c.write("in/x.json", preset_json(name="x" * 200_000_000)), expect="any",
             max_output=10 << 20, timeout=120))
    add(Case("name-1MB", "unbounded fields", ["render", "in/x.json", "-o", "out/x.png", "--size", "16"],
             setup=lambda c: c.write("in/x.json", preset_json(name="x" * 1_000_000)), expect="any", max_output=10 << 20))
    add(Case("name-1MB-leaf-json", "unbounded fields", ["export", "in/x.json", "-o", "out/x.leaf.json"],
             setup=lambda c: c.write("in/x.json", preset_json(name="x" * 1_000_000)), expect="any", max_output=10 << 20))

    # 14. API edges ---------------------------------------------------------------------------------------------
    api = {"render-16384-three-quarter": "leafview.render(leaf, size=(16384, 16384), view='three-quarter')",
           "render-size-zero": "leafview.render(leaf, size=(0, 0))",
           "render-grid-1e5": "leafview.render(leaf, size=(64, 64), grid=(100000, 100000))",
           "tessellate-1e6": "leafview.tessellate(leaf, 1000000, 1000000)",
           "gpu-evaluate-nan-u": "leafview.gpu.evaluate(leaf, [math.nan], [0.5])",
           "numpy-evaluate-nan-u": "leafview.evaluate(leaf, [math.nan], [0.5])",
           "fbm-noise-1e12": "leafview.fbm_noise(10**12, 1.0, 0)",
           "renderer-release-twice": "r = leafview.gpu.LeafRenderer(); r.release(); r.release()"}
    for key, body in api.items():
        expect = "succeed" if key == "renderer-release-twice" else "refuse"
        add(Case(f"api-{key}", "API edges", snippet=body, expect=expect, mem_limit=8 * GiB, timeout=120))
    add(Case("bench-bad-suite", "API edges", ["bench", "nosuch"]))
    add(Case("bench-bad-option", "API edges", ["bench", "core", "--bogus"]))
    return cases


def preset_json(**top: Any) -> str:
    return json.dumps({**preset_doc("ovate"), **top})


def _sparse(path: Path, size: int) -> None:
    with open(path, "wb") as fh:
        fh.truncate(size)


def _big_set(n: int) -> str:
    om = json.dumps(omega())
    body = ",\n".join(f'{{"omega":{om},"transform":{{"translation":[{i % 300 * 0.4},{i // 300 * 0.4},0]}}}}'
                      for i in range(n))
    return f'{{"leafview":1,"leaves":[\n{body}\n]}}'


def _enospc(*argv: str, limit: int = 600) -> str:
    """A snippet: leafview's Python-level writes (``os.write`` and files opened for writing
    through ``open``) fail with ENOSPC once ``limit`` bytes were written, as on a full disk."""
    return textwrap.dedent(f"""
        import builtins, errno, io, os, sys
        from leafview.cli import main
        written = [0]
        def spend(n):
            written[0] += n
            if written[0] > {limit}:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real_write, real_open = os.write, io.open
        def full_write(fd, data):
            if fd > 2:
                spend(len(data))
            return real_write(fd, data)
        class Full:
            def __init__(self, fh):
                self._fh = fh
            def write(self, data):
                spend(len(data))
                return self._fh.write(data)
            def __getattr__(self, name):
                return getattr(self._fh, name)
            def __enter__(self):
                return self
            def __exit__(self, *exc):
                return self._fh.__exit__(*exc)
        def full_open(file, mode="r", *args, **kwargs):
            fh = real_open(file, mode, *args, **kwargs)
            return Full(fh) if any(m in mode for m in "wax+") else fh
        os.write = full_write
        builtins.open = io.open = full_open
        sys.exit(main({list(argv)!r}))
    """)


# -- running a case -------------------------------------------------------------------------------------
SNIPPET = """\
import json, math, sys
import leafview
from leafview.errors import LeafviewError
leaf = leafview.LeafParams.load({ovate!r})
try:
{body}
except (LeafviewError, ValueError) as exc:   # a LeafviewError, or the documented ValueError of (u, v) checks
    print("REFUSED", json.dumps([type(exc).__name__, str(exc)]))
    sys.exit(2)
print("DONE")
"""


@dataclass
class Result:
    code: int | None = None
    stdout: str = ""
    stderr: str = ""
    seconds: float = 0.0
    hung: bool = False
    memory: int = 0         # the largest RSS seen, bytes
    killed_for_memory: bool = False
    interrupted: str = ""


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _rss(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def _tail(path: Path, n: int = 20_000) -> str:
    with open(path, "rb") as fh:
        size = fh.seek(0, 2)
        fh.seek(max(0, size - n))
        data = fh.read()
    return ("…" if size > n else "") + data.decode("utf-8", "replace")


def _launch(case: Case, cwd: Path, logs: Path, tag: str) -> tuple[subprocess.Popen[bytes], Path, Path]:
    if case.snippet is not None:
        body = textwrap.indent(case.snippet.strip(), "    ")
        code = case.snippet if "sys.exit(main(" in case.snippet else SNIPPET.format(
            ovate=str(PRESETS / "ovate.toml"), body=body)
        cmd = [sys.executable, "-c", code]
    else:
        cmd = [sys.executable, "-c", CLI, *[a.replace("@TRAP@", str(cwd / "trap")) for a in case.argv or []]]
    out_path, err_path = logs / f"{tag}.out", logs / f"{tag}.err"

    def limits() -> None:
        if case.fsize:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (case.fsize, case.fsize))

    with open(out_path, "wb") as out, open(err_path, "wb") as err:
        proc = subprocess.Popen(cmd, cwd=cwd, stdin=subprocess.DEVNULL, stdout=out, stderr=err, env=_env(),
                                start_new_session=True, preexec_fn=limits)
    return proc, out_path, err_path


def _watch(case: Case, proc: subprocess.Popen[bytes], cwd: Path, result: Result) -> None:
    """Wait for ``proc`` with the case's time-out and memory limit; send its interrupt."""
    started = time.monotonic()
    sent = case.interrupt is None
    while True:
        try:
            proc.wait(timeout=0.05)
            break
        except subprocess.TimeoutExpired:
            pass
        elapsed = time.monotonic() - started
        result.memory = max(result.memory, _rss(proc.pid))
        if result.memory > case.mem_limit:
            result.killed_for_memory = True
            os.killpg(proc.pid, signal.SIGKILL)
        elif elapsed > case.timeout:
            result.hung = True
            os.killpg(proc.pid, signal.SIGKILL)
        elif not sent and case.interrupt is not None:
            sig, wait = case.interrupt
            part = any(is_temp_name(r) for r in snapshot(cwd / "out"))
            if part or elapsed > wait:
                os.kill(proc.pid, sig)
                sent = True
                result.interrupted = f"{signal.Signals(sig).name} at {elapsed:.1f} s" + \
                    (" while a temporary file existed" if part else " (no temporary file seen)")
    result.code = proc.returncode
    result.seconds = time.monotonic() - started


def run_case(case: Case, base: Path) -> dict[str, Any]:
    slug = "".join(c if c.isalnum() or c in "-_" else "_" for c in case.name)[:60]
    cwd = Path(tempfile.mkdtemp(prefix=slug + "-", dir=base))
    logs = Path(tempfile.mkdtemp(prefix=slug + "-logs-", dir=base))
    ctx = Ctx(cwd)
    report: dict[str, Any] = {"name": case.name, "category": case.category, "command": case.command(),
                              "expect": case.expect}
    try:
        _standard(ctx)
        try:
            if case.setup:
                case.setup(ctx)
        except Skip as exc:
            report.update(cls="skipped", problems=[str(exc)])
            return report
        except Exception as exc:   # a broken case must not stop the rerun: shown as skipped, with why
            report.update(cls="skipped", problems=[f"setup failed: {type(exc).__name__}: {exc}"])
            return report
        before = snapshot(cwd)
        result = Result()
        runs = 2 if case.twice else 1
        procs = [_launch(case, cwd, logs, f"run{i}") for i in range(runs)]
        threads = []
        results = [result] + [Result() for _ in range(runs - 1)]
        for (proc, _, _), res in zip(procs, results):
            t = threading.Thread(target=_watch, args=(case, proc, cwd, res))
            t.start()
            threads.append(t)
        for t in threads:
            t.join()
        if case.rerun and not result.hung:
            first = result
            again = Case(**{**case.__dict__, "interrupt": None, "rerun": False})
            proc, out_path, err_path = _launch(again, cwd, logs, "rerun")
            result = Result(interrupted=f"first run: {first.interrupted}, exit {first.code}")
            _watch(again, proc, cwd, result)
            procs = [(proc, out_path, err_path)]
            results = [result]
        for (_, out_path, err_path), res in zip(procs, results):
            res.stdout, res.stderr = _tail(out_path), _tail(err_path)
        after = snapshot(cwd)
        cls, problems = classify(case, results, before, after, cwd)
        report.update(cls=cls, problems=problems, code=[r.code for r in results],
                      seconds=round(max(r.seconds for r in results), 2),
                      memory_mb=round(max(r.memory for r in results) / 2**20),
                      interrupted=result.interrupted or None,
                      stderr=result.stderr[-1500:], stdout=result.stdout[-600:])
        return report
    finally:
        for mount in reversed(ctx.mounts):
            subprocess.run(["umount", "-l", str(mount)], capture_output=True)
        shutil.rmtree(cwd, ignore_errors=True)
        shutil.rmtree(logs, ignore_errors=True)


def classify(case: Case, results: list[Result], before: dict[str, Any], after: dict[str, Any],
             cwd: Path) -> tuple[str, list[str]]:
    problems: list[str] = []
    if any(r.hung for r in results):
        return "hang", [f"no answer in {case.timeout:g} s"]
    interrupted = case.interrupt is not None and not case.rerun
    for r in results:
        if "Traceback (most recent call last)" in r.stderr + r.stdout:
            last = [line for line in r.stderr.splitlines() if line.strip()][-1:] or ["?"]
            return "traceback", [f"traceback: {last[0][:300]}"]
        if r.code is not None and r.code < 0 and not interrupted and not r.killed_for_memory:
            return "traceback", [f"died of signal {-r.code}"]
    for r in results:
        if r.killed_for_memory:
            problems.append(f"memory above {case.mem_limit / GiB:.0f} GiB (killed)")
            continue
        if interrupted:
            continue
        if case.snippet is not None and "sys.exit(main(" not in case.snippet:
            problems += _snippet_problems(case, r)
            continue
        problems += stream_problems(r.code, r.stdout, r.stderr)
        if case.expect == "refuse" and r.code == 0:
            problems.append("exit 0 where a refusal was expected")
        if case.expect == "succeed" and r.code != 0:
            problems.append(f"exit {r.code} where success was expected")
        for text in case.forbidden:
            if text in r.stderr or text in r.stdout:
                problems.append(f"repeated the content of another file ({text!r})")
    ok = all(r.code == 0 for r in results) and not interrupted
    tree, written = tree_problems(before, after, out=case.out, success=ok or interrupted)
    problems += tree
    if interrupted:   # no temporary file, nothing outside; what is left is complete, all or none
        problems += [f"an interrupted run left an incomplete file: {bad}" for rel in written
                     if (bad := file_problem(cwd / rel))]
        if case.all_or_none and len(written) not in (0, case.all_or_none):
            problems.append(f"an interrupted run left {len(written)} of its {case.all_or_none} files")
    if ok:
        for rel in written:
            path = cwd / rel
            bad = file_problem(path)
            if bad:
                problems.append(f"exit 0 with an incomplete file: {bad}")
            elif case.not_blank and rel.endswith((".png", ".tif", ".exr")) and image_coverage(path) == 0.0:
                problems.append(f"exit 0 with a blank image {rel}")
            if case.max_output and path.stat().st_size > case.max_output:
                problems.append(f"exit 0 with a {path.stat().st_size / 2**20:,.0f} MB file {rel}")
        if case.argv and case.argv[0] in ("render", "export", "scene", "shapes", "morph") and not written \
                and case.out and case.snippet is None:
            problems.append("exit 0 but nothing was written")
    if problems:
        return "wrong outcome", problems
    if interrupted:
        return "clean refusal", []
    return ("success" if ok else "clean refusal"), []


def _snippet_problems(case: Case, r: Result) -> list[str]:
    lines = [line for line in r.stdout.splitlines() if line.startswith(("REFUSED", "DONE"))]
    if not lines:
        return [f"exit {r.code}, no result: {r.stderr.strip()[-300:]}"]
    if lines[-1].startswith("REFUSED"):
        kind, message = json.loads(lines[-1][len("REFUSED "):])
        problems = [] if "\n" not in message.strip() else [f"a {message.count(chr(10)) + 1}-line {kind}"]
        if case.expect == "succeed":
            problems.append(f"refused where success was expected: {kind}: {message[:200]}")
        return problems
    return ["returned where a LeafviewError was expected"] if case.expect == "refuse" else []


# -- the report ----------------------------------------------------------------------------------------
def print_report(reports: list[dict[str, Any]], seconds: float) -> None:
    counts = Counter(r["cls"] for r in reports)
    print(f"\n{len(reports)} hostile cases in {seconds:.0f} s")
    print(f"{'class':16s} {'cases':>6s}")
    for cls in CLASSES:
        print(f"{cls:16s} {counts.get(cls, 0):6d}")
    categories = sorted({r["category"] for r in reports})
    short = {"clean refusal": "refused", "success": "ok", "traceback": "tb", "hang": "hang", "wrong outcome": "wrong",
             "skipped": "skip"}
    print(f"\n{'category':28s} " + " ".join(f"{short[c]:>7s}" for c in CLASSES))
    for cat in categories:
        c = Counter(r["cls"] for r in reports if r["category"] == cat)
        print(f"{cat:28s} " + " ".join(f"{c.get(k, 0):7d}" for k in CLASSES))
    bad = [r for r in reports if r["cls"] in ("traceback", "hang", "wrong outcome")]
    if bad:
        print(f"\n{len(bad)} cases break the promise (command -> observed):")
        for r in bad:
            print(f"- [{r['cls']}] {r['name']}: {r['command']}")
            print(f"    -> exit {r.get('code')}; " + "; ".join(p[:300] for p in r["problems"]))
            err = [line for line in (r.get("stderr") or "").splitlines() if line.strip()]
            if err and r["cls"] != "hang":
                print(f"    stderr: {err[-1][:300]}")
    skipped = [r for r in reports if r["cls"] == "skipped"]
    if skipped:
        print(f"\n{len(skipped)} skipped: " + "; ".join(f"{r['name']} ({r['problems'][0]})" for r in skipped[:5]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", metavar="FILE", help="write the report as JSON")
    parser.add_argument("--jobs", type=int, default=2, help="cases run at once (default 2)")
    parser.add_argument("--only", metavar="TEXT", help="only cases whose name or category contains TEXT")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    args = parser.parse_args(argv)
    cases = [c for c in corpus() if not args.only or args.only in c.name or args.only in c.category]
    if args.list:
        for c in cases:
            print(f"{c.category:26s} {c.name:40s} {c.command()}")
        print(f"{len(cases)} cases")
        return 0
    base = Path(tempfile.mkdtemp(prefix="leafview-hostile-"))
    started = time.time()
    try:
        with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
            reports = list(pool.map(lambda c: run_case(c, base), cases))
    finally:
        shutil.rmtree(base, ignore_errors=True)
    seconds = time.time() - started
    print_report(reports, seconds)
    if args.json:
        counts = Counter(r["cls"] for r in reports)
        Path(args.json).write_text(json.dumps({"started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(started)),
                                               "seconds": round(seconds, 1),
                                               "counts": {c: counts.get(c, 0) for c in CLASSES},
                                               "cases": reports}, indent=1), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
