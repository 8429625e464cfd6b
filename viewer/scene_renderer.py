"""Light-mapped scene renderer (thesis 4.3-4.4): diffuse from lightmaps, view-dependent lobes
from a cube map per object.

Only what the scene analysis asks for is built: a cube map for each object with specular or
transmission lobes (rendered from the centre of its bounding box, without the object itself,
light-mapped diffuse + emission + the environment through openings), and the specular shader
variant only if some object needs it. Cube maps are cached on disk keyed by a hash of the scene
content, the environment, the face size and the renderer version.
"""

from __future__ import annotations

import contextlib
import hashlib
import sys
import time
import warnings
from pathlib import Path

import moderngl
import numpy as np

from lobeview.core.methods import Method
from lobeview.materials.spec import build_bsdf
from lobeview.scenes.analysis import analyse
from lobeview.scenes.envmap import EnvironmentMap
from lobeview.scenes.scene import Scene

from .camera import Camera, perspective
from .cubemap import RadianceCube, equirect_to_cube_faces
from .interface import PROXY_KINDS, TEXTURE_UNITS, bind_sampler, method_defines, set_uniform, write_uniform
from .material_gpu import PackedMaterial, pack_material
from .render_base import RendererBase, RenderResult

CUBE_CACHE_VERSION = 3
CUBE_BOUNCE_METHOD = Method("lobe", 7)  # how other objects' lobes are shaded inside cube maps
MIRROR_BOUNCE_METHOD = Method("lobe", 3, normalize=True)  # ... inside mirror buffers (every frame: cheap)
FALLBACK_IRRADIANCE = 1.0  # E for objects whose lightmap is missing (warned), i.e. kd/pi shading


def face_view(face: int, eye) -> np.ndarray:
    """View matrix whose image plane maps (x, y) in NDC to (sc, tc) of the cube face, so the
    framebuffer (row 0 = t = 0) is the face's texel layout (core/cube_layout.py)."""
    from lobeview.core.cube_layout import face_point_directions

    zero = np.zeros(1)
    f = face_point_directions(face, zero, zero)[0]
    r = face_point_directions(face, np.ones(1), zero)[0] * np.sqrt(2) - f  # d/dsc
    u = face_point_directions(face, zero, np.ones(1))[0] * np.sqrt(2) - f  # d/dtc
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = r, u, -f
    view[:3, 3] = -view[:3, :3] @ np.asarray(eye, dtype=np.float64)
    return view


class _GpuObject:
    def __init__(self, ctx, obj, material: PackedMaterial, index: int):
        m = obj.mesh
        uv1 = obj.uv1 if obj.uv1 is not None else np.zeros((len(m.positions), 2), np.float32)
        data = np.concatenate([m.positions, m.normals, m.tangents, m.uvs, uv1], axis=1).astype(np.float32)
        self.vbo = ctx.buffer(data.tobytes())
        self.ibo = ctx.buffer(np.ascontiguousarray(m.indices, dtype=np.uint32).tobytes())
        self.material = material
        self.index = index
        self.name = obj.name
        lo, hi = m.positions.min(axis=0), m.positions.max(axis=0)
        self.centre = (lo + hi) / 2.0
        self.cube: RadianceCube | None = None

    def release(self):
        self.vbo.release()
        self.ibo.release()
        if self.cube is not None:
            self.cube.release()


# Sampler-uniform prefixes of the mirror and see-through buffers (units: interface.TEXTURE_UNITS).
BUFFER_PREFIXES = {"mirror": "u_mirror", "see-through": "u_through"}


class _MirrorTargets:
    """One reflector's mirror buffer (thesis 4.5.1): radiance with a MIP chain, world position
    (w = 1 geometry, 0 environment), normal, depth."""

    def __init__(self, ctx, size):
        self.size = size
        self.radiance = ctx.texture(size, 4, dtype="f4")
        self.radiance.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        self.radiance.repeat_x = self.radiance.repeat_y = False
        self.position = ctx.texture(size, 4, dtype="f4")
        self.normal = ctx.texture(size, 4, dtype="f4")
        for tex in (self.position, self.normal):
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.depth = ctx.depth_renderbuffer(size)
        self.fbo = ctx.framebuffer(
            color_attachments=[self.radiance, self.position, self.normal], depth_attachment=self.depth
        )
        self.camera = None  # scenes.planar_mirror.MirrorCamera of the last pass

    def release(self):
        for item in (self.fbo, self.radiance, self.position, self.normal, self.depth):
            item.release()


