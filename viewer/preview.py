"""Object preview renderer: one object lit only by a distant environment, no lightmaps.

The exact-comparison mode of lobeview: every method of DESIGN.md (lobe-N, fis-N, mc-N,
reference) renders the same object, and the G-buffer (world position, shading normal and
tangent per pixel) is returned so tests can evaluate the numpy reference at the same points.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass, field

import moderngl
import numpy as np
from scipy.stats import qmc

from lobeview.materials.bsdf import BSDF
from lobeview.scenes.envmap import EnvironmentMap
from lobeview.scenes.meshes import Mesh

from .camera import Camera
from .cubemap import EnvironmentCubes
from .material_gpu import MAX_LOBES, MAX_PATTERN, pack_material, pack_patterns
from .shaders import ProgramCache

SOBOL_SIDE = 256  # 65536 scrambled 4D Sobol points
SOBOL_SEED = 20100501
REFERENCE_BATCH = 64  # samples per lobe per pass of the reference method
DEFAULT_FIS_LOD_BIAS = 1.0  # Colbert & Krivanek's +1; measured in bench/ (issue 7)
DEFAULT_LOBE_LOD_BIAS = 0.0

_METHOD = re.compile(r"^(lobe|fis|mc)-(\d+)$|^(reference)$")


@dataclass(frozen=True)
class Method:
    kind: str  # 'lobe', 'fis', 'mc', 'reference'
    samples: int  # N per lobe (reference: per pass)

    @classmethod
    def parse(cls, text: str) -> Method:
        m = _METHOD.match(text.strip())
        if not m:
            raise ValueError(f"unknown method {text!r}; use lobe-N, fis-N, mc-N or reference")
        if m.group(3):
            return cls("reference", REFERENCE_BATCH)
        n = int(m.group(2))
        limit = MAX_PATTERN if m.group(1) == "lobe" else 4096
        if not 1 <= n <= limit:
            raise ValueError(f"{text}: N must be in [1, {limit}]")
        return cls(m.group(1), n)

    def __str__(self) -> str:
        return "reference" if self.kind == "reference" else f"{self.kind}-{self.samples}"


def sobol_points(count: int = SOBOL_SIDE * SOBOL_SIDE, seed: int = SOBOL_SEED) -> np.ndarray:
    """Owen-scrambled 4D Sobol points (scipy's generator), fixed seed: a frame renders the same
    image every time. Dimensions 0-1 drive BSDF sampling, 2-3 environment sampling."""
    return qmc.Sobol(d=4, scramble=True, seed=seed).random(count).astype(np.float32)


@dataclass
class RenderResult:
    radiance: np.ndarray  # (H, W, 3) linear
    position: np.ndarray  # (H, W, 3) world
    normal: np.ndarray  # (H, W, 3) shading normal used
    tangent: np.ndarray  # (H, W, 3)
    mask: np.ndarray  # (H, W) object pixels
    invalid: np.ndarray  # (H, W) pixels whose shading produced NaN/Inf (written as 0)
    timings: dict = field(default_factory=dict)
    samples_per_pixel: int = 0


class PreviewRenderer:
    def __init__(
        self,
        ctx: moderngl.Context,
        env: EnvironmentMap,
        mesh: Mesh,
        size=(512, 512),
        face_size: int = 256,
    ):
        self.ctx = ctx
        self.programs = ProgramCache(ctx)
        t0 = time.perf_counter()
        self.cubes = EnvironmentCubes(ctx, env, face_size)
        self.setup_seconds = time.perf_counter() - t0
        self.mesh = mesh
        self.vbo = ctx.buffer(mesh.interleaved().tobytes())
        self.ibo = ctx.buffer(np.ascontiguousarray(mesh.indices, dtype=np.uint32).tobytes())
        sobol = sobol_points()
        self.sobol = ctx.texture((SOBOL_SIDE, SOBOL_SIDE), 4, sobol.tobytes(), dtype="f4")
        self.sobol.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.sobol_count = len(sobol)
        self.resize(size)
        self._vaos: dict = {}

    def resize(self, size):
        self.size = (int(size[0]), int(size[1]))
        self.targets = [self.ctx.texture(self.size, 4, dtype="f4") for _ in range(4)]
        self.depth = self.ctx.depth_renderbuffer(self.size)
        self.fbo = self.ctx.framebuffer(color_attachments=self.targets, depth_attachment=self.depth)

    def _program(self, method: Method, has_diffuse: bool):
        defines = {
            "MAX_LOBES": MAX_LOBES,
            "MAX_PATTERN": MAX_PATTERN,
            "METHOD_LOBE": method.kind == "lobe",
            "METHOD_FIS": method.kind == "fis",
            "METHOD_MC": method.kind in ("mc", "reference"),
            "ENV_SAMPLING": method.kind == "reference",
            "HAS_DIFFUSE": has_diffuse,
        }
        program = self.programs.program("mesh.vert", "preview.frag", defines)
        key = id(program)
        if key not in self._vaos:
            self._vaos[key] = self.ctx.vertex_array(
                program,
                [(self.vbo, "3f 3f 4f", "in_position", "in_normal", "in_tangent")],
                self.ibo,
            )
        return program, self._vaos[key]

    def _set(self, program, name, value):
        if name in program:
            program[name].value = value

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
    ) -> RenderResult:
        method = Method.parse(method) if isinstance(method, str) else method
        material = pack_material(bsdf)
        if lod_bias is None:
            lod_bias = DEFAULT_FIS_LOD_BIAS if method.kind == "fis" else DEFAULT_LOBE_LOD_BIAS
        program, vao = self._program(method, material.has_diffuse)
        width, height = self.size
        model = np.eye(4) if model is None else np.asarray(model, dtype=np.float64)
        normal_matrix = np.linalg.inv(model[:3, :3]).T
        view_proj = camera.view_projection(width / height)

        self._set(program, "u_model", tuple(model.T.astype("f4").ravel()))
        self._set(program, "u_normal_matrix", tuple(normal_matrix.T.astype("f4").ravel()))
        self._set(program, "u_view_projection", tuple(view_proj.T.astype("f4").ravel()))
        self._set(program, "u_camera_position", tuple(float(x) for x in camera.position))
        self._set(program, "u_lobe_count", material.lobe_count)
        program["u_lobes"].write(material.lobes.tobytes())
        if method.kind == "lobe" and "u_pattern" in program:
            program["u_pattern"].write(pack_patterns(material, method.samples).tobytes())
        self._set(program, "u_kd", tuple(float(x) for x in material.kd))
        self._set(program, "u_gltf_diffuse", 1.0 if material.gltf_diffuse else 0.0)
        self._set(program, "u_face_size", float(self.cubes.face_size))
        self._set(program, "u_samples", method.samples)
        self._set(program, "u_lod_bias", float(lod_bias))
        self._set(program, "u_sobol_count", self.sobol_count)
        self._set(program, "u_seed", int(seed))
        self.cubes.radiance.use(0)
        self.cubes.irradiance.use(1)
        self.sobol.use(2)
        self._set(program, "u_radiance", 0)
        self._set(program, "u_irradiance", 1)
        self._set(program, "u_sobol", 2)
        if method.kind == "reference":
            self.cubes.env_cdf.use(3)
            self.cubes.env_pdf.use(4)
            self._set(program, "u_env_cdf", 3)
            self._set(program, "u_env_pdf", 4)
            self._set(program, "u_env_texels", int(self.cubes.importance.probabilities.size))
            self._set(program, "u_env_size", int(self.cubes.importance.size))

        passes = 1
        if method.kind == "reference":
            passes = max(1, int(np.ceil(spp / method.samples)))
        accumulated = np.zeros((height, width, 3), dtype=np.float64)
        invalid = np.zeros((height, width), dtype=bool)
        timings = {"shade": 0.0}
        g_buffers = None
        for p in range(passes):
            self._set(program, "u_sample_offset", p * method.samples)
            t0 = time.perf_counter()
            self.fbo.use()
            self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            self.ctx.enable(moderngl.DEPTH_TEST)
            vao.render(moderngl.TRIANGLES)
            self.ctx.finish()
            timings["shade"] += time.perf_counter() - t0
            radiance = self._read(0)
            accumulated += radiance[..., :3]
            invalid |= radiance[..., 3] < 0.0
            if g_buffers is None:
                g_buffers = [self._read(i) for i in (1, 2, 3)]
        radiance = (accumulated / passes).astype(np.float32)
        mask = g_buffers[0][..., 3] > 0.5
        if background:
            t0 = time.perf_counter()
            bg = self._background(view_proj)
            timings["background"] = time.perf_counter() - t0
            radiance = np.where(mask[..., None], radiance, bg)
        return RenderResult(
            radiance=radiance,
            position=g_buffers[0][..., :3],
            normal=g_buffers[1][..., :3],
            tangent=g_buffers[2][..., :3],
            mask=mask,
            invalid=invalid,
            timings=timings,
            samples_per_pixel=passes * method.samples
            if method.kind in ("reference", "mc", "fis")
            else method.samples,
        )

    def _background(self, view_proj: np.ndarray) -> np.ndarray:
        program = self.programs.program("background.vert", "background.frag", {})
        key = ("background", id(program))
        if key not in self._vaos:
            self._vaos[key] = self.ctx.vertex_array(program, [])
        program["u_inverse_view_projection"].value = tuple(
            np.linalg.inv(view_proj).T.astype("f4").ravel()
        )
        self.cubes.radiance.use(0)
        program["u_radiance"].value = 0
        self.fbo.use()
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.fbo.clear(0.0, 0.0, 0.0, 0.0)
        self._vaos[key].render(moderngl.TRIANGLES, vertices=3)
        self.ctx.finish()
        return self._read(0)[..., :3]

    def _read(self, attachment: int) -> np.ndarray:
        width, height = self.size
        data = self.fbo.read(components=4, attachment=attachment, dtype="f4")
        # OpenGL rows start at the bottom; return images with row 0 at the top.
        return np.frombuffer(data, dtype=np.float32).reshape(height, width, 4)[::-1].copy()

    def release(self):
        for vao in self._vaos.values():
            vao.release()
        for t in self.targets:
            t.release()
        self.depth.release()
        self.fbo.release()
        self.vbo.release()
        self.ibo.release()
        self.sobol.release()
        self.cubes.release()
