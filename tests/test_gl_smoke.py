"""Headless OpenGL smoke test: an EGL 4.5 core context draws a triangle into a float
framebuffer and the expected pixels come back. If headless GL breaks, CI fails here loudly."""

from __future__ import annotations

import numpy as np

from lobeview.viewer.context import create_headless_context, renderer_description

VERTEX = """
#version 450 core
in vec2 in_position;
in vec3 in_color;
out vec3 v_color;
void main() {
    v_color = in_color;
    gl_Position = vec4(in_position, 0.0, 1.0);
}
"""

FRAGMENT = """
#version 450 core
in vec3 v_color;
out vec4 frag_color;
void main() { frag_color = vec4(v_color, 1.0); }
"""


def test_egl_context_draws_triangle_into_float_framebuffer():
    ctx = create_headless_context()
    try:
        assert ctx.version_code >= 450, renderer_description(ctx)
        size = 64
        color = ctx.texture((size, size), 4, dtype="f4")
        fbo = ctx.framebuffer(color_attachments=[color])
        fbo.use()
        ctx.clear(0.0, 0.0, 0.0, 0.0)
        program = ctx.program(vertex_shader=VERTEX, fragment_shader=FRAGMENT)
        # A triangle covering the left half of the screen, with HDR values above 1 to prove the
        # target is float (an 8-bit target would clamp them).
        radiance = (4.0, 0.5, 1e-3)
        vertices = np.array([[-1, -1, *radiance], [0, -1, *radiance], [-1, 1, *radiance]], dtype="f4")
        vbo = ctx.buffer(vertices.tobytes())
        vao = ctx.vertex_array(program, [(vbo, "2f 3f", "in_position", "in_color")])
        vao.render()
        pixels = np.frombuffer(fbo.read(components=4, dtype="f4"), dtype="f4").reshape(size, size, 4)
        # Inside the triangle (lower-left quarter area): exactly the float radiance.
        np.testing.assert_allclose(pixels[8, 8, :3], radiance, rtol=1e-6)
        assert pixels[8, 8, 3] == 1.0
        # Outside (right half): the clear colour.
        np.testing.assert_array_equal(pixels[32, 48], [0.0, 0.0, 0.0, 0.0])
        covered = np.count_nonzero(pixels[..., 3])
        # The triangle covers a quarter of the viewport (half of the left half).
        assert abs(covered - size * size / 4) <= size
    finally:
        ctx.release()