class SceneRenderer(RendererBase):
    def __init__(
        self,
        ctx: moderngl.Context,
        scene: Scene,
        environment: EnvironmentMap,
        size=(640, 400),
        cube_face_size: int = 256,
        cache_dir: Path | None = None,
        progress: bool = True,
        cube_bounces: int = 2,
        mirror_scale: float = 1.0,
        mirror_specular: bool = True,
    ):
        super().__init__(ctx, size)
        if not 0.05 <= float(mirror_scale) <= 2.0:
            raise ValueError(f"mirror_scale must be in [0.05, 2], got {mirror_scale}")
        # Planar reflectors (thesis 4.5): one mirror pass per visible reflector per frame, at
        # mirror_scale times the frame's resolution; mirror_specular shades the glossy objects seen
        # in it from their cube maps (lobe-3) instead of the thesis' diffuse-only mirror pass.
        self.mirror_scale = float(mirror_scale)
        self.mirror_specular = bool(mirror_specular)
        # Refinement (mc-N, reference) on reflectors averages the tangent planes its samples found
        # at each pixel (Fig. 4.46b); False gives the plain two-step projection (for comparison).
        self.mirror_plane_average = True
        self.mirrors_enabled = True
        self.enabled_reflectors: set | None = None  # None: every reflector of the analysis
        self._mirror_targets: dict[tuple[int, str], _MirrorTargets] = {}  # (index, 'mirror' | 'see-through')
        self._mirror_key = None
        self._active_mirrors: dict = {}  # index -> {kind: targets} drawn for _mirror_key
        self._mirror_generation = 0
        self.mirror_report: list[str] = []  # what the last frame's mirror passes did
        self.scene = scene
        self.analysis = analyse(scene)
        self.progress = progress
        self.timings: dict = {}
        t0 = time.perf_counter()
        self.environment = RadianceCube(ctx, equirect_to_cube_faces(environment, 256))
        self.environment_name = environment.name
        self._env_hash = hashlib.sha256(environment.image.tobytes()).hexdigest()[:16]
        self.textures: dict[int, moderngl.Texture] = {}
        # Every sampler uniform gets its own unit and a texture, even when unused: two samplers
        # of different types on one unit make the draw call fail (GL_INVALID_OPERATION).
        self._white = ctx.texture((1, 1), 3, np.ones(3, np.float32).tobytes(), dtype="f4")
        self.objects = []
        for i, obj in enumerate(scene.objects):
            material = pack_material(build_bsdf(scene.materials[obj.material].desc))
            self.objects.append(_GpuObject(ctx, obj, material, i))
        for needs in self.analysis.objects:
            if not needs.has_lightmap:
                warnings.warn(
                    f"object {needs.name!r} has no usable lightmap: shaded with a constant "
                    f"irradiance of {FALLBACK_IRRADIANCE} (kd / pi)",
                    stacklevel=2,
                )
        self.timings["upload"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        self.cube_face_size = cube_face_size
        self.cube_bounces = max(1, int(cube_bounces))
        self.object_methods: dict[int, Method] = {}
        self.stale_cubes: list[int] = []
        self.cache_dir = Path(cache_dir) if cache_dir else None
        self._build_cube_maps(cache_dir)
        for obj in self.objects:
            if obj.cube is not None:
                obj.cube.cache_dir = self.cache_dir  # prefiltered maps are cached beside the cubes
        self.timings["cube maps"] = time.perf_counter() - t0

    # -- options the viewer's panel sets -------------------------------------------------------
    def set_mirrors(self, enabled: bool, scale: float | None = None) -> None:
        """Planar mirror passes on/off and their resolution (0.05..2 x the frame)."""
        if scale is not None:
            if not 0.05 <= float(scale) <= 2.0:
                raise ValueError(f"mirror_scale must be in [0.05, 2], got {scale}")
            self.mirror_scale = float(scale)
        self.mirrors_enabled = bool(enabled)

    def set_object_method(self, index: int, method: Method | None) -> None:
        """Shade object ``index`` with its own real-time method (None: the frame's method)."""
        if method is None:
            self.object_methods.pop(index, None)
        elif method.kind == "reference":
            raise ValueError("the per-object method must be a real-time one; refinement uses the reference")
        else:
            self.object_methods[index] = method

    def object_method(self, index: int) -> Method | None:
        """Object ``index``'s own method, or None when it follows the frame's."""
        return self.object_methods.get(index)

    @property
    def radiance_target(self):
        """The float radiance texture of the last drawn frame."""
        return self.targets[0]

    @property
    def stale_cube_count(self) -> int:
        """Cube maps still waiting to be re-rendered after a material edit."""
        return len(self.stale_cubes)

    def prefiltered_memory(self, index: int) -> dict[str, int]:
        """Bytes of each prefiltered map object ``index`` has built so far (empty: none)."""
        cube = self.objects[index].cube
        maps = cube.built_prefiltered_maps if cube is not None else None
        return dict(maps.memory) if maps is not None else {}

    # -- resources -------------------------------------------------------------------------
    def resize(self, size):
        """The frame targets of RendererBase (``self._plain_fbo``) plus two sets of
        averaged-tangent-plane state targets (Fig. 4.46b) with one framebuffer each: a refinement
        pass on a reflector writes one set and reads the set the previous such pass wrote
        (draw_frame picks ``self.fbo``); every other pass draws into the plain framebuffer, so
        real-time frames neither clear nor write the state targets."""
        if self.targets:
            for item in self._frame_fbos + self._plane_states:
                item.release()
            self.fbo = self._plain_fbo  # RendererBase.resize releases it
        super().resize(size)
        self._plain_fbo = self.fbo
        # Per set: point sums (mirror, see-through), normal sums (mirror, see-through): locations 4-7.
        self._plane_states = [self.ctx.texture(self.size, 4, dtype="f4") for _ in range(8)]
        self._frame_fbos = [
            self.ctx.framebuffer(color_attachments=[*self.targets, *self._plane_states[4 * k : 4 * k + 4]],
                                 depth_attachment=self.depth)
            for k in range(2)
        ]  # fmt: skip
        self._frame_parity = 0

    def _texture(self, image: np.ndarray) -> moderngl.Texture:
        key = id(image)
        if key not in self.textures:
            img = np.ascontiguousarray(image, dtype=np.float32)
            tex = self.ctx.texture((img.shape[1], img.shape[0]), 3, img.tobytes(), dtype="f4")
            tex.build_mipmaps()
            tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            tex.repeat_x = tex.repeat_y = True
            self.textures[key] = tex
        return self.textures[key]

    def _scene_hash(self) -> str:
        h = hashlib.sha256()
        h.update(f"v{CUBE_CACHE_VERSION} face{self.cube_face_size} b{self.cube_bounces} env{self._env_hash}".encode())
        for obj in self.scene.objects:
            h.update(obj.mesh.positions.tobytes())
            h.update(obj.mesh.indices.tobytes())
            if obj.uv1 is not None:
                h.update(obj.uv1.tobytes())
        for mat in self.scene.materials:
            h.update(repr(sorted(mat.desc.items())).encode())
            h.update(np.asarray(mat.emission, np.float64).tobytes())
            if mat.lightmap is not None:
                h.update(hashlib.sha256(mat.lightmap.image.tobytes()).digest())
            if mat.base_color_texture is not None:
                h.update(hashlib.sha256(mat.base_color_texture.tobytes()).digest())
        return h.hexdigest()[:20]

    def _build_cube_maps(self, cache_dir: Path | None):
        """Cube maps of every object that needs one. Bounce 1 sees the light-mapped diffuse scene
        (the thesis' cube maps, where metals are black); each further bounce re-renders them with
        the other objects' lobes shaded from the previous bounce's cube maps, so a chrome sphere
        shows up in the gold torus and a glass pane is see-through."""
        wanted = self.analysis.cube_mapped
        if not wanted:
            return
        key = self._scene_hash()
        cache_file = Path(cache_dir) / f"cubes-{key}.npz" if cache_dir else None
        if cache_file is not None and cache_file.exists():
            with np.load(cache_file) as data:
                if {f"cube_{i}" for i in wanted} <= set(data.files):
                    for i in wanted:
                        self.objects[i].cube = RadianceCube(self.ctx, data[f"cube_{i}"].astype(np.float32))
                    return
        faces = {}
        for bounce in range(self.cube_bounces):
            t0 = time.perf_counter()
            for i in wanted:
                faces[i] = self.render_cube_faces(self.objects[i].centre, exclude=i, specular=bounce > 0)
            for i in wanted:
                if self.objects[i].cube is not None:
                    self.objects[i].cube.release()
                self.objects[i].cube = RadianceCube(self.ctx, faces[i])
            if self.progress:
                print(
                    f"[cube] bounce {bounce + 1}: {len(wanted)} cube maps of {self.cube_face_size}^2 x 6"
                    f" in {time.perf_counter() - t0:.2f} s",
                    file=sys.stderr,
                    flush=True,
                )
        if cache_file is not None:
            cache_file.parent.mkdir(parents=True, exist_ok=True)
            # float32, not float16: a sun seen through a window exceeds half precision's 65504.
            np.savez_compressed(cache_file, **{f"cube_{i}": f.astype(np.float32) for i, f in faces.items()})

    def render_cube_faces(self, eye, exclude: int | None = None, specular: bool = False) -> np.ndarray:
        """Six faces of the light-mapped scene seen from ``eye`` (float32, (6, S, S, 3)); with
        ``specular``, objects that have cube maps are shaded with their lobes too."""
        size = self.cube_face_size
        color = self.ctx.texture((size, size), 4, dtype="f4")
        extra = [self.ctx.texture((size, size), 4, dtype="f4") for _ in range(3)]
        depth = self.ctx.depth_renderbuffer((size, size))
        fbo = self.ctx.framebuffer(color_attachments=[color, *extra], depth_attachment=depth)
        extent = float(np.max(self.scene.bounds[1] - self.scene.bounds[0]))
        proj = perspective(90.0, 1.0, 1e-3 * extent, 4.0 * extent)
        faces = np.empty((6, size, size, 3), dtype=np.float32)
        try:
            for face in range(6):
                view_proj = proj @ face_view(face, eye)
                fbo.use()
                self.ctx.viewport = (0, 0, size, size)
                fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
                self.draw_background(self.environment, view_proj)
                self._draw_objects(view_proj, eye, CUBE_BOUNCE_METHOD, specular=specular, exclude=exclude)
                self.ctx.finish()
                data = np.frombuffer(fbo.read(components=4, attachment=0, dtype="f4"), np.float32)
                faces[face] = data.reshape(size, size, 4)[..., :3]  # row 0 = t = 0, no flip
        finally:
            fbo.release()
            depth.release()
            color.release()
            for t in extra:
                t.release()
            self.ctx.viewport = (0, 0, *self.size)
        return faces

    # -- drawing -----------------------------------------------------------------------------
    def _program(self, method: Method, specular: bool, parallax: bool = False, mirror: bool = False):
        defines = {**method_defines(method), "SPECULAR": True} if specular else {"METHOD_LOBE": True}
        if specular and mirror:
            # Incident light from the mirror buffer; the cube's importance map does not apply, so
            # the reference samples the BSDF only (still unbiased for what the buffer holds).
            defines.update(MIRROR=True, ENV_SAMPLING=False, PLANE_AVERAGE=self._averages_planes(method))
        elif specular and parallax:
            # The cube's importance map samples directions seen from its centre, which the proxy
            # remaps: the reference then samples the BSDF only (still unbiased).
            defines.update(PARALLAX=True, ENV_SAMPLING=False)
        return self.programs.program("scene.vert", "scene.frag", defines)

    def _object_method(self, index: int, method: Method) -> Method:
        """The method object ``index`` is shaded with: the panel's per-object override of a
        real-time method, never of the reference."""
        return method if method.kind == "reference" else self.object_methods.get(index, method)

    def _averages_planes(self, method: Method) -> bool:
        """Whether a reflector shaded with ``method`` averages its tangent planes (refinement)."""
        return self.mirror_plane_average and method.kind in ("mc", "reference")

    # -- planar mirror passes (thesis 4.5) --------------------------------------------------------
    def mirror_size(self) -> tuple[int, int]:
        width, height = self.size
        return max(1, round(width * self.mirror_scale)), max(1, round(height * self.mirror_scale))

    def reflectors(self) -> dict:
        """Object index -> PlanarReflector of the reflectors in use (analysis, minus disabled)."""
        found = self.analysis.reflectors
        if not self.mirrors_enabled:
            return {}
        if self.enabled_reflectors is not None:
            found = {i: r for i, r in found.items() if i in self.enabled_reflectors}
        return found

    @staticmethod
    def mirror_skip_reason(reflector, camera: Camera, view_proj: np.ndarray) -> str | None:
        """Why a reflector needs no buffers this frame (None: it needs them): the camera is behind
        its plane (a reflector that transmits is seen from both sides), or its bounding box lies
        outside the view frustum."""
        if not reflector.transmission and reflector.side(np.asarray(camera.position, dtype=np.float64)) <= 1e-6:
            return "seen from behind"
        clip = np.c_[reflector.corners(), np.ones(8)] @ view_proj.T
        w = clip[:, 3:4]
        for axis in range(3):
            if np.all(clip[:, axis : axis + 1] > w) or np.all(clip[:, axis : axis + 1] < -w):
                return "outside the view"
        return None

    def render_mirror_passes(self, camera: Camera) -> dict:
        """The buffers of the reflectors that need them for ``camera`` (index -> {'mirror' and/or
        'see-through': targets}); reused while the camera, the size and the materials stay the same
        (refinement passes)."""
        from lobeview.scenes.planar_mirror import mirror_camera

        width, height = self.size
        view_proj = camera.view_projection(width / height)
        reflectors = self.reflectors()
        key = (
            tuple(camera.position), tuple(camera.target), tuple(camera.up), camera.fov_y, camera.near, camera.far,
            self.size, self.mirror_scale, self.mirror_specular, tuple(sorted(reflectors)), self._mirror_generation,
        )  # fmt: skip
        if key == self._mirror_key:
            return self._active_mirrors
        report, active = [], {}
        size = self.mirror_size()
        projection = perspective(camera.fov_y, width / height, camera.near, camera.far)
        for index, reflector in reflectors.items():
            name = self.objects[index].name
            reason = self.mirror_skip_reason(reflector, camera, view_proj)
            if reason is not None:
                report.append(f"{name}: no mirror pass ({reason})")
                continue
            active[index] = {}
            for kind in reflector.passes:
                targets = self._mirror_targets.get((index, kind))
                if targets is None or targets.size != size:
                    if targets is not None:
                        targets.release()
                    targets = self._mirror_targets[(index, kind)] = _MirrorTargets(self.ctx, size)
                buffer_camera = mirror_camera(camera.view(), projection, reflector, size, see_through=kind != "mirror")
                targets.fbo.use()
                self.ctx.viewport = (0, 0, *size)
                targets.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
                self.draw_background(self.environment, buffer_camera.plain_view_projection)
                self._draw_objects(
                    buffer_camera.view_projection,
                    buffer_camera.position,
                    MIRROR_BOUNCE_METHOD,
                    specular=self.mirror_specular,
                    exclude=index,
                )
                targets.radiance.build_mipmaps()
                targets.camera = buffer_camera
                active[index][kind] = targets
                report.append(f"{name}: {kind} pass {size[0]}x{size[1]}")
        self.ctx.viewport = (0, 0, width, height)
        self._mirror_key, self._active_mirrors, self.mirror_report = key, active, report
        return active

    def invalidate_mirrors(self) -> None:
        """Draw the mirror buffers again on the next frame even if nothing changed (benchmarks)."""
        self._mirror_key = None

    def _bind_mirror(self, program, index: int, buffers: dict, eye) -> None:
        """The reflector's buffers (a 1-texel dummy for a kind it does not have, flagged off in
        u_mirror_sides), its plane's normal on the camera's side and the plane-state targets."""
        plane = self.analysis.reflectors[index].plane
        front = plane[:3] if float(np.dot(plane[:3], eye) + plane[3]) >= 0.0 else -plane[:3]
        set_uniform(program, "u_mirror_front", tuple(float(x) for x in front))
        set_uniform(program, "u_mirror_sides", int("mirror" in buffers) | 2 * int("see-through" in buffers))
        for kind, prefix in BUFFER_PREFIXES.items():
            targets = buffers.get(kind)
            textures = (targets.radiance, targets.position, targets.normal) if targets else (self._white,) * 3
            for name, tex in zip(("radiance", "position", "normal"), textures, strict=True):
                bind_sampler(program, f"{prefix}_{name}", tex)
            if targets is None:
                continue
            camera = targets.camera
            set_uniform(program, f"{prefix}_view", tuple(camera.view.T.astype("f4").ravel()))
            set_uniform(
                program, f"{prefix}_view_projection", tuple(camera.plain_view_projection.T.astype("f4").ravel())
            )
            set_uniform(program, f"{prefix}_eye", tuple(float(x) for x in camera.position))
            set_uniform(program, f"{prefix}_focal_px", float(camera.focal_pixels))
        if "u_plane_point_state" in program:
            # The previous pass's sums, in the order of the state attachments: points (mirror,
            # see-through), then normals.
            previous = self._plane_states[4 * (1 - self._frame_parity) : 4 * (1 - self._frame_parity) + 4]
            for k, tex in enumerate(previous):
                bind_sampler(program, ("u_plane_point_state", "u_plane_normal_state")[k // 2], tex, index=k % 2)
            for name in ("u_plane_point_state", "u_plane_normal_state"):
                set_uniform(program, name, list(TEXTURE_UNITS[name]))

    def set_reflection_proxy(self, index: int, proxy) -> None:
        """Reflected-geometry correction for object ``index`` (scenes/reflection_proxy.py; None:
        the plain lookup). Takes effect on the next frame; the cube map itself is unchanged."""
        self.scene.objects[index].reflection_proxy = proxy

    def _bind_proxy(self, program, obj: _GpuObject, proxy) -> None:
        """The reflection proxy (scenes/reflection_proxy.py) as shaders/integrate.glsl PARALLAX reads it."""
        set_uniform(program, "u_cube_centre", tuple(float(x) for x in obj.centre))
        set_uniform(program, "u_proxy_kind", PROXY_KINDS[proxy.kind])
        set_uniform(program, "u_proxy_plane_count", len(proxy.planes) if proxy.kind == "planes" else 0)
        write_uniform(program, "u_proxy_planes", proxy.padded_planes())
        box = (proxy.box_min, proxy.box_max) if proxy.kind == "box" else (np.zeros(3), np.zeros(3))
        set_uniform(program, "u_proxy_box_min", tuple(float(x) for x in box[0]))
        set_uniform(program, "u_proxy_box_max", tuple(float(x) for x in box[1]))

    def _vao(self, program, obj: _GpuObject):
        key = (id(program), obj.index)
        if key not in self._vaos:
            self._vaos[key] = self.ctx.vertex_array(
                program,
                [
                    (
                        obj.vbo,
                        "3f 3f 4f 2f 2f",
                        "in_position",
                        "in_normal",
                        "in_tangent",
                        "in_uv0",
                        "in_uv1",
                    )
                ],
                obj.ibo,
            )
        return self._vaos[key]

    def _draw_objects(
        self,
        view_proj,
        eye,
        method: Method,
        specular: bool,
        exclude=None,
        lod_bias=None,
        sample_offset=0,
        seed=0,
        mirrors: dict | None = None,
    ):
        self.ctx.enable(moderngl.DEPTH_TEST)
        mirrors = mirrors or {}
        for obj in self.objects:
            if obj.index == exclude or (not specular and self.analysis.objects[obj.index].transmission_lobes):
                # Thin transmissive panes are see-through in the diffuse pass that fills cube
                # maps (as in the baker): a black pane would hide what lies behind it.
                continue
            use_specular = specular and obj.cube is not None
            # Per-object real-time method (the panel's override); the reference ignores it.
            obj_method = self._object_method(obj.index, method)
            mirror = mirrors.get(obj.index) if use_specular else None
            proxy = self.scene.objects[obj.index].reflection_proxy if use_specular and mirror is None else None
            program = self._program(obj_method, use_specular, proxy is not None, mirror is not None)
            mat = self.scene.materials[self.scene.objects[obj.index].material]
            set_uniform(program, "u_view_projection", tuple(view_proj.T.astype("f4").ravel()))
            set_uniform(program, "u_camera_position", tuple(float(x) for x in eye))
            self.set_material(program, obj.material, obj_method, lod_bias, seed, planar=mirror is not None)
            set_uniform(program, "u_sample_offset", int(sample_offset))
            set_uniform(program, "u_emission", tuple(float(x) for x in mat.emission))
            set_uniform(program, "u_object_id", float(obj.index))
            lightmap = mat.lightmap
            if lightmap is not None and (lightmap.tex_coord != 1 or self.scene.objects[obj.index].uv1 is not None):
                bind_sampler(program, "u_lightmap", self._texture(lightmap.image))
                set_uniform(program, "u_lightmap_texcoord", int(lightmap.tex_coord))
                set_uniform(program, "u_lightmap_intensity", float(lightmap.intensity))
            else:
                bind_sampler(program, "u_lightmap", self._white)
                set_uniform(program, "u_lightmap_texcoord", -1)
                set_uniform(program, "u_fallback_irradiance", (FALLBACK_IRRADIANCE,) * 3)
            has_base_color = mat.base_color_texture is not None
            base_color = self._texture(mat.base_color_texture) if has_base_color else self._white
            bind_sampler(program, "u_base_color", base_color)
            set_uniform(program, "u_has_base_color", int(has_base_color))
            if use_specular:
                self.bind_cube(program, obj.cube, obj_method, obj.material)
                if proxy is not None:
                    self._bind_proxy(program, obj, proxy)
                if mirror is not None:
                    self._bind_mirror(program, obj.index, mirror, eye)
            self._vao(program, obj).render(moderngl.TRIANGLES)

    def draw_frame(self, camera: Camera, method: Method, sample_offset: int = 0, lod_bias=None, seed: int = 0) -> None:
        """One pass into the renderer's own float targets (radiance in ``targets[0]``), no read
        back: what the interactive viewer calls every frame."""
        width, height = self.size
        view_proj = camera.view_projection(width / height)
        # Planar reflectors read this frame's mirror buffers; the prefiltered method is one cube
        # lookup per lobe, so there they keep their cube maps and no mirror pass is drawn.
        mirrors = self.render_mirror_passes(camera) if method.kind != "prefiltered" else {}
        if method.kind == "prefiltered":
            self.mirror_report = [f"{self.objects[i].name}: cube map (prefiltered method)" for i in self.reflectors()]
        if any(self._averages_planes(self._object_method(i, method)) for i in mirrors):
            # Alternate the state framebuffers: this pass writes the set the next one reads.
            self._frame_parity = 1 - self._frame_parity
            self.fbo = self._frame_fbos[self._frame_parity]
        else:
            self.fbo = self._plain_fbo
        self.fbo.use()
        self.ctx.viewport = (0, 0, width, height)
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self.draw_background(self.environment, view_proj)
        self._draw_objects(view_proj, camera.position, method, True, None, lod_bias, sample_offset, seed, mirrors)

    def pick(self, x: int, y: int) -> int | None:
        """Object index under pixel (x, y) (y down) of the last drawn frame, or None."""
        width, height = self.size
        if not (0 <= x < width and 0 <= y < height):
            return None
        data = self.fbo.read(viewport=(int(x), int(height - 1 - y), 1, 1), components=4, attachment=2, dtype="f4")
        value = float(np.frombuffer(data, dtype=np.float32)[3])
        return int(round(value)) - 1 if value >= 0.5 else None

    def update_material(self, index: int, desc: dict) -> None:
        """Replace the material of object ``index`` with a (validated) description. Other
        objects' cube maps keep the old appearance until :meth:`rebuild_cube_maps`."""
        from lobeview.materials.spec import validate

        desc = validate(desc)
        self._mirror_generation += 1  # what the mirror buffers show changed
        material_index = self.scene.objects[index].material
        self.scene.materials[material_index].desc = desc
        packed = pack_material(build_bsdf(desc))
        self.analysis = analyse(self.scene)
        # Everything else that reflects this object now sees an outdated appearance.
        self.stale_cubes = [i for i in self.analysis.cube_mapped if self.scene.objects[i].material != material_index]
        for gpu_obj in self.objects:
            if self.scene.objects[gpu_obj.index].material == material_index:
                gpu_obj.material = packed
                if gpu_obj.cube is None and self.analysis.objects[gpu_obj.index].needs_cube_map:
                    # A diffuse object that became glossy gets its cube map now (~0.1 s).
                    faces = self.render_cube_faces(gpu_obj.centre, exclude=gpu_obj.index, specular=True)
                    gpu_obj.cube = RadianceCube(self.ctx, faces)

    def refresh_one_stale_cube(self) -> str | None:
        """Re-render one out-of-date cube map (after a material edit changed what it sees);
        the viewer calls this once per frame so edits never freeze the UI. Returns its name."""
        while self.stale_cubes:
            index = self.stale_cubes.pop(0)
            obj = self.objects[index]
            if obj.cube is None:
                continue
            faces = self.render_cube_faces(obj.centre, exclude=index, specular=self.cube_bounces > 1)
            obj.cube.release()
            obj.cube = RadianceCube(self.ctx, faces)
            return obj.name
        return None

    def render(
        self,
        camera: Camera,
        method: Method | str,
        spp: int = 1024,
        lod_bias: float | None = None,
        seed: int = 0,
    ) -> RenderResult:
        method = Method.parse(method) if isinstance(method, str) else method
        width, height = self.size
        passes = method.passes(spp)
        accumulated = np.zeros((height, width, 3))
        invalid = np.zeros((height, width), dtype=bool)
        t_shade = 0.0
        t_gpu = 0.0
        timer = self.gpu_timer()
        g_buffers = None
        for p in range(passes):
            t0 = time.perf_counter()
            with timer or contextlib.nullcontext():
                self.draw_frame(camera, method, p * method.samples, lod_bias, seed)
            self.ctx.finish()
            t_shade += time.perf_counter() - t0
            if timer is not None:
                t_gpu += timer.elapsed * 1e-9
            radiance = self.read(0)
            accumulated += radiance[..., :3]
            invalid |= radiance[..., 3] < 0.0
            if g_buffers is None:
                g_buffers = [self.read(i) for i in (1, 2, 3)]
        return RenderResult(
            radiance=(accumulated / passes).astype(np.float32),
            position=g_buffers[0][..., :3],
            normal=g_buffers[1][..., :3],
            tangent=g_buffers[2][..., :3],
            mask=g_buffers[0][..., 3] > 0.5,
            invalid=invalid,
            timings={**self.timings, "shade": t_shade, **({"gpu shade": t_gpu} if timer is not None else {})},
            samples_per_pixel=passes * method.samples,
            object_id=np.rint(g_buffers[1][..., 3]).astype(np.int32) - 1,
        )

    def release(self):
        self.fbo = self._plain_fbo  # RendererBase releases it; the state framebuffers go below
        super().release()
        for targets in self._mirror_targets.values():
            targets.release()
        for item in self._plane_states + self._frame_fbos:
            item.release()
        for obj in self.objects:
            obj.release()
        for tex in self.textures.values():
            tex.release()
        self._white.release()
        self.environment.release()
