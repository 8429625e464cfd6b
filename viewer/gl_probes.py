"""GPU probes the test suite uses (shipped, so a user can
run the same checks on their own GPU): a headless GL context, and CubeLookup, which reads a cube
map at arbitrary directions and MIP levels through the driver's own filtering."""

from __future__ import annotations

import contextlib

import moderngl
import numpy as np

from lobeview.viewer.shaders import ProgramCache


@contextlib.contextmanager
def headless_gl():
    """A headless OpenGL 4.5 context (EGL), released on exit."""
    from lobeview.viewer.context import create_headless_context

    ctx = create_headless_context()
    try:
        yield ctx
    finally:
        ctx.release()


class CubeLookup:
    """Evaluate ``textureLod(cube, dir, lod)`` on the GPU for arrays of queries."""

    def __init__(self, ctx: moderngl.Context, programs: ProgramCache | None = None):
        self.ctx = ctx
        self.programs = programs or ProgramCache(ctx)
        self.shader = self.programs.compute("cube_lookup.comp")

    def __call__(self, cube: moderngl.TextureCube, dirs: np.ndarray, lod: np.ndarray) -> np.ndarray:
        dirs = np.asarray(dirs, dtype=np.float32).reshape(-1, 3)
        lod = np.broadcast_to(np.asarray(lod, dtype=np.float32), (len(dirs),))
        count = len(dirs)
        if count == 0:
            return np.zeros((0, 3))
        queries = np.concatenate([dirs, lod[:, None]], axis=1).astype(np.float32)
        q_buf = self.ctx.buffer(queries.tobytes())
        r_buf = self.ctx.buffer(reserve=count * 16)
        try:
            q_buf.bind_to_storage_buffer(0)
            r_buf.bind_to_storage_buffer(1)
            cube.use(0)
            self.shader["u_cube"] = 0
            self.shader["u_count"] = count
            self.shader.run(group_x=(count + 63) // 64)
            self.ctx.finish()
            out = np.frombuffer(r_buf.read(), dtype=np.float32).reshape(count, 4)[:, :3]
        finally:
            q_buf.release()
            r_buf.release()
        return out.astype(np.float64)
