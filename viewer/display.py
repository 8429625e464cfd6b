"""GPU-side progressive accumulation and display tonemapping for the interactive viewer."""

from __future__ import annotations

import moderngl
import numpy as np

from .interface import set_uniform
from .shaders import ProgramCache
from .tonemap import TONEMAPS


class Accumulator:
    """Float RGBA buffer holding sum(weight * radiance) in rgb and sum(weight) in alpha; the
    displayed image is their ratio, so passes with different sample counts average correctly."""

    def __init__(self, ctx: moderngl.Context, programs: ProgramCache, size):
        self.ctx = ctx
        self.programs = programs
        self.size = (int(size[0]), int(size[1]))
        self.texture = ctx.texture(self.size, 4, dtype="f4")
        self.fbo = ctx.framebuffer(color_attachments=[self.texture])
        self.accumulate = programs.program("fullscreen.vert", "accumulate.frag", {})
        self.display = programs.program("fullscreen.vert", "tonemap.frag", {})
        self._vao_acc = ctx.vertex_array(self.accumulate, [])
        self._vao_display = ctx.vertex_array(self.display, [])
        self.weight = 0.0
        self.reset()

    def reset(self) -> None:
        self.fbo.clear(0.0, 0.0, 0.0, 0.0)
        self.weight = 0.0

    def add(self, source: moderngl.Texture, weight: float = 1.0) -> None:
        """Add ``weight`` times ``source``: resampled bilinearly, or where it is an integer K > 1
        times this buffer's size each way (a supersampled frame), the mean of each K x K block."""
        box = self.box_factor(source.size)
        self.fbo.use()
        self.ctx.viewport = (0, 0, *self.size)
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.ctx.enable(moderngl.BLEND)
        self.ctx.blend_func = moderngl.ONE, moderngl.ONE
        source.use(0)
        set_uniform(self.accumulate, "u_source", 0)
        set_uniform(self.accumulate, "u_weight", float(weight))
        set_uniform(self.accumulate, "u_box", box)
        self._vao_acc.render(moderngl.TRIANGLES, vertices=3)
        self.ctx.disable(moderngl.BLEND)
        self.weight += weight

    def box_factor(self, source_size) -> int:
        """K where ``source_size`` is K times this buffer's size each way, else 1."""
        width, height = self.size
        factor = int(source_size[0]) // width
        if factor > 1 and tuple(source_size) == (factor * width, factor * height):
            return factor
        return 1

    def show(self, target, viewport, exposure: float = 0.0, operator: str = "aces") -> None:
        target.use()
        self.ctx.viewport = viewport
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.texture.use(0)
        set_uniform(self.display, "u_source", 0)
        set_uniform(self.display, "u_exposure", float(exposure))
        set_uniform(self.display, "u_operator", TONEMAPS.index(operator))
        self._vao_display.render(moderngl.TRIANGLES, vertices=3)

    def radiance(self) -> np.ndarray:
        """The mean radiance, (H, W, 3) float32, row 0 at the top."""
        data = np.frombuffer(self.texture.read(), dtype=np.float32).reshape(self.size[1], self.size[0], 4)[::-1]
        w = np.maximum(data[..., 3:4], 1e-30)
        return np.where(data[..., 3:4] > 0, data[..., :3] / w, 0.0).astype(np.float32)

    def release(self) -> None:
        self._vao_acc.release()
        self._vao_display.release()
        self.fbo.release()
        self.texture.release()


class RefinementBlend:
    """Mixes the refinement's running mean with the real-time frame per pixel, by a weight
    image (viewer/refinement.py two_half_estimate), into an Accumulator that the window shows."""

    def __init__(self, ctx: moderngl.Context, programs: ProgramCache, size):
        self.ctx = ctx
        self.size = (int(size[0]), int(size[1]))
        self.weight = ctx.texture(self.size, 1, dtype="f4")
        self.weight.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.set_weight(None)
        self.program = programs.program("fullscreen.vert", "refinement_blend.frag", {})
        self._vao = ctx.vertex_array(self.program, [])

    def set_weight(self, weight: np.ndarray | None) -> None:
        """The mean's weight per pixel, (H, W), row 0 at the top; None: 0 everywhere."""
        if weight is None:
            weight = np.zeros((self.size[1], self.size[0]), np.float32)
        self.weight.write(np.ascontiguousarray(weight[::-1], dtype=np.float32).tobytes())

    def blend(self, refined: Accumulator, realtime: Accumulator, target: Accumulator) -> None:
        target.reset()
        target.fbo.use()
        self.ctx.viewport = (0, 0, *self.size)
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.BLEND)
        for unit, texture in enumerate((refined.texture, realtime.texture, self.weight)):
            texture.use(unit)
        for unit, name in enumerate(("u_refined", "u_realtime", "u_weight")):
            set_uniform(self.program, name, unit)  # through the shadow (interface._store)
        self._vao.render(moderngl.TRIANGLES, vertices=3)
        target.weight = 1.0

    def release(self) -> None:
        self._vao.release()
        self.weight.release()
