"""Depth-only drawing (issue 18): the camera pass's depth pre-pass and the occlusion test of the
planar reflectors.

Depth pre-pass: the opaque objects' depth goes into the frame's depth buffer first, and the
shading pass then tests less-or-equal against it, so the expensive per-pixel integration runs
once per pixel instead of once per overlapping surface (depth.vert and scene.vert compute
gl_Position invariantly, so a surface meets its own depth exactly).

Occlusion test: a reflector whose mirror buffers no camera
pixel would read needs no mirror pass. The opaque objects' depth is drawn from the camera (a
depth-only pre-pass at the frame's resolution), then each candidate reflector is drawn against it
inside a samples-passed query; a reflector none of whose fragments passes is hidden (a floor
behind the corridor wall, a room behind a closed door).

Only what certainly hides is an occluder: opaque, single-layer materials (no alphaMode MASK or
BLEND, no transmission lobes) and no reflector (a reflector never hides another here, so its own
depth can never hide itself). Single-sided occluders lose their back faces as in the camera
pass. The test is exact at pixel centres, which is where the real-time methods shade; the
jittered reference is not tested (a reflector seen between pixel centres would lose its buffer
there)."""

from __future__ import annotations

import moderngl
import numpy as np

from .camera import outside_frustum_many
from .frame import new_framebuffer
from .interface import set_uniform

# Vertex layout of the scene renderer's object buffers: position, then normal, tangent and two
# UV sets (3 + 4 + 2 + 2 floats) that the depth pass skips.
POSITION_ONLY = "3f 44x"


class OcclusionTest:
    def __init__(self, ctx: moderngl.Context, programs):
        self.ctx = ctx
        self.programs = programs
        self.size: tuple[int, int] | None = None
        self.depth = None
        self.fbo = None
        self._vaos: dict[int, moderngl.VertexArray] = {}
        self._query = None

    def _targets(self, size) -> None:
        size = (int(size[0]), int(size[1]))
        if size == self.size:
            return
        self.release_targets()
        self.size = size
        self.depth = self.ctx.depth_renderbuffer(size)
        self.fbo = new_framebuffer(self.ctx, [], self.depth)

    def _vao(self, program, obj):
        vao = self._vaos.get(obj.index)
        if vao is None:
            vao = self._vaos[obj.index] = self.ctx.vertex_array(
                program, [(obj.vbo, POSITION_ONLY, "in_position")], obj.ibo
            )
        return vao

    def draw_depth(self, view_proj: np.ndarray, objects: list) -> tuple[int, int]:
        """Depth of ``objects`` ((GPU object, single-sided) pairs) into the bound framebuffer's
        depth buffer (less-than test, colour untouched: the program has no outputs); objects
        outside the frustum are skipped. Returns (drawn, culled)."""
        program = self.programs.program("depth.vert", "depth.frag", {})
        set_uniform(program, "u_view_projection", tuple(view_proj.T.astype("f4").ravel()))
        ctx = self.ctx
        ctx.disable(moderngl.BLEND)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.depth_func = "<"
        drawn = culled = 0
        outside = outside_frustum_many(np.array([obj.corners for obj, _ in objects]), view_proj) if objects else []
        for (obj, single_sided), hidden in zip(objects, outside, strict=True):
            if hidden:
                culled += 1
                continue
            if single_sided:
                ctx.enable(moderngl.CULL_FACE)
            else:
                ctx.disable(moderngl.CULL_FACE)
            self._vao(program, obj).render(moderngl.TRIANGLES)
            drawn += 1
        ctx.disable(moderngl.CULL_FACE)
        return drawn, culled

    def visible_samples(self, view_proj: np.ndarray, size, occluders: list, queried: dict) -> dict[int, int]:
        """Samples of each ``queried`` object (index -> GPU object) that no occluder hides from
        the camera of ``view_proj``. ``occluders``: (GPU object, single-sided) pairs."""
        self._targets(size)
        ctx = self.ctx
        ctx.scissor = None
        self.fbo.use()
        ctx.viewport = (0, 0, *self.size)
        self.fbo.clear(depth=1.0)
        self.draw_depth(view_proj, occluders)
        program = self.programs.program("depth.vert", "depth.frag", {})
        self.fbo.depth_mask = False
        ctx.depth_func = "<="  # a reflector lying on an occluder (a floor under a wall) is not hidden by it
        if self._query is None:
            self._query = ctx.query(samples=True)
        samples = {}
        for index, obj in queried.items():
            with self._query:
                self._vao(program, obj).render(moderngl.TRIANGLES)
            samples[index] = int(self._query.samples)
        self.fbo.depth_mask = True
        ctx.depth_func = "<"
        return samples

    def release_targets(self) -> None:
        for item in (self.fbo, self.depth):
            if item is not None:
                item.release()
        self.fbo = self.depth = None
        self.size = None

    def release(self) -> None:
        self.release_targets()
        for vao in self._vaos.values():
            vao.release()
        self._vaos.clear()
        self._query = None  # moderngl 5.13 queries have no release(): the context frees them
