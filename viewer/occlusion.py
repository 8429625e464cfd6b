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
behind the corridor wall, a room behind a closed door). With the multi-draws on, the candidates
are one multi-draw whose fragment shader counts each object's passing samples in a storage
buffer (shaders/visible_samples.frag): the same counts without a draw and a query per reflector.

A real-time frame (unjittered, with the depth pre-pass on) draws its pre-pass before the mirror
passes, and the test reads that depth (SceneRenderer.draw_frame): one depth pass of the scene less
a frame. Its occluders are then everything the camera pass draws opaquely, reflectors and glass
included (a wall hidden behind a glass pane is seen through the pane's see-through buffer, never
shaded in the camera pass), and the queried reflectors are drawn with a small polygon offset
towards the camera, since their own depth is in the pre-pass, drawn by another path. Otherwise
(the pre-pass off) the test draws its own depth, and only what certainly hides is an occluder:
opaque, single-layer materials (no alphaMode MASK or BLEND, no transmission lobes) and no
reflector (so that a reflector's own depth never hides itself). Single-sided occluders lose their
back faces as in the camera pass. The test is exact at pixel centres, which is where the
real-time methods shade; the jittered reference is not tested (a reflector seen between pixel
centres would lose its buffer there)."""

from __future__ import annotations

import moderngl
import numpy as np

from .camera import outside_frustum_boxes
from .frame import new_framebuffer
from .interface import bind_storage, set_uniform

GL_BUFFER_UPDATE_BARRIER_BIT = 0x00000200  # buffer reads (glGetBufferSubData) see shader writes after it


class OcclusionTest:
    """``geometry``: the scene's vertex and index buffers (viewer/object_batches.py SceneGeometry);
    ``draw_calls``: the drawer's counters (viewer/object_drawer.py DrawCalls)."""

    def __init__(self, ctx: moderngl.Context, programs, geometry, draw_calls, boxes: np.ndarray):
        self.ctx = ctx
        self.boxes = np.asarray(boxes, dtype=np.float64)  # (n, 2, 3) every object's world bounding box
        self.programs = programs
        self.geometry = geometry
        self.size: tuple[int, int] | None = None
        self.depth = None
        self.fbo = None
        self._vao = None
        self._queries: list = []  # one samples-passed query per queried object, reused
        self._objects = None  # the last objects list draw_depth was given, and its arrays:
        self._object_arrays = None  # (indices, enabled, single-sided) made once per list, not per pass
        self.draw_calls = draw_calls
        # The multi-drawn test (batches given): per-object counts, their vertex array, the commands
        # of the last queried objects (indices, buffer).
        self._counts = self._count_vao = self._count_commands = None

    def _targets(self, size) -> None:
        size = (int(size[0]), int(size[1]))
        if size == self.size:
            return
        self.release_targets()
        self.size = size
        self.depth = self.ctx.depth_renderbuffer(size)
        self.fbo = new_framebuffer(self.ctx, [], self.depth)

    def _positions(self, program) -> moderngl.VertexArray:
        """Every object's positions for the depth program (one vertex array)."""
        if self._vao is None:
            self._vao = self.geometry.vertex_array(self.ctx, program, position_only=True)
        return self._vao

    def _draw(self, program, obj) -> None:
        """Object ``obj``'s triangles, positions only."""
        self._positions(program).render(moderngl.TRIANGLES, vertices=obj.index_count, first=obj.first_index)
        self.draw_calls.single += 1

    def draw_depth(self, view_proj: np.ndarray, objects: list, batches=None) -> tuple[int, int]:
        """Depth of ``objects`` ((GPU object, single-sided) pairs) into the bound framebuffer's
        depth buffer (less-than test, colour untouched: the program has no outputs); objects
        outside the frustum are skipped. ``batches`` (viewer/object_batches.py ObjectBatches):
        drawn by multi-draws culled on the GPU instead of one draw each. Returns (drawn, culled)
        by the frustum test."""
        program = self.programs.program("depth.vert", "depth.frag", {})
        set_uniform(program, "u_view_projection", tuple(view_proj.T.astype("f4").ravel()))
        ctx = self.ctx
        ctx.disable(moderngl.BLEND)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.depth_func = "<"
        drawn = culled = 0
        indices, enabled, single_sided = self._arrays(objects)
        outside = outside_frustum_boxes(self.boxes[indices, 0], self.boxes[indices, 1], view_proj)
        if batches is not None:
            hidden = int(np.count_nonzero(outside))
            if hidden < len(objects):
                vao = self._positions(program)
                self.draw_calls.multi += batches.draw_depth(vao, enabled, single_sided, view_proj, True)
                self.draw_calls.culls += 1
            return len(objects) - hidden, hidden
        for (obj, single_sided), hidden in zip(objects, outside, strict=True):
            if hidden:
                culled += 1
                continue
            if single_sided:
                ctx.enable(moderngl.CULL_FACE)
            else:
                ctx.disable(moderngl.CULL_FACE)
            self._draw(program, obj)
            drawn += 1
        ctx.disable(moderngl.CULL_FACE)
        return drawn, culled

    def _arrays(self, objects: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(object indices, enabled per object, single-sided per object) of ``objects``: the
        drawer hands the same cached list every pass until its materials change."""
        if objects is not self._objects:
            indices = np.fromiter((obj.index for obj, _ in objects), dtype=np.int64, count=len(objects))
            enabled = np.zeros(self.geometry.first_index.size, dtype=bool)
            single_sided = np.zeros_like(enabled)
            enabled[indices] = True
            single_sided[indices] = np.fromiter((one for _, one in objects), dtype=bool, count=len(objects))
            self._objects, self._object_arrays = objects, (indices, enabled, single_sided)
        return self._object_arrays

    def visible_samples(
        self, view_proj: np.ndarray, size, occluders: list, queried: dict, batches=None, depth_fbo=None
    ) -> dict[int, int]:
        """Samples of each ``queried`` object (index -> GPU object) that no occluder hides from
        the camera of ``view_proj``. ``occluders``: (GPU object, single-sided) pairs;
        ``batches``: as in draw_depth. ``depth_fbo``: a framebuffer of ``size`` whose depth
        already holds the camera pass's depth pre-pass for ``view_proj`` (every opaque object,
        the queried ones too): the queries run against it, and the test draws no depth of its own
        (one depth pass of the scene less a frame); ``occluders`` are then not drawn."""
        ctx = self.ctx
        ctx.scissor = None
        if depth_fbo is None:
            self._targets(size)
            fbo = self.fbo
            fbo.use()
            ctx.viewport = (0, 0, *self.size)
            fbo.clear(depth=1.0)
            self.draw_depth(view_proj, occluders, batches)
        else:
            fbo = depth_fbo
            fbo.use()
            ctx.viewport = (0, 0, int(size[0]), int(size[1]))
            ctx.disable(moderngl.BLEND)
            ctx.enable(moderngl.DEPTH_TEST)
            # The queried object's own depth is in the pre-pass, drawn by another path (a
            # multi-draw): a small offset towards the camera keeps its fragments from failing
            # against their own depth by rounding. (An object just behind a surface within that
            # offset counts as visible: the test stays conservative.)
            ctx.polygon_offset = (-1.0, -4.0)
        fbo.depth_mask = False
        ctx.depth_func = "<="  # a reflector lying on an occluder (a floor under a wall) is not hidden by it
        if batches is not None:
            samples = self._counted_samples(view_proj, queried, batches)
        else:
            program = self.programs.program("depth.vert", "depth.frag", {})
            set_uniform(program, "u_view_projection", tuple(view_proj.T.astype("f4").ravel()))
            # Every object's query is issued before any result is read: reading one waits for the
            # GPU to finish it, so one wait a frame instead of one per reflector.
            while len(self._queries) < len(queried):
                self._queries.append(ctx.query(samples=True))
            queries = self._queries[: len(queried)]
            for query, obj in zip(queries, queried.values(), strict=True):
                with query:
                    self._draw(program, obj)
            samples = {index: int(query.samples) for query, index in zip(queries, queried, strict=True)}
        fbo.depth_mask = True
        ctx.depth_func = "<"
        ctx.polygon_offset = (0.0, 0.0)
        return samples

    def _counted_samples(self, view_proj: np.ndarray, queried: dict, batches) -> dict[int, int]:
        """The queried objects' visible samples by one multi-draw (``batches``: the drawer's
        ObjectBatches, for its command layout) in which every fragment that passes the depth
        test adds one to its object's count in a storage buffer (shaders/visible_samples.frag):
        what a samples-passed query per object counts, without a draw and a query each. No face
        culling, as the queries' draws. Reading the counts waits for the device, as reading the
        queries did."""
        ctx = self.ctx
        program = self.programs.program("depth.vert", "visible_samples.frag", {"OBJECT_INDEX": True})
        set_uniform(program, "u_view_projection", tuple(view_proj.T.astype("f4").ravel()))
        indices = tuple(int(index) for index in queried)
        if self._count_commands is None or self._count_commands[0] != indices:
            if self._count_commands is not None:
                self._count_commands[1].release()
            self._count_commands = (indices, batches.command_buffer(np.array(indices, dtype=np.int64), 1)[0])
        if self._counts is None:
            self._counts = ctx.buffer(reserve=4 * max(len(self.boxes), 1))
        if self._count_vao is None or self._count_vao[0] is not program:
            if self._count_vao is not None:
                self._count_vao[1].release()
            self._count_vao = (program, self.geometry.vertex_array(ctx, program, position_only=True))
        self._counts.clear()
        bind_storage(program, self._counts, 0)
        ctx.disable(moderngl.CULL_FACE)
        self._count_vao[1].render_indirect(self._count_commands[1], moderngl.TRIANGLES, count=len(indices))
        self.draw_calls.multi += 1
        ctx.memory_barrier(GL_BUFFER_UPDATE_BARRIER_BIT)  # the shader's writes, before the read below
        counts = np.frombuffer(self._counts.read(), dtype=np.uint32)
        return {index: int(counts[index]) for index in indices}

    def release_targets(self) -> None:
        for item in (self.fbo, self.depth):
            if item is not None:
                item.release()
        self.fbo = self.depth = None
        self.size = None

    def release(self) -> None:
        self.release_targets()
        if self._vao is not None:
            self._vao.release()
            self._vao = None
        self._queries = []  # moderngl 5.13 queries have no release(): the context frees them
        for item in (
            self._counts,
            self._count_vao[1] if self._count_vao else None,
            self._count_commands[1] if self._count_commands else None,
        ):
            if item is not None:
                item.release()
        self._counts = self._count_vao = self._count_commands = None
