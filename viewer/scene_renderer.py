"""Light-mapped scene renderer (thesis 4.3-4.4): diffuse from lightmaps, view-dependent lobes
from a cube map per object or a planar mirror buffer.

SceneRenderer orchestrates the passes and owns the scene's GPU resources:
- the cube-map pass (viewer/cube_bake.py): a cube map for each object with specular or
  transmission lobes, bounces, disk cache, the stale-cube queue after material edits;
- the mirror pass (viewer/mirror_pass.py): buffers for the planar reflectors in view;
- the shading pass (``_draw_objects`` here): every object with its material, lightmap and the
  method's shader variant (viewer/interface.py), into the frame targets (viewer/frame.py);
- accumulation and tonemapping live in viewer/display.py (the window's refinement).
Only what the scene analysis asks for is built. The window changes options through
set_mirrors / set_object_method / update_material, never by writing attributes.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import moderngl
import numpy as np

from lobeview.core.cache import BoundedCache
from lobeview.core.methods import Method
from lobeview.materials.gltf import specular_f0_unclamped
from lobeview.materials.patterns import lobe_spread, lobe_width_face_size, specular_lobes
from lobeview.materials.spec import build_bsdf
from lobeview.scenes.analysis import DEFAULT_CUBE_FACE, analyse
from lobeview.scenes.envmap import EnvironmentMap
from lobeview.scenes.probe_groups import SHARED_PROBE_LINK, SHARED_PROBE_MAX_FACE, group_probes
from lobeview.scenes.scene import CLAMP_TO_EDGE, MIRRORED_REPEAT, TEXTURE_SLOTS, Scene, SceneMaterial, TextureSlot

from .camera import Camera, box_corners, jittered, outside_frustum_many
from .cube_bake import CubeBake, CubeResidency, scene_content_key
from .cubemap import RadianceCube, equirect_to_cube_faces
from .interface import (
    ALPHA_MODES,
    PROXY_KINDS,
    TEXTURE_UNITS,
    DrawRecorder,
    bind_sampler,
    has_uniform,
    method_defines,
    replay,
    set_uniform,
    use_unit,
    write_uniform,
)
from .material_gpu import PackedMaterial, pack_material
from .mip_chain import DEFAULT_MIP_FILTER, check_mip_filter
from .mirror_pass import MirrorPasses
from .occlusion import OcclusionTest
from .render_base import RendererBase, RenderResult

__all__ = ["SceneRenderer"]
MAX_SCENE_TEXTURES = 256  # lightmaps and material textures kept on the GPU
MAX_DRAW_RECORDS = 16384  # recorded object draw states (programs x objects x methods in use)
GL_SRGB8_ALPHA8 = 0x8C43  # colour textures: the GPU decodes sRGB before filtering (glTF 3.9.2)


@dataclass
class PassCounts:
    drawn: int = 0
    culled: int = 0


class DrawCounts:
    """Objects drawn and culled (frustum) per kind of pass: 'camera' and 'mirror' for the last
    frame (new_frame resets them), 'cube map' since start-up (bake and refreshes)."""

    PER_FRAME = ("camera", "mirror", "depth pre-pass")

    def __init__(self):
        self.passes: dict[str, PassCounts] = {}

    def of(self, pass_kind: str) -> PassCounts:
        return self.passes.setdefault(pass_kind, PassCounts())

    def new_frame(self) -> None:
        for kind in self.PER_FRAME:
            self.passes[kind] = PassCounts()

    def report(self) -> list[str]:
        labels = {"camera": "camera pass", "mirror": "mirror passes", "cube map": "cube-map faces since start"}
        return [
            f"{labels.get(kind, kind)}: {c.drawn} object draws, {c.culled} culled (outside the frustum)"
            for kind, c in self.passes.items()
            if c.drawn or c.culled
        ]


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
        self.corners = box_corners(lo, hi)  # world space (meshes are stored transformed): frustum culling
        self.box = (lo, hi)
        self.cube: RadianceCube | None = None
        # Shared probes (scenes/probe_groups.py): the object whose cube map this one reads (itself
        # unless it shares a group's), and where its own cube map is rendered from and without whom.
        self.probe_owner = index
        self.probe_centre = self.centre
        self.probe_exclude = frozenset((index,))

    def release(self):
        self.vbo.release()
        self.ibo.release()
        if self.cube is not None:
            self.cube.release()


def per_pixel_lobes(mat: SceneMaterial) -> bool:
    """Whether textures make a glTF material's lobes differ from pixel to pixel (shaders/scene.frag),
    so that maps baked for one set of lobe parameters (prefiltered-rsibr) cannot shade it: every
    texture but occlusion and emission, and the normal map too where a clearcoat keeps the
    geometric normal for its own lobe."""
    if mat.desc["model"] != "gltf":
        return False
    lobe_neutral = {"occlusion", "emissive"} | ({"normal"} if not mat.desc.get("clearcoat") else set())
    return bool(set(mat.textures) - lobe_neutral)


class SceneRenderer(RendererBase):
    PLANE_STATE = True  # refinement on reflectors averages tangent planes across passes

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
        frustum_culling: bool = True,
        lobe_width_cubes: bool = True,
        reflector_cubes_on_demand: bool = True,
        cube_budget_mb: float | None = None,
        mip_filter: str = DEFAULT_MIP_FILTER,
        shared_probes: bool = False,
        probe_link: float = SHARED_PROBE_LINK,
    ):
        super().__init__(ctx, size)
        # How the MIP chains of cube maps and mirror buffers are made (viewer/mip_chain.py).
        self.mip_filter = check_mip_filter(mip_filter)
        if not 0.05 <= float(mirror_scale) <= 2.0:
            raise ValueError(f"mirror_scale must be in [0.05, 2], got {mirror_scale}")
        if cube_budget_mb is not None and not float(cube_budget_mb) > 0:
            raise ValueError(f"cube_budget_mb must be positive, got {cube_budget_mb}")
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
        self.scene = scene
        # Each object's cube map is as large as its lobes resolve (scenes/analysis.py, issue 18);
        # cube_face_size is the narrowest lobes' size. False: every cube map at cube_face_size.
        self.lobe_width_cubes = bool(lobe_width_cubes)
        # A planar reflector's mirror pass replaces its cube map (issue 18): it gets one only when
        # a frame needs it (prefiltered method, its mirror pass turned off), and meanwhile other
        # cube maps and mirror passes see it without its lobes (measured: tests/test_cube_sizes.py).
        self.reflector_cubes_on_demand = bool(reflector_cubes_on_demand)
        self.analysis = analyse(scene, cube_face_size, self.lobe_width_cubes, self.reflector_cubes_on_demand)
        self.progress = progress
        self.timings: dict = {}
        t0 = time.perf_counter()
        self.environment = RadianceCube(ctx, equirect_to_cube_faces(environment, 256), mip_filter=self.mip_filter)
        self.environment_name = environment.name
        # Diffuse light of objects without a lightmap: the environment's irradiance (SH9).
        self.environment_sh9 = environment.irradiance_sh9().astype(np.float32)
        self._env_hash = hashlib.sha256(environment.image.tobytes()).hexdigest()[:16]
        # Lightmaps and base-colour textures by the image they upload; the image is kept with the
        # texture so that its id() cannot be reused while the entry lives.
        self.textures = BoundedCache(MAX_SCENE_TEXTURES, on_evict=lambda item: item[1].release())
        # Every sampler uniform gets its own unit and a texture, even when unused: two samplers
        # of different types on one unit make the draw call fail (GL_INVALID_OPERATION).
        self._white = ctx.texture((1, 1), 3, np.ones(3, np.float32).tobytes(), dtype="f4")
        self._samplers: dict = {}  # glTF sampler state -> moderngl.Sampler (a handful per scene)
        self._dfg = None  # made on first use by a textured glTF lobe under normalised lobe-N
        # Per-object draw state recorded once and replayed per draw (_object_state).
        self.draw_records = True
        self._records = BoundedCache(MAX_DRAW_RECORDS)
        self._record_generation = 0
        self.record_builds = 0  # records made so far (a count for tests and benchmarks)
        self.objects = []
        for i, obj in enumerate(scene.objects):
            material = pack_material(build_bsdf(scene.materials[obj.material].desc))
            self.objects.append(_GpuObject(ctx, obj, material, i))
        for needs in self.analysis.objects:
            if not needs.has_lightmap:
                warnings.warn(
                    f"object {needs.name!r} has no usable lightmap: its diffuse light is the environment's "
                    "irradiance at each normal (SH9, nothing occludes it: bake the scene for shadows)",
                    stacklevel=2,
                )
        self.timings["upload"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        self.object_methods: dict[int, Method] = {}
        self.cache_dir = Path(cache_dir) if cache_dir else None
        if self.cache_dir is not None:  # cache_dir is the cubes' folder inside the --cache folder
            self.table_cache_root = self.cache_dir.parent
        # Frustum culling (issue 18): objects whose bounding box lies outside a pass's frustum are
        # not drawn; draw_counts says, per kind of pass, how many were drawn and culled.
        self.frustum_culling = bool(frustum_culling)
        self._object_corners = np.array([obj.corners for obj in self.objects]).reshape(len(self.objects), 8, 3)
        # Per cube map, the box whose visibility needs it (a shared probe's: its group's).
        self._probe_corners = self._object_corners.copy()
        self.draw_counts = DrawCounts()
        # Occlusion test of the reflectors (viewer/occlusion.py): no mirror pass for a reflector
        # that opaque objects hide from the camera (a floor behind a wall).
        self.mirror_occlusion = True
        # Scissored mirror passes (scenes/planar_mirror.py mirror_scissor): a lobe-N reflector's
        # pass shades only the buffer region its lookups can read.
        self.mirror_scissor = True
        self._spreads: dict = {}  # (reflector, N, normalize, pattern) -> materials.patterns.lobe_spread
        # Depth pre-pass of the camera pass (viewer/occlusion.py): shading once per pixel.
        self.depth_prepass = True
        self.occlusion = OcclusionTest(ctx, self.programs)
        self.mirror_passes = MirrorPasses(
            ctx,
            self.environment,
            self.draw_background,
            functools.partial(self._draw_pass, pass_kind="mirror"),
            self._visible_samples,
            self._restore_cubes,
            self.mip_filter,
        )
        self.bounds = scene.bounds  # static scene: near/far planes are fitted to it every frame
        extent = float(np.max(self.bounds[1] - self.bounds[0]))
        self.cube_bake = CubeBake(
            ctx,
            cube_face_size,
            cube_bounces,
            extent,
            self.environment,
            self.draw_background,
            functools.partial(self._draw_pass, pass_kind="cube map"),
            progress,
            self.cache_dir,  # prefiltered maps are cached beside the cubes
            self.mip_filter,
        )
        # Nearby small objects with wide lobes share one cube map (scenes/probe_groups.py): an
        # option (--shared-probes), its error measured by bench/probe_sharing.py.
        self.shared_probes = bool(shared_probes)
        self.probe_link = float(probe_link)  # group_probes' link (bench/probe_sharing.py sweeps it)
        self.probe_groups: list = []
        self._apply_probe_groups(self._probe_rule_groups())
        sizes = {i: self._cube_size(i) for i in self.analysis.cube_mapped}
        key = scene_content_key(
            scene, self._env_hash, self.cube_bake.face_size, self.cube_bake.bounces, sizes, self.mip_filter
        )
        if self.reflector_cubes_on_demand:  # the second bounce then sees reflectors without lobes
            key += "-r"
        if self.probe_groups:
            key += "-g" + hashlib.sha256(repr([g.members for g in self.probe_groups]).encode()).hexdigest()[:8]
        self.cube_bake.build(self.objects, self._cubes_at_start(), key, sizes)
        self.timings["cube maps"] = time.perf_counter() - t0
        self.residency = CubeResidency(None if cube_budget_mb is None else int(float(cube_budget_mb) * 2**20))
        self._edited = False  # a material edit makes the start-up cache files outdated

    @property
    def cube_face_size(self) -> int:
        return self.cube_bake.face_size

    # -- shared probes (scenes/probe_groups.py) ---------------------------------------------------
    def _probe_rule_groups(self) -> list:
        """The groups scenes/probe_groups.py forms from the current analysis."""
        candidates = {
            i: self.objects[i].box
            for i in self.analysis.cubes_at_start
            if self.analysis.objects[i].reflector is None
            and self._wide_lobes(i)
            and not self.analysis.objects[i].emissive  # a lamp left out of a probe would be missed
            # What a pane transmits is what lies right behind it: seen from a probe elsewhere it
            # moves (the demo's frosted pane grouped with the table: 11 % relative RMSE).
            and not self.analysis.objects[i].transmission_lobes
        }
        return group_probes(candidates, link=self.probe_link) if self.shared_probes else []

    def _wide_lobes(self, index: int) -> bool:
        """Whether object ``index``'s lobes are wide enough to share: the lobe-width rule gives them
        a face of at most SHARED_PROBE_MAX_FACE out of the default 256 (whatever --face-size is)."""
        footprint = self.analysis.objects[index].sample_solid_angle
        return footprint is not None and lobe_width_face_size(footprint, DEFAULT_CUBE_FACE) <= SHARED_PROBE_MAX_FACE

    def _apply_probe_groups(self, groups: list) -> set:
        """Point every member of ``groups`` at its group's owner and every other object at its own
        cube map; the scene analysis says who shares with whom (its report and the panel). Returns
        the objects whose probe changed."""
        before = {obj.index: (obj.probe_owner, obj.probe_exclude) for obj in self.objects}
        for obj in self.objects:
            obj.probe_owner, obj.probe_centre, obj.probe_exclude = obj.index, obj.centre, frozenset((obj.index,))
            self._probe_corners[obj.index] = obj.corners
            self.analysis.objects[obj.index].shared_probe = ""
        for group in groups:
            for index in group.members:
                obj = self.objects[index]
                obj.probe_owner = group.owner
                if index == group.owner:
                    obj.probe_centre = group.centre
                    obj.probe_exclude = frozenset(group.members)
                    # restored when any member is in view
                    self._probe_corners[index] = box_corners(group.box_min, group.box_max)
        self.probe_groups = list(groups)
        self._describe_probes(self.probe_groups)
        changed = {o.index for o in self.objects if before[o.index] != (o.probe_owner, o.probe_exclude)}
        if changed:
            self._record_generation += 1  # the members' proxies read the probe's centre
        return changed

    def _describe_probes(self, groups: list) -> None:
        for group in groups:
            names = [self.objects[i].name for i in group.members]
            size = self._cube_size(group.owner)
            for index in group.members:
                others = ", ".join(repr(n) for n in names if n != self.objects[index].name)
                self.analysis.objects[index].shared_probe = f"{size}^2 with {others}"

    def _cube_size(self, index: int) -> int:
        """Face size of object ``index``'s own cube map: its lobes', or the widest of its group's."""
        group = self._group_of(index)
        members = group.members if group is not None and index == group.owner else (index,)
        return max(self.analysis.objects[i].cube_face for i in members)

    def _group_of(self, index: int):
        return next((g for g in self.probe_groups if index in g.members), None)

    def _cubes_at_start(self) -> list[int]:
        """The objects that get their own cube map at start-up (group members read the owner's)."""
        return [i for i in self.analysis.cubes_at_start if self.objects[i].probe_owner == i]

    def _dissolve_group(self, index: int) -> None:
        """Give every member of object ``index``'s group its own cube map again (refinement
        converges to a cube map per object, as `shot --method reference` renders), and say so."""
        group = self._group_of(index)
        if group is None:
            return
        for member in sorted(self._apply_probe_groups([g for g in self.probe_groups if g is not group])):
            if self.analysis.objects[member].needs_cube_map:
                self.cube_bake.build_one(self.objects, member, self.analysis.objects[member].cube_face, cached=False)

    @property
    def cube_bounces(self) -> int:
        return self.cube_bake.bounces

    @property
    def draw_report(self) -> list[str]:
        """Objects drawn and culled: by the last frame's camera and mirror passes, and by every
        cube-map face rendered since start-up."""
        return self.draw_counts.report()

    @property
    def mirror_report(self) -> list[str]:
        """What the last frame's mirror passes did, one line per reflector."""
        return self.mirror_passes.report

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
        """Cube maps still waiting to be re-rendered: made stale by a material edit, or queued for
        the full face size by request_full_faces."""
        return len(self.cube_bake.stale) + len(self.cube_bake.upgrades)

    def prefiltered_memory(self, index: int) -> dict[str, int]:
        """Bytes of each prefiltered map object ``index`` has built so far (empty: none)."""
        cube = self.objects[self.objects[index].probe_owner].cube
        maps = cube.built_prefiltered_maps if cube is not None else None
        return dict(maps.memory) if maps is not None else {}

    # -- resources -------------------------------------------------------------------------
    def _texture(self, image: np.ndarray) -> moderngl.Texture:
        def upload():
            img = np.ascontiguousarray(image, dtype=np.float32)
            tex = self.ctx.texture((img.shape[1], img.shape[0]), 3, img.tobytes(), dtype="f4")
            tex.build_mipmaps()
            tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            tex.repeat_x = tex.repeat_y = True
            return image, tex

        return self.textures.get(id(image), upload)[1]

    def _map_texture(self, slot: TextureSlot) -> moderngl.Texture:
        """A material texture on the GPU: uint8 RGBA as stored (SRGB8_ALPHA8 for colour slots),
        float RGBA for generated scenes; full MIP chain (the sampler object picks the filter)."""

        def upload():
            image = slot.image
            if image.dtype == np.uint8:
                if image.shape[-1] == 3:
                    image = np.concatenate([image, np.full(image.shape[:-1] + (1,), 255, np.uint8)], axis=-1)
                data = np.ascontiguousarray(image)
                internal = GL_SRGB8_ALPHA8 if slot.srgb else None
                tex = self.ctx.texture((data.shape[1], data.shape[0]), 4, data.tobytes(), internal_format=internal)
            else:
                data = np.ascontiguousarray(slot.linear(), dtype=np.float32)
                tex = self.ctx.texture((data.shape[1], data.shape[0]), 4, data.tobytes(), dtype="f4")
            tex.build_mipmaps()
            return image, tex

        return self.textures.get(("map", id(slot.image), slot.srgb), upload)[1]

    def _dfg_texture(self) -> moderngl.Texture:
        """The split-sum DFG table (viewer/prefiltered.py), for per-pixel glTF lobe albedo."""
        if self._dfg is None:
            from .prefiltered import dfg_texture

            self._dfg = dfg_texture(self.ctx, self.cache_dir)
        return self._dfg

    def _map_sampler(self, slot: TextureSlot | None) -> moderngl.Sampler:
        """Sampler object for a slot's glTF sampler: repeat or clamp-to-edge per axis and the
        filters (glTF uses the GL enums); mirrored repeat repeats here and is folded in
        shaders/material_maps.glsl."""
        key = (slot.wrap_s, slot.wrap_t, slot.min_filter, slot.mag_filter) if slot is not None else ("white",)
        sampler = self._samplers.get(key)
        if sampler is None:
            sampler = self.ctx.sampler()
            if slot is not None:
                sampler.repeat_x = slot.wrap_s != CLAMP_TO_EDGE
                sampler.repeat_y = slot.wrap_t != CLAMP_TO_EDGE
                sampler.filter = (slot.min_filter, slot.mag_filter)
            self._samplers[key] = sampler
        return sampler

    def _object_state(self, program, obj: _GpuObject, method: Method, planar: bool, proxy) -> None:
        """Everything an object's draw sets that the pass does not: material, textures, lightmap,
        reflection proxy. Recorded once per program, object and method (``draw_records``,
        viewer/interface.py DrawRecorder) and replayed, so a draw sends only the uniform bytes the
        program does not hold yet (issue 18: state uploaded when it changes, not per draw). The
        records are made again after a material edit or a proxy change (``_record_generation``)
        and after a texture cache released a texture they bind."""
        if not self.draw_records:
            self._set_object_state(program, obj, method, planar, proxy)
            return
        key = (
            program,
            obj.index,
            method,
            planar,
            proxy is not None,
            self._record_generation,
            self.textures.evictions,
            self._material_textures.evictions,
        )

        def make():
            recorder = DrawRecorder(program)
            self._set_object_state(recorder, obj, method, planar, proxy)
            self.record_builds += 1
            return recorder.record()

        replay(program, self._records.get(key, make))

    def _set_object_state(self, program, obj: _GpuObject, method: Method, planar: bool, proxy) -> None:
        mat = self.scene.materials[self.scene.objects[obj.index].material]
        self.set_material_state(program, obj.material, method, planar)
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
            write_uniform(program, "u_irradiance_sh9", self.environment_sh9)
        self._bind_material(program, mat)
        if proxy is not None:
            self._bind_proxy(program, obj, proxy)

    def _bind_material(self, program, mat: SceneMaterial) -> None:
        """glTF's per-pixel inputs (shaders/scene.frag): textures, factors, alpha mode."""
        desc = mat.desc
        gltf_model = desc["model"] == "gltf"
        base = desc["base_color"] if gltf_model else [1.0, 1.0, 1.0]
        set_uniform(program, "u_gltf_model", int(gltf_model))
        set_uniform(program, "u_base_color_factor", (*(float(c) for c in base), float(mat.base_alpha)))
        set_uniform(program, "u_metallic_factor", float(desc.get("metallic", 0.0)))
        set_uniform(program, "u_roughness_factor", float(desc.get("roughness", 1.0)))
        set_uniform(program, "u_anisotropy", float(desc.get("anisotropy", 0.0)) if gltf_model else 0.0)
        set_uniform(program, "u_clearcoat_roughness", float(desc.get("clearcoat_roughness", 0.0)))
        set_uniform(program, "u_clearcoat_normal_scale", float(mat.clearcoat_normal_scale))
        raw_f0 = (
            specular_f0_unclamped(desc.get("ior", 1.5), desc.get("specular_color", (1.0, 1.0, 1.0)))
            if gltf_model
            else (0.04, 0.04, 0.04)
        )
        set_uniform(program, "u_specular_f0_raw", tuple(float(x) for x in raw_f0))
        set_uniform(program, "u_normal_scale", float(mat.normal_scale))
        set_uniform(program, "u_occlusion_strength", float(mat.occlusion_strength))
        set_uniform(program, "u_alpha_mode", ALPHA_MODES[mat.alpha_mode.lower()])
        set_uniform(program, "u_alpha_cutoff", float(mat.alpha_cutoff))
        texcoords, transforms, mirrored = [], [], []
        for i, name in enumerate(TEXTURE_SLOTS):
            slot = mat.textures.get(name)
            unit = TEXTURE_UNITS["u_material_maps"][i]
            use_unit(program, self._map_texture(slot) if slot is not None else self._white, unit)
            use_unit(program, self._map_sampler(slot), unit)
            texcoords.append(slot.tex_coord if slot is not None else -1)
            transform = np.asarray(slot.transform if slot is not None else np.eye(3), dtype=np.float32)
            transforms.append(transform.T)  # GLSL mat3 is column-major
            mirrored.append(
                [int(slot.wrap_s == MIRRORED_REPEAT), int(slot.wrap_t == MIRRORED_REPEAT)] if slot else [0, 0]
            )
        set_uniform(program, "u_material_maps", list(TEXTURE_UNITS["u_material_maps"]))
        write_uniform(program, "u_map_texcoord", np.asarray(texcoords, dtype=np.int32))
        write_uniform(program, "u_map_transform", np.asarray(transforms, dtype=np.float32))
        write_uniform(program, "u_map_mirrored", np.asarray(mirrored, dtype=np.int32))
        if has_uniform(program, "u_albedo_per_pixel"):  # normalised lobe-N (shaders/patterns.glsl lobe_albedo)
            # Every texture but the normal maps, occlusion and emission changes the lobes' albedo.
            per_pixel = gltf_model and bool(set(mat.textures) - {"normal", "occlusion", "emissive", "clearcoat_normal"})
            set_uniform(program, "u_albedo_per_pixel", int(per_pixel))

            # Bound even when unused: a sampler left on unit 0 would meet the radiance cube there
            # (two sampler types on one unit fail the draw with GL_INVALID_OPERATION).
            bind_sampler(program, "u_dfg", self._dfg_texture() if per_pixel else self._white)

    def render_cube_faces(
        self, eye, exclude: int | None = None, specular: bool = False, size: int | None = None
    ) -> np.ndarray:
        """Six faces of the scene seen from ``eye`` (viewer/cube_bake.py CubeBake.render_faces)."""
        return self.cube_bake.render_faces(eye, exclude, specular, size)

    # -- drawing -----------------------------------------------------------------------------
    def _program(
        self, method: Method, specular: bool, parallax: bool = False, mirror: bool = False, rational: bool = False
    ):
        defines = {**method_defines(method), "SPECULAR": True} if specular else {"METHOD_LOBE": True}
        defines["HAS_RATIONAL"] = rational  # a Rational BRDF's functions (shaders/rational.glsl)
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
    def reflectors(self) -> dict:
        """Object index -> PlanarReflector of the reflectors in use (analysis, minus disabled)."""
        found = self.analysis.reflectors
        if not self.mirrors_enabled:
            return {}
        if self.enabled_reflectors is not None:
            found = {i: r for i, r in found.items() if i in self.enabled_reflectors}
        return found

    def render_mirror_passes(
        self, camera: Camera, jitters: bool = False, method: Method | None = None, lod_bias: float | None = None
    ) -> dict:
        """This frame's mirror and see-through buffers (viewer/mirror_pass.py). ``jitters``: the
        frame's passes move off the pixel centres (box-filtered reference), where the occlusion
        test, exact at pixel centres, does not apply. ``method`` (the frame's) and ``lod_bias``:
        reflectors shaded by lobe-N get passes scissored to where their lookups read
        (``mirror_scissor``; None: every pass whole)."""
        names = [obj.name for obj in self.objects]
        occlusion = self.mirror_occlusion and not jitters
        reflectors = self.reflectors()
        spreads = {}
        if method is not None and self.mirror_scissor:
            spreads = {index: self._lobe_spread(index, self._object_method(index, method)) for index in reflectors}
        bias = Method("lobe", 1).default_lod_bias(self.mip_filter) if lod_bias is None else float(lod_bias)
        return self.mirror_passes.render(
            camera, self.size, reflectors, names, self.mirror_scale, self.mirror_specular, occlusion, spreads, bias
        )

    def _restore_cubes(self, view_projection, exclude: int | None = None) -> None:
        """Restore the evicted cube maps (``cube_budget_mb``) of objects a pass with this frustum
        may draw, before it binds its framebuffer (restoring renders or reads cube faces)."""
        wanted = self.residency.wanted(self._probe_corners, view_projection, exclude)
        for index in wanted:
            t0 = time.perf_counter()
            where = self.cube_bake.restore(self.objects, index, self._cube_size(index), self._edited)
            self.residency.evicted.discard(index)
            self.residency.restores[where] = self.residency.restores.get(where, 0) + 1
            self.residency.restore_seconds += time.perf_counter() - t0

    def _reflector_cubes_for(self, method: Method) -> None:
        """Build the cube maps of reflectors that this frame shades from a cube map (the
        prefiltered method, globally or as their override, or their mirror pass turned off)."""
        enabled = self.reflectors()
        for index in self.analysis.reflectors:
            obj = self.objects[index]
            if obj.cube is not None:
                continue
            if (
                index in enabled
                and method.kind != "prefiltered"
                and self._object_method(index, method).kind != "prefiltered"
            ):
                continue
            self.cube_bake.build_one(self.objects, index, self.analysis.objects[index].cube_face)

    def _lobe_spread(self, index: int, method: Method) -> tuple[float, float] | None:
        """How far the lobe-N lookups of reflector ``index`` reach (None: not lobe-N, unbounded)."""
        mat = self.scene.materials[self.scene.objects[index].material]
        if method.kind != "lobe" or per_pixel_lobes(mat):  # textures vary the lobes: no bound here
            return None
        key = (index, method.samples, method.normalize, method.pattern)
        if key not in self._spreads:
            lobes = specular_lobes(build_bsdf(mat.desc))
            self._spreads[key] = lobe_spread(lobes, method.samples, method.normalize) if lobes else None
        return self._spreads[key]

    def _opaque_objects(self, occluders_only: bool) -> list:
        """(GPU object, single-sided) for the objects the camera pass draws opaquely (no alphaMode
        MASK or BLEND: their discarded or blended pixels hide nothing). ``occluders_only``: also
        without reflectors and transmissive objects (the reflectors' occlusion test:
        viewer/occlusion.py says why)."""
        reflectors = self.analysis.reflectors
        found = []
        for obj in self.objects:
            mat = self.scene.materials[self.scene.objects[obj.index].material]
            if mat.alpha_mode.upper() != "OPAQUE":
                continue
            if occluders_only and (obj.index in reflectors or self.analysis.objects[obj.index].transmission_lobes):
                continue
            found.append((obj, not mat.double_sided))
        return found

    def _visible_samples(self, view_proj, indices: list) -> dict[int, int]:
        """Camera pixels of each reflector in ``indices`` that no opaque object hides."""
        return self.occlusion.visible_samples(
            view_proj, self.size, self._opaque_objects(True), {index: self.objects[index] for index in indices}
        )

    def invalidate_mirrors(self) -> None:
        """Draw the mirror buffers again on the next frame even if nothing changed (benchmarks)."""
        self.mirror_passes.invalidate()

    def set_reflection_proxy(self, index: int, proxy) -> None:
        """Reflected-geometry correction for object ``index`` (scenes/reflection_proxy.py; None:
        the plain lookup). Takes effect on the next frame; the cube map itself is unchanged."""
        self.scene.objects[index].reflection_proxy = proxy
        self._record_generation += 1

    def _bind_proxy(self, program, obj: _GpuObject, proxy) -> None:
        """The reflection proxy (scenes/reflection_proxy.py) as shaders/integrate.glsl PARALLAX reads it."""
        # The centre the cube map was rendered from (a shared probe's: its group's).
        set_uniform(program, "u_cube_centre", tuple(float(x) for x in self.objects[obj.probe_owner].probe_centre))
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
        cull: bool = False,
        pass_kind: str = "camera",
        cull_view_projection=None,
    ):
        """Every object with its material whose bounding box reaches the frustum of
        ``view_proj`` (``frustum_culling``; counted in ``draw_counts[pass_kind]``). ``cull``: skip
        the back faces of single-sided materials (the camera pass only: mirror and cube-map
        passes flip the winding). ``cull_view_projection``: the frustum to cull against when it is
        smaller than ``view_proj``'s (a scissored mirror pass)."""
        self.ctx.enable(moderngl.DEPTH_TEST)
        cull_view_projection = view_proj if cull_view_projection is None else cull_view_projection
        culled = outside_frustum_many(self._object_corners, cull_view_projection) if self.frustum_culling else None
        mirrors = mirrors or {}
        counts = self.draw_counts.of(pass_kind)
        view_proj_values = tuple(view_proj.T.astype("f4").ravel())
        eye_values = tuple(float(x) for x in eye)
        excluded = exclude if isinstance(exclude, frozenset | set | tuple) else (exclude,)
        for obj, blended in self._draw_order(eye):
            if obj.index in excluded or (not specular and self.analysis.objects[obj.index].transmission_lobes):
                # Thin transmissive panes are see-through in the diffuse pass that fills cube
                # maps (as in the baker): a black pane would hide what lies behind it.
                continue
            if culled is not None and culled[obj.index]:
                counts.culled += 1
                continue
            counts.drawn += 1
            if blended:  # alphaMode BLEND: composited over what is drawn, depth tested, not written
                self.ctx.enable(moderngl.BLEND)
                self.ctx.blend_func = moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA
                self.ctx.fbo.depth_mask = False
            single_sided = cull and not self.scene.materials[self.scene.objects[obj.index].material].double_sided
            if single_sided:
                self.ctx.enable(moderngl.CULL_FACE)  # glTF doubleSided false: back faces are not drawn
            else:
                self.ctx.disable(moderngl.CULL_FACE)
            # A reflector drawn from its mirror buffer needs no cube map (on demand: it may have none).
            mirror = mirrors.get(obj.index) if specular else None
            own_cube = self.objects[obj.probe_owner].cube  # its own, or its group's shared probe
            use_specular = specular and (own_cube is not None or mirror is not None)
            if use_specular and own_cube is not None and pass_kind != "cube map":
                self.residency.touch(obj.probe_owner)
            # Per-object real-time method (the panel's override); the reference ignores it.
            obj_method = self._object_method(obj.index, method)
            proxy = self.scene.objects[obj.index].reflection_proxy if use_specular and mirror is None else None
            program = self._program(
                obj_method, use_specular, proxy is not None, mirror is not None, obj.material.has_rational
            )
            mat = self.scene.materials[self.scene.objects[obj.index].material]
            set_uniform(program, "u_view_projection", view_proj_values)
            set_uniform(program, "u_camera_position", eye_values)
            self.set_pass_state(program, obj_method, lod_bias, seed)
            set_uniform(program, "u_sample_offset", int(sample_offset))
            self._object_state(program, obj, obj_method, mirror is not None, proxy)
            if use_specular:
                cube = own_cube if own_cube is not None else self.environment  # bound, unread under MIRROR
                self.bind_cube(program, cube, obj_method, obj.material, per_pixel_lobes(mat))
                if mirror is not None:
                    self.mirror_passes.bind(
                        program, self.analysis.reflectors[obj.index], mirror, eye, self._white,
                        self.frame.previous_plane_states(),
                    )  # fmt: skip
            self._vao(program, obj).render(moderngl.TRIANGLES)
        self.ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
        self.ctx.fbo.depth_mask = True

    def _draw_order(self, eye) -> list:
        """(object, blended): opaque and masked objects first, then the alphaMode BLEND ones
        from back to front by the distance of their bounding-box centre (glTF 3.9.4)."""
        opaque, blended = [], []
        for obj in self.objects:
            mode = self.scene.materials[self.scene.objects[obj.index].material].alpha_mode
            (blended if mode == "BLEND" else opaque).append(obj)
        eye = np.asarray(eye, dtype=np.float64)
        blended.sort(key=lambda o: -float(np.linalg.norm(o.centre - eye)))
        return [(o, False) for o in opaque] + [(o, True) for o in blended]

    def _draw_pass(
        self,
        view_proj,
        eye,
        method: Method,
        specular: bool,
        exclude=None,
        pass_kind="cube map",
        cull_view_projection=None,
    ) -> None:
        """The scene as the cube-map and mirror passes draw it (no per-frame state)."""
        self._draw_objects(
            view_proj, eye, method, specular, exclude, pass_kind=pass_kind, cull_view_projection=cull_view_projection
        )

    def draw_frame(
        self, camera: Camera, method: Method, sample_offset: int = 0, lod_bias=None, seed: int = 0, jitter=(0.0, 0.0)
    ) -> None:
        """One pass into the renderer's own float targets (radiance in ``targets[0]``), no read
        back: what the interactive viewer calls every frame. ``jitter``: this pass's sub-pixel
        position in pixels (a box-filtered reference, viewer/camera.py pixel_offset); the mirror
        passes keep the unjittered camera (they are looked up by world position)."""
        camera = camera.fitted_to(self.bounds)  # any scene scale, mm to km (viewer/camera.py)
        width, height = self.size
        view_proj = jittered(camera.view_projection(width / height), jitter, self.size)
        self.draw_counts.new_frame()
        # Planar reflectors read this frame's mirror buffers; the prefiltered method is one cube
        # lookup per lobe, so there they keep their cube maps and no mirror pass is drawn.
        self._restore_cubes(view_proj)
        if method.kind == "prefiltered":
            mirrors = {}
            names = [obj.name for obj in self.objects]
            self.mirror_passes.skip_all(self.reflectors(), names, "cube map (prefiltered method)")
        else:
            mirrors = self.render_mirror_passes(camera, method.kind == "reference", method, lod_bias)
        self._reflector_cubes_for(method)
        self.frame.begin(averages_planes=any(self._averages_planes(self._object_method(i, method)) for i in mirrors))
        self.draw_background(self.environment, view_proj)
        if self.depth_prepass:
            # Opaque depth first (viewer/occlusion.py): the shading pass then integrates the lobes
            # once per pixel, not once per overlapping surface.
            self.frame.depth_fbo.use()
            counts = self.draw_counts.of("depth pre-pass")
            counts.drawn, counts.culled = self.occlusion.draw_depth(view_proj, self._opaque_objects(False))
            self.frame.fbo.use()
            self.ctx.depth_func = "<="
        self._draw_objects(
            view_proj, camera.position, method, True, None, lod_bias, sample_offset, seed, mirrors, cull=True
        )
        self.ctx.depth_func = "<"
        self.residency.evict(self.objects)

    def pick(self, x: int, y: int) -> int | None:
        """Object index under pixel (x, y) (y down) of the last drawn frame, or None."""
        return self.frame.pick(x, y)

    def update_material(self, index: int, desc: dict) -> None:
        """Replace the material of object ``index`` with a (validated) description. The cube
        maps of the other glossy objects show the old appearance until refresh_one_stale_cube
        has re-rendered them (one per frame in the viewer)."""
        from lobeview.materials.spec import validate

        desc = validate(desc)
        self.mirror_passes.generation += 1  # what the mirror buffers show changed
        self._record_generation += 1  # the objects' recorded draw state (_object_state)
        self._edited = True
        self._spreads.clear()  # a reflector's lobes may have changed
        material_index = self.scene.objects[index].material
        self.scene.materials[material_index].desc = desc
        packed = pack_material(build_bsdf(desc))
        edited = [o for o in self.objects if self.scene.objects[o.index].material == material_index]
        for gpu_obj in edited:  # before any cube map is rendered below (and its draws recorded)
            gpu_obj.material = packed
        self.analysis = analyse(self.scene, self.cube_face_size, self.lobe_width_cubes, self.reflector_cubes_on_demand)
        # The same sharing rule as a fresh start on the edited scene (what `shot --materials` renders).
        regrouped = self._apply_probe_groups(self._probe_rule_groups())
        # Everything else that reflects this object now sees an outdated appearance.
        self.cube_bake.stale = [
            i for i in self.analysis.cube_mapped if self.scene.objects[i].material != material_index
        ]
        for gpu_obj in self.objects:
            i = gpu_obj.index
            if i in regrouped and gpu_obj.probe_owner != i and gpu_obj.cube is not None:
                gpu_obj.cube.release()  # it reads its group's probe now
                gpu_obj.cube = None
                self.residency.evicted.discard(i)
            size = self._cube_size(i)
            # A shared probe is as fine as its narrowest member: an edited member may resize it.
            cube_size = gpu_obj.cube.face_size if gpu_obj.cube is not None else size
            resized_probe = self._group_of(i) is not None and cube_size != size
            if i not in regrouped and self.scene.objects[i].material != material_index and not resized_probe:
                continue
            needs = self.analysis.objects[i]
            on_demand = i not in self.analysis.cubes_at_start and gpu_obj.cube is None
            if (
                needs.needs_cube_map
                and not on_demand
                and gpu_obj.probe_owner == i
                and (i in regrouped or gpu_obj.cube is None or gpu_obj.cube.face_size != size)
            ):
                # A diffuse object that became glossy gets its cube map now (~0.1 s), one whose
                # lobes narrowed or widened gets it at the face size they need, and a probe whose
                # group changed is rendered for its new members.
                self.cube_bake.build_one(self.objects, i, size, cached=False)

    @property
    def has_rational(self) -> bool:
        """Whether any object draws a Rational BRDF (reference passes then shrink: Method.for_rational)."""
        return any(obj.material.has_rational for obj in self.objects)

    def request_full_faces(self, camera: Camera) -> int:
        """Queue the cube maps of the objects in view whose faces were sized by their lobes for
        re-rendering at the full face size (one per ``refresh_one_stale_cube``): progressive
        refinement reads level 0, finer than the lobe-N lookups the sizes were chosen for, and
        should converge to what ``shot --method reference`` (full faces) renders. Returns how
        many were queued."""
        if not self.lobe_width_cubes:
            return 0
        width, height = self.size
        view_projection = camera.fitted_to(self.bounds).view_projection(width / height)
        culled = outside_frustum_many(self._object_corners, view_projection)
        for group in list(self.probe_groups):  # refinement converges to per-object cube maps
            if not all(culled[i] for i in group.members):
                self._dissolve_group(group.owner)
        queued = [
            obj.index
            for obj in self.objects
            if obj.cube is not None
            and obj.cube.face_size < self.cube_face_size
            and not culled[obj.index]
            and obj.index not in self.cube_bake.upgrades
        ]
        self.cube_bake.upgrades.extend(queued)
        return len(queued)

    def refresh_one_stale_cube(self) -> str | None:
        """Re-render one out-of-date cube map (after a material edit changed what it sees);
        the viewer calls this once per frame so edits never freeze the UI. Returns its name."""
        return self.cube_bake.refresh_one(self.objects)

    def render(
        self,
        camera: Camera,
        method: Method | str,
        spp: int = 1024,
        lod_bias: float | None = None,
        seed: int = 0,
        pixel_filter: str = "box",
    ) -> RenderResult:
        """``pixel_filter`` as in PreviewRenderer.render: 'box' (default) makes a reference the
        pixel's integral, 'point' shades every pass at the pixel centre."""
        method = Method.parse(method) if isinstance(method, str) else method
        method, offsets = self.pass_plan(method, spp, pixel_filter, self.has_rational)
        width, height = self.size
        passes = len(offsets)
        accumulated = np.zeros((height, width, 3))
        invalid = np.zeros((height, width), dtype=bool)
        t_shade = 0.0
        t_gpu = 0.0
        timer = self.gpu_timer()
        g_buffers = None
        for p, offset in enumerate(offsets):
            t0 = time.perf_counter()
            _ = self.ctx.error  # reset the flag: only errors of this frame's passes count below
            with timer or contextlib.nullcontext():
                self.draw_frame(camera, method, p * method.samples, lod_bias, seed, jitter=offset)
            self.ctx.finish()
            self.raise_on_gl_error(method)
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
        super().release()
        self.mirror_passes.release()
        self.occlusion.release()
        for obj in self.objects:
            obj.release()
        self.textures.clear()
        for sampler in self._samplers.values():
            sampler.release()
        if self._dfg is not None:
            self._dfg.release()
        self._white.release()
        self.environment.release()
