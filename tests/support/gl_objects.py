"""Counting the GL objects a test left alive (leak checks)."""

import gc

import moderngl

GL_TYPES = (moderngl.Buffer, moderngl.Texture, moderngl.Framebuffer, moderngl.Renderbuffer,
            moderngl.VertexArray, moderngl.Program, moderngl.ComputeShader)


def live_gl_objects() -> int:
    """GL objects alive and not released (framebuffer 0's wrappers are references, not objects)."""
    gc.collect()
    return sum(1 for o in gc.get_objects()
               if isinstance(o, GL_TYPES) and type(o.mglo).__name__ != "InvalidObject"
               and not getattr(o, "_is_reference", False))
