"""Every ``leafview`` sub-command on generated input and argument lists (issue 14 §2, CLI level).

``leafview.cli.main(argv)`` runs in this process (stdout and stderr as a process without a
terminal has them), in a fresh sandbox with ``in/``, ``out/`` and ``trap/`` folders, with tiny
image sizes so that an example takes milliseconds. The property is the README's promise: exit 0
and every file written under ``out/`` reads back complete and finite, or exit 1/2 with one line
on stderr (naming the input file when its content is what is wrong) and nothing written; never
an exception escaping ``main``, never a hang, never a temporary file left, never a file outside
``out/``, no GL error left pending.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from support.fuzzing import (
    CATALOGUE,
    LOBED,
    PRESETS,
    InputFile,
    Sandbox,
    any_input,
    budget,
    input_files,
    run_main,
    sandbox,
    tally,
)
from support.promise import file_problem, image_coverage, snapshot, stream_problems, tree_problems

from leafview.core.io import load_leaves
from leafview.errors import GLUnavailable, LeafviewError
from leafview.export.gltf import BACK_FACES, INSTANCING_MODES
from leafview.export.objply import UP_AXES
from leafview.gpu import default_renderer

RUN_TIMEOUT = 90.0    # seconds; an example takes well under one
FLOAT32_MAX = float(np.finfo(np.float32).max)


def _gl_error() -> str | None:
    try:
        error = default_renderer().ctx.error
    except GLUnavailable:
        return None
    return None if error == "GL_NO_ERROR" else error


def _overflows(path_in_sandbox: str, sb: Sandbox) -> bool:
    """Whether the leaves of an input reach beyond float32 once placed (a blank image of them
    means the geometry was not finite on the GPU)."""
    try:
        leaves = load_leaves(sb.root / path_in_sandbox)
    except LeafviewError:
        return False
    for leaf in leaves:
        m = leaf.transform.matrix()
        reach = float(np.abs(m).max()) * (1.0 + max(abs(x) for x in leaf.to_vector()))
        if not np.isfinite(m).all() or reach > FLOAT32_MAX / 16:
            return True
    return False


def check_cli(sb: Sandbox, argv: Sequence[str], *, must_name: tuple[str, ...] = (), expect_output: bool = True,
              out: tuple[str, ...] = ("out",), blank_input: str | None = None) -> None:
    """Run ``leafview argv`` in ``sb`` and assert the promise."""
    argv = [a.replace("@TRAP@", str(sb.trap)) for a in argv]
    before = snapshot(sb.root)
    run = run_main(argv, sb.root, timeout=RUN_TIMEOUT)
    after = snapshot(sb.root)
    problems: list[str] = []
    if run.hung:
        problems.append(f"hang: no answer in {RUN_TIMEOUT:g} s")
    if run.error:
        problems.append("an exception escaped leafview.cli.main")
    problems += stream_problems(run.code, run.stdout, run.stderr, must_name=must_name if run.code == 2 else ())
    tree, written = tree_problems(before, after, out=out, success=run.code == 0)
    problems += tree
    if run.code == 0:
        for rel in written:
            bad = file_problem(sb.root / rel)
            if bad:
                problems.append(f"exit 0 with a file that is not complete: {bad}")
            elif blank_input and rel.endswith((".png", ".tif", ".exr")) and image_coverage(sb.root / rel) == 0.0 \
                    and _overflows(blank_input, sb):
                problems.append(f"exit 0 with a blank image {rel} of geometry beyond float32")
        if expect_output and not written:
            problems.append("exit 0 but nothing was written")
    gl = _gl_error()
    if gl:
        problems.append(f"left the GL error {gl} pending")
    assert not problems, run.describe() + "\n" + "\n".join(problems)


def _opt(flag: str, values: st.SearchStrategy[str]) -> st.SearchStrategy[list[str]]:
    return values.map(lambda v: [flag, v])


def _maybe(strategy: st.SearchStrategy[list[str]], weight: int = 1) -> st.SearchStrategy[list[str]]:
    """``strategy`` in 1 of 1 + weight draws, else no arguments."""
    return st.one_of(*([st.just([])] * weight), strategy)


LEAF_KINDS = st.sampled_from(["preset", "preset", "compact", "set"])
BAD_NUMBERS = ["0", "-1", "7", "x", "1e400", "nan", "inf", "99999999999999999999", "", "1_0", "0x10", " 8"]


# -- render ---------------------------------------------------------------------------------------
RENDER_OUT = ["out/leaf.png", "out/leaf.tif", "out/leaf.exr", "out/dir", "out", "out/leaf", "out/sub/deeper/leaf.png"]


@st.composite
def render_args(draw: st.DrawFn) -> tuple[list[str], bool]:
    """(options after PRESET, whether they are all valid)."""
    valid = True
    size = draw(st.sampled_from(["8", "12", "16"]))
    if draw(st.integers(0, 12)) == 0:
        size, valid = draw(st.sampled_from(BAD_NUMBERS + ["8193", "16384"])), False
    args = ["-o", draw(st.sampled_from(RENDER_OUT)), "--size", size]
    if draw(st.booleans()):
        args += ["--view", draw(st.sampled_from(["top", "front", "three-quarter", "side"]))]
    if draw(st.integers(0, 3)) == 0:
        args[1] = "out/sheet.png"
        args += ["--sheet"]
    if draw(st.integers(0, 4)) == 0:
        fmt = draw(st.sampled_from(["png", "exr", "tif", "jpg"]))
        args += ["--format", fmt]
        valid = valid and fmt != "jpg"
    if draw(st.integers(0, 4)) == 0:
        g = draw(st.sampled_from(["3x5", "2x3", "9x17", "1x1", "0x0", "1026x3", "x", "3x"]))
        args += ["--grid", g]
        valid = valid and g in ("3x5", "2x3", "9x17")
    if draw(st.booleans()):
        args.append("-q")
    return args, valid


@budget("cli.render", ci=200, long=3000)
@given(item=LEAF_KINDS.flatmap(any_input), opts=render_args())
def test_render(item: InputFile, opts: tuple[list[str], bool]) -> None:
    tally("cli.render")
    args, valid = opts
    with sandbox() as sb:
        path = sb.put(item)
        rel = str(path.relative_to(sb.root))
        check_cli(sb, ["render", rel, *args], must_name=(item.name, args[1]) if valid else (),
                  blank_input=rel)


# -- export ---------------------------------------------------------------------------------------
EXPORT_OUT = ["out/x.glb", "out/x.gltf", "out/x.obj", "out/x.ply", "out/x.usda", "out/x.usdc", "out/x.leaf.json",
              "out/x.leaves.json", "out/dir", "out/x.stl"]


@st.composite
def export_args(draw: st.DrawFn) -> tuple[list[str], bool]:
    valid = True
    target = draw(st.sampled_from(EXPORT_OUT))
    args = ["-o", target, "--backend", draw(st.sampled_from(["numpy", "numpy", "gpu"]))]
    valid = target != "out/x.stl"
    res = draw(st.sampled_from(["3x5", "2x3", "5x9", "9x17"]))
    if draw(st.integers(0, 10)) == 0:
        res, valid = draw(st.sampled_from(["1x1", "2x2", "1026x5", "x", "0x0", "100000x100000"])), False
    args += ["--resolution", res]
    if target == "out/dir" and draw(st.booleans()):
        args += ["--format", draw(st.sampled_from(["glb", "obj", "ply", "usda"]))]
    if draw(st.integers(0, 5)) == 0:
        length = draw(st.sampled_from(["0.1", "1e-300", "1e308", "0", "-1", "nan", "inf", "x"]))
        args += ["--length-m", length]
        valid = valid and length in ("0.1", "1e-300", "1e308")
    if target.endswith(".json") and draw(st.integers(0, 3)) == 0:
        digits = draw(st.sampled_from(["1", "6", "17", "0", "18", "x"]))
        args += ["--digits", digits]
        valid = valid and digits in ("1", "6", "17")
    if draw(st.integers(0, 5)) == 0:
        args += ["--up", draw(st.sampled_from(UP_AXES))]
    if draw(st.integers(0, 5)) == 0:
        args += ["--back-faces", draw(st.sampled_from(BACK_FACES))]
    if draw(st.integers(0, 5)) == 0:
        args += ["--instancing", draw(st.sampled_from(INSTANCING_MODES))]
    if draw(st.booleans()):
        args.append("-q")
    return args, valid


@budget("cli.export", ci=200, long=3000)
@given(item=st.sampled_from(["preset", "compact", "set", "scene"]).flatmap(any_input), opts=export_args())
def test_export(item: InputFile, opts: tuple[list[str], bool]) -> None:
    tally("cli.export")
    args, valid = opts
    with sandbox() as sb:
        path = sb.put(item)
        check_cli(sb, ["export", str(path.relative_to(sb.root)), *args],
                  must_name=(item.name, args[1]) if valid else ())


# -- scene ----------------------------------------------------------------------------------------
@st.composite
def scene_args(draw: st.DrawFn) -> tuple[list[str], bool]:
    valid = True
    args: list[str] = []
    outputs = draw(st.lists(st.sampled_from(["image", "save", "export"]), min_size=1, max_size=3, unique=True))
    if "image" in outputs:
        args += ["-o", draw(st.sampled_from(["out/s.png", "out/s.tif", "out/s.exr"])),
                 "--size", draw(st.sampled_from(["16x16", "32x24", "24x40"]))]
        if draw(st.integers(0, 3)) == 0:
            args += ["--camera", draw(st.sampled_from(["three-quarter", "top", "front", "side", "ground"]))]
        args += draw(st.sampled_from([[], ["--no-cull"], ["--no-lod"], ["--no-cull", "--no-lod"]]))
    if "save" in outputs:
        target = draw(st.sampled_from(["out/s.toml", "out/s.json", "out/s.leaves.json", "out/s.txt"]))
        args += ["--save", target]
        valid = valid and target != "out/s.txt"
    if "export" in outputs:
        args += ["--export", draw(st.sampled_from(["out/s.glb", "out/s.usda", "out/s.gltf"]))]
    for flag, good, bad in (("--leaves", ["1", "5", "30"], ["0", "-1", "1e400", "nan", "x", "10000001", "1e-3"]),
                            ("--seed", ["0", "7", "9223372036854775807"],
                             ["-1", "18446744073709551616", "99999999999999999999999", "x", "1.5"]),
                            ("--plants", ["1", "2"], ["0", "-1", "x", "1e400"]),
                            ("--variation", ["0", "0.2", "0.5"], ["0.6", "-0.1", "nan", "x"]),
                            ("--layout", ["plant", "field", "hedge"], ["forest", ""]),
                            # the canopy look and the wind (leafview.scene.lighting, leafview.deform.wind)
                            ("--sun", ["135,50", "0,0", "-180,90"], ["10,95", "x", "nan,1", "1", "400,10"]),
                            ("--shadows", ["on", "off"], ["maybe", ""]),
                            ("--exposure", ["0", "-2.5"], ["nan", "11", "x"]),
                            ("--wind", ["0", "8"], ["-1", "61", "nan", "inf"])):
        choice = draw(st.integers(0, 8))
        if choice in (1, 2):
            args += [flag, draw(st.sampled_from(good))]
        elif choice == 3:
            args += [flag, draw(st.sampled_from(bad))]
            valid = False
    if draw(st.integers(0, 4)) == 0:
        species = draw(st.lists(st.sampled_from(PRESETS[:6] + ["in/input.toml", "in/sub/ok.toml", "nosuch", "",
                                                                 "@TRAP@/secret.toml"]), min_size=1, max_size=3))
        args += ["--species", ",".join(species)]
        valid = valid and all(s in PRESETS or s.startswith("in/") for s in species)
    if draw(st.booleans()):
        args.append("--no-stems")
    if draw(st.integers(0, 15)) == 0:
        args += draw(st.sampled_from([["--view", "--frames", "0"], ["--frames", "2"], ["--screenshot", "out/w.png"]]))
        valid = False
    if draw(st.booleans()):
        args.append("-q")
    return args, valid


@budget("cli.scene", ci=80, long=1000)
@given(item=st.one_of(st.none(), st.sampled_from(["scene", "scene", "set"]).flatmap(any_input)), opts=scene_args())
def test_scene(item: InputFile | None, opts: tuple[list[str], bool]) -> None:
    tally("cli.scene")
    args, valid = opts
    with sandbox() as sb:
        head = ["scene"]
        if item is not None:
            head.append(str(sb.put(item).relative_to(sb.root)))
        elif "--leaves" not in args:
            args = [*args, "--leaves", "20"]
        check_cli(sb, [*head, *args], must_name=(item.name,) if item is not None and valid else ())


# -- shapes ---------------------------------------------------------------------------------------
@st.composite
def shapes_argv(draw: st.DrawFn) -> tuple[list[str], InputFile | None, bool, bool]:
    """(argv after 'shapes', a lobed file to put in in/ or None, whether output is expected,
    whether every argument but the lobed file's content is valid)."""
    mode = draw(st.sampled_from(["list", "render", "render", "lobed", "lobed"]))
    names = draw(st.lists(st.sampled_from(CATALOGUE[:12] + ["nosuch", "", "cordate,ovate", "ovate,,x"]),
                          min_size=1, max_size=3))
    good_size = draw(st.integers(0, 8)) > 0
    size = ["--size", draw(st.sampled_from(["8", "16"]) if good_size else st.sampled_from(BAD_NUMBERS))]
    if mode == "list":
        return ["--names", *names], None, False, False
    if mode == "render":
        target = draw(st.sampled_from(["out/x.png", "out/dir", "out/x.exr", "out/x.jpg"]))
        args = ["--names", *names, "-o", target, *size]
        if draw(st.integers(0, 3)) == 0:
            args = ["--names", *names[:2], "--sheet", "-o", draw(st.sampled_from(["out/s.png", "out/s.exr"])), *size]
        if draw(st.integers(0, 20)) == 0:
            args = ["--names", names[0], "--seed", draw(st.sampled_from(["3", "-1", "18446744073709551616"])),
                    "-o", "out/seeded.png", *size]
        return args, None, True, False
    lobed: InputFile | None = None
    if draw(st.booleans()):
        lobed = draw(input_files("lobed", specials=False))
        which = "in/" + lobed.name
    else:
        which = draw(st.sampled_from([*LOBED, "nosuch", "in", "in/sub/ok.toml", ""]))
    args = ["--lobed", which]
    valid = good_size
    if draw(st.integers(0, 2)):
        target = draw(st.sampled_from(["out/l.png", "out/l.exr", "out/l.txt"]))
        args += ["-o", target, *size]
        valid = valid and target != "out/l.txt"
    if draw(st.integers(0, 10)) == 0:
        args += ["--sheet"]
        valid = False
    return args, lobed, "-o" in args, valid


@budget("cli.shapes", ci=80, long=1000)
@given(case=shapes_argv())
def test_shapes(case: tuple[list[str], InputFile | None, bool, bool]) -> None:
    tally("cli.shapes")
    args, lobed, expect, valid = case
    with sandbox() as sb:
        names: tuple[str, ...] = ()
        if lobed is not None:
            sb.put(lobed)
            names = (lobed.name,) if valid else ()
        check_cli(sb, ["shapes", *args], must_name=names, expect_output=expect)


# -- morph ----------------------------------------------------------------------------------------
@st.composite
def morph_argv(draw: st.DrawFn) -> tuple[list[str], list[InputFile], bool]:
    """(argv after 'morph', landmark files to put in in/, whether every argument but those
    files' content is valid)."""
    files: list[InputFile] = []
    valid = [True]

    def shape(stem: str) -> str:
        choice = draw(st.integers(0, 4))
        if choice == 0:
            item = draw(input_files("landmark", specials=False, stem=stem))
            files.append(item)
            return "in/" + item.name
        if choice == 1:
            other = draw(st.sampled_from(["nosuch", "in/sub/ok.toml", "", "in"]))
            valid[0] = False
            return other
        return draw(st.sampled_from(CATALOGUE))

    args = [shape("a"), shape("b")]
    for i in range(draw(st.integers(0, 2))):
        weight = draw(st.sampled_from(["", ":1", ":0", ":2.5", ":-1", ":nan", ":x", ":1e400"]))
        valid[0] = valid[0] and weight in ("", ":1", ":0", ":2.5")
        args += ["--ref", shape(f"r{i}") + weight]
    good_frames = draw(st.integers(0, 6)) > 0
    frames = draw(st.sampled_from(["2", "3"]) if good_frames else
                  st.sampled_from(["0", "1", "1001", "x", "-5", "10000000000"]))
    target = draw(st.sampled_from(["out/m", "out", "out/m.png"]))
    args += ["--frames", frames, "--size", "8", "-o", target, "-q"]
    if draw(st.integers(0, 9)) or frames != "2":
        args.append("--fast")
    args += draw(st.sampled_from([[], ["--method", "keyframe"], ["--presets"], ["--view", "side"]]))
    return args, files, valid[0] and good_frames and target != "out/m.png"


@budget("cli.morph", ci=40, long=400)
@given(case=morph_argv())
def test_morph(case: tuple[list[str], list[InputFile], bool]) -> None:
    tally("cli.morph")
    args, files, valid = case
    with sandbox() as sb:
        for item in files:
            sb.put(item)
        check_cli(sb, ["morph", *args], must_name=tuple(f.name for f in files) if valid else ())


# -- argument lists of every command --------------------------------------------------------------
VALUES = ["", "-", "--", "0", "-1", "3", "8", "1e400", "nan", "99999999999999999999", "1x1", "16x16", "x", "3x5",
          "top", "png", "glb", "out", "out/x.png", "out/x.glb", "out/x.leaf.json", "out/s.toml", "in/missing.toml",
          "ovate", "ovate,maize", "maple", "cordate", "é", "a" * 300 + ".png", "out/" + "a" * 300 + ".png",
          "@TRAP@/abs.png", "/proc/leafview-fuzz.png", "out/x.png/y.png", "in/sub/ok.toml", "in/sub"]
OPTIONS = {
    "render": ["-o", "--size", "--view", "--format", "--sheet", "--together", "--grid", "-q", "--help"],
    "export": ["-o", "--format", "--resolution", "--backend", "--length-m", "--up", "--back-faces", "--instancing",
               "--digits", "-q"],
    "scene": ["--leaves", "--species", "--layout", "--seed", "--plants", "--variation", "--no-stems", "-o", "--size",
              "--camera", "--no-cull", "--no-lod", "--save", "--export", "-q", "--frames", "--screenshot", "--sun",
              "--shadows", "--sky", "--ground", "--exposure", "--ssao", "--wind", "--time", "--fps"],
    "shapes": ["-o", "--names", "--sheet", "--size", "--view", "--lobed", "-q"],
    "morph": ["--ref", "--frames", "-o", "--size", "--view", "--method", "--fast", "--presets", "-q"],
    "presets": ["--help", "-q", "x"],
    "view": ["--size", "--frames", "--screenshot", "--dev", "--samples"],
    "bench": ["--json", "--quick", "--bogus"],
    "dataset": ["-o", "--count", "--leaves", "--layout", "--species", "--size", "--seed", "--elevation", "--azimuth",
                "--distance", "--sun-elevation", "--light-intensity", "--split", "--shard-size", "--engine",
                "--workers", "--address", "--gpus-per-worker", "-q"],
    "fit": ["-o", "--scanlines", "--iterations", "--keep-unexplained", "-q", "--base", "--apex", "--dpi",
            "--texture-size", "--jobs"],
    "capture": ["-o", "--delta-plane", "--report", "--seed", "-q"],
    "eval-capture": ["--capture", "--truth", "--json", "--seed", "-q"],
}
# one argument that makes sure the command refuses before opening a window or measuring
VIEW_REFUSALS = [["--size", "10x10"], ["--frames", "0"], ["in/missing.toml"], ["--screenshot", "w.jpg"],
                 ["--samples", "3"], ["--help"], ["in/sub"]]
BENCH_REFUSALS = [["nosuch"], ["CORE"], ["--bogus"], ["--help"], ["core", "extra"]]


@st.composite
def any_argv(draw: st.DrawFn) -> list[str]:
    command = draw(st.sampled_from([*OPTIONS, "", "nosuch"]))
    if command in ("", "nosuch"):
        return draw(st.sampled_from([[], ["--version"], ["--help"], ["nosuch"], ["-x"], ["--", "render"]]))
    tokens = [command]
    for _ in range(draw(st.integers(0, 6))):
        if draw(st.booleans()):
            tokens.append(draw(st.sampled_from(OPTIONS[command])))
        tokens.append(draw(st.sampled_from(VALUES)))
    if command == "view":
        tokens += draw(st.sampled_from(VIEW_REFUSALS))
    elif command == "bench":
        tokens = ["bench", *draw(st.sampled_from(BENCH_REFUSALS)), *tokens[1:]]
    elif command == "scene":
        tokens += ["--leaves", draw(st.sampled_from(["3", "0", "x"]))]
        if "--view" in tokens:
            tokens += ["--frames", "0"]
    elif command == "morph":
        tokens += ["--frames", draw(st.sampled_from(["2", "0", "x"])), "--fast", "--size", "8"]
    elif command == "dataset":   # tiny images, at most one image and one local worker (the last value wins)
        tokens[1:1] = ["-o", "out/ds"]
        tokens += ["--count", draw(st.sampled_from(["1", "0", "x"])), "--size", "16x16", "--leaves", "2",
                   "--workers", "1", "--engine", draw(st.sampled_from(["local", "x"]))]   # Ray: tests/test_dataset.py
    elif command == "shapes" and "-o" in tokens and "--names" not in tokens:
        tokens += ["--names", "ovate"]
    return tokens


@budget("cli.argv", ci=400, long=5000)
@given(argv=any_argv())
def test_argument_lists(argv: list[str]) -> None:
    """Random argument lists for every sub-command (view and bench only up to a refusal): a clean
    refusal or a complete success, written under out/ (or into the sandbox's trap/ for an
    absolute -o)."""
    tally("cli.argv")
    with sandbox() as sb:
        check_cli(sb, argv, expect_output=False, out=("out", "trap"))
