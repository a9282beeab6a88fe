"""A Dear ImGui renderer on moderngl (imgui-bundle 1.92+ texture protocol), no PyOpenGL.

imgui-bundle's own Python backends (``imgui_bundle.python_backends``) draw through PyOpenGL;
this is the same algorithm (a port of ``ImGui_ImplOpenGL3_RenderDrawData`` and
``ImGui_ImplOpenGL3_UpdateTexture``) on the moderngl context the scene already uses, so the
viewer needs no second GL binding. It declares ``RendererHasTextures`` (the backend creates and
updates the font atlas pages imgui asks for) and ``RendererHasVtxOffset``.
"""

from __future__ import annotations

import ctypes
from typing import Any

import moderngl
import numpy as np
from imgui_bundle import imgui

from leafview.gpu.layout import ATLAS_UNIT
from leafview.gpu.shaders import build_program

__all__ = ["ImguiRenderer"]

_Status = imgui.ImTextureStatus


class ImguiRenderer:
    """Draws ``imgui.get_draw_data()`` into the bound framebuffer of ``ctx``.

    Create it after ``imgui.create_context()`` (it configures that context's io) and call
    :meth:`release` before destroying the imgui context; it owns every GL object it creates.
    """

    def __init__(self, ctx: moderngl.Context) -> None:
        if imgui.get_current_context() is None:
            raise RuntimeError("create the imgui context (imgui.create_context()) before ImguiRenderer")
        self.ctx = ctx
        self.program = build_program(ctx, "overlay_imgui.vert", "overlay_imgui.frag")
        self.vbo = ctx.buffer(reserve=1 << 16, dynamic=True)
        self.ibo = ctx.buffer(reserve=1 << 16, dynamic=True)
        self.vao = ctx.vertex_array(self.program, [(self.vbo, "2f 2f 4f1", "in_pos", "in_uv", "in_color")],
                                    index_buffer=self.ibo, index_element_size=imgui.INDEX_SIZE)
        self.textures: dict[int, moderngl.Texture] = {}
        io = imgui.get_io()
        io.backend_flags |= imgui.BackendFlags_.renderer_has_textures
        io.backend_flags |= imgui.BackendFlags_.renderer_has_vtx_offset
        limit = int(ctx.info.get("GL_MAX_TEXTURE_SIZE", 4096))
        pio = imgui.get_platform_io()
        pio.renderer_texture_max_width = limit
        pio.renderer_texture_max_height = limit

    # -- textures (font atlas pages) ------------------------------------------------------------
    def update_textures(self) -> None:
        """Create, update or destroy the textures imgui asks for (call once per frame)."""
        for tex in imgui.get_platform_io().textures:
            if tex.status != _Status.ok:
                self._update_texture(tex)

    def _update_texture(self, tex: Any) -> None:
        if tex.status == _Status.want_create:
            pixels = tex.get_pixels_array()
            gl_tex = self.ctx.texture((tex.width, tex.height), 4, pixels.tobytes())
            gl_tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
            gl_tex.repeat_x = gl_tex.repeat_y = False
            self.textures[gl_tex.glo] = gl_tex
            tex.set_tex_id(gl_tex.glo)
            tex.status = _Status.ok
        elif tex.status == _Status.want_updates:
            known = self.textures.get(int(tex.tex_id))
            if known is not None:
                pixels = tex.get_pixels_array().reshape(tex.height, tex.width, 4)
                for r in tex.updates:
                    block = np.ascontiguousarray(pixels[r.y:r.y + r.h, r.x:r.x + r.w])
                    known.write(block.tobytes(), viewport=(r.x, r.y, r.w, r.h))
            tex.status = _Status.ok
        elif tex.status == _Status.want_destroy and tex.unused_frames > 0:
            self._destroy(tex)

    def _destroy(self, tex: Any) -> None:
        gl_tex = self.textures.pop(int(tex.tex_id), None)
        if gl_tex is not None:
            gl_tex.release()
        tex.set_tex_id(0)
        tex.status = _Status.destroyed

    # -- drawing --------------------------------------------------------------------------------
    def render(self, draw_data: Any) -> None:
        """Draw one frame's draw data over what the bound framebuffer holds."""
        self.update_textures()
        scale_x, scale_y = draw_data.framebuffer_scale.x, draw_data.framebuffer_scale.y
        pos_x, pos_y = draw_data.display_pos.x, draw_data.display_pos.y
        fb_w = int(draw_data.display_size.x * scale_x)
        fb_h = int(draw_data.display_size.y * scale_y)
        if fb_w <= 0 or fb_h <= 0 or not draw_data.cmd_lists:
            return
        ctx = self.ctx
        ctx.enable_only(moderngl.BLEND)
        # moderngl-stubs 5.13 type both as 2-tuples; moderngl takes one equation for rgb and alpha
        # and a separate (rgb, alpha) blend func pair, as the stubs' own docstrings show
        ctx.blend_equation = moderngl.FUNC_ADD  # type: ignore[assignment]
        ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA,  # type: ignore[assignment]
                          moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
        ctx.wireframe = False
        ctx.viewport = (0, 0, fb_w, fb_h)
        left, right = pos_x, pos_x + draw_data.display_size.x
        top, bottom = pos_y, pos_y + draw_data.display_size.y
        proj = np.array([
            [2.0 / (right - left), 0.0, 0.0, 0.0],
            [0.0, 2.0 / (top - bottom), 0.0, 0.0],
            [0.0, 0.0, -1.0, 0.0],
            [(right + left) / (left - right), (top + bottom) / (bottom - top), 0.0, 1.0],
        ], dtype="f4")
        proj_uniform = self.program["proj"]
        assert isinstance(proj_uniform, moderngl.Uniform)   # moderngl types a lookup as any member kind
        proj_uniform.write(proj.tobytes())
        try:
            for cmd_list in draw_data.cmd_lists:
                self._draw_list(cmd_list, pos_x, pos_y, scale_x, scale_y, fb_w, fb_h)
        finally:
            ctx.scissor = None
            ctx.disable(moderngl.BLEND)
            ctx.blend_func = moderngl.DEFAULT_BLENDING  # type: ignore[assignment]  # a 2-tuple, stubbed as int

    def _draw_list(self, cmd_list: Any, pos_x: float, pos_y: float, sx: float, sy: float,
                   fb_w: int, fb_h: int) -> None:
        n_vtx, n_idx = cmd_list.vtx_buffer.size(), cmd_list.idx_buffer.size()
        if n_vtx == 0 or n_idx == 0:
            return
        vtx = (ctypes.c_char * (n_vtx * imgui.VERTEX_SIZE)).from_address(cmd_list.vtx_buffer.data_address())
        idx_bytes = (ctypes.c_char * (n_idx * imgui.INDEX_SIZE)).from_address(cmd_list.idx_buffer.data_address())
        commands = list(cmd_list.cmd_buffer)
        if any(cmd.vtx_offset for cmd in commands):
            # no glDrawElementsBaseVertex in moderngl: fold the vertex offsets into the indices
            dtype = np.uint16 if imgui.INDEX_SIZE == 2 else np.uint32
            idx = np.frombuffer(idx_bytes, dtype=dtype).astype(np.uint32)
            for cmd in commands:
                idx[cmd.idx_offset:cmd.idx_offset + cmd.elem_count] += cmd.vtx_offset
            idx_data: Any = idx.astype(dtype).tobytes()
        else:
            idx_data = idx_bytes
        self._upload(self.vbo, vtx)
        self._upload(self.ibo, idx_data)
        for cmd in commands:
            if cmd.elem_count == 0:
                continue
            clip = cmd.clip_rect
            x0, y0 = (clip.x - pos_x) * sx, (clip.y - pos_y) * sy
            x1, y1 = min((clip.z - pos_x) * sx, fb_w), min((clip.w - pos_y) * sy, fb_h)
            x0, y0 = max(x0, 0.0), max(y0, 0.0)
            if x1 <= x0 or y1 <= y0:
                continue
            self.ctx.scissor = (int(x0), int(fb_h - y1), int(x1 - x0), int(y1 - y0))
            tex = self.textures.get(int(cmd.tex_ref.get_tex_id()))
            if tex is None:
                continue  # a texture this renderer does not know (none is created elsewhere)
            tex.use(location=ATLAS_UNIT)
            self.vao.render(moderngl.TRIANGLES, vertices=cmd.elem_count, first=cmd.idx_offset)

    @staticmethod
    def _upload(buf: moderngl.Buffer, data: Any) -> None:
        size = len(memoryview(data).cast("B"))
        if size > buf.size:
            buf.orphan(1 << (size - 1).bit_length())
        buf.write(data)

    # -- lifetime -------------------------------------------------------------------------------
    def release(self) -> None:
        """Destroy the textures and GL objects (the imgui context must still exist)."""
        if imgui.get_current_context() is not None:
            for tex in imgui.get_platform_io().textures:
                if int(tex.tex_id) in self.textures:
                    self._destroy(tex)
            io = imgui.get_io()
            io.backend_flags &= ~imgui.BackendFlags_.renderer_has_textures
            io.backend_flags &= ~imgui.BackendFlags_.renderer_has_vtx_offset
        for gl_tex in self.textures.values():
            gl_tex.release()
        self.textures.clear()
        for obj in (self.vao, self.vbo, self.ibo, self.program):
            obj.release()
