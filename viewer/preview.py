"""Object preview renderer: one object lit only by a distant environment, no lightmaps.

The exact-comparison mode of lobeview: every method of docs/methods.md (lobe-N, fis-N, mc-N,
reference) renders the same object, and the G-buffer (world position, shading normal and
tangent per pixel) is returned so tests can evaluate the numpy reference at the same points.
"""

from __future__ import annotations

import contextlib
import time

import moderngl
import numpy as np

from lobeview.core.methods import Method
from lobeview.materials.bsdf import BSDF
from lobeview.scenes.envmap import EnvironmentMap
from lobeview.scenes.meshes import Mesh

from .camera import Camera, jittered
from .cubemap import EnvironmentCubes
from .interface import bind_sampler, method_defines, set_uniform, uses_blur_stack
from .material_gpu import pack_material
from .mip_chain import DEFAULT_MIP_FILTER
from .render_base import RendererBase, RenderResult
from .shading import volume_uniforms

__all__ = ["PREVIEW_CAMERA", "PreviewRenderer", "RenderResult"]
# The camera of `lobeview shot --object` (position, target, up, vertical fov) for a unit-sized object.
PREVIEW_CAMERA = ((0.0, 0.35, 3.2), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 40.0)


class PreviewRenderer(RendererBase):
    def __init__(
        self,
        ctx: moderngl.Context,
        env: EnvironmentMap,
        mesh: Mesh,
        size=(512, 512),
        face_size: int = 256,
        mip_filter: str = DEFAULT_MIP_FILTER,
        bright_sources: bool = False,
    ):
        # mip_filter: how the environment cube's MIP levels are made (viewer/mip_chain.py
        # MIP_FILTERS); lobe-N's default LOD bias follows it (Method.default_lod_bias).
        # bright_sources: separate the cube's bright sources as lights (viewer/cubemap.py).
        super().__init__(ctx, size, mip_filter=mip_filter)
        t0 = time.perf_counter()
        self.cubes = EnvironmentCubes(ctx, env, face_size, mip_filter=mip_filter, bright_sources=bright_sources)
        self.setup_seconds = time.perf_counter() - t0
        self.mesh = mesh
        self.vbo = ctx.buffer(mesh.interleaved().tobytes())
        self.positions = np.asarray(mesh.positions, dtype=np.float64)
        self.ibo = ctx.buffer(np.ascontiguousarray(mesh.indices, dtype=np.uint32).tobytes())

    def _program(self, method: Method, has_diffuse: bool, has_rational: bool = False, has_measured: bool = False):
        defines = {
            **method_defines(method), "HAS_DIFFUSE": has_diffuse, "HAS_RATIONAL": has_rational,
            "HAS_MEASURED": has_measured,
            # lobe-N+norm+fit's coarse reads from the environment's blur stack (materials/blur_stack.py)
            "BLUR_STACK": uses_blur_stack(method),
        }  # fmt: skip
        program = self.programs.program("mesh.vert", "preview.frag", defines)
        key = id(program)
        if key not in self._vaos:
            self._vaos[key] = self.ctx.vertex_array(
                program,
                [(self.vbo, "3f 3f 4f", "in_position", "in_normal", "in_tangent")],
                self.ibo,
            )
        return program, self._vaos[key]

    def render(
        self,
        camera: Camera,
        bsdf: BSDF,
        method: Method | str,
        spp: int = 1024,
        lod_bias: float | None = None,
        background: bool = True,
        model: np.ndarray | None = None,
        seed: int = 0,
        pixel_filter: str = "box",
        footprint_lights: bool = True,
    ) -> RenderResult:
        """``pixel_filter`` (reference only): 'box', the pixel's integral (each pass at another
        sub-pixel position), or 'point', the pixel centre (what the G-buffer holds). The
        G-buffer is always pass 0's, at the pixel centre. ``footprint_lights``: the bright
        sources integrated against each lobe widened by the pixel's footprint
        (shaders/cap_lights.glsl); False: at the pixel centre's lobe (the numpy twin's)."""
        method = Method.parse(method) if isinstance(method, str) else method
        material = pack_material(bsdf)
        method, offsets = self.pass_plan(method, spp, pixel_filter, material.has_rational)
        program, vao = self._program(method, material.has_diffuse, material.has_rational, material.has_measured)
        width, height = self.size
        model = np.eye(4) if model is None else np.asarray(model, dtype=np.float64)
        normal_matrix = np.linalg.inv(model[:3, :3]).T
        view_proj = camera.view_projection(width / height)

        set_uniform(program, "u_model", tuple(model.T.astype("f4").ravel()))
        set_uniform(program, "u_normal_matrix", tuple(normal_matrix.T.astype("f4").ravel()))
        set_uniform(program, "u_camera_position", tuple(float(x) for x in camera.position))
        set_uniform(program, "u_point_sampled_lights", 0 if footprint_lights else 1)
        self.shading.set_material(program, material, method, lod_bias, seed)
        # KHR_materials_volume: the previewed object as the volume (its vertices under ``model``).
        positions = self.positions @ model[:3, :3].T
        volume, attenuation_colour = volume_uniforms(
            getattr(bsdf, "volume", None), positions, abs(np.linalg.det(model[:3, :3])) ** (1.0 / 3.0)
        )
        set_uniform(program, "u_volume", volume)
        set_uniform(program, "u_volume_attenuation", attenuation_colour)
        self.shading.bind_cube(program, self.cubes, method, material)
        bind_sampler(program, "u_irradiance", self.cubes.irradiance)

        passes = len(offsets)
        accumulated = np.zeros((height, width, 3), dtype=np.float64)
        invalid = np.zeros((height, width), dtype=bool)
        timings = {"shade": 0.0}
        g_buffers = None
        for p, offset in enumerate(offsets):
            pass_view_proj = jittered(view_proj, offset, self.size)
            set_uniform(program, "u_view_projection", tuple(pass_view_proj.T.astype("f4").ravel()))
            set_uniform(program, "u_sample_offset", p * method.samples)
            t0 = time.perf_counter()
            self.frame.begin()
            if background:  # behind the object in every pass: silhouettes are filtered too
                self.draw_background(self.cubes, pass_view_proj)
            self.ctx.enable(moderngl.DEPTH_TEST)
            timer = self.gpu_timer()
            _ = self.ctx.error  # only this pass's errors count
            with timer or contextlib.nullcontext():
                vao.render(moderngl.TRIANGLES)
            self.ctx.finish()
            self.raise_on_gl_error(method)
            timings["shade"] += time.perf_counter() - t0
            if timer is not None:
                timings["gpu shade"] = timings.get("gpu shade", 0.0) + timer.elapsed * 1e-9
            radiance = self.read(0)
            accumulated += radiance[..., :3]
            invalid |= radiance[..., 3] < 0.0
            if g_buffers is None:
                g_buffers = [self.read(i) for i in (1, 2, 3)]
        mask = g_buffers[0][..., 3] > 0.5
        return RenderResult(
            radiance=(accumulated / passes).astype(np.float32),
            position=g_buffers[0][..., :3],
            normal=g_buffers[1][..., :3],
            tangent=g_buffers[2][..., :3],
            mask=mask,
            invalid=invalid,
            timings=timings,
            samples_per_pixel=passes * method.samples,
        )

    def release(self):
        super().release()
        self.vbo.release()
        self.ibo.release()
        self.cubes.release()
