"""The shader loader: includes, #line mapping, errors naming stage, file and line."""

import pytest

from leafview.gpu.shaders import ShaderError, build_compute, build_program, preprocess

pytestmark = pytest.mark.gl

FRAG = "#version 450\nout vec4 c;\nvoid main() { c = vec4(1.0); }\n"


def _write(root, files):
    for name, text in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)


def test_includes_are_inlined_once_per_directive(tmp_path):
    _write(tmp_path, {"a.vert": '#version 450\n#include "lib/b.glsl"\nvoid main() {}\n',
                      "lib/b.glsl": "float b() { return 1.0; }\n"})
    src = preprocess("a.vert", root=tmp_path)
    assert src.text.startswith("#version 450\n")
    assert "float b()" in src.text and src.files == ["a.vert", "lib/b.glsl"]


def test_compile_error_names_stage_file_and_line(gl, tmp_path):
    _write(tmp_path, {
        "bad.vert": '#version 450\n#include "helpers.glsl"\nvoid main() {\n    gl_Position = vec4(helper());\n}\n',
        "helpers.glsl": "// helpers\nfloat helper() {\n    return undefined_name;\n}\n",
        "ok.frag": FRAG,
    })
    with pytest.raises(ShaderError) as info:
        build_program(gl.ctx, "bad.vert", "ok.frag", root=tmp_path)
    err = info.value
    assert err.stage == "vertex"
    assert err.location == "helpers.glsl:3", str(err)
    assert "undefined_name" in str(err)


def test_error_in_the_main_file_after_an_include(gl, tmp_path):
    _write(tmp_path, {"m.frag": '#version 450\n#include "x.glsl"\nout vec4 c;\nvoid main() { c = nope; }\n',
                      "x.glsl": "float x() { return 1.0; }\n",
                      "ok.vert": "#version 450\nvoid main() { gl_Position = vec4(0.0); }\n"})
    with pytest.raises(ShaderError) as info:
        build_program(gl.ctx, "ok.vert", "m.frag", root=tmp_path)
    assert info.value.stage == "fragment" and info.value.location == "m.frag:4"


def test_error_after_an_include_in_a_skipped_branch(gl, tmp_path):
    """The #line after an #include inside an #ifdef that is not taken is ignored by the compiler;
    the loader restates the position after #else/#endif, so the line is still right."""
    _write(tmp_path, {"m.frag": '#version 450\n#ifdef NOT_SET\n#include "x.glsl"\n#else\nout vec4 c;\n#endif\n'
                                "// a comment\n// another\nvoid main() { c = nope; }\n",
                      "x.glsl": "out vec4 c;\nfloat x() { return 1.0; }\n// 3\n// 4\n// 5\n",
                      "ok.vert": "#version 450\nvoid main() { gl_Position = vec4(0.0); }\n"})
    with pytest.raises(ShaderError) as info:
        build_program(gl.ctx, "ok.vert", "m.frag", root=tmp_path)
    assert info.value.stage == "fragment" and info.value.location == "m.frag:9", str(info.value)


def test_compute_error_and_link_error(gl, tmp_path):
    _write(tmp_path, {"c.comp": "#version 450\nlayout(local_size_x = 1) in;\nvoid main() {\n  oops;\n}\n",
                      "v.vert": "#version 450\nout vec3 x;\nvoid main() { x = vec3(1.0); gl_Position = vec4(0.0); }\n",
                      "f.frag": "#version 450\nin vec4 x;\nout vec4 c;\nvoid main() { c = x; }\n"})
    with pytest.raises(ShaderError) as info:
        build_compute(gl.ctx, "c.comp", root=tmp_path)
    assert info.value.stage == "compute" and info.value.location == "c.comp:4"
    with pytest.raises(ShaderError) as info:
        build_program(gl.ctx, "v.vert", "f.frag", root=tmp_path)
    assert info.value.stage == "link" and "x" in info.value.log


def test_include_problems(tmp_path):
    _write(tmp_path, {"loop.vert": '#version 450\n#include "a.glsl"\n', "a.glsl": '#include "b.glsl"\n',
                      "b.glsl": '#include "a.glsl"\n', "missing.vert": '#version 450\n\n#include "none.glsl"\n'})
    with pytest.raises(ShaderError, match="circular"):
        preprocess("loop.vert", root=tmp_path)
    with pytest.raises(ShaderError) as info:
        preprocess("missing.vert", root=tmp_path)
    assert info.value.location == "missing.vert:3" and "none.glsl" in str(info.value)


def test_project_shaders_compile(gl):
    for defines in ({}, {"LEAF_INSTANCED": 1}):
        prog = build_program(gl.ctx, "leaf.vert", "leaf.frag", defines=defines)
        prog.release()
