"""What the preview and scene renderers share: float render targets with a G-buffer, the pass
plan of a method, the shading binder (viewer/shading.py) and the environment background."""

from __future__ import annotations

from dataclasses import dataclass, field

import moderngl
import numpy as np

from lobeview.core.methods import Method

from .camera import pixel_offset
from .cubemap import RadianceCube
from .frame import FrameTargets
from .interface import bind_sampler, set_uniform
from .mip_chain import DEFAULT_MIP_FILTER
from .shaders import ProgramCache
from .shading import ShadingBinder


@dataclass
class RenderResult:
    radiance: np.ndarray  # (H, W, 3) linear
    position: np.ndarray  # (H, W, 3) world
    normal: np.ndarray  # (H, W, 3) shading normal used
    tangent: np.ndarray  # (H, W, 3)
    mask: np.ndarray  # (H, W) object pixels
    invalid: np.ndarray  # (H, W) pixels whose shading produced NaN/Inf (written as 0)
    timings: dict = field(default_factory=dict)  # seconds; 'gpu shade' from a GL timer query
    samples_per_pixel: int = 0
    object_id: np.ndarray | None = None  # (H, W) scene object index, -1 = background (scenes only)


class RendererBase:
    """The frame targets (viewer/frame.py), the shading binder (material and cube-map state,
    viewer/shading.py) and the environment background."""

    PLANE_STATE = False  # whether the frame has the averaged-tangent-plane state targets

    def __init__(
        self, ctx: moderngl.Context, size, shading: ShadingBinder | None = None, mip_filter: str | None = None
    ):
        self.ctx = ctx
        # ``shading``: the scene renderer's own binder (viewer/scene_shading.py); otherwise a plain
        # one whose MIP chains are made by ``mip_filter`` (lobe-N's default LOD bias follows it).
        self.shading = (
            shading if shading is not None else ShadingBinder(ctx, ProgramCache(ctx), mip_filter or DEFAULT_MIP_FILTER)
        )
        self.programs = self.shading.programs
        self._vaos: dict = {}
        self._timer = None
        self.frame = FrameTargets(ctx, size, plane_state=self.PLANE_STATE)

    @property
    def mip_filter(self) -> str:
        return self.shading.mip_filter

    def resize(self, size):
        self.frame.resize(size)

    @property
    def size(self) -> tuple[int, int]:
        return self.frame.size

    @property
    def targets(self) -> list:
        return self.frame.targets

    @property
    def fbo(self):
        """The framebuffer the last pass drew into."""
        return self.frame.fbo

    def gpu_timer(self):
        """A GL_TIME_ELAPSED query (``with timer: draw``; ``timer.elapsed`` in ns), or None where
        the driver has none: callers then report wall-clock time only."""
        if self._timer is None:
            try:
                self._timer = self.ctx.query(time=True)
            except moderngl.Error:
                self._timer = False
        return self._timer or None

    @staticmethod
    def pass_plan(method: Method, spp: int, pixel_filter: str, has_rational: bool) -> tuple[Method, list]:
        """The method of each pass and the passes' sub-pixel positions (pixels from the centre)
        for ``spp`` samples per lobe: a box-filtered reference moves each pass (pixel_offset,
        pass 0 at the centre), everything else shades the pixel centres; a Rational BRDF's
        reference passes shrink (Method.for_rational)."""
        method = method.for_pixel_filter(spp, pixel_filter)
        if has_rational:
            method = method.for_rational()
        passes = method.passes(spp)
        if method.kind == "reference" and pixel_filter == "box":
            return method, [pixel_offset(p) for p in range(passes)]
        return method, [(0.0, 0.0)] * passes

    def read(self, attachment: int) -> np.ndarray:
        """(H, W, 4) of G-buffer target ``attachment``, row 0 at the top."""
        return self.frame.read(attachment)

    def raise_on_gl_error(self, method) -> None:
        """Raise if GL flagged an error since the flag was last read: a failed draw call leaves
        objects out of the image (or the whole image empty) without any other sign."""
        error = self.ctx.error
        if error != "GL_NO_ERROR":
            raise RuntimeError(f"OpenGL reported {error} while drawing {method}: a renderer bug, please report it")

    def draw_background(self, cube: RadianceCube, view_proj: np.ndarray) -> None:
        """Environment behind everything (depth test off, so it writes no depth)."""
        draw_environment(self.ctx, self.programs, self._vaos, cube, view_proj)

    def release(self):
        self.shading.release()
        for vao in self._vaos.values():
            vao.release()
        self._vaos.clear()
        self._timer = None  # moderngl 5 queries have no release(); freed with the context
        self.frame.release()


def draw_environment(ctx, programs: ProgramCache, vaos: dict, cube: RadianceCube, view_proj: np.ndarray) -> None:
    """The environment ``cube`` behind everything drawn with ``view_proj`` (depth test off, so it
    writes no depth); its vertex array is kept in ``vaos``."""
    program = programs.program("background.vert", "background.frag", {})
    key = ("background", id(program))
    if key not in vaos:
        vaos[key] = ctx.vertex_array(program, [])
    set_uniform(program, "u_inverse_view_projection", tuple(np.linalg.inv(view_proj).T.astype("f4").ravel()))
    bind_sampler(program, "u_background", cube.radiance)
    ctx.disable(moderngl.DEPTH_TEST)
    vaos[key].render(moderngl.TRIANGLES, vertices=3)
